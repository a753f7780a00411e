"""Residual evaluation: tests that turn filter outputs into fault decisions."""
from jaxfdi.detection.chi2 import (
    Detector,
    chi2_detector,
    chi2_threshold,
    first_crossing,
    moving_window_sum,
    normalized_innovation_squared,
)

__all__ = [
    "Detector",
    "chi2_detector",
    "chi2_threshold",
    "first_crossing",
    "moving_window_sum",
    "normalized_innovation_squared",
]
