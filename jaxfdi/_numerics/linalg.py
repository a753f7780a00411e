"""Small dense linear-algebra helpers shared by every filter.

Solve, don't invert: every innovation covariance goes through its Cholesky factor, so a loss of
positive-definiteness shows as NaN in the factor, which filters turn into ``healthy = False``, not a silent wrong
answer.

Small matrices (static ``n <= UNROLL_MAX``) are factorised element by element: the filters' states and outputs
have a handful of components, vmapped over banks and runs, and on CPU ``jax.scipy.linalg`` lowers to LAPACK calls
that loop over the batch one 5x5 matrix at a time, while written-out algorithms are element-wise operations XLA
fuses and vectorises (faster for the filters' batches, e.g. the UKF over runs, ``benchmarks/bench_filters.py``).
Larger matrices use LAPACK/cuSOLVER.

Products likewise (``matmul``): XLA:CPU runs each small ``dot`` as a library call, whose cost does not shrink with
the batch; as a sum of ``k`` outer products it is fused code, faster for one small product and more so for the
filters' batches (IMM banks). Only matrices with every dimension ``<= UNROLL_MAX`` are unrolled: beyond, XLA fuses
chains of unrolled products into consumers that recompute them (the 13-state IMM got slower). Their derivative is
one broadcast multiply-and-reduce, not the transpose of ``k`` sliced products (``_written_out_matmul``), which makes
the engine IMM's tuning gradient cheaper relative to its forward pass.

This pays only for batches. A single sequence (``run_filter`` eager or under ``jit`` alone) has nothing to
vectorise and the written-out algebra only bloats it (a much larger program, slower to compile);
``library_calls()`` makes every helper use ``dot`` and LAPACK while such a trace is made on CPU.
Under ``vmap`` or ``grad``, and on GPU (a cuSOLVER call per small factorisation costs more than the written-out
algebra), the algebra stays written out.
"""

from __future__ import annotations

import contextlib
import math
import threading

import jax
import jax.numpy as jnp
from jax import Array
from jax.custom_derivatives import SymbolicZero
from jax.scipy import linalg as jsl

#: largest static size factorised element by element; larger ones go to LAPACK.
UNROLL_MAX = 8

_TRACE_STATE = threading.local()


@contextlib.contextmanager
def library_calls():
    """While active (a trace of one unbatched sequence), ``matmul``, ``cholesky`` and the triangular solves use
    ``dot`` and LAPACK whatever their size and ``unroll`` flag."""
    previous = getattr(_TRACE_STATE, "library", False)
    _TRACE_STATE.library = True
    try:
        yield
    finally:
        _TRACE_STATE.library = previous


def _library() -> bool:
    return getattr(_TRACE_STATE, "library", False)


def symmetrize(matrix: Array) -> Array:
    """Return ``(A + A^T) / 2``: removes the round-off asymmetry of covariance updates."""
    return 0.5 * (matrix + jnp.swapaxes(matrix, -1, -2))


def is_small(*arrays: Array) -> bool:
    """True when every array is 1-D or 2-D with every dimension in ``1..UNROLL_MAX``."""
    return all(x.ndim in (1, 2) and all(1 <= d <= UNROLL_MAX for d in x.shape) for x in arrays)


