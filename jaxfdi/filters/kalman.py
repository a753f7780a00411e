"""Linear Kalman filter (Kalman 1960) with the Joseph-form covariance update.

Update (Joseph form, valid for any gain, keeps ``P`` symmetric positive definite):
``r = y - C m - D u``, ``S = C P C^T + R``, ``K = P C^T S^-1``,
``m+ = m + K r``, ``P+ = (I - K C) P (I - K C)^T + K R K^T`` (Bucy & Joseph 1968).
Predict: ``m' = Phi m+ + Gamma u``, ``P' = Phi P+ Phi^T + Q``.
Missing measurements (NaN components of ``y``) are skipped component-wise.
"""
from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array
from jax.scipy.linalg import cholesky

from jaxfdi import _linalg
from jaxfdi.filters._base import (
    Filter,
    FilterInfo,
    GaussianState,
    check_step_inputs,
    gaussian_init,
    mask_innovation_cov,
    observed_mask,
)
from jaxfdi.models.linear import LinearGaussianModel, validate_linear_model


class ConditionedGaussian(NamedTuple):
    """Result of one measurement update (shared by the KF and the EKF)."""

    mean: Array
    cov: Array
    innovation: Array
    innovation_cov: Array
    log_likelihood: Array
    nis: Array
    num_observed: Array
    healthy: Array


def joseph_update(mean: Array, cov: Array, y: Array, y_pred: Array, H: Array, R: Array) -> ConditionedGaussian:
    """Condition ``N(mean, cov)`` on ``y = H x + v``, ``v ~ N(0, R)``, predicted ``y_pred``.

    NaN components of ``y`` are missing: their rows of ``H`` are zeroed and their
    innovation set to 0, so they neither update the state nor enter the likelihood.
    """
    mask, y_obs, num_observed = observed_mask(y)
    H = jnp.where(mask[:, None], H, 0.0)
    innovation = jnp.where(mask, y_obs - y_pred, 0.0)
    R_masked = jnp.where(mask[:, None] & mask[None, :], R, 0.0)
    cross_cov = cov @ H.T
    S = mask_innovation_cov(_linalg.symmetrize(H @ cross_cov + R_masked), mask)
    chol_S = cholesky(S, lower=True)
    gain = _linalg.gain_from_cross_cov(cross_cov, chol_S)
    whitened = _linalg.whiten(chol_S, innovation)
    I_KH = jnp.eye(mean.shape[0], dtype=cov.dtype) - gain @ H
    new_cov = _linalg.symmetrize(I_KH @ cov @ I_KH.T + gain @ R_masked @ gain.T)
    new_mean = mean + gain @ innovation
    log_lik = _linalg.gaussian_log_likelihood(whitened, chol_S, num_observed)
    healthy = _linalg.cholesky_is_finite(chol_S) & jnp.all(jnp.isfinite(new_mean))
    return ConditionedGaussian(new_mean, new_cov, innovation, S, log_lik, jnp.sum(whitened**2), num_observed, healthy)


def finish_step(prior: GaussianState, post: ConditionedGaussian, next_mean: Array, next_cov: Array):
    """Assemble the next state and the step's ``FilterInfo``; checks ``P[k|k]`` is PD."""
    chol_P = cholesky(post.cov, lower=True)
    healthy = post.healthy & _linalg.cholesky_is_finite(chol_P) & jnp.all(jnp.isfinite(next_mean))
    info = FilterInfo(
        predicted_mean=prior.mean,
        predicted_cov=prior.cov,
        filtered_mean=post.mean,
        filtered_cov=post.cov,
        innovation=post.innovation,
        innovation_cov=post.innovation_cov,
        log_likelihood=post.log_likelihood,
        nis=post.nis,
        num_observed=post.num_observed,
        healthy=healthy,
    )
    return GaussianState(next_mean, next_cov), info


def kalman_filter(model: LinearGaussianModel) -> Filter:
    """Linear Kalman filter for a ``LinearGaussianModel``.

    Returns ``Filter(init, step)``; ``init(mean, cov)`` is the prior of ``x[0]``,
    ``step(state, y, u)`` updates with ``y[k]`` (m,) and predicts with ``u[k]`` (nu,).
    """
    n, nu, m = validate_linear_model(model)

    def step(state: GaussianState, y: Array, u: Array):
        check_step_inputs(y, u, m, nu)
        y_pred = model.C @ state.mean + model.D @ u
        post = joseph_update(state.mean, state.cov, y, y_pred, model.C, model.R)
        next_mean = model.Phi @ post.mean + model.Gamma @ u
        next_cov = _linalg.symmetrize(model.Phi @ post.cov @ model.Phi.T + model.Q)
        return finish_step(state, post, next_mean, next_cov)

    return Filter(gaussian_init(n), step)
