"""Parallel-in-time Kalman filter: the filtering recursion as an associative scan (Särkkä & García-Fernández 2021,
"Temporal parallelization of Bayesian smoothers", IEEE TAC 66(1), sec. III-B), O(log T) depth instead of O(T).

Step ``k`` is an element ``(A, b, C, eta, J)`` of ``p(x_k | x_{k-1}, y_k) = N(A x_{k-1} + b, C)`` and
``p(y_k | x_{k-1}) ∝ N_I(x_{k-1}; eta, J)`` (information form). For ``x_k = Phi x_{k-1} + Gamma u_{k-1} + w``,
``y_k = C_y x_k + D u_k + v``, ``c = Gamma u_{k-1}``, ``e = y_k - D u_k - C_y c``:

    S = C_y Q C_y^T + R,   K = Q C_y^T S^-1,
    A = (I - K C_y) Phi,   b = c + K e,   C = (I - K C_y) Q (I - K C_y)^T + K R K^T,
    eta = Phi^T C_y^T S^-1 e,   J = Phi^T C_y^T S^-1 C_y Phi,

step 0 conditioning ``N(m0, P0)`` on ``y_0`` (``A = 0``, ``eta = 0``, ``J = 0``). Combination (their eqs. 14-15;
``i`` before ``j``):

    M = I + C_i J_j,
    A_ij = A_j M^-1 A_i,            b_ij = A_j M^-1 (b_i + C_i eta_j) + b_j,
    C_ij = A_j M^-1 C_i A_j^T + C_j,
    eta_ij = A_i^T M^-T (eta_j - J_j b_i) + eta_i,   J_ij = A_i^T M^-T J_j A_i + J_i,

and the prefix up to ``k`` is ``N(x_k | y_0..y_k) = N(b, C)``; ``FilterInfo`` follows for all steps at once, equal to
``run_filter(kalman_filter(model, missing_measurements=True), ...)`` to round-off. Cost: ~4x the sequential
arithmetic (n x n solves per combination, ``2T`` combinations) in ``2 log2 T`` rounds: wins on a GPU for long
sequences, loses on a CPU (``benchmarks/bench_scale.py``).

A dead (non-finite) component of ``y_k`` is left out of its step exactly (rows of ``C_y``, ``R`` dropped) and reported
as elsewhere (innovation NaN, ``nis = +inf``, ``filters._base.report_dead``); the sequential default's
pseudo-measurement (the prediction) depends on the predicted mean, unknown to an element before the scan. Solves and
Cholesky use ``_linalg``'s written-out forms, not LAPACK (with batched LAPACK in every level XLA:CPU, jaxlib 0.10.2,
never returned for T >= 2048-4096; ``tests/filters/test_parallel_kalman.py``); above ``_linalg.UNROLL_MAX`` (8)
states Cholesky is LAPACK again (long sequences untested on CPU).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import (
    FilterInfo,
    GaussianState,
    check_gaussian,
    check_sequences,
    report_dead,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model


class FilteringElement(NamedTuple):
    """One associative-scan element (leading time axis when stacked).

    Attributes:
      A: (n, n)
      b: (n,)
      C: (n, n)
      eta: (n,)
      J: (n, n)
    """

    A: Array
    b: Array
    C: Array
    eta: Array
    J: Array


def _mT(a: Array) -> Array:
    return jnp.swapaxes(a, -1, -2)


def _sym(a: Array) -> Array:
    return 0.5 * (a + _mT(a))


def _mv(a: Array, x: Array) -> Array:
    return jnp.einsum("...ij,...j->...i", a, x)


def _psd_solve(S: Array, rhs: Array) -> Array:
    """``S^-1 rhs`` for a stack of symmetric positive definite ``S`` (Cholesky)."""
    return _linalg.stack_cho_solve(_linalg.stack_cholesky(_sym(S)), rhs)


def _observed(model: LinearGaussianModel, ys: Array) -> tuple[Array, Array, Array, Array]:
    """``(mask, C_k, R_k, ys with 0)``: per step, rows of ``C`` and ``R`` for the finite components of ``ys`` (T, m);
    a dead one's row is 0, its ``R`` entry 1 (unit variance, uncorrelated, innovation 0: it moves nothing)."""
    mask = jnp.isfinite(ys)
    C = jnp.where(mask[:, :, None], model.C, 0.0)  # (T, m, n)
    both = mask[:, :, None] & mask[:, None, :]
    R = jnp.where(both, model.R, jnp.eye(model.R.shape[0], dtype=model.R.dtype))  # (T, m, m)
    return mask, C, R, jnp.where(mask, ys, 0.0)


