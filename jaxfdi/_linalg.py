"""Small dense linear-algebra helpers shared by every filter.

Solve, don't invert: every use of an innovation covariance goes through its Cholesky
factor, so a loss of positive-definiteness shows up as NaN in the factor, which the
filters turn into a ``healthy = False`` flag instead of a silent wrong answer.

Small matrices are factorised element by element. The filters of this library work
with states and outputs of a handful of components, vmapped over banks and Monte
Carlo runs. On CPU, ``jax.scipy.linalg.cholesky``/``solve_triangular`` lower to LAPACK
calls that loop over a vmapped batch one 5x5 matrix at a time; written out for a static
size ``n <= UNROLL_MAX`` the same algorithms are element-wise array operations that XLA
fuses and vectorises across the batch (measured: the UKF over 100 runs 2x faster, see
``benchmarks/RESULTS.md``). Larger matrices use LAPACK/cuSOLVER.

Matrix products go the same way (``matmul``): XLA:CPU runs every small ``dot`` as its
own library call, 0.5-0.8 us for one 7x7 product whether alone or in a vmapped batch,
while the same product as a sum of ``k`` outer products is fused element-wise code: 4x
faster for one 7x7 product, 8x for a batch of 700 (the IMM bank over 100 runs). Only
matrices with every dimension ``<= UNROLL_MAX`` are unrolled: past that, XLA fuses
chains of unrolled products into consumers that recompute them (the 13-state IMM got
2.5x slower; benchmarks/RESULTS.md).
"""
from __future__ import annotations

import math

import jax.numpy as jnp
from jax import Array
from jax.scipy import linalg as jsl

#: largest static size factorised element by element; larger ones go to LAPACK.
UNROLL_MAX = 8


def symmetrize(matrix: Array) -> Array:
    """Return ``(A + A^T) / 2``: removes the round-off asymmetry of covariance updates."""
    return 0.5 * (matrix + jnp.swapaxes(matrix, -1, -2))


def is_small(*arrays: Array) -> bool:
    """True when every array is 1-D or 2-D with every dimension in ``1..UNROLL_MAX``."""
    return all(x.ndim in (1, 2) and all(1 <= d <= UNROLL_MAX for d in x.shape) for x in arrays)


