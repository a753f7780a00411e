"""Strapdown INS and INS/GPS integrity (Yoo et al. 2010, INS half).

Public: the NED strapdown step (``strapdown_step`` on a ``NavState``); the 15-state error model's system matrix, ``F``
by ``jax.jacfwd`` (``error_jacobian``); an HG1900-class IMU error model (``hg1900``); UAV flights and their perfect IMU
(``fly``); the error-state EKF as a ``Filter`` (``loosely_coupled_filter``) on the receiver's fixes (``GpsFix``); Da's
state chi-square test with two propagators (``state_chi2_test``). Inside, and assembled by the GPS/INS study
(``jaxfdi.scenarios.gps_ins``): WGS-84 radii, gravity, Earth and transport rates, the step's inverse, the error state's
feedback and discretisation, the GPS receiver and IMU as a loop plant, and RAIM -> EKF -> chi-square and SCST as the
loop's FDI stage. The quaternion algebra is that of the reaction-wheel model.
"""

from jaxfdi.ins._error_state import error_jacobian
from jaxfdi.ins._imu import hg1900
from jaxfdi.ins._loosely_coupled import GpsFix, loosely_coupled_filter
from jaxfdi.ins._mechanization import NavState, strapdown_step
from jaxfdi.ins._scst import state_chi2_test
from jaxfdi.ins._trajectory import fly

__all__ = [
    "NavState",
    "strapdown_step",
    "error_jacobian",
    "hg1900",
    "fly",
    "GpsFix",
    "loosely_coupled_filter",
    "state_chi2_test",
]