def filtering_elements(
    model: LinearGaussianModel, m0: Array, P0: Array, ys: Array, us: Array
) -> FilteringElement:
    """The T elements of ``ys`` (T, m), inputs ``us`` (T, nu) (module doc; non-finite components left out)."""
    Phi, Gamma, _, D, Q, _ = model
    mask, C, R, ys = _observed(model, ys)
    n = Phi.shape[0]
    eye = jnp.eye(n, dtype=m0.dtype)
    bias = jnp.concatenate(
        [jnp.zeros((1, n), m0.dtype), us[:-1] @ Gamma.T]
    )  # Gamma u_{k-1}, (T, n)
    prior_mean = jnp.concatenate([m0[None], bias[1:]])  # mean of x_k given x_{k-1} = 0
    prior_cov = jnp.concatenate([P0[None], jnp.broadcast_to(Q, (ys.shape[0] - 1, n, n))])
    residual = jnp.where(mask, ys - us @ D.T - _mv(C, prior_mean), 0.0)  # e, (T, m)
    S = _sym(C @ prior_cov @ _mT(C) + R)
    gain = _mT(_psd_solve(S, C @ prior_cov))  # (T, n, m)
    contraction = eye - gain @ C
    cov = _sym(contraction @ prior_cov @ _mT(contraction) + gain @ R @ _mT(gain))
    A = jnp.concatenate([jnp.zeros((1, n, n), m0.dtype), contraction[1:] @ Phi])
    CPhi = C[1:] @ Phi  # (T - 1, m, n)
    S_inv_C_Phi = _psd_solve(S[1:], CPhi)
    S_inv_residual = _psd_solve(S[1:], residual[1:, :, None])[..., 0]  # (T - 1, m)
    eta = jnp.concatenate(
        [jnp.zeros((1, n), m0.dtype), jnp.einsum("tm,tmn->tn", S_inv_residual, CPhi)]
    )
    J = jnp.concatenate(
        [jnp.zeros((1, n, n), m0.dtype), _sym(jnp.einsum("tmi,tmj->tij", CPhi, S_inv_C_Phi))]
    )
    return FilteringElement(A, prior_mean + _mv(gain, residual), cov, eta, J)


def combine_filtering(earlier: FilteringElement, later: FilteringElement) -> FilteringElement:
    """``earlier ⊗ later`` for stacks of elements (Särkkä & García-Fernández 2021, eqs. 14-15)."""
    A1, b1, C1, eta1, J1 = earlier
    A2, b2, C2, eta2, J2 = later
    M = jnp.eye(A1.shape[-1], dtype=A1.dtype) + C1 @ J2
    A2_Minv = _mT(_linalg.solve_pivoted(_mT(M), _mT(A2)))  # A_j M^-1 (no LAPACK: _linalg)
    Minv_A1 = _linalg.solve_pivoted(M, A1)  # M^-1 A_i; A_i^T M^-T = its transpose
    return FilteringElement(
        A=A2_Minv @ A1,
        b=_mv(A2_Minv, b1 + _mv(C1, eta2)) + b2,
        C=_sym(A2_Minv @ C1 @ _mT(A2) + C2),
        eta=_mv(_mT(Minv_A1), eta2 - _mv(J2, b1)) + eta1,
        J=_sym(_mT(Minv_A1) @ J2 @ A1 + J1),
    )


