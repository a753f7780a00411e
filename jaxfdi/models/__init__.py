"""Plant models: linear ones as ``LinearGaussianModel`` data, nonlinear ones as pure ``f(x, u, params)`` /
``h(x, u, params)`` with a params pytree.

Constants: ``ENGINE_OUTPUT_NAMES`` the turbojet's outputs, ``("RPM", "P2", "T2", "P4", "T4")``;
``ENGINE_OPERATING_POINT`` their values at the operating point, a (5,) NumPy array ``[27000, 3398, 442, 1657, 1025]``
(RPM, P2, T2 [K], P4, T4 [K]); ``ENGINE_TS`` the engine's sample period, 0.01 s; ``VTOL_TS`` the VTOL's sample period,
0.1 s; ``VTOL_X0`` the VTOL's initial state, a (4,) NumPy array ``[50, 1, 5, 1]`` (``[v_h, v_v, q, theta]``, Lee & Lyou
Section V).
"""

from jaxfdi.models import f16
from jaxfdi.models._engine import OUTPUT_NAMES as ENGINE_OUTPUT_NAMES
from jaxfdi.models._engine import OUTPUT_OPERATING_POINT as ENGINE_OPERATING_POINT
from jaxfdi.models._engine import TS as ENGINE_TS
from jaxfdi.models._engine import engine_model
from jaxfdi.models._fault_modes import bias_mode_initial_state, bias_modes, noise_inflation_modes
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
    body_rate_field,
    delivered_torque,
    filter_input,
    gyro_observation,
    kitsat3_params,
    spacecraft_step,
    stop_hypotheses,
    stop_transfer,
    wheel_momentum,
    wheel_rate_transition,
)
from jaxfdi.models._vtol import TS as VTOL_TS
from jaxfdi.models._vtol import X0 as VTOL_X0
from jaxfdi.models._vtol import vtol_model, vtol_true_plant, vtol_unknown_input

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
    "ENGINE_OUTPUT_NAMES",
    "ENGINE_OPERATING_POINT",
    "ENGINE_TS",
    "bias_mode_initial_state",
    "bias_modes",
    "noise_inflation_modes",
    "body_rate_field",
    "filter_input",
    "gyro_observation",
    "stop_hypotheses",
    "wheel_rate_transition",
    "VTOL_TS",
    "VTOL_X0",
    "vtol_model",
    "vtol_true_plant",
    "vtol_unknown_input",
]
