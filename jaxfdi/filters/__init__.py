"""Filters: each a factory returning ``Filter(init, step)``; ``run_filter`` scans it."""
from jaxfdi.filters._base import ConditionedGaussian, Filter, FilterInfo, GaussianState, gaussian_filter, run_filter, run_filter_batch
from jaxfdi.filters.ekf import extended_kalman_filter
from jaxfdi.filters.kalman import kalman_filter
from jaxfdi.filters.ukf import unscented_kalman_filter

__all__ = [
    "ConditionedGaussian",
    "Filter",
    "gaussian_filter",
    "FilterInfo",
    "GaussianState",
    "run_filter",
    "run_filter_batch",
    "kalman_filter",
    "extended_kalman_filter",
    "unscented_kalman_filter",
]
