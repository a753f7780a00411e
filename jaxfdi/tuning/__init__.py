"""Gradient-based tuning: parameterisations, differentiable losses, the optax loop."""
from jaxfdi.tuning._losses import innovation_nll, mode_cross_entropy, soft_detection_loss
from jaxfdi.tuning._parameterize import cholesky_factor, constrain, positive, simplex
from jaxfdi.tuning._train import TrainResult, fit, load_params, save_params

__all__ = [
    "fit",
    "TrainResult",
    "save_params",
    "load_params",
    "innovation_nll",
    "soft_detection_loss",
    "mode_cross_entropy",
    "constrain",
    "positive",
    "simplex",
    "cholesky_factor",
]
