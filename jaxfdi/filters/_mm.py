"""Static multiple-model filter (Magill 1965; MMAE), with a probability floor.

Modes run on their own, never mixed; only ``mu_j(k) ∝ L_j(k) mu_j(k-1)`` (Han et al. 2022, eq. 6) is updated, in
log space. Without a floor an underflowed mode never comes back (a fault after a long fault-free stretch is never
recognised); ``floor`` keeps ``mu_j >= floor`` by mixing in the uniform, ``mu <- floor + (1 - M floor) mu`` (Maybeck
1999). ``floor = 0``: the textbook MM, equal to an IMM with ``pi = I``.
"""

from __future__ import annotations

from typing import Any, Callable

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.filters._base import Filter
from jaxfdi.filters._mixture import (
    IMMInfo,
    IMMState,
    bank_init,
    bank_predict,
    bank_update,
    bayes_mode_update,
    check_mode_filter,
    finish_mixture_step,
    num_modes,
)


def apply_floor(log_mode_prob: Array, floor: Array) -> Array:
    """``log(floor + (1 - M floor) mu)``: each ``>= floor``, sum 1, smooth, the identity for ``floor = 0``."""
    M = log_mode_prob.shape[-1]
    floor = floor.astype(log_mode_prob.dtype)
    log_floor = jnp.where(floor > 0, jnp.log(jnp.where(floor > 0, floor, 1.0)), -jnp.inf)
    return jnp.logaddexp(log_floor, jnp.log1p(-M * floor) + log_mode_prob)


def multiple_model(
    mode_filter: Callable[[Any], Filter], mode_params: Any, floor: float | Array = 0.0
) -> Filter:
    """Static MM filter over a bank of mode-matched Gaussian filters.

    Args:
      mode_filter: ``params -> Filter`` with ``update`` and ``predict`` (as for the IMM).
      mode_params: pytree whose leaves have a leading mode axis ``M``.
      floor: lower bound on every mode probability, in ``[0, 1/M)``.

    Returns:
      ``Filter``; ``init(mean, cov, mode_prob)`` as for the IMM;
      ``step(state, y, u) -> (IMMState, IMMInfo)`` with the floored probabilities.
    """
    M = num_modes(mode_params)
    check_mode_filter(mode_filter, mode_params)
    value = checks.concrete(floor)
    if value is not None and not (value.shape == () and 0.0 <= value < 1.0 / M):
        raise ValueError(
            f"floor: expected a scalar probability in [0, 1/M) = [0, {1.0 / M:.4g}), got {floor}"
        )
    floor = jnp.asarray(floor)

    def init(mean: Array, cov: Array, mode_prob: Array) -> IMMState:
        return bank_init(mode_filter, mode_params, M, mean, cov, mode_prob)

    def step(state: IMMState, y: Array, u: Array) -> tuple[IMMState, IMMInfo]:
        post = bank_update(mode_filter, mode_params, state, y, u)
        log_mu, log_lik = bayes_mode_update(state.log_mode_prob, post.log_likelihood)
        log_mu = apply_floor(log_mu, floor)
        prediction = bank_predict(
            mode_filter, mode_params, post.filtered_mean, post.filtered_cov, u
        )
        return finish_mixture_step(post, log_mu, log_lik, prediction, log_mu)

    return Filter(init, step)
