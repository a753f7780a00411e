"""jaxfdi: model-based fault detection and isolation in JAX.

Top level: faults as data, the simulator, the closed loop's stages and scan, the fused monitor, the Monte Carlo driver,
the study engine, detection summaries. Then ``filters``, ``detection`` (residual tests, isolation), ``models``,
``control``, ``tuning``, ``gnss``, ``ins``, ``scenarios`` (the papers' studies), ``plotting``, ``streaming``,
``distributed``; the public API is their ``__all__`` (one documentation page).
"""

import importlib
import importlib.util
from typing import TYPE_CHECKING

from jaxfdi import _version

# what ``__getattr__`` gives, for type checkers and the API page (mkdocstrings reads the source, not the module)
if TYPE_CHECKING:
    from jaxfdi import (
        control,
        detection,
        distributed,
        filters,
        gnss,
        ins,
        models,
        plotting,
        scenarios,
        streaming,
        tuning,
    )
    from jaxfdi._faults import (
        Fault,
        FaultKind,
        concat_faults,
        fault,
        fault_group,
        no_fault,
        stack_faults,
    )
    from jaxfdi._loop import LoopResult, run_loop, state_feedback
    from jaxfdi._metrics import DetectionRecord, DetectionSummary, summarize_detection
    from jaxfdi._monitor import MonitorResult, monitor
    from jaxfdi._montecarlo import monte_carlo
    from jaxfdi._simulate import linear_simulator, simulate, simulator
    from jaxfdi._stages import FDI, Controller, Plant, Scorer
    from jaxfdi._study import Structure, Study, run_study

__version__ = _version.__version__


def enable_x64(enable: bool = True) -> None:
    """Switch JAX to float64 (library code never does this by itself).

    Returns:
      None; it sets ``jax_enable_x64`` to ``enable`` (``False`` switches back to float32).
    """
    import jax

    jax.config.update("jax_enable_x64", enable)


def enable_compilation_cache(path: str | None = None) -> str:
    """Keep compiled XLA programs on disk (a repeated run skips most compilation); ``path`` defaults to
    ``$JAXFDI_CACHE_DIR`` or ``~/.cache/jaxfdi/xla``.

    Returns:
      str, the folder used for the cache.
    """
    import os
    from pathlib import Path

    import jax

    cache = path or os.environ.get(
        "JAXFDI_CACHE_DIR", str(Path.home() / ".cache" / "jaxfdi" / "xla")
    )
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    return cache


#: the top-level names, by the module that defines them (the ``TYPE_CHECKING`` imports above, which a test holds equal)
_EXPORTS = {
    "jaxfdi._faults": (
        "Fault",
        "FaultKind",
        "concat_faults",
        "fault",
        "fault_group",
        "no_fault",
        "stack_faults",
    ),
    "jaxfdi._loop": ("LoopResult", "run_loop", "state_feedback"),
    "jaxfdi._metrics": ("DetectionRecord", "DetectionSummary", "summarize_detection"),
    "jaxfdi._monitor": ("MonitorResult", "monitor"),
    "jaxfdi._montecarlo": ("monte_carlo",),
    "jaxfdi._simulate": ("linear_simulator", "simulate", "simulator"),
    "jaxfdi._stages": ("FDI", "Controller", "Plant", "Scorer"),
    "jaxfdi._study": ("Structure", "Study", "run_study"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str):
    """Everything but the version and the two switches is imported on first use (PEP 562), so that ``import jaxfdi``
    imports no JAX (``jaxfdi --help`` takes no JAX start-up): a top-level name from its module (``_EXPORTS``), a
    subpackage or module of the package (``jaxfdi.filters``, ``jaxfdi._faults``) by importing it. The value is kept in
    the package's namespace, so this runs once per name."""
    if name in _WHERE:
        value = getattr(importlib.import_module(_WHERE[name]), name)
    elif (
        name.isidentifier()
        and not name.startswith("__")
        and importlib.util.find_spec(f"{__name__}.{name}") is not None
    ):
        value = importlib.import_module(f"{__name__}.{name}")
    else:
        raise AttributeError(f"module 'jaxfdi' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


__all__ = [
    # faults and simulation
    "Fault",
    "FaultKind",
    "fault",
    "fault_group",
    "no_fault",
    "stack_faults",
    "concat_faults",
    "simulator",
    "linear_simulator",
    "simulate",
    # the closed loop, the monitor, Monte Carlo, studies, summaries
    "Plant",
    "FDI",
    "Controller",
    "Scorer",
    "run_loop",
    "state_feedback",
    "LoopResult",
    "monitor",
    "MonitorResult",
    "monte_carlo",
    "Study",
    "Structure",
    "run_study",
    "DetectionRecord",
    "summarize_detection",
    "DetectionSummary",
    # set-up
    "enable_x64",
    "enable_compilation_cache",
    # subpackages
    "filters",
    "detection",
    "models",
    "control",
    "tuning",
    "gnss",
    "ins",
    "scenarios",
    "plotting",
    "streaming",
    "distributed",
]
