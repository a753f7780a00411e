"""Paper scenarios: short compositions of library pieces, each runnable from the CLI."""
from jaxfdi.scenarios.engine import EngineSettings, EngineStudy, engine_methods, engine_spec, engine_study, plot_engine
from jaxfdi.scenarios.engine_chi2 import EngineChi2Result, engine_chi2_study, engine_faults

#: study functions by name (the CLI has every scenario: ``jaxfdi list``)
SCENARIOS = {"engine": engine_study, "engine-chi2": engine_chi2_study}

__all__ = ["SCENARIOS", "EngineChi2Result", "EngineSettings", "EngineStudy", "engine_chi2_study", "engine_faults",
           "engine_methods", "engine_spec", "engine_study", "plot_engine"]