def matmul(a: Array, b: Array) -> Array:
    """``a @ b`` for 1-D or 2-D operands; small ones (``is_small``) are written out as
    ``sum_j a[:, j] b[j, :]`` so that XLA fuses the product (see the module doc)."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    if not is_small(a, b) or a.shape[-1] != b.shape[0]:
        return a @ b
    k = b.shape[0]
    left = a if a.ndim == 2 else a[None, :]
    right = b if b.ndim == 2 else b[:, None]
    total = left[:, 0, None] * right[None, 0, :]
    for j in range(1, k):
        total = total + left[:, j, None] * right[None, j, :]
    if a.ndim == 1:
        total = total[0]
    return total if b.ndim == 2 else total[..., 0]


def cholesky(matrix: Array, unroll: bool = True) -> Array:
    """Lower Cholesky factor ``L`` (``L L^T = A``) of one (n, n) matrix.

    Cholesky-Banachiewicz order, element by element for ``n <= UNROLL_MAX``: a matrix
    that is not positive definite yields NaN (square root of a negative pivot), as the
    LAPACK path does, so ``cholesky_is_finite`` reports it.
    """
    n = matrix.shape[-1]
    if matrix.ndim != 2 or n > UNROLL_MAX or not unroll:
        return jsl.cholesky(matrix, lower=True)
    zero = jnp.zeros((), matrix.dtype)
    L = [[zero] * n for _ in range(n)]
    for j in range(n):
        pivot = matrix[j, j] - sum((L[j][k] * L[j][k] for k in range(j)), zero)
        L[j][j] = jnp.sqrt(pivot)
        for i in range(j + 1, n):
            L[i][j] = (matrix[i, j] - sum((L[i][k] * L[j][k] for k in range(j)), zero)) / L[j][j]
    return jnp.stack([jnp.stack(row) for row in L])


def solve_lower(chol: Array, rhs: Array, unroll: bool = True) -> Array:
    """``L^{-1} b`` for lower-triangular ``L`` (n, n) and ``b`` (n,) or (n, p)."""
    n = chol.shape[-1]
    if chol.ndim != 2 or n > UNROLL_MAX or not unroll:
        return jsl.solve_triangular(chol, rhs, lower=True)
    rows = []
    for i in range(n):
        acc = rhs[i]
        for k in range(i):
            acc = acc - chol[i, k] * rows[k]
        rows.append(acc / chol[i, i])
    return jnp.stack(rows)


def solve_lower_transposed(chol: Array, rhs: Array, unroll: bool = True) -> Array:
    """``L^{-T} b`` for lower-triangular ``L`` (n, n) and ``b`` (n,) or (n, p)."""
    n = chol.shape[-1]
    if chol.ndim != 2 or n > UNROLL_MAX or not unroll:
        return jsl.solve_triangular(chol, rhs, lower=True, trans="T")
    rows = [None] * n
    for i in reversed(range(n)):
        acc = rhs[i]
        for k in range(i + 1, n):
            acc = acc - chol[k, i] * rows[k]
        rows[i] = acc / chol[i, i]
    return jnp.stack(rows)


def cho_solve(chol: Array, rhs: Array, unroll: bool = True) -> Array:
    """``A^{-1} b`` from the lower Cholesky factor ``L`` of ``A = L L^T``."""
    return solve_lower_transposed(chol, solve_lower(chol, rhs, unroll), unroll)


def psd_solve(matrix: Array, rhs: Array) -> Array:
    """``A^{-1} b`` for a symmetric positive definite ``A`` (symmetrised, then Cholesky)."""
    return cho_solve(cholesky(symmetrize(matrix)), rhs)


def det(matrix: Array) -> Array:
    """Determinant; 1x1 to 3x3 written out (cofactor expansion), so a vmapped batch is
    element-wise code rather than one LU call per matrix."""
    matrix = jnp.asarray(matrix)
    n = matrix.shape[-1]
    if n == 1:
        return matrix[..., 0, 0]
    if n == 2:
        return matrix[..., 0, 0] * matrix[..., 1, 1] - matrix[..., 0, 1] * matrix[..., 1, 0]
    if n == 3:
        a = matrix
        return (a[..., 0, 0] * (a[..., 1, 1] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 1])
                - a[..., 0, 1] * (a[..., 1, 0] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 0])
                + a[..., 0, 2] * (a[..., 1, 0] * a[..., 2, 1] - a[..., 1, 1] * a[..., 2, 0]))
    return jnp.linalg.det(matrix)


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


def whiten(chol: Array, innovation: Array, unroll: bool = True) -> Array:
    """``L^{-1} r`` for ``S = L L^T``; its squared norm is the normalised innovation."""
    return solve_lower(chol, innovation, unroll)


def gaussian_log_likelihood(whitened: Array, chol: Array, num_observed: Array | int) -> Array:
    """``log N(r; 0, S)`` from ``w = L^{-1} r`` and ``L`` (``S = L L^T``).

    ``-0.5 (w^T w + log det S + k log 2 pi)`` with ``k`` the number of observed
    components (missing components enter ``S`` as unit variance with zero residual and
    so contribute nothing but are not counted in ``k``).
    """
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol)))
    return -0.5 * (jnp.sum(whitened**2) + log_det + num_observed * math.log(2.0 * math.pi))


def joseph_cov(cov: Array, gain: Array, H: Array, noise_cov: Array) -> Array:
    """Joseph-form posterior covariance ``(I - K H) P (I - K H)^T + K R K^T`` (Bucy &
    Joseph 1968): symmetric positive semi-definite for any gain ``K``."""
    I_KH = jnp.eye(cov.shape[0], dtype=cov.dtype) - matmul(gain, H)
    return symmetrize(matmul(matmul(I_KH, cov), I_KH.T) + matmul(matmul(gain, noise_cov), gain.T))


def gain_from_cross_cov(cross_cov: Array, chol: Array, unroll: bool = True) -> Array:
    """Kalman gain ``K = P_xy S^{-1}`` by a Cholesky solve (``S = L L^T``)."""
    return cho_solve(chol, cross_cov.T, unroll).T
