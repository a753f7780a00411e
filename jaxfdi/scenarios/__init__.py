"""Paper scenarios: short compositions of library pieces, each runnable from the CLI (its
``RUNNERS`` is the one registry of studies: ``jaxfdi list``)."""
from jaxfdi.scenarios.engine import EngineSettings, EngineStudy, engine_methods, engine_spec, engine_study, plot_engine
from jaxfdi.scenarios.engine_chi2 import EngineChi2Result, engine_chi2_study, engine_faults

__all__ = ["EngineChi2Result", "EngineSettings", "EngineStudy", "engine_chi2_study", "engine_faults",
           "engine_methods", "engine_spec", "engine_study", "plot_engine"]
