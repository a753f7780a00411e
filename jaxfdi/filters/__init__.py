"""Filters: each a factory returning ``Filter(init, step)``; ``run_filter`` scans it."""
from jaxfdi.filters._base import Filter, FilterInfo, GaussianState, run_filter
from jaxfdi.filters.ekf import extended_kalman_filter
from jaxfdi.filters.kalman import kalman_filter
from jaxfdi.filters.ukf import unscented_kalman_filter

__all__ = [
    "Filter",
    "FilterInfo",
    "GaussianState",
    "run_filter",
    "kalman_filter",
    "extended_kalman_filter",
    "unscented_kalman_filter",
]
