"""Gradient-based tuning: parameterisations, differentiable losses, the optax loop."""
from jaxfdi.tuning.losses import innovation_nll, mode_cross_entropy, soft_alarm_log_prob, soft_detection_loss
from jaxfdi.tuning.parameterize import (
    Transform,
    cholesky_factor,
    constrain,
    identity,
    log_diagonal,
    log_scale,
    merge,
    partition,
    positive,
    simplex,
    sticky_log_prior,
    stochastic_rows,
    unconstrain,
    unit_interval,
)
from jaxfdi.tuning.train import (
    TrainHistory,
    TrainResult,
    checkpointed,
    fit,
    fixed_batches,
    fresh_batches,
    load_params,
    save_params,
)

__all__ = [
    "Transform", "TrainHistory", "TrainResult", "checkpointed", "cholesky_factor", "constrain", "fit",
    "fixed_batches", "fresh_batches", "identity", "innovation_nll", "load_params", "log_diagonal", "log_scale", "merge",
    "mode_cross_entropy", "partition", "positive", "save_params", "simplex", "soft_alarm_log_prob", "soft_detection_loss",
    "sticky_log_prior", "stochastic_rows", "unconstrain", "unit_interval",
]
