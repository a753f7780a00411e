"""Residual evaluation: tests that turn filter outputs into fault decisions.

Constants: ``PAPER_USED_THRESHOLD`` the GLRT threshold Han et al. (2022) set by simulation, 200.0 on the GLR statistic
(dimensionless, chi-square scale); ``FOLLOW`` the hybrid FDI's ``follow`` codes, a dict ``{"none": 0, "psa": 1,
"hybrid": 2, "verified": 3}``.
"""

from jaxfdi.detection._calibration import empirical_threshold, scale_to_run_false_alarm
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
from jaxfdi.detection._credits import hypothesis_credits
from jaxfdi.detection._dual_filter import dual_filter
from jaxfdi.detection._frozen import FrozenState, frozen_channel_detector, frozen_threshold
from jaxfdi.detection._glrt import (
    PAPER_USED_THRESHOLD,
    detector_setup,
    fault_directions,
    fault_signatures,
    glr_sequence,
    glrt_threshold,
)
from jaxfdi.detection._glrt_correction import corrected_glrt
from jaxfdi.detection._glrt_recursive import glrt_detector
from jaxfdi.detection._glrt_transient import transient_glrt_detector
from jaxfdi.detection._hybrid_psa import (
    FOLLOW,
    HybridPSAConfig,
    hybrid_psa_config,
    hybrid_psa_fdi,
    hybrid_psa_init,
)
from jaxfdi.detection._known_change import known_change_detector
from jaxfdi.detection._mode_probability import mode_probability_detector
from jaxfdi.detection._noncentral_chi2 import noncentrality_for_missed_detection
from jaxfdi.detection._parity import (
    IsolationCalibration,
    detection_threshold,
    isolation_functions,
    isolation_threshold,
    parity_space,
    parity_statistic,
    parity_vector,
    singular_faults,
    subspace_angles,
)
from jaxfdi.detection._sensor_configuration import (
    isolability,
    isolation_rate,
    optimize_configuration,
)
from jaxfdi.detection._signature import isolate, location_symptoms
from jaxfdi.detection._two_stage import two_stage_isolation
from jaxfdi.detection._wavelet import (
    block_alarms,
    causal_detail_sigma,
    chi2_detail_sigma,
    haar_denoise,
)

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
    "empirical_threshold",
    "scale_to_run_false_alarm",
    "hypothesis_credits",
    "frozen_threshold",
    "PAPER_USED_THRESHOLD",
    "detector_setup",
    "glr_sequence",
    "FOLLOW",
    "HybridPSAConfig",
    "hybrid_psa_init",
    "IsolationCalibration",
    "detection_threshold",
    "isolation_functions",
    "isolation_threshold",
    "parity_vector",
    "singular_faults",
    "subspace_angles",
    "isolability",
    "isolation_rate",
    "optimize_configuration",
    "location_symptoms",
    "block_alarms",
    "causal_detail_sigma",
    "chi2_detail_sigma",
]
