"""Small dense linear-algebra helpers shared by every filter.

Solve, don't invert: every use of an innovation covariance goes through its Cholesky
factor, so a loss of positive-definiteness shows up as NaN in the factor, which the
filters turn into a ``healthy = False`` flag instead of a silent wrong answer.
"""
from __future__ import annotations

import math

import jax.numpy as jnp
from jax import Array
from jax.scipy.linalg import cho_solve, solve_triangular

def symmetrize(matrix: Array) -> Array:
    """Return ``(A + A^T) / 2``: removes the round-off asymmetry of covariance updates."""
    return 0.5 * (matrix + jnp.swapaxes(matrix, -1, -2))

def cholesky_is_finite(chol: Array) -> Array:
    """True when a Cholesky factor is finite, i.e. its matrix was positive definite."""
    return jnp.all(jnp.isfinite(chol))

def psd_sqrt(cov: Array) -> Array:
    """Matrix square root ``L`` with ``L L^T = cov`` for a positive *semi*-definite ``cov``.

    Uses the symmetric eigendecomposition (clipping round-off negative eigenvalues), so
    singular noise covariances (a noise-free channel) are allowed. Meant for sampling,
    outside the hot loop.
    """
    eigval, eigvec = jnp.linalg.eigh(symmetrize(cov))
    return eigvec * jnp.sqrt(jnp.clip(eigval, 0.0, None))

def whiten(chol: Array, innovation: Array) -> Array:
    """``L^{-1} r`` for ``S = L L^T``; its squared norm is the normalised innovation."""
    return solve_triangular(chol, innovation, lower=True)

def gaussian_log_likelihood(whitened: Array, chol: Array, num_observed: Array | int) -> Array:
    """``log N(r; 0, S)`` from ``w = L^{-1} r`` and ``L`` (``S = L L^T``).

    ``-0.5 (w^T w + log det S + k log 2 pi)`` with ``k`` the number of observed
    components (missing components enter ``S`` as unit variance with zero residual and
    so contribute nothing but are not counted in ``k``).
    """
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol)))
    return -0.5 * (jnp.sum(whitened**2) + log_det + num_observed * math.log(2.0 * math.pi))

def gain_from_cross_cov(cross_cov: Array, chol: Array) -> Array:
    """Kalman gain ``K = P_xy S^{-1}`` by a Cholesky solve (``S = L L^T``)."""
    return cho_solve((chol, True), cross_cov.T).T