def parallel_scan(
    model: LinearGaussianModel, init_state: GaussianState, ys: Array, us: Array | None = None
) -> tuple[GaussianState, FilterInfo]:
    """Kalman filter over a whole sequence by an associative scan (module doc), as run by
    ``run_filter(kalman_filter(model, missing_measurements=True), ..., parallel=True)``.

    Args:
      model: a ``LinearGaussianModel``.
      init_state: ``GaussianState(m0, P0)``, the prior of ``x_0`` (``kalman_filter(model).init``).
      ys: (T, m) measurements, T >= 1; a non-finite component is a dead sensor (module doc).
      us: (T, nu) inputs, or ``None``.

    Returns:
      ``(final_state, info)`` as ``run_filter(kalman_filter(model, True), init_state, ys, us)``: the prediction for
      step T and the per-step ``FilterInfo`` (leading axis T).
    """
    n, nu, m = validate_linear_model(model)
    if not isinstance(init_state, GaussianState):
        raise TypeError(
            f"init_state: expected a GaussianState(mean, cov) (kalman_filter(model).init(m0, P0)), "
            f"got {checks.received(init_state)}"
        )
    m0, P0 = check_gaussian(
        init_state.mean, init_state.cov, n, ("init_state.mean", "init_state.cov")
    )
    check_sequences(ys, us, "(T, m)", "(T, nu)")
    checks.check_shape("ys", ys, (None, m), "T steps x m outputs")
    if checks.shape_of(ys)[0] < 1:
        raise ValueError(f"ys: expected at least one step, got shape {checks.shape_of(ys)}")
    num_steps = checks.shape_of(ys)[0]
    if us is None:
        us = jnp.zeros((num_steps, nu))
    checks.check_shape("us", us, (num_steps, nu), "T steps x nu inputs, as many steps as ys")
    dtype = jnp.result_type(m0, P0, ys, *model)
    return _parallel_filter(
        LinearGaussianModel(*(jnp.asarray(a, dtype) for a in model)),
        m0.astype(dtype),
        P0.astype(dtype),
        jnp.asarray(ys, dtype),
        jnp.asarray(us, dtype),
    )


@jax.jit
def _parallel_filter(model: LinearGaussianModel, m0: Array, P0: Array, ys: Array, us: Array):
    Phi, Gamma, _, D, Q, _ = model
    dead = ~jnp.isfinite(ys)
    elements = filtering_elements(model, m0, P0, ys, us)
    filtered = jax.lax.associative_scan(combine_filtering, elements)
    mean, cov = filtered.b, filtered.C
    next_mean = mean @ Phi.T + us @ Gamma.T  # x[k+1|k], (T, n)
    next_cov = _sym(Phi @ cov @ Phi.T + Q)
    predicted_mean = jnp.concatenate([m0[None], next_mean[:-1]])
    predicted_cov = jnp.concatenate([P0[None], next_cov[:-1]])
    mask, C, R, ys = _observed(model, ys)
    innovation = jnp.where(mask, ys - _mv(C, predicted_mean) - us @ D.T, 0.0)
    S = _sym(C @ predicted_cov @ _mT(C) + R)
    chol_S = _linalg.stack_cholesky(S)
    whitened = _linalg.stack_solve_lower(chol_S, innovation[..., None])[..., 0]
    nis = jnp.sum(whitened**2, axis=-1)
    num_observed = jnp.sum(mask, axis=-1).astype(jnp.int32)
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol_S, axis1=-2, axis2=-1)), axis=-1)
    log_likelihood = -0.5 * (nis + log_det + num_observed * math.log(2.0 * math.pi))
    healthy = (
        jnp.all(jnp.isfinite(chol_S), axis=(-2, -1))
        & jnp.all(jnp.isfinite(mean), axis=-1)
        & jnp.all(jnp.isfinite(_linalg.stack_cholesky(cov)), axis=(-2, -1))
        & jnp.all(jnp.isfinite(next_mean), axis=-1)
        & jnp.isfinite(nis)
        & jnp.isfinite(log_likelihood)
    )
    innovation, nis = report_dead(innovation, nis, dead, axis=-1)
    info = FilterInfo(
        predicted_mean,
        predicted_cov,
        mean,
        cov,
        innovation,
        S,
        log_likelihood,
        nis,
        num_observed,
        healthy,
    )
    return GaussianState(next_mean[-1], next_cov[-1]), info
