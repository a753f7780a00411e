"""Discrete algebraic Riccati equation (DARE) by structure-preserving doubling, its verification and derivative,
and the steady-state Kalman filter.

``X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q`` (``scipy.linalg.solve_discrete_are`` convention), i.e.
``X = A^T X (I + G X)^-1 A + Q`` with ``G = B R^-1 B^T``. SDA (Chu, Fan & Lin 2005, "A structure-preserving doubling
algorithm for discrete-time algebraic Riccati equations", Linear Algebra Appl. 396), from
``A_0 = A, G_0 = G, H_0 = Q``::

    W_k     = I + G_k H_k
    A_{k+1} = A_k W_k^-1 A_k
    G_{k+1} = G_k + A_k W_k^-1 G_k A_k^T
    H_{k+1} = H_k + A_k^T H_k W_k^-1 A_k

``H_k`` is the ``2^k``-step Riccati iterate; it converges quadratically to the stabilising solution when ``(A, B)``
is stabilisable and ``(Q, A)`` has no unobservable mode on the unit circle. One LU per iteration, in a
``lax.while_loop`` (jits, vmaps); the loop stops at the first non-finite iterate (without a stabilising solution
``H_k`` grows like ``|lambda|^(2^k)`` and overflows).

Verification: ``converged`` only when ``X`` is finite, the relative residual
``||X - A^T X A + A^T X B K - Q||_F / (||X||_F + ||A^T X A||_F + ||Q||_F)``, ``K = (R + B^T X B)^-1 B^T X A``, is
<= ``sqrt(eps)``, and ``rho(A - B K) < 1 - sqrt(eps)``. The residual is computed on ``X / max |X|`` (the equation is
homogeneous in ``(X, Q, R)``), so a large valid solution does not overflow it.

Derivative (implicit, a ``jax.custom_jvp``): ``K`` is a stationary point of
``F(X, K) = Q + K^T R K + (A - B K)^T X (A - B K)``, so differentiating ``X = F(X, K)`` gives the Stein equation

    dX - A_c^T dX A_c = dQ + K^T dR K + (dA - dB K)^T X A_c + A_c^T X (dA - dB K),

``A_c = A - B K`` (e.g. Kao & Hennequin 2020, "Automatic differentiation of Sylvester, Lyapunov, and algebraic
Riccati equations"), solved by Smith's doubling ``Y_{j+1} = Y_j + P_j^T Y_j P_j``, ``P_{j+1} = P_j^2`` in
``lax.custom_linear_solve`` (transpose ``Z - A_c Z A_c^T = b``: the same doubling on ``A_c^T``). Linear tangents give
forward mode (``jvp``, ``jacfwd``) and, by transposition, reverse mode (``grad``, ``vjp``); a ``custom_vjp`` would
lose forward mode. The solver's loop is never differentiated.

The filter Riccati equation of ``jaxfdi.filters._kalman`` (``P' = Phi P+ Phi^T + Q``, ``Q`` the per-step process
noise, not ``Gamma Q Gamma^T``) is the DARE with ``A = Phi^T``, ``B = C^T``; LQR's is ``(Phi, Gamma, Q_x, R_u)``.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.models import LinearGaussianModel, validate_linear_model


class DareSolution(NamedTuple):
    """A discrete algebraic Riccati equation's solution with its checks.

    Attributes:
      solution: (n, n) X, the stabilising solution when ``converged``
      converged: () bool: X finite, residual <= sqrt(eps), closed loop stable
      iterations: () int: doubling steps taken (X is the 2^iterations-step iterate)
      residual: () relative DARE residual of X (inf when X is not finite)
      spectral_radius: () max |eig(A - B K)|, K = (R + B^T X B)^-1 B^T X A (inf when not finite)
    """

    solution: Array
    converged: Array
    iterations: Array
    residual: Array
    spectral_radius: Array


class SteadyStateKalman(NamedTuple):
    """Steady-state Kalman filter of a ``LinearGaussianModel``.

    Attributes:
      predicted_cov: (n, n) P = lim P[k|k-1]
      innovation_cov: (m, m) S = C P C^T + R
      gain: (n, m) K = P C^T S^-1, the measurement-update gain
      converged: () bool, from the Riccati solver (a stabilising solution was found)
      residual: () relative residual of the filter Riccati equation
      spectral_radius: () max |eig(Phi (I - K C))|, the predictor's error dynamics (< 1)
    """

    predicted_cov: Array
    innovation_cov: Array
    gain: Array
    converged: Array
    residual: Array
    spectral_radius: Array


#: the message of every "no stabilising solution" error
NO_SOLUTION = "no stabilising solution of the discrete algebraic Riccati equation"


def _check_dare(A, B, Q, R, names=("A", "B", "Q", "R")) -> None:
    n = checks.check_square(names[0], A, None, "state matrix")
    checks.check_matrix(names[1], B, (n, None), "n states x p inputs")
    p = checks.shape_of(B)[1]
    checks.check_covariance(names[2], Q, n)
    checks.check_covariance(names[3], R, p, definite=True)


def _float_dtype(*arrays):
    dtype = checks.float_dtype(*arrays)
    return dtype if jnp.issubdtype(dtype, jnp.floating) else jnp.result_type(float)


def _settings(dtype, tol, max_iter) -> tuple[float, int]:
    max_iter = checks.check_int(
        "max_iter", max_iter, minimum=1, meaning="a number of doubling steps"
    )
    if tol is None:
        return 100.0 * float(jnp.finfo(dtype).eps), max_iter
    checks.check_positive("tol", tol, "a positive relative tolerance (a Python float)")
    return float(tol), max_iter


def solve_discrete_are_info(
    A: Array, B: Array, Q: Array, R: Array, tol=None, max_iter: int = 64
) -> DareSolution:
    """Stabilising solution of ``X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q`` by structure-preserving
    doubling (Chu, Fan & Lin 2005), verified (module doc).

    Never raises without a stabilising solution: ``converged = False`` (``residual``, ``spectral_radius`` say why),
    so it works under ``jit``/``vmap``. Differentiable in ``A, B, Q, R``, forward and reverse mode (module doc).

    Args:
      A: (n, n) state matrix.
      B: (n, p) input matrix.
      Q: (n, n) symmetric positive semi-definite state weight.
      R: (p, p) symmetric positive definite input weight.
      tol: stop when ``||H_{k+1} - H_k||_F <= tol ||H_{k+1}||_F``; default ``100 eps`` of the dtype (increments
        shrink like ``rho(A_cl)^(2^k)``, so they reach round-off).
      max_iter: most doubling steps (static).

    Returns:
      ``DareSolution`` in the dtype of ``A`` promoted with the others.
    """
    _check_dare(A, B, Q, R)
    dtype = _float_dtype(A, B, Q, R)
    tol, max_iter = _settings(dtype, tol, max_iter)
    return _solve(*(jnp.asarray(x, dtype) for x in (A, B, Q, R)), tol, max_iter)


def solve_discrete_are(
    A: Array, B: Array, Q: Array, R: Array, tol=None, max_iter: int = 64
) -> Array:
    """(n, n) stabilising DARE solution ``X`` (``scipy.linalg.solve_discrete_are(A, B, Q, R)`` convention).

    Raises ``ValueError`` when the arguments are concrete and no stabilising solution was found; under
    ``jit``/``vmap`` use ``solve_discrete_are_info`` and its ``converged``.

    Returns:
      (n, n) ``X``, the stabilising solution, in the dtype of ``A`` promoted with the others.
    """
    result = solve_discrete_are_info(A, B, Q, R, tol, max_iter)
    require_stabilising(
        result,
        (A, B, Q, R),
        "A, B, Q, R",
        "(A, B) is not stabilisable or (Q, A) has an unobservable mode on the unit circle",
    )
    return result.solution


def require_stabilising(
    result, arguments, names: str, why: str, allow_marginal: bool = False
) -> None:
    """Raise ``ValueError`` (naming ``names``) when all ``arguments`` are concrete and ``result`` (``DareSolution``
    or ``SteadyStateKalman``) is not stabilising; nothing under ``jit``/``vmap`` (the caller has the flag).
    ``allow_marginal`` also accepts a finite solution with closed-loop eigenvalues on the unit circle (within
    ``sqrt(eps)``): an uncontrollable mode at ``|z| = 1`` no gain can move (``lqr_pi``'s paper design).
    """
    leaves = jax.tree_util.tree_leaves((arguments, result))
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
        return
    if bool(result.converged):
        return
    radius, residual = float(result.spectral_radius), float(result.residual)
    if allow_marginal:
        margin = float(np.sqrt(np.finfo(np.asarray(result.spectral_radius).dtype).eps))
        if np.isfinite(residual) and abs(radius - 1.0) <= margin:
            return
    steps = (
        f", after {int(result.iterations)} doubling steps" if hasattr(result, "iterations") else ""
    )
    raise ValueError(
        f"{names}: {NO_SOLUTION}: {why} (closed-loop spectral radius {radius:.6g}, "
        f"relative residual {residual:.3g}{steps})"
    )


@partial(jax.jit, static_argnums=(4, 5))
def _solve(A: Array, B: Array, Q: Array, R: Array, tol: float, max_iter: int) -> DareSolution:
    X, iterations = _stabilising_solution(A, B, Q, R, tol, max_iter)
    residual, radius = _verify(*(jax.lax.stop_gradient(a) for a in (A, B, Q, R, X)))
    eps = jnp.finfo(X.dtype).eps
    converged = (
        jnp.all(jnp.isfinite(X)) & (residual <= jnp.sqrt(eps)) & (radius < 1.0 - jnp.sqrt(eps))
    )
    return DareSolution(X, converged, iterations, residual, radius)


def _gain(A: Array, B: Array, R: Array, X: Array) -> Array:
    """``K = (R + B^T X B)^-1 B^T X A`` (LU: ``R + B^T X B`` may be indefinite off the solution)."""
    return jnp.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)


def _verify(A: Array, B: Array, Q: Array, R: Array, X: Array) -> tuple[Array, Array]:
    """Relative residual and closed-loop spectral radius of ``X`` (module doc); ``inf`` for a non-finite ``X``."""
    finite = jnp.all(jnp.isfinite(X))
    scale = jnp.max(jnp.abs(jnp.where(finite, X, 0.0)))  # not a norm: its squares could overflow
    scale = jnp.where(finite & (scale > 0), scale, 1.0)
    Xs, Qs, Rs = (jnp.where(finite, a / scale, 0.0) for a in (X, Q, R))
    K = _gain(A, B, Rs, Xs)
    closed_loop = A - B @ K
    AtXA = A.T @ Xs @ A
    residual_matrix = Xs - AtXA + A.T @ Xs @ B @ K - Qs
    denominator = jnp.linalg.norm(Xs) + jnp.linalg.norm(AtXA) + jnp.linalg.norm(Qs)
    residual = jnp.linalg.norm(residual_matrix) / jnp.where(denominator > 0, denominator, 1.0)
    ok = finite & jnp.all(jnp.isfinite(closed_loop)) & jnp.isfinite(residual)
    radius = jnp.max(jnp.abs(jnp.linalg.eigvals(jnp.where(ok, closed_loop, 0.0))))
    inf = jnp.asarray(jnp.inf, X.dtype)
    return jnp.where(ok, residual, inf), jnp.where(ok, radius.astype(X.dtype), inf)


@partial(jax.custom_jvp, nondiff_argnums=(4, 5))
def _stabilising_solution(
    A: Array, B: Array, Q: Array, R: Array, tol: float, max_iter: int
) -> tuple[Array, Array]:
    """``(X, iterations)`` by doubling; differentiated implicitly (``_solution_jvp``)."""
    return _doubling(A, B, Q, R, tol, max_iter)


def _doubling(
    A: Array, B: Array, Q: Array, R: Array, tol: float, max_iter: int
) -> tuple[Array, Array]:
    n = A.shape[0]
    eye = jnp.eye(n, dtype=A.dtype)
    G = _linalg.symmetrize(
        B @ jsl.cho_solve(jsl.cho_factor(_linalg.symmetrize(R), lower=True), B.T)
    )  # B R^-1 B^T
    H = _linalg.symmetrize(Q)

    def cond(carry):
        _, _, _, k, done = carry
        return (k < max_iter) & ~done

    def body(carry):
        A_k, G_k, H_k, k, _ = carry
        W = eye + G_k @ H_k
        solved = jsl.lu_solve(jsl.lu_factor(W), jnp.concatenate([A_k, G_k @ A_k.T], axis=1))
        W_inv_A, W_inv_GAt = solved[:, :n], solved[:, n:]
        increment = _linalg.symmetrize(A_k.T @ H_k @ W_inv_A)
        H_next = H_k + increment
        G_next = _linalg.symmetrize(G_k + A_k @ W_inv_GAt)
        A_next = A_k @ W_inv_A
        small = jnp.linalg.norm(increment) <= tol * jnp.linalg.norm(H_next)
        finite = (
            jnp.all(jnp.isfinite(H_next))
            & jnp.all(jnp.isfinite(A_next))
            & jnp.all(jnp.isfinite(G_next))
        )
        return A_next, G_next, H_next, k + 1, small | ~finite  # stop at round-off or at overflow

    init = (A, G, H, jnp.zeros((), jnp.int32), jnp.zeros((), bool))
    _, _, X, iterations, _ = jax.lax.while_loop(cond, body, init)
    return X, iterations


@_stabilising_solution.defjvp
def _solution_jvp(tol, max_iter, primals, tangents):
    A, B, Q, R = primals
    dA, dB, dQ, dR = tangents
    X, iterations = _stabilising_solution(A, B, Q, R, tol, max_iter)
    K = _gain(A, B, R, X)
    closed_loop = A - B @ K
    dA_c = dA - dB @ K
    forcing = dQ + K.T @ dR @ K + dA_c.T @ X @ closed_loop + closed_loop.T @ X @ dA_c
    dX = stein_solve(closed_loop, _linalg.symmetrize(forcing))
    return (X, iterations), (dX, np.zeros(iterations.shape, jax.dtypes.float0))


def stein_solve(closed_loop: Array, forcing: Array) -> Array:
    """``Y`` with ``Y - A_c^T Y A_c = M`` (``A_c`` = ``closed_loop`` stable, ``M`` = ``forcing``), linear in ``M``
    and transposable by JAX (``lax.custom_linear_solve``)."""

    def stein(Y):
        return Y - closed_loop.T @ Y @ closed_loop

    return jax.lax.custom_linear_solve(
        stein,
        forcing,
        solve=lambda _, b: _smith_doubling(closed_loop, b),
        transpose_solve=lambda _, b: _smith_doubling(closed_loop.T, b),
    )


def _smith_doubling(closed_loop: Array, forcing: Array, max_iter: int = 64) -> Array:
    """``sum_k (A^T)^k M A^k`` by doubling (Smith 1968): ``Y <- Y + P^T Y P``, ``P <- P^2``, until the increment
    reaches round-off (quadratic once ``rho(A)^(2^j)`` is small)."""
    eps = jnp.finfo(forcing.dtype).eps

    def cond(carry):
        _, _, j, done = carry
        return (j < max_iter) & ~done

    def body(carry):
        Y, P, j, _ = carry
        increment = P.T @ Y @ P
        Y_next = Y + increment
        small = jnp.linalg.norm(increment) <= eps * jnp.linalg.norm(Y_next)
        return Y_next, P @ P, j + 1, small | ~jnp.all(jnp.isfinite(Y_next))

    Y, _, _, _ = jax.lax.while_loop(
        cond, body, (forcing, closed_loop, jnp.zeros((), jnp.int32), jnp.zeros((), bool))
    )
    return Y


def steady_state_kalman(
    model: LinearGaussianModel, tol=None, max_iter: int = 64
) -> SteadyStateKalman:
    """Steady-state Kalman filter of ``model``, as ``jaxfdi.filters.kalman_filter`` converges to.

    ``P = Phi (P - P C^T S^-1 C P) Phi^T + Q`` is the DARE with ``A = Phi^T``, ``B = C^T`` (Anderson & Moore 1979,
    ch. 4); ``S = C P C^T + R``, ``K = P C^T S^-1``. ``kalman_filter(model)`` started from ``(mean, P)`` keeps
    ``P[k|k-1] = P`` and the constant gain ``K``. Differentiable in the model (implicit differentiation).

    Raises ``ValueError`` when the model is concrete and has no stabilising solution (``(C, Phi)`` not detectable,
    or ``(Phi, Q)`` with an uncontrollable mode on the unit circle); under ``jit``/``vmap`` check ``converged``.

    Returns:
      ``SteadyStateKalman``: ``P_ss``, ``S``, ``K`` and the solver's checks.
    """
    validate_linear_model(model)
    _check_dare(
        jnp.asarray(model.Phi).T,
        jnp.asarray(model.C).T,
        model.Q,
        model.R,
        ("model.Phi", "model.C", "model.Q", "model.R"),
    )
    dtype = _float_dtype(model.Phi, model.C, model.Q, model.R)
    tol, max_iter = _settings(dtype, tol, max_iter)
    arrays = tuple(jnp.asarray(a, dtype) for a in (model.Phi, model.C, model.Q, model.R))
    steady = _steady_state(*arrays, tol, max_iter)
    require_stabilising(
        steady,
        arrays,
        "model.Phi, model.C, model.Q",
        "(C, Phi) is not detectable or (Phi, Q) has an uncontrollable mode on the unit circle",
    )
    return steady


@partial(jax.jit, static_argnums=(4, 5))
def _steady_state(
    Phi: Array, C: Array, Q: Array, R: Array, tol: float, max_iter: int
) -> SteadyStateKalman:
    """One compiled executable; LAPACK factorisations compile faster here than ``_linalg``'s element-wise
    small-matrix versions (made for vmapped loops)."""
    dare = _solve.__wrapped__(Phi.T, C.T, Q, R, tol, max_iter)
    P = _linalg.symmetrize(dare.solution)
    S = _linalg.symmetrize(C @ P @ C.T + R)
    K = jsl.cho_solve(jsl.cho_factor(S, lower=True), C @ P).T  # P C^T S^-1
    return SteadyStateKalman(P, S, K, dare.converged, dare.residual, dare.spectral_radius)
