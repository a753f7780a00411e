"""Control: discrete LQR with integral action, eigenstructure assignment of a reconfigured gain for a faulty actuator,
and the PI controller that switches to it when the FDD isolates a fault (Lee & Lyou, Section IV); reaction-wheel
attitude control and the spacecraft as a loop plant (Choi & Park 2009); F-16 stability augmentation with altitude and
bank-angle hold, and the sampled F-16 as loop stages (Park et al. 2004)."""
from jaxfdi.control._attitude import control_torque, slew
from jaxfdi.control._closed_loop import reconfigurable_pi
from jaxfdi.control._eigenstructure import assign_eigenstructure
from jaxfdi.control._f16_loop import f16_plant
from jaxfdi.control._flight import design_flight_control, flight_controller
from jaxfdi.control._lqr import lqr_gain, lqr_pi

__all__ = [
    "lqr_gain",
    "lqr_pi",
    "assign_eigenstructure",
    "reconfigurable_pi",
    "slew",
    "control_torque",
    "design_flight_control",
    "flight_controller",
    "f16_plant",
]
