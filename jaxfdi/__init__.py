"""jaxfdi: model-based fault detection and isolation in JAX.

Top level: faults as data, the simulator, the closed loop's stages and scan, the fused monitor, the Monte Carlo driver,
the study engine, detection summaries. Then ``filters``, ``detection`` (residual tests, isolation), ``models``,
``control``, ``tuning``, ``gnss``, ``ins``, ``scenarios`` (the papers' studies), ``plotting``, ``streaming``,
``distributed``; the public API is their ``__all__`` (one documentation page).
"""

from jaxfdi import _version, detection, filters, models
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


_LAZY_SUBMODULES = (
    "control",
    "tuning",
    "gnss",
    "ins",
    "scenarios",
    "plotting",
    "streaming",
    "distributed",
)


def __getattr__(name: str):
    """The subpackages beyond the core (``control`` and ``tuning`` import optax, ~0.1 s) are imported on first use, not
    by ``import jaxfdi``."""
    if name in _LAZY_SUBMODULES:
        import importlib

        return importlib.import_module(f"jaxfdi.{name}")
    raise AttributeError(f"module 'jaxfdi' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_SUBMODULES))


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
