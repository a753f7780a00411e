"""The Stevens & Lewis F-16 (the aircraft of Park et al. 2004) as a JAX model: the book's tables and Morelli's
polynomial, engine and atmosphere, the 13-state dynamics, trim, linearisation and modes, and the sampled plant with its
sensors (as a stage of the closed loop: ``jaxfdi.control.f16_plant``).

References: Stevens & Lewis (2003) *Aircraft Control and Simulation*, 2nd ed. (App. A); Morelli (1998) "Global nonlinear
parametric modeling with application to F-16 aerodynamics"; Park, Kim, Park & Roh (2004).
"""

from jaxfdi.models.f16._dynamics import F16Params, f16_dynamics, f16_params
from jaxfdi.models.f16._linearize import linearize
from jaxfdi.models.f16._plant import f16_sensors
from jaxfdi.models.f16._rates import rate_model
from jaxfdi.models.f16._trim import TrimCondition, trim

__all__ = [
    "F16Params",
    "f16_params",
    "f16_dynamics",
    "TrimCondition",
    "trim",
    "linearize",
    "f16_sensors",
    "rate_model",
]
