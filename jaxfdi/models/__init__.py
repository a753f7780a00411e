"""Plant models: linear ones as ``LinearGaussianModel`` data, nonlinear ones as pure
``f(x, u, params)`` / ``h(x, u, params)`` with a params pytree."""
from jaxfdi.models import f16
from jaxfdi.models.engine import engine_model
from jaxfdi.models.f16 import F16Params, f16_dynamics, f16_params, f16_sensors
from jaxfdi.models.fault_modes import bias_mode_initial_state, bias_modes, noise_inflation_modes
from jaxfdi.models.linear import (
    LinearGaussianModel,
    c2d,
    linear_gaussian_model,
    linear_observation,
    linear_transition,
    validate_linear_model,
)
from jaxfdi.models.reaction_wheels import (
    SpacecraftParams,
    body_rate_field,
    gyro_observation,
    kitsat3_params,
    pyramid_axes,
    rate_jacobian,
    spacecraft_step,
    stop_hypotheses,
    total_momentum,
    wheel_rate_transition,
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
    "linear_gaussian_model",
    "linear_observation",
    "linear_transition",
    "validate_linear_model",
    "engine_model",
    "f16",
    "F16Params",
    "f16_dynamics",
    "f16_params",
    "f16_sensors",
    "noise_inflation_modes",
    "bias_modes",
    "bias_mode_initial_state",
    "SpacecraftParams",
    "body_rate_field",
    "gyro_observation",
    "kitsat3_params",
    "pyramid_axes",
    "rate_jacobian",
    "spacecraft_step",
    "stop_hypotheses",
    "total_momentum",
    "wheel_rate_transition",
    "RigidBodyParams",
    "rigid_body_observation",
    "rigid_body_params",
    "rigid_body_transition",
]
