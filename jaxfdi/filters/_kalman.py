"""Linear Kalman filter (Kalman 1960) with the Joseph-form covariance update (Bucy & Joseph 1968).

Update: ``r = y - C m - D u``, ``S = C P C^T + R``, ``K = P C^T S^-1``, ``m+ = m + K r``,
``P+ = (I - K C) P (I - K C)^T + K R K^T`` (valid for any gain, keeps ``P`` SPD). Predict: ``m' = Phi m+ + Gamma u``,
``P' = Phi P+ Phi^T + Q``. With ``missing_measurements=True`` NaN components of ``y`` are skipped component-wise; a
dead (non-finite) component is reported, never used (``filters._base``).
"""

from __future__ import annotations

from functools import partial

import jax.numpy as jnp
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
    observed_mask,
    observed_rows,
    report_dead,
    used_innovation,
)
from jaxfdi.filters._kalman_batch import (
    check_per_run_model,
    kalman_batch_kernel,
    per_run_leaves,
    supports,
)
from jaxfdi.filters._parallel import parallel_scan
from jaxfdi.models import LinearGaussianModel, validate_linear_model


def joseph_update(
    mean: Array,
    cov: Array,
    y: Array,
    y_pred: Array,
    H: Array,
    R: Array,
    missing_measurements: bool = False,
    unroll: bool = True,
) -> FilterInfo:
    """Condition ``N(mean, cov)`` on ``y = H x + v``, ``v ~ N(0, R)``, predicted ``y_pred``.

    With ``missing_measurements`` (static) NaN components of ``y`` are missing: rows of ``H`` zeroed, innovation 0,
    so they neither update the state nor enter the likelihood. Without it the covariance recursion ignores the data,
    so under ``vmap`` over runs sharing the model and ``P0`` XLA carries one covariance, not one per run; a
    non-finite component then updates the mean with a zero innovation and is reported as a dead channel
    (``_base`` module doc).

    Returns:
      the step's ``FilterInfo``: predicted and filtered moments, innovation and its covariance,
      log-likelihood, NIS, observed count and health.
    """
    if missing_measurements:
        mask, y_obs, num_observed = observed_mask(y)
        H, R = observed_rows(mask, H, R)
        innovation = jnp.where(mask, y_obs - y_pred, 0.0)
    else:
        num_observed = jnp.sum(jnp.isfinite(y)).astype(jnp.int32)
        innovation = used_innovation(y, y_pred)
    mm = _linalg.matmul
    cross_cov = mm(cov, H.T)
    S = _linalg.symmetrize(mm(H, cross_cov) + R)
    if missing_measurements:
        S = mask_innovation_cov(S, mask)
    chol_S = _linalg.cholesky(S, unroll)
    gain = _linalg.gain_from_cross_cov(cross_cov, chol_S, unroll)
    whitened = _linalg.whiten(chol_S, innovation, unroll)
    new_cov = _linalg.joseph_cov(cov, gain, H, R)
    new_mean = mean + mm(gain, innovation)
    log_lik = _linalg.gaussian_log_likelihood(
        whitened, chol_S, num_observed if missing_measurements else y.shape[0]
    )
    healthy = _linalg.cholesky_is_finite(chol_S) & jnp.all(jnp.isfinite(new_mean))
    innovation, nis = report_dead(
        innovation, jnp.sum(whitened**2), dead_components(y, missing_measurements)
    )
    return FilterInfo(
        mean, cov, new_mean, new_cov, innovation, S, log_lik, nis, num_observed, healthy
    )


