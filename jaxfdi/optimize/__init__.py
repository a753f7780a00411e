"""Numerical optimisation in JAX: nonlinear least squares (Levenberg-Marquardt)."""
from jaxfdi.optimize.least_squares import levenberg_marquardt

__all__ = [
    "levenberg_marquardt",
]
