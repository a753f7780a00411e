"""Gradient-based tuning: parameterisations, differentiable losses, the optax loop."""

from jaxfdi.tuning._imm import ImmData, ImmProblem, evaluate_imm, imm_filter, imm_loss, tune_imm
from jaxfdi.tuning._losses import innovation_nll, mode_cross_entropy, soft_detection_loss
from jaxfdi.tuning._parameterize import (
    Transform,
    cholesky_factor,
    constrain,
    log_diagonal,
    log_scale,
    positive,
    simplex,
    stochastic_rows,
    unconstrain,
    unit_interval,
)
from jaxfdi.tuning._train import (
    TrainResult,
    checkpointed,
    fit,
    fixed_batches,
    load_params,
    save_params,
    strongly_typed,
)

__all__ = [
    "ImmProblem",
    "ImmData",
    "imm_filter",
    "imm_loss",
    "tune_imm",
    "evaluate_imm",
    "fit",
    "TrainResult",
    "save_params",
    "load_params",
    "innovation_nll",
    "soft_detection_loss",
    "mode_cross_entropy",
    "constrain",
    "unconstrain",
    "positive",
    "unit_interval",
    "simplex",
    "stochastic_rows",
    "log_diagonal",
    "cholesky_factor",
    "Transform",
    "log_scale",
    "checkpointed",
    "fixed_batches",
    "strongly_typed",
]
