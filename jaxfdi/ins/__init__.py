"""Strapdown INS and INS/GPS integrity (Yoo et al. 2010, INS half).

Modules: ``earth`` (WGS-84 radii, gravity, Earth and transport rates), ``mechanization``
(NED strapdown step, its inverse, the continuous equations), ``error_state`` (the 15 error states, feedback, ``F`` by
``jax.jacfwd``, discretisation), ``imu`` (HG1900-class error model), ``trajectory`` (UAV
flights and their perfect IMU), ``plant`` (GPS receiver + IMU as a loop plant),
``loosely_coupled`` (the 15-state error-state EKF as a ``Filter``), ``scst`` (Da's state
chi-square test with two propagators), ``integrity`` (RAIM -> EKF -> chi-square and SCST as
the loop's FDI stage). The quaternion algebra is ``jaxfdi.models.rotation``.
"""
from jaxfdi.ins.imu import hg1900
from jaxfdi.ins.integrity import gps_ins_fdi
from jaxfdi.ins.loosely_coupled import loosely_coupled_filter
from jaxfdi.ins.mechanization import NavState
from jaxfdi.ins.plant import gps_ins_plant
from jaxfdi.ins.scst import state_chi2_test
from jaxfdi.ins.trajectory import fly

__all__ = [
    "NavState",
    "hg1900",
    "fly",
    "loosely_coupled_filter",
    "state_chi2_test",
    "gps_ins_plant",
    "gps_ins_fdi",
]
