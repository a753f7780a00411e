"""Fault-tolerant control: discrete LQR with integral action, and eigenstructure
assignment of a reconfigured gain for a faulty actuator (seed 001, Section IV)."""
from jaxfdi.control.eigenstructure import EigenstructureResult, assign_eigenstructure, effectiveness_input
from jaxfdi.control.lqr import PIDesign, integral_augmentation, lqr_gain, lqr_pi

__all__ = [
    "EigenstructureResult",
    "PIDesign",
    "assign_eigenstructure",
    "effectiveness_input",
    "integral_augmentation",
    "lqr_gain",
    "lqr_pi",
]
