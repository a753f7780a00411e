"""Paper scenarios: short compositions of library pieces, each runnable from the CLI (its
``RUNNERS`` is the one registry of studies: ``jaxfdi list``)."""
from jaxfdi.scenarios.engine import EngineStudy, engine_spec, engine_study
from jaxfdi.scenarios.engine_chi2 import engine_chi2_study

__all__ = [
    "EngineStudy",
    "engine_spec",
    "engine_study",
    "engine_chi2_study",
]
