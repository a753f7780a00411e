"""Control: discrete LQR and LQR-PI, eigenstructure assignment of a reconfigured gain for a faulty actuator (Lee & Lyou,
Section IV); F-16 stability augmentation with altitude and bank-angle hold, and the sampled F-16 as loop stages (Park
et al. 2004). Inside, and composed by the studies (``jaxfdi.scenarios.vtol_loop``,
``jaxfdi.scenarios.reaction_wheels``): the PI controller that switches to the reconfigured gain when the FDD isolates a
fault, and the reaction-wheel attitude loop with the spacecraft as a loop plant (Choi & Park 2009).

Constants: ``LONGITUDINAL_TRACKED`` the F-16 longitudinal axis's tracked outputs, ``(0, 4)`` (VT and h, indices into
``[VT, alpha, theta, Q, h, pow]``); ``LATERAL_TRACKED`` the lateral axis's, ``(1,)`` (phi, an index into
``[beta, phi, P, R]``): each has an integrator in the LQR-PI design.
"""

from jaxfdi.control._attitude import (
    AttitudeGains,
    Slew,
    pd_gains,
    slew,
    slew_reference,
    wheel_attitude_controller,
    wheel_plant,
)
from jaxfdi.control._closed_loop import Reconfiguration, reconfigurable_pi
from jaxfdi.control._eigenstructure import (
    GainSchedule,
    assign_eigenstructure,
    effectiveness_gain_schedule,
    nominal_eigenstructure,
)
from jaxfdi.control._f16_loop import f16_plant, rate_passthrough_fdi
from jaxfdi.control._flight import (
    LATERAL_TRACKED,
    LONGITUDINAL_TRACKED,
    FlightGains,
    FlightPlan,
    FlightReference,
    FlightWeights,
    commanded_profile,
    default_weights,
    design_flight_control,
    flight_controller,
    flight_plan,
    flight_reference,
    initial_condition,
    plan_trims,
)
from jaxfdi.control._lqr import integral_augmentation, lqr_gain, lqr_pi

__all__ = [
    "lqr_gain",
    "lqr_pi",
    "assign_eigenstructure",
    "FlightWeights",
    "design_flight_control",
    "flight_controller",
    "f16_plant",
    "AttitudeGains",
    "Slew",
    "pd_gains",
    "slew",
    "slew_reference",
    "wheel_attitude_controller",
    "wheel_plant",
    "Reconfiguration",
    "reconfigurable_pi",
    "GainSchedule",
    "effectiveness_gain_schedule",
    "nominal_eigenstructure",
    "rate_passthrough_fdi",
    "FlightGains",
    "FlightPlan",
    "FlightReference",
    "LATERAL_TRACKED",
    "LONGITUDINAL_TRACKED",
    "commanded_profile",
    "default_weights",
    "flight_plan",
    "flight_reference",
    "initial_condition",
    "plan_trims",
    "integral_augmentation",
]
