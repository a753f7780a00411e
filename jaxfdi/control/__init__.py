"""Control: discrete LQR and LQR-PI, eigenstructure assignment of a reconfigured gain for a faulty actuator (Lee & Lyou,
Section IV); F-16 stability augmentation with altitude and bank-angle hold, and the sampled F-16 as loop stages (Park
et al. 2004). Inside, and composed by the studies (``jaxfdi.scenarios.vtol_loop``,
``jaxfdi.scenarios.reaction_wheels``): the PI controller that switches to the reconfigured gain when the FDD isolates a
fault, and the reaction-wheel attitude loop with the spacecraft as a loop plant (Choi & Park 2009)."""

from jaxfdi.control._eigenstructure import assign_eigenstructure
from jaxfdi.control._f16_loop import f16_plant
from jaxfdi.control._flight import FlightWeights, design_flight_control, flight_controller
from jaxfdi.control._lqr import lqr_gain, lqr_pi

__all__ = [
    "lqr_gain",
    "lqr_pi",
    "assign_eigenstructure",
    "FlightWeights",
    "design_flight_control",
    "flight_controller",
    "f16_plant",
]
