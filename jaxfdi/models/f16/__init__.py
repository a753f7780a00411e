"""The Stevens & Lewis F-16 (the aircraft of Park et al. 2004) as a JAX model: the book's tables and Morelli's
polynomial, engine and atmosphere, the 13-state dynamics, trim, linearisation and modes, and the sampled plant with its
sensors (as a stage of the closed loop: ``jaxfdi.control.f16_plant``).

Indices (Stevens & Lewis's names): the states ``VT``, ``ALPHA``, ``BETA``, ``PHI``, ``THETA``, ``PSI``, ``P``,
``Q``, ``R``, ``PN``, ``PE``, ``H``, ``POW`` are 0-12 of the 13-state vector and the inputs ``THTL``, ``EL``,
``AIL``, ``RDR`` 0-3 of the control vector; ``LATERAL_STATES`` (beta, phi, p, r), ``LATERAL_INPUTS`` (aileron,
rudder) and ``LONGITUDINAL_DESIGN_STATES`` (vt, alpha, theta, q, h, pow) select a linear model's blocks
(``submodel``); ``RATE_OFFSET`` is the first rate channel in the sampled plant's measurement.

References: Stevens & Lewis (2003) *Aircraft Control and Simulation*, 2nd ed. (App. A); Morelli (1998) "Global nonlinear
parametric modeling with application to F-16 aerodynamics"; Park, Kim, Park & Roh (2004).
"""

from jaxfdi.models.f16._dynamics import (
    AIL,
    ALPHA,
    BETA,
    EL,
    PE,
    PHI,
    PN,
    POW,
    PSI,
    RDR,
    THETA,
    THTL,
    VT,
    F16Params,
    H,
    P,
    Q,
    R,
    f16_dynamics,
    f16_params,
)
from jaxfdi.models.f16._linearize import (
    LATERAL_INPUTS,
    LATERAL_STATES,
    LONGITUDINAL_DESIGN_STATES,
    LinearF16,
    linearize,
    submodel,
)
from jaxfdi.models.f16._plant import (
    RATE_OFFSET,
    F16Sensors,
    FlightView,
    SampledF16,
    f16_sensors,
    flight_view,
    measurement_cov,
    rate_estimator,
    sampled_observation,
    sampled_transition,
)
from jaxfdi.models.f16._rates import rate_model
from jaxfdi.models.f16._trim import (
    TrimCondition,
    TrimResult,
    climb,
    coordinated_turn,
    level_flight,
    pull_up,
    trim,
    trim_batch,
)

__all__ = [
    "VT",
    "ALPHA",
    "BETA",
    "PHI",
    "THETA",
    "PSI",
    "P",
    "Q",
    "R",
    "PN",
    "PE",
    "H",
    "POW",
    "THTL",
    "EL",
    "AIL",
    "RDR",
    "LATERAL_STATES",
    "LATERAL_INPUTS",
    "LONGITUDINAL_DESIGN_STATES",
    "LinearF16",
    "submodel",
    "FlightView",
    "RATE_OFFSET",
    "F16Sensors",
    "SampledF16",
    "flight_view",
    "measurement_cov",
    "rate_estimator",
    "sampled_observation",
    "sampled_transition",
    "TrimResult",
    "climb",
    "coordinated_turn",
    "level_flight",
    "pull_up",
    "trim_batch",
    "F16Params",
    "f16_params",
    "f16_dynamics",
    "TrimCondition",
    "trim",
    "linearize",
    "f16_sensors",
    "rate_model",
]
