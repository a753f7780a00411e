"""Kalman filter robust to an unknown input: the unbiased minimum-variance (UMV) filter of Kitanidis (1987), the
state estimator of Lee & Lyou's feedback loop.

Plant ``x[k+1] = Phi x + Gamma u + E d + w``, ``y = C x + D u + v``, ``d`` unknown (arbitrary, e.g. model
uncertainty ``Delta A x``). Gain

    K = K0 + (I - K0 C) E (F^T S^-1 F)^-1 F^T S^-1,   K0 = P C^T S^-1,  F = C E,

minimum-variance among gains with ``(I - K C) E = 0`` (posterior error free of ``d``; the KF's limit for a diffuse
``d``). Whitened (``S = L L^T``, QR ``L^-1 F = [Q1 Q2] [R1; 0]``) the correction is ``(I - K0 C) E R1^-1 Q1^T L^-1``,
and the innovation's ``d``-free part ``Q2^T L^-1 r`` (``m - q`` components) gives the chi-square(m - q) statistic
(``nis``) and de Jong's (1991) diffuse log-likelihood. Decoupling needs ``rank(C E) = rank(E) = q <= m`` (Lee &
Lyou, eq. 5; ``check_decoupling`` at build time). Predict as the KF without ``E d`` (the gain removed its effect).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import (
    Filter,
    FilterInfo,
    GaussianState,
    check_step_inputs,
    dead_components,
    gaussian_filter,
    mask_innovation_cov,
    observed_rows,
    report_dead,
    used_innovation,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model


def check_decoupling(model: LinearGaussianModel, unknown_input: Array) -> int:
    """Check ``rank(C E) = rank(E) = q <= m`` (Lee & Lyou, eq. 5) and return ``q``; raises a ``ValueError`` naming
    the failed condition; ``E`` must be concrete."""
    n, _, m = validate_linear_model(model)
    checks.check_matrix("unknown_input", unknown_input, (n, None), "E: n states x q unknown inputs")
    E = checks.concrete(unknown_input)
    C = checks.concrete(model.C)
    if E is None or C is None:
        raise ValueError(
            "unknown_input: E and model.C must be concrete (not traced) to check decoupling"
        )
    q = E.shape[1]
    rank_E = np.linalg.matrix_rank(E) if q else 0
    rank_CE = np.linalg.matrix_rank(C @ E) if q else 0
    if q > m:
        raise ValueError(
            f"unknown_input: q = {q} unknown inputs cannot be decoupled with m = {m} outputs (need q <= m)"
        )
    if rank_E != q:
        raise ValueError(f"unknown_input: E must have full column rank q = {q}, got rank {rank_E}")
    if rank_CE != q:
        raise ValueError(
            f"unknown_input: decoupling needs rank(C E) = rank(E) = {q}, got rank(C E) = {rank_CE} "
            "(the unknown input does not reach the outputs in every direction)"
        )
    return q


def unbiased_minimum_variance_gain(
    cross_cov: Array, chol_S: Array, C: Array, unknown_input: Array | None
) -> tuple[Array, Array]:
    """``(K, N)``: the UMV gain (Kalman gain without unknown input) and the (m, m - q) orthonormal basis ``N`` of
    the whitened innovation's ``d``-free part (identity without unknown input).

    Args:
      cross_cov: (n, m) ``P C^T``; chol_S: (m, m) Cholesky factor of ``S``; C: (m, n); unknown_input: (n, q) ``E``
        or ``None``.
    """
    gain = _linalg.gain_from_cross_cov(cross_cov, chol_S)  # K0 = P C^T S^-1
    m = chol_S.shape[0]
    if unknown_input is None or unknown_input.shape[1] == 0:
        return gain, jnp.eye(m, dtype=chol_S.dtype)
    mm = _linalg.matmul
    E = jnp.asarray(unknown_input, chol_S.dtype)
    q = E.shape[1]
    Q_full, R_f = jnp.linalg.qr(
        _linalg.solve_lower(chol_S, mm(C, E)), mode="complete"
    )  # L^-1 C E = Q1 R1
    coeff = jax.scipy.linalg.solve_triangular(R_f[:q], Q_full[:, :q].T, lower=False)  # R1^-1 Q1^T
    I_KC = jnp.eye(E.shape[0], dtype=E.dtype) - mm(gain, C)
    correction = mm(mm(I_KC, E), coeff)  # acts on L^-1 r
    return gain + _linalg.solve_lower_transposed(chol_S, correction.T).T, Q_full[:, q:]


def decouplable(chol_S: Array, C_observed: Array, C: Array, unknown_input: Array) -> Array:
    """() bool: ``rank(C_obs E) = q``: the whitened ``L^-1 C_obs E`` has ``q`` pivots (``|diag R1|``, from its Gram
    matrix's Cholesky factor) above round-off of the scale of ``L^-1 C E`` with every sensor."""
    mm = _linalg.matmul
    E = jnp.asarray(unknown_input, chol_S.dtype)
    white = _linalg.solve_lower(chol_S, mm(C_observed, E))
    scale = jnp.max(jnp.abs(_linalg.solve_lower(chol_S, mm(C, E))))
    pivots = jnp.diagonal(_linalg.cholesky(_linalg.symmetrize(mm(white.T, white))))
    return jnp.all(pivots > 1e3 * jnp.finfo(chol_S.dtype).eps * scale)


def diffuse_log_likelihood(
    statistic: Array, chol_S: Array, C: Array, unknown_input: Array | None, dof: int
) -> Array:
    """``-0.5 (lambda + log det S + log det(F^T S^-1 F) + dof log 2 pi)``, ``F = C E``: the Kalman log-likelihood, or
    with an unknown input de Jong's (1991) diffuse one, independent of ``d``."""
    log_det = 2.0 * jnp.sum(jnp.log(jnp.diagonal(chol_S)))
    if unknown_input is not None and unknown_input.shape[1]:
        F_white = _linalg.solve_lower(
            chol_S, _linalg.matmul(C, jnp.asarray(unknown_input, chol_S.dtype))
        )
        log_det = log_det + jnp.linalg.slogdet(F_white.T @ F_white)[1]
    return -0.5 * (statistic + log_det + dof * math.log(2.0 * math.pi))


def unknown_input_filter(
    model: LinearGaussianModel, unknown_input: Array, missing_measurements: bool = False
) -> Filter:
    """Kitanidis's unbiased minimum-variance filter, decoupling ``E d``.

    Args:
      model: the nominal ``LinearGaussianModel``.
      unknown_input: (n, q) distribution ``E`` of the unknown input (concrete), ``rank(C E) = rank(E) = q <= m``.
      missing_measurements: NaN components of ``y`` are not measured: their rows of ``C`` are left out of update,
        decoupling and statistic (``chi2(m_obs - q)``), as in ``kalman.joseph_update``. Decoupling then needs
        ``rank(C_obs E) = q``; where the remaining sensors lose it, the step keeps the prediction (no update,
        statistic 0 with 0 dof): nothing they say is free of ``d``.

    Returns:
      a Gaussian ``Filter`` (``init``, ``step``, ``update``, ``predict``); ``FilterInfo.nis`` is the decoupled
      statistic, chi-square with ``m - q`` dof (in ``num_observed``; ``m_obs - q`` with missing measurements);
      ``innovation``, ``innovation_cov`` are the full ``r``, ``S``. A dead (non-finite; with
      ``missing_measurements`` infinite) component of ``y`` is reported and not used (``filters._base``).
    """
    n, nu, m = validate_linear_model(model)
    q = check_decoupling(model, unknown_input)
    E = jnp.asarray(unknown_input)
    mm = _linalg.matmul

    def update(state: GaussianState, y: Array, u: Array) -> FilterInfo:
        check_step_inputs(y, u, m, nu)
        innovation = used_innovation(
            y, mm(model.C, state.mean) + mm(model.D, u)
        )  # a dead component: 0
        C, R, dof = model.C, model.R, jnp.asarray(m - q, jnp.int32)
        if missing_measurements:
            mask = jnp.isfinite(y)
            C, R = observed_rows(mask, C, R)
            dof = (jnp.sum(mask) - q).astype(jnp.int32)
        cross_cov = mm(state.cov, C.T)
        S = _linalg.symmetrize(mm(C, cross_cov) + R)
        if missing_measurements:  # a missing component: unit variance, uncorrelated, innovation 0
            S = mask_innovation_cov(S, mask)
        chol_S = _linalg.cholesky(S)
        gain, basis = unbiased_minimum_variance_gain(cross_cov, chol_S, C, E)
        decoupled = mm(basis.T, _linalg.whiten(chol_S, innovation))
        statistic = jnp.sum(decoupled**2)
        mean = state.mean + mm(gain, innovation)
        cov = _linalg.joseph_cov(state.cov, gain, C, R)
        log_lik = diffuse_log_likelihood(statistic, chol_S, C, E, dof)
        if missing_measurements:  # the sensors left cannot decouple d: keep the prediction
            blind = ~decouplable(chol_S, C, model.C, E)
            mean, cov = jnp.where(blind, state.mean, mean), jnp.where(blind, state.cov, cov)
            statistic, log_lik = jnp.where(blind, 0.0, statistic), jnp.where(blind, 0.0, log_lik)
            dof = jnp.where(blind, 0, dof).astype(jnp.int32)
        healthy = _linalg.cholesky_is_finite(chol_S) & jnp.all(jnp.isfinite(mean))
        innovation, statistic = report_dead(
            innovation, statistic, dead_components(y, missing_measurements)
        )
        return FilterInfo(
            state.mean, state.cov, mean, cov, innovation, S, log_lik, statistic, dof, healthy
        )

    def predict(post: GaussianState, u: Array) -> GaussianState:
        mean = mm(model.Phi, post.mean) + mm(model.Gamma, u)
        return GaussianState(
            mean, _linalg.symmetrize(mm(mm(model.Phi, post.cov), model.Phi.T) + model.Q)
        )

    return gaussian_filter(n, update, predict)
