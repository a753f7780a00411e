"""Strapdown INS and INS/GPS integrity (Yoo et al. 2010, INS half).

Public: the NED strapdown step (``strapdown_step`` on a ``NavState``); the 15-state error model's system matrix, ``F``
by ``jax.jacfwd`` (``error_jacobian``); an HG1900-class IMU error model (``hg1900``); UAV flights and their perfect IMU
(``fly``); the error-state EKF as a ``Filter`` (``loosely_coupled_filter``) on the receiver's fixes (``GpsFix``); Da's
state chi-square test with two propagators (``state_chi2_test``). Inside, and assembled by the GPS/INS study
(``jaxfdi.scenarios.gps_ins``): WGS-84 radii, gravity, Earth and transport rates, the step's inverse, the error state's
feedback and discretisation, the GPS receiver and IMU as a loop plant, and RAIM -> EKF -> chi-square and SCST as the
loop's FDI stage. The quaternion algebra is that of the reaction-wheel model.

Constants: ``STATE_SIZE`` the error state's size, 15 (``[dp, dv, psi, db_a, db_g]``); ``DEG_PER_HOUR`` 1 deg/h in
rad/s (4.848e-6); ``MILLI_G`` 1 mg in m/s^2 (9.80665e-3); ``IMU_HEALTH_WINDOW`` the IMU health test's window, 20
samples; ``IMU_HEALTH_PFA`` its false-alarm probability per window and channel, 1e-9; ``DEFAULT_MAX_CONDITION`` the
SCST's largest accepted condition estimate of its scaled ``B``, 1e10 (dimensionless).
"""

from jaxfdi.ins._error_state import STATE_SIZE, correct, error_jacobian, navigation_error
from jaxfdi.ins._imu import DEG_PER_HOUR, MILLI_G, ImuModel, draw_errors, hg1900
from jaxfdi.ins._integrity import (
    IMU_HEALTH_PFA,
    IMU_HEALTH_WINDOW,
    attribute_ins_alarms,
    gps_ins_fdi,
    imu_health_test,
    initial_covariance,
)
from jaxfdi.ins._loosely_coupled import GpsFix, loosely_coupled_filter
from jaxfdi.ins._mechanization import NavState, strapdown_step
from jaxfdi.ins._plant import FlightTables, flight_tables, gps_ins_plant
from jaxfdi.ins._scst import DEFAULT_MAX_CONDITION, state_chi2_test
from jaxfdi.ins._trajectory import fly, manoeuvre_legs, park_legs

__all__ = [
    "NavState",
    "strapdown_step",
    "error_jacobian",
    "hg1900",
    "fly",
    "GpsFix",
    "loosely_coupled_filter",
    "state_chi2_test",
    "STATE_SIZE",
    "correct",
    "navigation_error",
    "DEG_PER_HOUR",
    "ImuModel",
    "MILLI_G",
    "draw_errors",
    "IMU_HEALTH_PFA",
    "IMU_HEALTH_WINDOW",
    "attribute_ins_alarms",
    "gps_ins_fdi",
    "imu_health_test",
    "initial_covariance",
    "FlightTables",
    "flight_tables",
    "gps_ins_plant",
    "DEFAULT_MAX_CONDITION",
    "manoeuvre_legs",
    "park_legs",
]
