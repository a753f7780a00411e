"""Tests run in float64 unless they test float32 explicitly (they then pass float32
arrays: the library keeps the caller's dtype).

Scheduling (``pytest -n auto --dist loadfile``): each test file goes to one worker as a
whole, in collection order. pytest-xdist >= 3.7 would reorder the files by their number
of tests (most first), which sends the expensive end-to-end files (a CLI run or a
notebook, one to ten tests each) to the end of the run, where one of them keeps a worker
busy while the other idles. Here the reordering is off and the files below start first,
the longest first (a longest-processing-time-first schedule); every other file follows
in its usual order. The list is a scheduling hint only: a file missing from it still
runs, a name that no longer exists is ignored. Its entries are file names, matched in any
folder of ``tests/`` (the folders mirror ``jaxfdi/``; a test file's name is unique across
them, as pytest's default import mode needs without ``__init__.py`` files).

Imports: the shared helpers (``_problems.py``, ``_notebooks.py``, ...) stay in ``tests/``,
which ``pythonpath = ["tests"]`` (pyproject.toml) puts on ``sys.path`` for every folder.

Compilation (most of the suite's time): one persistent XLA compilation cache serves the
whole run, every worker and every process a test starts (CLI runs, notebook kernels:
``JAXFDI_CACHE_DIR``), so that a program compiled anywhere in the run, e.g. a scenario's
Monte Carlo that a CLI test and its notebook both run at the same size, is compiled once.

Memory maps: a compiled program stays loaded, about 3 memory maps of the process, while
JAX's caches hold it. A worker that runs half the suite loads some 20 thousand programs
and passes Linux's ``vm.max_map_count`` (65530), and its next compile, cache write or
cache read dies inside XLA with a segfault or an abort: four CI runs lost a worker that
way at 76-96 % (the 125 first tests of ``tests/filters`` alone reach 24.6k maps). So each
test module ends with ``jax.clear_caches()``, which unloads its programs
(``_release_programs``).

The persistent cache starts empty in a temporary folder made by the controller and is
deleted at the end: nothing is carried between runs, so a CI run still compiles
everything it uses once. (Compiling at LLVM optimisation level 0, ``--xla_backend_optimization_level=0``,
was tried and made the suite slower: 1727 s and 54.7 CPU-minutes for a fresh-clone run,
the programs' runs being slower by more than their compilation got cheaper, and a float32
square-root UKF test moved by 4 %.)"""

import gc
import os
import shutil
import tempfile

import jax
import pytest

jax.config.update("jax_enable_x64", True)

#: fixtures shared by the notebook tests (``python3_kernel``)
pytest_plugins = ["_notebooks"]

#: the run's shared XLA cache folder (set by the controller, inherited by the workers)
_CACHE_ENV = "JAXFDI_TEST_XLA_CACHE"
#: programs that compile faster than this in a test process are not written to the cache
#: (the CLI and the notebooks write every program: ``jaxfdi.enable_compilation_cache``)
_CACHE_MIN_COMPILE_S = 0.2

#: the most expensive test files, longest first (seconds on 2 cores; see .ci/run)
HEAVY_FIRST = (
    "test_engine_scenario.py",
    "test_f16_fdi.py",
    "test_filter_contracts.py",
    "test_detector_contracts.py",
    "test_linalg_batch.py",
    "test_engine_tuning.py",
    "test_vtol.py",
    "test_ins_integrity.py",
    "test_reaction_wheels_end_to_end.py",
    "test_gnss_real.py",
    "test_engine_chi2_tuning.py",
    "test_tuning.py",
    "test_reaction_wheels_model.py",
    "test_cli.py",
    "test_notebook_kalman.py",
    "test_gnss_scenario.py",
    "test_cli_validation.py",
)


def pytest_configure(config):
    if hasattr(config.option, "loadscopereorder"):  # pytest-xdist >= 3.7
        config.option.loadscopereorder = False
    if not hasattr(config, "workerinput") and _CACHE_ENV not in os.environ:  # the controller
        config._jaxfdi_xla_cache = os.environ[_CACHE_ENV] = tempfile.mkdtemp(
            prefix="jaxfdi-test-xla-"
        )
    cache = os.environ.get(_CACHE_ENV)
    if cache:
        import jaxfdi

        os.environ["JAXFDI_CACHE_DIR"] = cache  # every subprocess (CLI, notebook kernel)
        jaxfdi.enable_compilation_cache(cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", _CACHE_MIN_COMPILE_S)


def pytest_unconfigure(config):
    cache = getattr(config, "_jaxfdi_xla_cache", None)
    if cache:
        shutil.rmtree(cache, ignore_errors=True)


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    # a stable sort: tests keep their order within a file, other files theirs
    items.sort(key=lambda item: rank.get(item.path.name, len(HEAVY_FIRST)))


@pytest.fixture(autouse=True, scope="module")
def _release_programs():
    """After each test module, drop JAX's caches so that its compiled programs are
    unloaded (module doc: a worker otherwise runs out of memory maps)."""
    yield
    jax.clear_caches()
    gc.collect()
