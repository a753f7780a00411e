"""Discrete algebraic Riccati equation by structure-preserving doubling, and the
steady-state Kalman filter.

``X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q`` (the convention of
``scipy.linalg.solve_discrete_are``). With ``G = B R^-1 B^T`` it reads
``X = A^T X (I + G X)^-1 A + Q``, and the structure-preserving doubling algorithm
(SDA; Chu, Fan & Lin 2005, "A structure-preserving doubling algorithm for discrete-time
algebraic Riccati equations", Linear Algebra Appl. 396) iterates from
``A_0 = A, G_0 = G, H_0 = Q``::

    W_k     = I + G_k H_k
    A_{k+1} = A_k W_k^-1 A_k
    G_{k+1} = G_k + A_k W_k^-1 G_k A_k^T
    H_{k+1} = H_k + A_k^T H_k W_k^-1 A_k

``H_k`` is the Riccati iterate after ``2^k`` steps and converges quadratically to the
stabilising solution when ``(A, B)`` is stabilisable and ``(Q, A)`` detectable. One
iteration costs one LU factorisation and a few products, so the solver is a
``lax.while_loop`` that jit-compiles and vmaps (it is not reverse-differentiable:
differentiate the Riccati equation implicitly if a gradient is needed).

The filter Riccati equation of ``jaxfdi.filters.kalman`` (``P' = Phi P+ Phi^T + Q``,
``Q`` the per-step process-noise covariance, not ``Gamma Q Gamma^T``) is the DARE with
``A = Phi^T``, ``B = C^T``; the LQR equation is the DARE with ``(Phi, Gamma, Q_x, R_u)``.
"""
from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jax import Array

from jaxfdi import _checks, _linalg
from jaxfdi.models.linear import LinearGaussianModel, validate_linear_model


class DareSolution(NamedTuple):
    solution: Array    # (n, n) stabilising solution X
    converged: Array   # () bool: the last relative update was below tol
    iterations: Array  # () int: doubling steps taken (X is the 2^iterations-step iterate)


class SteadyStateKalman(NamedTuple):
    """Steady-state Kalman filter of a ``LinearGaussianModel``."""

    predicted_cov: Array   # (n, n) P = lim P[k|k-1]
    innovation_cov: Array  # (m, m) S = C P C^T + R
    gain: Array            # (n, m) K = P C^T S^-1, the measurement-update gain
    converged: Array       # () bool, from the Riccati solver


def _check_dare(A, B, Q, R) -> None:
    n = _checks.check_square("A", A, None, "state matrix")
    _checks.check_shape("B", B, (n, None), "n states x p inputs")
    p = _checks.shape_of(B)[1]
    _checks.check_covariance("Q", Q, n)
    _checks.check_covariance("R", R, p)


def solve_discrete_are_info(A: Array, B: Array, Q: Array, R: Array, tol=None, max_iter: int = 64) -> DareSolution:
    """Stabilising solution of ``X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q`` by
    structure-preserving doubling (Chu, Fan & Lin 2005), with its convergence flag.

    Args:
      A: (n, n) state matrix.
      B: (n, p) input matrix.
      Q: (n, n) symmetric positive semi-definite state weight.
      R: (p, p) symmetric positive definite input weight.
      tol: stop when ``||H_{k+1} - H_k||_F <= tol ||H_{k+1}||_F``; default ``100 eps`` of
        the dtype (the increments shrink like ``rho(A_cl)^(2^k)`` so they reach round-off).
      max_iter: most doubling steps (static).

    Returns:
      ``DareSolution(solution (n, n), converged (), iterations ())`` in the dtype of ``A``
      promoted with the others.
    """
    _check_dare(A, B, Q, R)
    if int(max_iter) < 1:
        raise ValueError(f"max_iter: expected a positive number of doubling steps, got {max_iter}")
    dtype = jnp.result_type(A, B, Q, R)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    A, B, Q, R = (jnp.asarray(x, dtype) for x in (A, B, Q, R))
    tol = 100.0 * jnp.finfo(dtype).eps if tol is None else tol
    return _doubling(A, B, Q, R, jnp.asarray(tol, dtype), int(max_iter))


def solve_discrete_are(A: Array, B: Array, Q: Array, R: Array, tol=None, max_iter: int = 64) -> Array:
    """(n, n) stabilising DARE solution ``X``, same convention as
    ``scipy.linalg.solve_discrete_are(A, B, Q, R)``; see ``solve_discrete_are_info``."""
    return solve_discrete_are_info(A, B, Q, R, tol, max_iter).solution


@partial(jax.jit, static_argnums=5)
def _doubling(A: Array, B: Array, Q: Array, R: Array, tol: Array, max_iter: int) -> DareSolution:
    n = A.shape[0]
    eye = jnp.eye(n, dtype=A.dtype)
    G = _linalg.symmetrize(B @ jsl.cho_solve(jsl.cho_factor(_linalg.symmetrize(R), lower=True), B.T))  # B R^-1 B^T
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
        return A_next, G_next, H_next, k + 1, small & jnp.all(jnp.isfinite(H_next))

    init = (A, G, H, jnp.zeros((), jnp.int32), jnp.zeros((), bool))
    _, _, X, iterations, converged = jax.lax.while_loop(cond, body, init)
    return DareSolution(X, converged, iterations)


def steady_state_kalman(model: LinearGaussianModel, tol=None, max_iter: int = 64) -> SteadyStateKalman:
    """Steady-state Kalman filter of ``model``, as ``jaxfdi.kalman_filter`` converges to.

    ``P = Phi (P - P C^T S^-1 C P) Phi^T + Q`` is the DARE with ``A = Phi^T``,
    ``B = C^T`` (Anderson & Moore 1979, ch. 4); ``S = C P C^T + R``, ``K = P C^T S^-1``.
    A ``kalman_filter(model)`` started from the prior ``(mean, P)`` keeps ``P[k|k-1] = P``
    and the constant gain ``K``.
    """
    validate_linear_model(model)
    Phi, C, Q, R = (jnp.asarray(a) for a in (model.Phi, model.C, model.Q, model.R))
    _check_dare(Phi.T, C.T, Q, R)
    dtype = jnp.result_type(Phi, C, Q, R)
    tol = 100.0 * jnp.finfo(dtype).eps if tol is None else tol
    return _steady_state(*(a.astype(dtype) for a in (Phi, C, Q, R)), jnp.asarray(tol, dtype), int(max_iter))


@partial(jax.jit, static_argnums=5)
def _steady_state(Phi: Array, C: Array, Q: Array, R: Array, tol: Array, max_iter: int) -> SteadyStateKalman:
    """One compiled executable. A one-off computation: LAPACK factorisations compile
    faster than ``_linalg``'s element-wise small-matrix versions (made for vmapped loops)."""
    dare = _doubling(Phi.T, C.T, Q, R, tol, max_iter)
    P = _linalg.symmetrize(dare.solution)
    S = _linalg.symmetrize(C @ P @ C.T + R)
    K = jsl.cho_solve(jsl.cho_factor(S, lower=True), C @ P).T  # P C^T S^-1
    return SteadyStateKalman(P, S, K, dare.converged)
