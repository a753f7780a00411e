"""Strapdown INS and INS/GPS integrity (Yoo et al. 2010, INS half).

Modules: ``earth`` (WGS-84 radii, gravity, Earth and transport rates), ``mechanization``
(NED strapdown step, its inverse, the continuous equations), ``error_state`` (the 15 error states, feedback, ``F`` by
``jax.jacfwd``, discretisation), ``imu`` (HG1900-class error model), ``trajectory`` (UAV
flights and their perfect IMU), ``plant`` (GPS receiver + IMU as a loop plant),
``loosely_coupled`` (the 15-state error-state EKF as a ``Filter``), ``scst`` (Da's state
chi-square test with two propagators), ``integrity`` (RAIM -> EKF -> chi-square and SCST as
the loop's FDI stage). The quaternion algebra is ``jaxfdi.models.rotation``.
"""

#: the subpackage's modules (imported on ``from jaxfdi.ins import *``)
__all__ = ["earth", "error_state", "imu", "integrity", "loosely_coupled", "mechanization", "plant", "scst",
           "trajectory"]
