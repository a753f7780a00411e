"""Control: discrete LQR with integral action, eigenstructure assignment of a
reconfigured gain for a faulty actuator, and the closed loop that switches to it when
the FDD isolates a fault (Lee & Lyou, Section IV); reaction-wheel attitude control (Choi & Park 2009);
F-16 stability augmentation with altitude and bank-angle hold (Park et al. 2004)."""
from jaxfdi.control.attitude import (
    AttitudeGains,
    Slew,
    allocate_wheel_torques,
    control_torque,
    pd_gains,
    slew,
    slew_reference,
)
from jaxfdi.control.closed_loop import LoopDesign, LoopStep, run_closed_loop
from jaxfdi.control.eigenstructure import (
    EigenstructureResult,
    GainSchedule,
    assign_eigenstructure,
    effectiveness_gain_schedule,
    effectiveness_input,
    scheduled_gain,
)
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
    "LoopDesign",
    "LoopStep",
    "PIDesign",
    "assign_eigenstructure",
    "effectiveness_gain_schedule",
    "effectiveness_input",
    "integral_augmentation",
    "lqr_gain",
    "lqr_pi",
    "run_closed_loop",
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
]
