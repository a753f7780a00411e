"""jaxfdi: model-based fault detection and isolation in JAX.

Top level: faults as data, the simulator, the closed loop's stages, scan and scorers, the fused monitor, the Monte Carlo
driver, the study engine, detection summaries with their intervals. Then ``filters``, ``detection`` (residual tests,
isolation), ``models``, ``control``, ``tuning``, ``gnss``, ``ins``, ``scenarios`` (the papers' studies), ``plotting``,
``streaming``, ``distributed``, and the modules ``checks`` and ``rotation``; the public API is their ``__all__`` (one
documentation page each).

Constants: ``NEVER`` a step beyond any simulation, 2**30: the ``end`` of a fault that never clears.
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
    from jaxfdi._io.progress import status
    from jaxfdi._numerics.riccati import steady_state_kalman
    from jaxfdi._simulation.faults import (
        NEVER,
        Fault,
        FaultKind,
        Target,
        as_stack,
        concat_faults,
        episodes,
        fault,
        fault_group,
        fault_label,
        is_active,
        no_fault,
        sensor_labels,
        stack_faults,
    )
    from jaxfdi._simulation.loop import (
        LoopResult,
        combine_scorers,
        detection_scorer,
        episode_scorer,
        feedforward,
        health_scorer,
        peak_scorer,
        run_loop,
        state_feedback,
    )
    from jaxfdi._simulation.monitor import MonitorHistory, MonitorResult, monitor, replay_detector
    from jaxfdi._simulation.simulate import Simulator, linear_simulator, simulate, simulator
    from jaxfdi._simulation.stages import FDI, Controller, Plant, Scorer
    from jaxfdi._simulation.tracking import TrackingScore, tracked_plant
    from jaxfdi._studies.frame import results_frame, study_result, text_table
    from jaxfdi._studies.metrics import (
        DetectionRecord,
        DetectionSummary,
        EpisodeRecord,
        EpisodeSummary,
        binomial_interval,
        binomial_lower_bound,
        cell,
        delay_statistics,
        fault_row,
        rate_cell,
        rate_interval,
        record_from_alarms,
        step_health,
        summarize_detection,
        summarize_episodes,
        unhealthy_rows_warning,
        unhealthy_warning,
    )
    from jaxfdi._studies.montecarlo import monte_carlo
    from jaxfdi._studies.study import Structure, Study, case_slices, run_study

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
    "jaxfdi._simulation.faults": (
        "Fault",
        "FaultKind",
        "concat_faults",
        "fault",
        "fault_group",
        "no_fault",
        "stack_faults",
        "NEVER",
        "Target",
        "as_stack",
        "episodes",
        "fault_label",
        "is_active",
        "sensor_labels",
    ),
    "jaxfdi._simulation.loop": (
        "LoopResult",
        "run_loop",
        "state_feedback",
        "combine_scorers",
        "detection_scorer",
        "episode_scorer",
        "feedforward",
        "health_scorer",
        "peak_scorer",
    ),
    "jaxfdi._studies.metrics": (
        "DetectionRecord",
        "DetectionSummary",
        "summarize_detection",
        "EpisodeRecord",
        "EpisodeSummary",
        "binomial_interval",
        "binomial_lower_bound",
        "cell",
        "delay_statistics",
        "fault_row",
        "rate_cell",
        "rate_interval",
        "record_from_alarms",
        "step_health",
        "summarize_episodes",
        "unhealthy_rows_warning",
        "unhealthy_warning",
    ),
    "jaxfdi._simulation.monitor": ("MonitorResult", "monitor", "MonitorHistory", "replay_detector"),
    "jaxfdi._studies.montecarlo": ("monte_carlo",),
    "jaxfdi._simulation.simulate": ("linear_simulator", "simulate", "simulator", "Simulator"),
    "jaxfdi._simulation.stages": ("FDI", "Controller", "Plant", "Scorer"),
    "jaxfdi._studies.study": ("Structure", "Study", "run_study", "case_slices"),
    "jaxfdi._studies.frame": ("results_frame", "study_result", "text_table"),
    "jaxfdi._io.progress": ("status",),
    "jaxfdi._numerics.riccati": ("steady_state_kalman",),
    "jaxfdi._simulation.tracking": ("TrackingScore", "tracked_plant"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str):
    """Everything but the version and the two switches is imported on first use (PEP 562), so that ``import jaxfdi``
    imports no JAX (``jaxfdi --help`` takes no JAX start-up): a top-level name from its module (``_EXPORTS``), a
    subpackage or module of the package (``jaxfdi.filters``, ``jaxfdi._simulation.faults``) by importing it. The
    value is kept in the package's namespace, so this runs once per name."""
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
    "Target",
    "fault",
    "fault_group",
    "no_fault",
    "stack_faults",
    "concat_faults",
    "as_stack",
    "episodes",
    "is_active",
    "fault_label",
    "sensor_labels",
    "NEVER",
    "Simulator",
    "simulator",
    "linear_simulator",
    "simulate",
    "steady_state_kalman",
    # the closed loop and its scorers, the monitor, tracking
    "Plant",
    "FDI",
    "Controller",
    "Scorer",
    "run_loop",
    "state_feedback",
    "feedforward",
    "LoopResult",
    "detection_scorer",
    "episode_scorer",
    "health_scorer",
    "peak_scorer",
    "combine_scorers",
    "monitor",
    "MonitorResult",
    "MonitorHistory",
    "replay_detector",
    "tracked_plant",
    "TrackingScore",
    # Monte Carlo and studies
    "monte_carlo",
    "Study",
    "Structure",
    "run_study",
    "case_slices",
    "study_result",
    "results_frame",
    "text_table",
    "status",
    # detection records, summaries, rates with their intervals, table cells
    "DetectionRecord",
    "record_from_alarms",
    "summarize_detection",
    "DetectionSummary",
    "EpisodeRecord",
    "summarize_episodes",
    "EpisodeSummary",
    "delay_statistics",
    "step_health",
    "binomial_interval",
    "binomial_lower_bound",
    "rate_interval",
    "rate_cell",
    "cell",
    "fault_row",
    "unhealthy_warning",
    "unhealthy_rows_warning",
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
