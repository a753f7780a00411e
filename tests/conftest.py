"""Tests run in float64 unless they test float32 explicitly (they then pass float32
arrays: the library keeps the caller's dtype).

Scheduling (``pytest -n auto --dist loadfile``): each test file goes to one worker as a
whole, in collection order. pytest-xdist >= 3.7 would reorder the files by their number
of tests (most first), which sends the expensive end-to-end files (a CLI run or a
notebook, one to ten tests each) to the end of the run, where one of them keeps a worker
busy while the other idles. Here the reordering is off and the files below start first,
the longest first (a longest-processing-time-first schedule); every other file follows
in its usual order. The list is a scheduling hint only: a file missing from it still
runs, a name that no longer exists is ignored."""
import jax

jax.config.update("jax_enable_x64", True)

#: the most expensive test files, longest first (seconds on 2 cores; see .ci/run)
HEAVY_FIRST = (
    "test_engine_scenario.py",
    "test_contracts.py",
    "test_linalg_batch.py",
    "test_engine_tuning.py",
    "test_f16_fdi.py",
    "test_notebook_gps_ins.py",
    "test_notebook_f16.py",
    "test_reaction_wheels_end_to_end.py",
    "test_notebook_tuning.py",
    "test_engine_chi2_tuning.py",
    "test_tuning.py",
    "test_reaction_wheels_model.py",
    "test_notebook_vtol.py",
    "test_cli.py",
    "test_notebook_kalman.py",
    "test_gnss_scenario.py",
    "test_vtol.py",
    "test_cli_validation.py",
)


def pytest_configure(config):
    if hasattr(config.option, "loadscopereorder"):  # pytest-xdist >= 3.7
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    # a stable sort: tests keep their order within a file, other files theirs
    items.sort(key=lambda item: rank.get(item.path.name, len(HEAVY_FIRST)))
