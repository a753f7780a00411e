"""Numerical optimisation in JAX: nonlinear least squares (Levenberg-Marquardt)."""
from jaxfdi.optimize._least_squares import levenberg_marquardt

__all__ = [
    "levenberg_marquardt",
]
