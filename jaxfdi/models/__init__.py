"""Plant models: linear ones as ``LinearGaussianModel`` data, nonlinear ones as pure ``f(x, u, params)`` /
``h(x, u, params)`` with a params pytree."""

from jaxfdi.models import f16
from jaxfdi.models._engine import engine_model
from jaxfdi.models._linear import (
    LinearGaussianModel,
    c2d,
    linear_gaussian_model,
    linear_observation,
    linear_transition,
    validate_linear_model,
)
from jaxfdi.models._reaction_wheels import (
    AttitudeReading,
    SpacecraftParams,
    WheelCommand,
    delivered_torque,
    kitsat3_params,
    spacecraft_step,
    stop_transfer,
    wheel_momentum,
)

__all__ = [
    "validate_linear_model",
    "linear_observation",
    "linear_transition",
    "AttitudeReading",
    "SpacecraftParams",
    "WheelCommand",
    "delivered_torque",
    "spacecraft_step",
    "stop_transfer",
    "wheel_momentum",
    "LinearGaussianModel",
    "linear_gaussian_model",
    "c2d",
    "engine_model",
    "kitsat3_params",
    "f16",
]
