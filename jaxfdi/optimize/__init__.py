"""Numerical optimisation in JAX: nonlinear least squares (Levenberg-Marquardt)."""
from jaxfdi.optimize.least_squares import LeastSquaresResult, levenberg_marquardt

__all__ = ["LeastSquaresResult", "levenberg_marquardt"]