def kalman_filter(
    model: LinearGaussianModel,
    missing_measurements: bool = False,
    unroll_factorizations: bool = True,
) -> Filter:
    """Linear Kalman filter for a ``LinearGaussianModel``.

    Args:
      model: the ``LinearGaussianModel``; leaves with a leading run axis N (e.g. ``model._replace(Q=Qs)``, ``Qs``
        (N, n, n)) give one model per run: the filter then runs only over N runs at once (``run_filter`` with
        ``ys`` (N, T, m)) by the structure-of-arrays kernel (up to 16 states and 8 outputs), with the standard-form
        covariance update (equal to Joseph's for the optimal gain).
      missing_measurements: treat NaN components of ``y`` as not measured (static). Off by default: covariances then
        do not depend on the data, which makes vmapped Monte Carlo fast (``joseph_update``).
      unroll_factorizations: small Cholesky factorisations and triangular solves written out element by element
        (default; ``_linalg``), fast for *batches* of covariances (IMM modes, per-run covariances). With one
        covariance for the whole batch (a single sequence, or runs sharing the model) LAPACK (``False``) is faster,
        and its gradients much faster to run and to compile (the engine's log-likelihood gradient,
        ``benchmarks/bench_tuning.py``).

    ``run_filter`` over runs with their own prior or model runs ``kalman_batch.py``'s structure-of-arrays step; with
    ``missing_measurements=True`` also the associative scan ``run_filter(..., parallel=True)`` (Särkkä and
    García-Fernández 2021; ``parallel.py``).

    Returns:
      ``Filter(init, step)``; ``init(mean, cov)``: prior of ``x[0]``; ``step(state, y, u)`` updates with ``y[k]``
      (m,), predicts with ``u[k]`` (nu,), returns ``(GaussianState, FilterInfo)``; with ``update`` and ``predict``,
      and ``parallel`` (``missing_measurements=True``) or else ``batch`` where the kernel supports the model. Model
      per run: ``init`` and ``batch`` only (``step`` raises ``ValueError``; ``run_filter`` over (N, T, m) runs the
      kernel).
    """
    if isinstance(model, LinearGaussianModel) and any(per_run_leaves(model)):
        return _per_run_kalman_filter(model, missing_measurements)
    n, nu, m = validate_linear_model(model)

    def update(state: GaussianState, y: Array, u: Array) -> FilterInfo:
        check_step_inputs(y, u, m, nu)
        y_pred = _linalg.matmul(model.C, state.mean) + _linalg.matmul(model.D, u)
        return joseph_update(
            state.mean,
            state.cov,
            y,
            y_pred,
            model.C,
            model.R,
            missing_measurements,
            unroll_factorizations,
        )

    def predict(post: GaussianState, u: Array) -> GaussianState:
        mm = _linalg.matmul
        next_mean = mm(model.Phi, post.mean) + mm(model.Gamma, u)
        return GaussianState(
            next_mean, _linalg.symmetrize(mm(mm(model.Phi, post.cov), model.Phi.T) + model.Q)
        )

    filt = gaussian_filter(n, update, predict, unroll_factorizations)
    if missing_measurements:  # dead components left out exactly, as the associative scan does
        return filt._replace(parallel=partial(parallel_scan, model))
    if not supports(model):
        return filt
    return filt._replace(
        batch=kalman_batch_kernel(model)
    )  # run_filter over runs with their own prior


def _per_run_kalman_filter(model: LinearGaussianModel, missing_measurements: bool) -> Filter:
    """``kalman_filter`` of a model with a run axis on some leaves: ``init`` takes a shared or per-run prior,
    ``step`` refuses a single sequence, ``batch`` is the kernel."""
    if missing_measurements:
        raise ValueError(
            "missing_measurements: a model per run runs the batch kernel, which reports a non-finite "
            "component and keeps it out of the mean but not out of the covariance; use jax.vmap over "
            "kalman_filter(model_of_one_run, missing_measurements=True)"
        )
    model, per_run, num_runs = check_per_run_model(model)
    n = checks.shape_of(model.Phi)[-1]

    def init(mean: Array, cov: Array) -> GaussianState:
        for name, value, shapes in (
            ("mean", mean, ((n,), (num_runs, n))),
            ("cov", cov, ((n, n), (num_runs, n, n))),
        ):
            checks.check_real(name, value, "a real prior")
            checks.check_finite(name, value, "prior")
            if checks.shape_of(value) not in shapes:
                raise ValueError(
                    f"{name}: expected shape {shapes[0]} shared or {shapes[1]} per run, got "
                    f"{checks.shape_of(value)}"
                )
        dtype = jnp.result_type(model.Phi, mean, cov)
        return GaussianState(jnp.asarray(mean, dtype), jnp.asarray(cov, dtype))

    def step(state: GaussianState, y: Array, u: Array):
        raise ValueError(
            f"model: a model with a run axis ({num_runs} runs) runs over its runs at once: pass ys of "
            f"shape ({num_runs}, T, m) to run_filter"
        )

    return Filter(init, step, batch=kalman_batch_kernel(model, per_run))
