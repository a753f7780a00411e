"""Strapdown INS and INS/GPS integrity (Yoo et al. 2010, INS half).

Inside: WGS-84 radii, gravity, Earth and transport rates; the NED strapdown step
(``NavState``), its inverse and the continuous equations; the 15 error states, their
feedback, ``F`` by ``jax.jacfwd`` and its discretisation; an HG1900-class IMU error model
(``hg1900``); UAV flights and their perfect IMU (``fly``); the GPS receiver and IMU as a
loop plant (``gps_ins_plant``); the 15-state error-state EKF as a ``Filter``
(``loosely_coupled_filter``); Da's state chi-square test with two propagators
(``state_chi2_test``); RAIM -> EKF -> chi-square and SCST as the loop's FDI stage
(``gps_ins_fdi``). The quaternion algebra is that of the reaction-wheel model.
"""
from jaxfdi.ins._imu import hg1900
from jaxfdi.ins._integrity import gps_ins_fdi
from jaxfdi.ins._loosely_coupled import loosely_coupled_filter
from jaxfdi.ins._mechanization import NavState
from jaxfdi.ins._plant import gps_ins_plant
from jaxfdi.ins._scst import state_chi2_test
from jaxfdi.ins._trajectory import fly

__all__ = [
    "NavState",
    "hg1900",
    "fly",
    "loosely_coupled_filter",
    "state_chi2_test",
    "gps_ins_plant",
    "gps_ins_fdi",
]
