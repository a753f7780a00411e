"""Plant models: linear ones as ``LinearGaussianModel`` data, nonlinear ones as pure
``f(x, u, params)`` / ``h(x, u, params)`` with a params pytree."""
from jaxfdi.models.engine import engine_model
from jaxfdi.models.linear import (
    LinearGaussianModel,
    c2d,
    linear_observation,
    linear_transition,
    validate_linear_model,
)
from jaxfdi.models.rigid_body import (
    RigidBodyParams,
    rigid_body_observation,
    rigid_body_params,
    rigid_body_transition,
)

__all__ = [
    "LinearGaussianModel",
    "c2d",
    "linear_observation",
    "linear_transition",
    "validate_linear_model",
    "engine_model",
    "RigidBodyParams",
    "rigid_body_observation",
    "rigid_body_params",
    "rigid_body_transition",
]
