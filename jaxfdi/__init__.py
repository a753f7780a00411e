"""jaxfdi: model-based fault detection and isolation in JAX."""
from jaxfdi.filters import (
    Filter,
    FilterInfo,
    GaussianState,
    extended_kalman_filter,
    interacting_multiple_model,
    kalman_filter,
    multiple_model,
    run_filter,
    two_stage_kalman_filter,
    unscented_kalman_filter,
)
from jaxfdi.filters import init_from_posterior
from jaxfdi.models import LinearGaussianModel, c2d, linear_gaussian_model

from jaxfdi import _version

__version__ = _version.__version__


def enable_x64(enable: bool = True) -> None:
    """Switch JAX to float64 (library code never does this by itself)."""
    import jax

    jax.config.update("jax_enable_x64", enable)


def enable_compilation_cache(path: str | None = None) -> str:
    """Keep compiled XLA programs on disk so that a repeated run (a CLI call, a notebook
    re-run) skips most compilation. ``path`` defaults to ``$JAXFDI_CACHE_DIR`` or
    ``~/.cache/jaxfdi/xla``; returns the folder used."""
    import os
    from pathlib import Path

    import jax

    cache = path or os.environ.get("JAXFDI_CACHE_DIR", str(Path.home() / ".cache" / "jaxfdi" / "xla"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    return cache

from jaxfdi import detection, faults, loop, metrics, models  # noqa: E402
from jaxfdi.detection import chi2_detector, chi2_threshold, glrt_detector, mode_probability_detector  # noqa: E402
from jaxfdi.faults import (  # noqa: E402
    Fault,
    FaultKind,
    Target,
    active_label,
    concat_faults,
    episodes,
    fault,
    fault_group,
    no_fault,
    stack_faults,
)
from jaxfdi.loop import LoopResult, LoopTrace, detection_scorer, episode_scorer, feedforward, run_loop, state_feedback
from jaxfdi.stages import Controller, FDI, Plant, Scorer
from jaxfdi.metrics import (  # noqa: E402
    DetectionRecord,
    DetectionSummary,
    EpisodeRecord,
    EpisodeSummary,
    confusion_matrix,
    step_health,
    summarize_detection,
    summarize_episodes,
)
from jaxfdi.montecarlo import monte_carlo  # noqa: E402
from jaxfdi.riccati import solve_discrete_are, steady_state_kalman  # noqa: E402
from jaxfdi._monitor import MonitorHistory, MonitorResult, monitor, replay_detector  # noqa: E402
from jaxfdi._simulate import SimStep, Simulator, linear_simulator, simulate, simulator  # noqa: E402


_LAZY_SUBMODULES = ("control", "tuning", "streaming", "distributed", "plotting")


def __getattr__(name: str):
    """``jaxfdi.control`` and ``jaxfdi.tuning`` (which import optax, ~0.1 s) and the
    multi-host helpers are imported on first use, not by ``import jaxfdi``."""
    if name in _LAZY_SUBMODULES:
        import importlib

        return importlib.import_module(f"jaxfdi.{name}")
    raise AttributeError(f"module 'jaxfdi' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_SUBMODULES))


__all__ = [
    # filters and models
    "Filter", "FilterInfo", "GaussianState", "LinearGaussianModel", "c2d", "extended_kalman_filter",
    "init_from_posterior", "interacting_multiple_model", "kalman_filter", "linear_gaussian_model",
    "multiple_model", "run_filter", "two_stage_kalman_filter", "unscented_kalman_filter",
    "solve_discrete_are", "steady_state_kalman",
    # faults and simulation
    "Fault", "FaultKind", "Target", "active_label", "concat_faults", "episodes", "fault", "fault_group",
    "no_fault", "stack_faults", "SimStep", "Simulator", "linear_simulator", "simulator",
    # detection, loop, Monte Carlo, metrics
    "chi2_detector", "chi2_threshold", "glrt_detector", "mode_probability_detector",
    "FDI", "Controller", "LoopResult", "LoopTrace", "Plant", "Scorer", "detection_scorer", "episode_scorer",
    "feedforward", "run_loop", "state_feedback", "MonitorHistory", "MonitorResult", "replay_detector",
    "monte_carlo", "DetectionRecord", "DetectionSummary", "EpisodeRecord", "EpisodeSummary",
    "confusion_matrix", "step_health", "summarize_detection", "summarize_episodes",
    # set-up
    "enable_x64", "enable_compilation_cache",
    # subpackages and modules
    "control", "detection", "faults", "filters", "loop", "metrics", "models", "monitor", "montecarlo",
    "plotting", "progress", "riccati", "simulate", "streaming", "tuning", "distributed",
]
