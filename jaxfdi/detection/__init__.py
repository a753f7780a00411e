"""Residual evaluation: tests that turn filter outputs into fault decisions."""
from jaxfdi.detection._dual_filter import dual_filter
from jaxfdi.detection.chi2 import (
    Decision,
    Detector,
    chi2_detector,
    chi2_threshold,
    first_crossing,
    moving_window_sum,
)
from jaxfdi.detection.frozen import frozen_channel_detector
from jaxfdi.detection.glrt import fault_directions, fault_signatures, glrt_detector, glrt_threshold
from jaxfdi.detection.glrt_correction import corrected_glrt
from jaxfdi.detection.glrt_recursive import recursive_glrt_detector
from jaxfdi.detection.glrt_transient import transient_glrt_detector
from jaxfdi.detection.hybrid_psa import hybrid_psa_config, hybrid_psa_fdi
from jaxfdi.detection.known_change import known_change_detector
from jaxfdi.detection.mode_probability import mode_probability_detector
from jaxfdi.detection.parity import parity_space
from jaxfdi.detection.signature import isolate
from jaxfdi.detection.two_stage import two_stage_isolation
from jaxfdi.detection.wavelet import haar_denoise

__all__ = [
    "Decision",
    "Detector",
    "chi2_detector",
    "chi2_threshold",
    "moving_window_sum",
    "first_crossing",
    "frozen_channel_detector",
    "glrt_detector",
    "glrt_threshold",
    "recursive_glrt_detector",
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
