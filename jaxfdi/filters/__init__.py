"""Filters: each a factory returning ``Filter(init, step)``; ``run_filter`` scans it.

Gaussian filters (KF, EKF, UKF), the multiple-model filters built on them (IMM, MM),
the two-stage (bias) Kalman filter, optimal or robust to an unknown input, and the
unbiased minimum-variance filter that decouples an unknown input.
"""
from jaxfdi.filters._base import ConditionedGaussian, Filter, FilterInfo, GaussianState, gaussian_filter, run_filter
from jaxfdi.filters._mixture import IMMInfo, IMMState
from jaxfdi.filters.ekf import extended_kalman_filter
from jaxfdi.filters.imm import interacting_multiple_model
from jaxfdi.filters.kalman import kalman_filter
from jaxfdi.filters.mm import multiple_model
from jaxfdi.filters.posterior import init_from_posterior
from jaxfdi.filters.tskf import (
    FaultDirection,
    TSKFInfo,
    TSKFState,
    actuator_direction,
    sensor_direction,
    stack_directions,
    tskf_statistic_dof,
    two_stage_kalman_filter,
)
from jaxfdi.filters.sqrt_kalman import SqrtGaussianState, sqrt_kalman_filter
from jaxfdi.filters.sqrt_ukf import sqrt_unscented_kalman_filter
from jaxfdi.filters.smoother import SmootherResult, parallel_rts_smoother, rts_smoother
from jaxfdi.filters._time_varying import TimedState, model_at, time_varying
from jaxfdi.filters.ukf import unscented_kalman_filter
from jaxfdi.filters.unknown_input import unknown_input_filter

__all__ = [
    "ConditionedGaussian",
    "Filter",
    "gaussian_filter",
    "FilterInfo",
    "GaussianState",
    "run_filter",
    "kalman_filter",
    "rts_smoother",
    "parallel_rts_smoother",
    "SmootherResult",
    "sqrt_kalman_filter",
    "sqrt_unscented_kalman_filter",
    "SqrtGaussianState",
    "extended_kalman_filter",
    "unscented_kalman_filter",
    "interacting_multiple_model",
    "multiple_model",
    "init_from_posterior",
    "IMMInfo",
    "IMMState",
    "FaultDirection",
    "TSKFInfo",
    "TSKFState",
    "actuator_direction",
    "sensor_direction",
    "stack_directions",
    "tskf_statistic_dof",
    "two_stage_kalman_filter",
    "unknown_input_filter",
    "time_varying",
    "model_at",
    "TimedState",
]
