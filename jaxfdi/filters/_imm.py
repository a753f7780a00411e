"""Interacting multiple model filter (Blom & Bar-Shalom 1988), any Gaussian mode filter.

One cycle, ``pi[i, j] = P(mode j at k+1 | mode i at k)`` row-stochastic (Bar-Shalom, Li & Kirubarajan 2001,
sec. 11.6.6; Han et al. 2022, eqs. 6-12):

1. mode-matched update of every mode's prior with ``y[k]``: posteriors ``x_j, P_j``, likelihoods
   ``L_j = N(r_j; 0, S_j)``;
2. ``mu_j(k) ∝ L_j cbar_j(k)`` (log space, log-sum-exp);
3. mixing: ``cbar_j(k+1) = sum_i pi_ij mu_i``, ``mu_{i|j} = pi_ij mu_i / cbar_j``, ``x0_j = sum_i mu_{i|j} x_i``,
   ``P0_j = sum_i mu_{i|j} [P_i + (x_i - x0_j)(x_i - x0_j)^T]`` (Han et al.'s printed eq. 11 has the wrong terms);
4. every mode's time update from ``(x0_j, P0_j)`` with ``u[k]``.

The moment-matched ``x = sum_j mu_j x_j`` is an output, never fed back. The bank is one ``mode_filter`` vmapped
over ``mode_params`` (leading mode axis): ``kalman_filter`` over stacked ``LinearGaussianModel`` s or an EKF/UKF over
stacked params; modes share the state (so mixing is defined). Steps 1-4: filterpy's ``IMMEstimator.update, .predict``.
"""

from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.filters._base import Filter
from jaxfdi.filters._imm_batch import kalman_imm_batch_kernel, supports
from jaxfdi.filters._kalman import kalman_filter
from jaxfdi.filters._mixture import (
    IMMInfo,
    IMMState,
    bank_init,
    bank_predict,
    bank_update,
    bayes_mode_update,
    check_distribution,
    check_mode_filter,
    finish_mixture_step,
    mixing,
    moment_match,
    num_modes,
    safe_log,
)
from jaxfdi.filters._posterior import posterior_input
from jaxfdi.models import LinearGaussianModel


def interacting_multiple_model(
    mode_filter: Callable[[Any], Filter], mode_params: Any, transition: Array
) -> Filter:
    """IMM filter over a bank of mode-matched Gaussian filters.

    Args:
      mode_filter: ``params -> Filter`` with ``update`` and ``predict``, e.g. ``kalman_filter`` or
        ``lambda p: unscented_kalman_filter(f, h, p.Q, p.R, ...)``.
      mode_params: pytree with a leading mode axis ``M`` (e.g. ``noise_inflation_modes``); may be traced (tuning).
      transition: (M, M) row-stochastic ``pi[i, j] = P(j at k+1 | i at k)``; may be traced; zero entries stay
        exactly zero (finite gradients).

    Returns:
      ``Filter``; ``init(mean, cov, mode_prob)``: shared ``(n,), (n, n)`` or per-mode ``(M, n), (M, n, n)`` prior of
      ``x[0]``, ``mode_prob`` (M,) = ``P(mode at step 0)`` (filterpy's ``IMMEstimator(filters, mu, M)`` then
      ``update`` is ``init(x, P, mu @ M)``); ``init(mean, cov, mode_prob, posterior=True, u=u)`` starts from a
      posterior of step -1 (predict-first; ``mode_prob`` the posterior ``mu0``, ``u`` the input before ``y[0]``,
      ``None`` without inputs): mixing and prediction, as ``init_from_posterior(imm, mean, cov, u, mode_prob)``;
      ``step(state, y, u) -> (IMMState, IMMInfo)``. Over ``kalman_filter`` modes up to 16 states
      (``imm_batch.supports``) ``run_filter`` runs ``imm_batch.py``'s structure-of-arrays step (same results, faster
      than ``vmap`` on CPU).
    """
    checks.check_real("transition", transition, "a real row-stochastic matrix")
    transition = jnp.asarray(transition)
    M = transition.shape[0] if transition.ndim == 2 else None
    checks.check_shape(
        "transition", transition, (M, M), "row-stochastic mode transition matrix pi[i, j]"
    )
    num_modes(mode_params, expected=M)
    check_mode_filter(mode_filter, mode_params)
    check_distribution("transition", transition, axis=1)
    log_transition = safe_log(transition)
    batch = None
    if (
        mode_filter is kalman_filter
        and isinstance(mode_params, LinearGaussianModel)
        and supports(mode_params)
    ):
        batch = kalman_imm_batch_kernel(mode_params, log_transition)  # run_filter's path

    def init(
        mean: Array,
        cov: Array,
        mode_prob: Array,
        *,
        posterior: bool = False,
        u: Array | None = None,
    ) -> IMMState:
        state = bank_init(mode_filter, mode_params, M, mean, cov, mode_prob)
        if not posterior:
            if u is not None:
                raise ValueError(
                    "u: only used with posterior=True (the input of the first prediction)"
                )
            return state
        # steps 3-4 of the cycle from the posteriors (state holds them): mix, then predict
        dtype = state.mode_mean.dtype
        log_cbar, weights = mixing(state.log_mode_prob, log_transition.astype(dtype))
        mixed_mean, mixed_cov = jax.vmap(moment_match, in_axes=(1, None, None))(
            weights, state.mode_mean, state.mode_cov
        )
        prediction = bank_predict(
            mode_filter, mode_params, mixed_mean, mixed_cov, posterior_input(u, dtype)
        )
        return IMMState(prediction.mean, prediction.cov, log_cbar.astype(dtype))

    def step(state: IMMState, y: Array, u: Array) -> tuple[IMMState, IMMInfo]:
        post = bank_update(mode_filter, mode_params, state, y, u)
        log_mu, log_lik = bayes_mode_update(state.log_mode_prob, post.log_likelihood)
        log_cbar, weights = mixing(log_mu, log_transition.astype(log_mu.dtype))
        mixed_mean, mixed_cov = jax.vmap(moment_match, in_axes=(1, None, None))(
            weights, post.filtered_mean, post.filtered_cov
        )
        prediction = bank_predict(mode_filter, mode_params, mixed_mean, mixed_cov, u)
        return finish_mixture_step(post, log_mu, log_lik, prediction, log_cbar)

    return Filter(init, step, batch=batch)