def matmul(a: Array, b: Array) -> Array:
    """``a @ b`` for 1-D/2-D operands; small ones (``is_small``) as ``sum_j a[:, j] b[j, :]``, fused by XLA."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    if _library() or not is_small(a, b) or a.shape[-1] != b.shape[0]:
        return a @ b
    left = a if a.ndim == 2 else a[None, :]
    right = b if b.ndim == 2 else b[:, None]
    total = _written_out_matmul(left, right)
    if a.ndim == 1:
        total = total[0]
    return total if b.ndim == 2 else total[..., 0]


@jax.custom_jvp
def _written_out_matmul(a: Array, b: Array) -> Array:
    """``soa_matmul`` of two 2-D matrices, with a tangent rule whose transpose is cheap.

    Differentiated as written, each term ``a[:, j] b[j, :]`` slices its operands and the reverse pass pads every
    slice back to full size (``k`` pads per product). The tangent here, ``sum_j da[:, j, None] * b[None, j, :]``, is
    one broadcast multiply-and-reduce whose transpose is another: no pads. Keeps forward mode (``jvp``, ``jacfwd``),
    which a ``custom_vjp`` would lose (engine IMM tuning gradient, ``benchmarks/bench_tuning.py``).
    """
    return soa_matmul(a, b)


def _broadcast_matmul(a: Array, b: Array) -> Array:
    return jnp.sum(a[:, :, None] * b[None, :, :], axis=1)


def _written_out_matmul_jvp(primals, tangents):
    (a, b), (da, db) = primals, tangents
    out = soa_matmul(a, b)
    terms = []
    if not isinstance(da, SymbolicZero):
        terms.append(_broadcast_matmul(da, b))
    if not isinstance(db, SymbolicZero):
        terms.append(_broadcast_matmul(a, db))
    return out, sum(terms[1:], terms[0]) if terms else jnp.zeros_like(out)


_written_out_matmul.defjvp(_written_out_matmul_jvp, symbolic_zeros=True)


def materialize(tree):
    """``tree``, computed once and stored (a structure-of-arrays kernel's intermediate).

    XLA:CPU fuses cheap element-wise producers into every consumer, so a chain of written-out products or
    factorisations redoes the inner computation per outer element (13-state models: several times slower);
    ``optimization_barrier`` does not stop it on CPU. A ``lax.cond`` is a fusion boundary: the true branch returns
    ``tree``, the predicate (a bit of the first element's bit pattern OR 1) is always true but unknown to the
    compiler; the false branch (zeros) is never taken. If XLA folded the predicate: same values, only slower.
    """
    leaves = jax.tree.leaves(tree)
    first = jnp.ravel(leaves[0])[0]
    bits = jax.lax.bitcast_convert_type(
        first, {2: jnp.uint16, 4: jnp.uint32, 8: jnp.uint64}[first.dtype.itemsize]
    )
    always = (bits | jnp.ones((), bits.dtype)) != 0
    return jax.lax.cond(always, lambda t: t, lambda t: jax.tree.map(jnp.zeros_like, t), tree)


# Structure-of-arrays forms: a (rows, cols, *batch) stack makes each A[i, j] a contiguous batch vector, so the
# written-out algorithms below are element-wise over whole batch vectors, which XLA:CPU vectorises (batch-first
# leaves 5-element strided rows). The 2-D case (no batch axes) is what ``matmul``, ``cholesky`` and solves unroll.


def soa_transpose(a: Array) -> Array:
    """Per-matrix transpose of a (rows, cols, *batch) stack."""
    return jnp.swapaxes(a, 0, 1)


def soa_symmetrize(a: Array) -> Array:
    """``(A + A^T) / 2`` per matrix of a (n, n, *batch) stack."""
    return 0.5 * (a + soa_transpose(a))


def soa_matmul(a: Array, b: Array) -> Array:
    """``a @ b`` per batch element, (p, k, *batch) x (k, q, *batch) -> (p, q, *batch), batch axes broadcast."""
    if b.shape[0] == 0:  # k = 0 (a model without inputs): the empty sum
        batch = jnp.broadcast_shapes(a.shape[2:], b.shape[2:])
        return jnp.zeros((a.shape[0], b.shape[1], *batch), jnp.result_type(a, b))
    total = a[:, 0, None] * b[None, 0]
    for j in range(1, b.shape[0]):
        total = total + a[:, j, None] * b[None, j]
    return total


def soa_matvec(a: Array, x: Array) -> Array:
    """``a @ x`` per batch element: (p, k, *batch) x (k, *batch) -> (p, *batch)."""
    if x.shape[0] == 0:  # k = 0 (a model without inputs): the empty sum
        batch = jnp.broadcast_shapes(a.shape[2:], x.shape[1:])
        return jnp.zeros((a.shape[0], *batch), jnp.result_type(a, x))
    total = a[:, 0] * x[0]
    for j in range(1, x.shape[0]):
        total = total + a[:, j] * x[j]
    return total


def soa_cholesky(matrix: Array) -> Array:
    """Lower Cholesky factor of each matrix of a (n, n, *batch) stack, element by element
    (Cholesky-Banachiewicz); not positive definite yields NaN (``cholesky_is_finite`` reports it)."""
    n = matrix.shape[0]
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        pivot = matrix[j, j]
        for k in range(j):
            pivot = pivot - L[j][k] * L[j][k]
        L[j][j] = jnp.sqrt(pivot)
        for i in range(j + 1, n):
            acc = matrix[i, j]
            for k in range(j):
                acc = acc - L[i][k] * L[j][k]
            L[i][j] = acc / L[j][j]
    zero = jnp.zeros_like(L[0][0])
    return jnp.stack([jnp.stack([L[i][j] if j <= i else zero for j in range(n)]) for i in range(n)])


def soa_solve_lower(chol: Array, rhs: Array) -> Array:
    """``L^{-1} b`` per batch element: ``L`` (n, n, *batch), ``b`` (n, ...) batch axes last (forward substitution)."""
    rows = []
    for i in range(chol.shape[0]):
        acc = rhs[i]
        for k in range(i):
            acc = acc - chol[i, k] * rows[k]
        rows.append(acc / chol[i, i])
    return jnp.stack(rows)


def soa_solve_lower_transposed(chol: Array, rhs: Array) -> Array:
    """``L^{-T} b`` per batch element, as ``soa_solve_lower`` (back substitution)."""
    n = chol.shape[0]
    rows = [None] * n
    for i in reversed(range(n)):
        acc = rhs[i]
        for k in range(i + 1, n):
            acc = acc - chol[k, i] * rows[k]
        rows[i] = acc / chol[i, i]
    return jnp.stack(rows)


def cholesky(matrix: Array, unroll: bool = True) -> Array:
    """Lower Cholesky factor ``L`` (``L L^T = A``) of one (n, n) matrix: written out (``soa_cholesky``) for
    ``n <= UNROLL_MAX``, else LAPACK; not positive definite yields NaN (``cholesky_is_finite``)."""
    n = matrix.shape[-1]
    if matrix.ndim != 2 or n > UNROLL_MAX or not unroll or _library():
        return jsl.cholesky(matrix, lower=True)
    return soa_cholesky(matrix)


def solve_lower(chol: Array, rhs: Array, unroll: bool = True) -> Array:
    """``L^{-1} b`` for lower-triangular ``L`` (n, n) and ``b`` (n,) or (n, p)."""
    n = chol.shape[-1]
    if chol.ndim != 2 or n > UNROLL_MAX or not unroll or _library():
        return jsl.solve_triangular(chol, rhs, lower=True)
    return soa_solve_lower(chol, rhs)


def solve_lower_transposed(chol: Array, rhs: Array, unroll: bool = True) -> Array:
    """``L^{-T} b`` for lower-triangular ``L`` (n, n) and ``b`` (n,) or (n, p)."""
    n = chol.shape[-1]
    if chol.ndim != 2 or n > UNROLL_MAX or not unroll or _library():
        return jsl.solve_triangular(chol, rhs, lower=True, trans="T")
    return soa_solve_lower_transposed(chol, rhs)


def solve_upper(upper: Array, rhs: Array, unroll: bool = True) -> Array:
    """``R^{-1} b``, ``R`` (n, n) upper triangular, ``b`` (n,) or (n, p): ``solve_lower_transposed`` on ``R^T``."""
    return solve_lower_transposed(upper.T, rhs, unroll)


def cho_solve(chol: Array, rhs: Array, unroll: bool = True) -> Array:
    """``A^{-1} b`` from the lower Cholesky factor ``L`` of ``A = L L^T``."""
    return solve_lower_transposed(chol, solve_lower(chol, rhs, unroll), unroll)


def psd_solve(matrix: Array, rhs: Array) -> Array:
    """``A^{-1} b`` for a symmetric positive definite ``A`` (symmetrised, then Cholesky)."""
    return cho_solve(cholesky(symmetrize(matrix)), rhs)


def _to_soa(a: Array) -> Array:
    return jnp.moveaxis(a, (-2, -1), (0, 1))


def _from_soa(a: Array) -> Array:
    return jnp.moveaxis(a, (0, 1), (-2, -1))


def stack_cholesky(matrix: Array) -> Array:
    """Lower Cholesky factors of a stack (..., n, n): written out for ``n <= UNROLL_MAX``, else LAPACK (why the
    associative scan avoids LAPACK on CPU: ``solve_pivoted``)."""
    if matrix.shape[-1] > UNROLL_MAX:
        return jnp.linalg.cholesky(matrix)
    return _from_soa(soa_cholesky(_to_soa(matrix)))


def stack_cho_solve(chol: Array, rhs: Array) -> Array:
    """``A^{-1} B`` for stacks of lower factors ``L`` (..., n, n) of ``A`` and ``B`` (..., n, k): written out for
    ``n <= UNROLL_MAX``, else LAPACK."""
    if chol.shape[-1] > UNROLL_MAX:
        return jsl.cho_solve((chol, True), rhs)
    L = _to_soa(chol)
    return _from_soa(soa_solve_lower_transposed(L, soa_solve_lower(L, _to_soa(rhs))))


def stack_solve_lower(chol: Array, rhs: Array) -> Array:
    """``L^{-1} B`` for stacks ``L`` (..., n, n) lower triangular, ``B`` (..., n, k)."""
    if chol.shape[-1] > UNROLL_MAX:
        return jsl.solve_triangular(chol, rhs, lower=True)
    return _from_soa(soa_solve_lower(_to_soa(chol), _to_soa(rhs)))


def solve_pivoted(matrix: Array, rhs: Array) -> Array:
    """``A^{-1} B`` for stacks ``A`` (..., n, n), ``B`` (..., n, k): Gauss-Jordan with partial pivoting (Golub & Van
    Loan, 4th ed., sec. 3.4), a ``fori_loop`` over the n columns, element-wise over the stack, no LAPACK call.

    For ``filters.parallel``'s associative scan: on XLA:CPU (jaxlib 0.10.2) a program with the scan's 2 log2 T levels
    of batched ``getrf`` (``jnp.linalg.solve``) never completes from T = 2048-4096 on (workers idle;
    ``tests/filters/test_parallel_kalman.py``); this form has no custom call to wedge. Singular ``A``: inf/NaN, as LU.
    """
    n = matrix.shape[-1]
    augmented = jnp.concatenate([matrix, rhs.astype(matrix.dtype)], axis=-1)  # (..., n, n + k)
    rows = jnp.arange(n)

    def eliminate(k, a):
        column = jnp.where(rows >= k, jnp.abs(a[..., :, k]), -1.0)  # candidates: rows k..n-1
        pivot = jnp.argmax(column, axis=-1)  # (...,)
        is_pivot = (rows == pivot[..., None]).astype(a.dtype)[..., None]  # (..., n, 1)
        is_k = (rows == k).astype(a.dtype)[:, None]  # (n, 1)
        row_pivot = jnp.sum(is_pivot * a, axis=-2)  # (..., n + k)
        row_k = a[..., k, :]
        a = a + (is_k - is_pivot) * (row_pivot - row_k)[..., None, :]  # swap rows k and pivot
        normalised = row_pivot / row_pivot[..., k, None]
        a = a - a[..., :, k, None] * normalised[..., None, :]  # zero column k off row k
        return a + is_k * normalised[..., None, :]  # row k = the normalised pivot row

    return jax.lax.fori_loop(0, n, eliminate, augmented)[..., n:]


def det(matrix: Array) -> Array:
    """Determinant; 1x1 to 3x3 by cofactors: element-wise for a vmapped batch, not one LU call per matrix."""
    matrix = jnp.asarray(matrix)
    n = matrix.shape[-1]
    if n == 1:
        return matrix[..., 0, 0]
    if n == 2:
        return matrix[..., 0, 0] * matrix[..., 1, 1] - matrix[..., 0, 1] * matrix[..., 1, 0]
    if n == 3:
        a = matrix
        return (
            a[..., 0, 0] * (a[..., 1, 1] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 1])
            - a[..., 0, 1] * (a[..., 1, 0] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 0])
            + a[..., 0, 2] * (a[..., 1, 0] * a[..., 2, 1] - a[..., 1, 1] * a[..., 2, 0])
        )
    return jnp.linalg.det(matrix)


def cholesky_is_finite(chol: Array) -> Array:
    """True when a Cholesky factor is finite, i.e. its matrix was positive definite."""
    return jnp.all(jnp.isfinite(chol))


def psd_sqrt(cov: Array) -> Array:
    """Square root ``L``, ``L L^T = cov``, of a PSD ``cov`` (eigendecomposition, round-off negative eigenvalues
    clipped): singular noise covariances (noise-free channel) allowed. For sampling, outside the hot loop."""
    eigval, eigvec = jnp.linalg.eigh(symmetrize(cov))
    return eigvec * jnp.sqrt(jnp.clip(eigval, 0.0, None))


def whiten(chol: Array, innovation: Array, unroll: bool = True) -> Array:
    """``L^{-1} r`` for ``S = L L^T``; its squared norm is the normalised innovation."""
    return solve_lower(chol, innovation, unroll)


def gaussian_log_likelihood(whitened: Array, chol: Array, num_observed: Array | int) -> Array:
    """``log N(r; 0, S) = -0.5 (w^T w + log det S + k log 2 pi)`` from ``w = L^{-1} r`` and ``L`` (``S = L L^T``),
    ``k`` the number of observed components (missing ones enter ``S`` as unit variance with zero residual: they
    add nothing and are not counted in ``k``)."""
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol)))
    return -0.5 * (jnp.sum(whitened**2) + log_det + num_observed * math.log(2.0 * math.pi))


def joseph_cov(cov: Array, gain: Array, H: Array, noise_cov: Array) -> Array:
    """Joseph-form covariance ``(I - K H) P (I - K H)^T + K R K^T`` (Bucy & Joseph 1968): PSD for any gain ``K``.

    With library calls, the same quadratic form in one block, ``M diag(P, R) M^T`` with ``M = [I - K H, K]``: three
    ``dot`` calls instead of five.
    """
    I_KH = jnp.eye(cov.shape[0], dtype=cov.dtype) - matmul(gain, H)
    if _library():
        M = jnp.concatenate([I_KH, gain], axis=1)
        return symmetrize(M @ jsl.block_diag(cov, noise_cov) @ M.T)
    return symmetrize(matmul(matmul(I_KH, cov), I_KH.T) + matmul(matmul(gain, noise_cov), gain.T))


def gain_from_cross_cov(cross_cov: Array, chol: Array, unroll: bool = True) -> Array:
    """Kalman gain ``K = P_xy S^{-1}`` by a Cholesky solve (``S = L L^T``)."""
    return cho_solve(chol, cross_cov.T, unroll).T
