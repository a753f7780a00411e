"""The Stevens & Lewis F-16 (the aircraft of Park et al. 2004) as a JAX model: the book's tables and
Morelli's polynomial, engine and atmosphere, the 13-state dynamics, trim, linearisation
and modes, and the sampled plant with its sensors (its ``jaxfdi.loop`` stages:
``jaxfdi.control.f16_loop``).

References: Stevens & Lewis (2003) *Aircraft Control and Simulation*, 2nd ed. (App. A);
Morelli (1998) "Global nonlinear parametric modeling with application to F-16
aerodynamics"; Park, Kim, Park & Roh (2004).
"""
from jaxfdi.models.f16.aero import AeroCoefficients, table_coefficients
from jaxfdi.models.f16.atmosphere import AirData, air_data
from jaxfdi.models.f16.book import BookCase, book_cases, comparison_rows, trim_book_cases
from jaxfdi.models.f16.dynamics import (
    CONTROL_NAMES,
    STATE_NAMES,
    F16Params,
    aero_coefficients,
    f16_dynamics,
    f16_params,
    inertia_constants,
    saturate,
)
from jaxfdi.models.f16.engine import power_rate, throttle_gearing, thrust
from jaxfdi.models.f16._linearize import (
    LinearF16,
    Mode,
    flight_modes,
    lateral,
    lateral_modes,
    linearize,
    longitudinal,
    longitudinal_modes,
)
from jaxfdi.models.f16.morelli import MorelliCoefficients, morelli_coefficients_data, polynomial_coefficients
from jaxfdi.models.f16.plant import (
    MEASUREMENT_NAMES,
    F16Sensors,
    FlightView,
    f16_sensors,
    flight_view,
    rate_estimator,
    skewed_rate_axes,
)
from jaxfdi.models.f16.tables import (
    PROFILES,
    AeroTables,
    AtmosphereData,
    EngineData,
    aero_tables,
    atmosphere_data,
    engine_data,
    lookup1,
    lookup2,
    table_arrays,
)
from jaxfdi.models.f16._trim import (
    TrimCondition,
    TrimResult,
    climb,
    coordinated_turn,
    level_flight,
    pull_up,
    trim,
    trim_batch,
    trim_condition,
)

__all__ = [
    "AeroCoefficients", "table_coefficients", "AirData", "air_data", "BookCase", "book_cases", "comparison_rows",
    "trim_book_cases", "CONTROL_NAMES", "STATE_NAMES", "F16Params", "aero_coefficients", "f16_dynamics", "f16_params",
    "inertia_constants", "saturate", "power_rate", "throttle_gearing", "thrust", "LinearF16", "Mode", "flight_modes",
    "lateral", "lateral_modes", "linearize", "longitudinal", "longitudinal_modes", "MorelliCoefficients",
    "morelli_coefficients_data", "polynomial_coefficients", "MEASUREMENT_NAMES", "F16Sensors", "FlightView",
    "f16_sensors", "flight_view", "rate_estimator", "skewed_rate_axes",
    "PROFILES", "AeroTables", "AtmosphereData", "EngineData", "aero_tables", "atmosphere_data", "engine_data",
    "lookup1", "lookup2", "table_arrays", "TrimCondition", "TrimResult", "climb", "coordinated_turn", "level_flight",
    "pull_up", "trim", "trim_batch", "trim_condition",
]


# the UKF process model of Park et al. (2004): the body rates alone (moment equations 34-36)
from jaxfdi.models.f16.dynamics import moment_equations  # noqa: E402
from jaxfdi.models.f16.rates import (  # noqa: E402
    RATE_INPUT_NAMES,
    RateModel,
    rate_derivative,
    rate_model,
    rate_model_input,
    rate_observation,
    rate_transition,
)

__all__ += ["moment_equations", "RATE_INPUT_NAMES", "RateModel", "rate_derivative", "rate_model", "rate_model_input",
            "rate_observation", "rate_transition"]
