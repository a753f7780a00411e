"""Residual evaluation: tests that turn filter outputs into fault decisions."""

from jaxfdi.detection._chi2 import (
    Decision,
    Detector,
    WindowState,
    chi2_detector,
    chi2_threshold,
    first_crossing,
    flag_dead,
    moving_window_sum,
)
from jaxfdi.detection._dual_filter import dual_filter
from jaxfdi.detection._frozen import FrozenState, frozen_channel_detector
from jaxfdi.detection._glrt import fault_directions, fault_signatures, glrt_threshold
from jaxfdi.detection._glrt_correction import corrected_glrt
from jaxfdi.detection._glrt_recursive import glrt_detector
from jaxfdi.detection._glrt_transient import transient_glrt_detector
from jaxfdi.detection._hybrid_psa import hybrid_psa_config, hybrid_psa_fdi
from jaxfdi.detection._known_change import known_change_detector
from jaxfdi.detection._mode_probability import mode_probability_detector
from jaxfdi.detection._noncentral_chi2 import noncentrality_for_missed_detection
from jaxfdi.detection._parity import parity_space, parity_statistic
from jaxfdi.detection._signature import isolate
from jaxfdi.detection._two_stage import two_stage_isolation
from jaxfdi.detection._wavelet import haar_denoise

__all__ = [
    "flag_dead",
    "WindowState",
    "noncentrality_for_missed_detection",
    "parity_statistic",
    "FrozenState",
    "Decision",
    "Detector",
    "chi2_detector",
    "chi2_threshold",
    "moving_window_sum",
    "first_crossing",
    "frozen_channel_detector",
    "glrt_detector",
    "glrt_threshold",
    "corrected_glrt",
    "transient_glrt_detector",
    "known_change_detector",
    "mode_probability_detector",
    "fault_directions",
    "fault_signatures",
    "isolate",
    "haar_denoise",
    "parity_space",
    "dual_filter",
    "two_stage_isolation",
    "hybrid_psa_config",
    "hybrid_psa_fdi",
]
