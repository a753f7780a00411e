"""Residual evaluation: tests that turn filter outputs into fault decisions."""
from jaxfdi.detection.calibration import empirical_threshold, scale_to_run_false_alarm
from jaxfdi.detection.chi2 import (
    Detector,
    chi2_detector,
    chi2_threshold,
    first_crossing,
    flag_dead,
    moving_window_sum,
    normalized_innovation_squared,
)
from jaxfdi.detection.credits import credit_isolator, hypothesis_credits
from jaxfdi.detection._dual_filter import DualFilterInfo, DualFilterState, dual_filter, system_matrix_det
from jaxfdi.detection.frozen import frozen_channel_detector, frozen_threshold
from jaxfdi.detection.glrt import (
    PAPER_USED_THRESHOLD,
    FaultDirections,
    GLRResult,
    fault_directions,
    fault_signatures,
    glr_by_onset,
    glr_statistic,
    glrt_detector,
    glrt_threshold,
)
from jaxfdi.detection.glrt_recursive import RecursiveGLRTState, recursive_glrt_detector
from jaxfdi.detection.mode_probability import mode_probability_detector
from jaxfdi.detection.noncentral_chi2 import ncx2_cdf, ncx2_quantile, noncentrality_for_missed_detection
from jaxfdi.detection.signature import UNMATCHED, isolate, signature_matrix
from jaxfdi.detection.two_stage import TwoStageOutput, two_stage_isolation
from jaxfdi.detection.wavelet import (
    block_alarms,
    chi2_detail_sigma,
    haar_decompose,
    haar_denoise,
    haar_reconstruct,
    soft_threshold,
)

__all__ = [
    "DualFilterInfo",
    "DualFilterState",
    "credit_isolator",
    "dual_filter",
    "hypothesis_credits",
    "system_matrix_det",
    "TwoStageOutput",
    "two_stage_isolation",
    "PAPER_USED_THRESHOLD",
    "Detector",
    "FaultDirections",
    "GLRResult",
    "fault_directions",
    "fault_signatures",
    "glr_by_onset",
    "glr_statistic",
    "glrt_detector",
    "glrt_threshold",
    "recursive_glrt_detector",
    "RecursiveGLRTState",
    "mode_probability_detector",
    "ncx2_cdf",
    "ncx2_quantile",
    "noncentrality_for_missed_detection",
    "chi2_detector",
    "chi2_threshold",
    "first_crossing",
    "flag_dead",
    "frozen_channel_detector",
    "frozen_threshold",
    "moving_window_sum",
    "normalized_innovation_squared",
    "UNMATCHED",
    "isolate",
    "signature_matrix",
    "block_alarms",
    "chi2_detail_sigma",
    "haar_decompose",
    "haar_denoise",
    "haar_reconstruct",
    "soft_threshold",
    "empirical_threshold",
    "scale_to_run_false_alarm",
]


# Park et al. (2004): parity space of redundant sensor groups, the hybrid PSA + on-demand filter FDI,
# and the sensor arrangement by gradient
from jaxfdi.detection.hybrid_psa import (  # noqa: E402
    HybridDecision,
    HybridPSAConfig,
    HybridPSAOutput,
    HybridPSAState,
    hybrid_psa_config,
    hybrid_psa_fdi,
    hybrid_psa_init,
)
from jaxfdi.detection.parity import (  # noqa: E402
    ParitySpace,
    detection_threshold,
    fault_detection_statistic,
    isolation_functions,
    isolation_threshold,
    parity_space,
    parity_vector,
    singular_directions,
    singular_faults,
    subspace_angles,
)
from jaxfdi.detection.sensor_configuration import isolability, optimize_configuration  # noqa: E402

__all__ += [
    "HybridDecision", "HybridPSAConfig", "HybridPSAOutput", "HybridPSAState", "hybrid_psa_config", "hybrid_psa_fdi",
    "hybrid_psa_init", "ParitySpace", "detection_threshold", "fault_detection_statistic", "isolation_functions",
    "isolation_threshold", "parity_space", "parity_vector", "singular_directions", "singular_faults",
    "subspace_angles", "isolability", "optimize_configuration",
]

# the GLRT's steady-state check and the Willsky-Jones correction
from jaxfdi.detection.glrt import check_steady_state, steady_state_tolerance  # noqa: E402
from jaxfdi.detection.glrt_correction import (  # noqa: E402
    CorrectedGLRTInfo,
    CorrectedGLRTState,
    corrected_glrt,
)
from jaxfdi.detection.glrt_transient import (  # noqa: E402
    TransientGLRTState,
    time_varying_signatures,
    transient_glrt_detector,
)

__all__ += ["CorrectedGLRTInfo", "CorrectedGLRTState", "check_steady_state", "corrected_glrt",
            "steady_state_tolerance", "TransientGLRTState", "time_varying_signatures", "transient_glrt_detector"]

# the known-change GLR / CUSUM bank (signature and size known), the limit's detector
from jaxfdi.detection.known_change import (  # noqa: E402
    KnownChangeState,
    KnownChangeTerms,
    known_change_bank,
    known_change_by_onset,
    known_change_detector,
    known_change_terms,
)

__all__ += ["KnownChangeState", "KnownChangeTerms", "known_change_bank", "known_change_by_onset",
            "known_change_detector", "known_change_terms"]
