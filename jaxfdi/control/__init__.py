"""Control: discrete LQR with integral action, eigenstructure assignment of a
reconfigured gain for a faulty actuator, and the PI controller that switches to it when
the FDD isolates a fault (Lee & Lyou, Section IV); reaction-wheel attitude control and
the spacecraft as a loop plant (Choi & Park 2009); F-16 stability augmentation with
altitude and bank-angle hold, and the sampled F-16 as loop stages (Park et al. 2004)."""
from jaxfdi.control.attitude import (
    AttitudeGains,
    Slew,
    allocate_wheel_torques,
    control_torque,
    pd_gains,
    slew,
    slew_reference,
)
from jaxfdi.control.closed_loop import Reconfiguration, reconfigurable_pi
from jaxfdi.control.eigenstructure import (
    EigenstructureResult,
    GainSchedule,
    assign_eigenstructure,
    effectiveness_gain_schedule,
    effectiveness_input,
    scheduled_gain,
)
from jaxfdi.control.f16_loop import f16_plant, rate_passthrough_fdi
from jaxfdi.control.flight import (
    FlightDesign,
    FlightGains,
    FlightPlan,
    FlightReference,
    FlightWeights,
    bryson_weights,
    commanded_profile,
    default_weights,
    design_flight_control,
    flight_controller,
    flight_plan,
    flight_reference,
    initial_condition,
    plan_trims,
)
from jaxfdi.control.lqr import PIDesign, integral_augmentation, lqr_gain, lqr_pi

__all__ = [
    "AttitudeGains",
    "Slew",
    "allocate_wheel_torques",
    "control_torque",
    "pd_gains",
    "slew",
    "slew_reference",
    "EigenstructureResult",
    "GainSchedule",
    "Reconfiguration",
    "PIDesign",
    "assign_eigenstructure",
    "effectiveness_gain_schedule",
    "effectiveness_input",
    "integral_augmentation",
    "lqr_gain",
    "lqr_pi",
    "reconfigurable_pi",
    "scheduled_gain",
    "FlightDesign",
    "FlightGains",
    "FlightPlan",
    "FlightReference",
    "FlightWeights",
    "bryson_weights",
    "commanded_profile",
    "default_weights",
    "design_flight_control",
    "flight_controller",
    "flight_plan",
    "flight_reference",
    "initial_condition",
    "plan_trims",
    "f16_plant",
    "rate_passthrough_fdi",
]
