"""Filters: each a factory returning ``Filter(init, step)``; ``run_filter`` scans it.

Gaussian filters (KF, EKF, UKF), the multiple-model filters built on them (IMM, MM), the two-stage (bias) Kalman
filter, optimal or robust to an unknown input, and the unbiased minimum-variance filter decoupling an unknown input.
"""

from jaxfdi._numerics.riccati import solve_discrete_are, steady_state_kalman
from jaxfdi.filters._base import Filter, FilterInfo, GaussianState
from jaxfdi.filters._driver import run_filter
from jaxfdi.filters._ekf import extended_kalman_filter
from jaxfdi.filters._history import RingBuffer, replay_filter, ring_buffer
from jaxfdi.filters._imm import interacting_multiple_model
from jaxfdi.filters._kalman import joseph_update, kalman_filter
from jaxfdi.filters._mm import multiple_model
from jaxfdi.filters._posterior import init_from_posterior
from jaxfdi.filters._smoother import rts_smoother
from jaxfdi.filters._sqrt_kalman import sqrt_kalman_filter
from jaxfdi.filters._sqrt_ukf import sqrt_unscented_kalman_filter
from jaxfdi.filters._time_varying import time_varying
from jaxfdi.filters._tskf import (
    FaultDirection,
    actuator_direction,
    sensor_direction,
    sensor_matrix,
    stack_directions,
    two_stage_kalman_filter,
)
from jaxfdi.filters._ukf import unscented_kalman_filter
from jaxfdi.filters._unknown_input import unknown_input_filter

__all__ = [
    "joseph_update",
    "RingBuffer",
    "ring_buffer",
    "replay_filter",
    "Filter",
    "FilterInfo",
    "GaussianState",
    "run_filter",
    "kalman_filter",
    "extended_kalman_filter",
    "unscented_kalman_filter",
    "sqrt_kalman_filter",
    "sqrt_unscented_kalman_filter",
    "two_stage_kalman_filter",
    "sensor_direction",
    "actuator_direction",
    "interacting_multiple_model",
    "multiple_model",
    "unknown_input_filter",
    "time_varying",
    "rts_smoother",
    "init_from_posterior",
    "solve_discrete_are",
    "steady_state_kalman",
    "FaultDirection",
    "sensor_matrix",
    "stack_directions",
]
