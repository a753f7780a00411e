"""What the multiple-model filters (IMM, static MM) share: state, info, the vmapped mode bank, the Bayes update of
the mode probabilities in log space, moment matching.

A bank of M mode-matched filters is ONE Gaussian filter vmapped over a params pytree with a leading mode axis M
(STYLE.md rule 3), never a Python list. Mode probabilities are logs normalised by log-sum-exp: the wrong modes'
likelihoods ``L_j = N(r_j; 0, S_j)`` of a 5-output engine are routinely below 1e-300 (1e-38 in float32).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import Filter, FilterInfo, GaussianState


class IMMState(NamedTuple):
    """State carried between steps by the IMM and the static MM filter: per-mode priors of step k and log prior
    mode probabilities (IMM: predicted ``log cbar_j(k)``; MM: the posterior of step k-1).

    Attributes:
      mode_mean: (M, n) x_j[k|k-1]
      mode_cov: (M, n, n) P_j[k|k-1]
      log_mode_prob: (M,) log P(mode j at k | y[:k-1])
    """

    mode_mean: Array
    mode_cov: Array
    log_mode_prob: Array


class IMMInfo(NamedTuple):
    """Per-step outputs of the IMM and the static MM filter (posteriors at step k).

    Attributes:
      mode_prob: (M,) mu_j(k) = P(mode j | y[:k])
      log_mode_prob: (M,) log mu_j(k)
      mean: (n,) combined x[k|k] (moment matched)
      cov: (n, n) combined P[k|k]
      mode_mean: (M, n) mode-matched x_j[k|k]
      mode_cov: (M, n, n) mode-matched P_j[k|k]
      mode_log_likelihood: (M,) log L_j(k) = log N(r_j; 0, S_j)
      log_likelihood: () log sum_j prior_j L_j, the mixture likelihood
      healthy: () bool: every mode update sound, all finite
      dead: (m,) bool: components of y[k] that were not finite (dead channel: reported here, not used by the modes)
    """

    mode_prob: Array
    log_mode_prob: Array
    mean: Array
    cov: Array
    mode_mean: Array
    mode_cov: Array
    mode_log_likelihood: Array
    log_likelihood: Array
    healthy: Array
    dead: Array


def num_modes(mode_params: Any, expected: int | None = None) -> int:
    """The common leading (mode) axis of every leaf of ``mode_params``; trace-time checks."""
    leaves = jax.tree.leaves(mode_params)
    if not leaves:
        raise ValueError(
            "mode_params: expected a pytree of arrays with a leading mode axis M, got no arrays"
        )
    shapes = [checks.shape_of(leaf) for leaf in leaves]
    size = expected if expected is not None else (shapes[0][0] if shapes[0] else None)
    for shape in shapes:
        if not shape or shape[0] != size:
            where = f" (the size of transition, ({size}, {size}))" if expected is not None else ""
            raise ValueError(
                f"mode_params: expected every leaf to have a leading mode axis of size M = {size}{where}, "
                f"got a leaf of shape {shape}"
            )
    return size


def check_mode_filter(mode_filter: Callable[[Any], Filter], mode_params: Any) -> None:
    """``mode_filter`` must build a Gaussian filter (with ``update`` and ``predict``)."""
    checks.check_callable(
        "mode_filter", mode_filter, "a callable params -> Filter (e.g. kalman_filter)"
    )
    filt = mode_filter(first_mode(mode_params))
    if not isinstance(filt, Filter) or filt.update is None or filt.predict is None:
        raise ValueError(
            "mode_filter: expected it to return a Gaussian Filter with update and predict "
            "(kalman_filter, extended_kalman_filter, unscented_kalman_filter)"
        )


def first_mode(mode_params: Any) -> Any:
    return jax.tree.map(lambda leaf: leaf[0], mode_params)


def bank_init(
    mode_filter, mode_params, M: int, mean: Array, cov: Array, mode_prob: Array
) -> IMMState:
    """Per-mode priors from a shared ``(n,), (n, n)`` or per-mode ``(M, n), (M, n, n)`` initial Gaussian, validated
    by the mode filter's own ``init``; ``log mode_prob``."""
    ndim = len(checks.shape_of(mean))
    if ndim not in (1, 2) or (ndim == 2 and checks.shape_of(mean)[0] != M):
        raise ValueError(
            f"mean: expected shape (n,) shared by the modes or ({M}, n) per mode, got {checks.shape_of(mean)}"
        )
    if ndim == 2:
        checks.check_shape("cov", cov, (M, None, None), "one covariance per mode")
    axis = 0 if ndim == 2 else None
    prior = jax.vmap(lambda p, m, c: mode_filter(p).init(m, c), in_axes=(0, axis, axis))(
        mode_params, mean, cov
    )
    checks.check_shape("mode_prob", mode_prob, (M,), "one prior probability per mode")
    check_distribution("mode_prob", mode_prob)
    dtype = prior.mean.dtype
    return IMMState(prior.mean, prior.cov, safe_log(jnp.asarray(mode_prob, dtype)))


def check_distribution(name: str, prob: Any, axis: int = -1) -> None:
    """Real probabilities; when concrete: finite, non-negative, summing to 1 along ``axis`` (to ``sqrt(eps)``)."""
    checks.check_real(name, prob, "real probabilities")
    value = checks.concrete(prob)
    if value is None:
        return
    eps = np.finfo(value.dtype if value.dtype.kind == "f" else np.float64).eps
    if not np.all(np.isfinite(value)) or np.any(value < 0):
        raise ValueError(f"{name}: expected non-negative finite probabilities, got {value}")
    if np.max(np.abs(np.sum(value, axis=axis) - 1.0)) > np.sqrt(eps):
        what = (
            "every row to sum to 1 (row-stochastic)" if value.ndim == 2 else "entries summing to 1"
        )
        raise ValueError(f"{name}: expected {what}, got sums {np.sum(value, axis=axis)}")


def safe_log(prob: Array) -> Array:
    """``log p`` with ``log 0 = -inf`` and a finite (zero) gradient at ``p = 0``."""
    positive = prob > 0
    return jnp.where(positive, jnp.log(jnp.where(positive, prob, 1.0)), -jnp.inf)


def log_normalizer(logits: Array, axis: int = -1) -> Array:
    """``log sum exp(logits)`` along ``axis``: ``-inf`` (not NaN) when every term is ``-inf``, finite gradients."""
    top = jax.lax.stop_gradient(jnp.max(logits, axis=axis, keepdims=True))
    top = jnp.where(jnp.isfinite(top), top, 0.0)
    total = jnp.sum(jnp.exp(logits - top), axis=axis)
    positive = total > 0
    return jnp.where(
        positive, jnp.log(jnp.where(positive, total, 1.0)) + jnp.squeeze(top, axis), -jnp.inf
    )


def bayes_mode_update(
    log_prior: Array, log_likelihood: Array, axis: int = -1
) -> tuple[Array, Array]:
    """``log mu_j = log L_j + log prior_j - log sum_i L_i prior_i`` (modes along ``axis``) and the mixture
    log-likelihood ``log sum_i L_i prior_i`` (Bar-Shalom et al. 2001, eq. 11.6.6-19)."""
    joint = log_likelihood + log_prior
    log_mix = log_normalizer(joint, axis=axis)
    return joint - jnp.expand_dims(log_mix, axis), log_mix


def mixing(log_mode_prob: Array, log_transition: Array) -> tuple[Array, Array]:
    """``(log cbar (M,), mixing weights mu_{i|j} (M, M))`` in log space; weight columns ``j`` sum to 1 (a column of
    ``-inf`` logits gives zeros, not NaN). Trailing batch axes broadcast: ``(M, N)``, ``(M, M, 1)`` ->
    ``(M, N)``, ``(M, M, N)``."""
    joint = log_mode_prob[:, None] + log_transition  # log pi_ij mu_i
    log_cbar = log_normalizer(joint, axis=0)
    weights = jnp.exp(joint - jnp.where(jnp.isfinite(log_cbar), log_cbar, 0.0)[None, :])
    return log_cbar, jnp.where(jnp.isfinite(log_cbar)[None, :], weights, 0.0)


def moment_match(weights: Array, means: Array, covs: Array) -> tuple[Array, Array]:
    """Gaussian with the moments of ``sum_i w_i N(x_i, P_i)`` (weights sum to 1): ``x = sum_i w_i x_i``,
    ``P = sum_i w_i [P_i + (x_i - x)(x_i - x)^T]``."""
    mean = _linalg.matmul(weights, means)
    deviation = means - mean
    cov = _linalg.matmul((weights[:, None] * deviation).T, deviation)
    if _linalg.is_small(means):  # sum_i w_i P_i unrolled, for the reason _linalg.matmul is
        for i in range(covs.shape[0]):
            cov = cov + weights[i] * covs[i]
    else:
        cov = cov + jnp.einsum("i,ijk->jk", weights, covs)
    return mean, _linalg.symmetrize(cov)


def bank_update(mode_filter, mode_params, state: IMMState, y: Array, u: Array) -> FilterInfo:
    """Every mode's measurement update with ``y[k]``: one filter vmapped over the params."""
    prior = GaussianState(state.mode_mean, state.mode_cov)
    post = jax.vmap(lambda p, s: mode_filter(p).update(s, y, u))(mode_params, prior)
    # Materialise the posteriors, else XLA fuses each mode's update into the mixing that reads it M times and
    # recomputes it there (slower at 7 modes).
    mean, cov = jax.lax.optimization_barrier((post.filtered_mean, post.filtered_cov))
    return post._replace(filtered_mean=mean, filtered_cov=cov)


def bank_predict(mode_filter, mode_params, means: Array, covs: Array, u: Array) -> GaussianState:
    """Every mode's time update with ``u[k]`` from its own (mixed) posterior."""
    return jax.vmap(lambda p, s: mode_filter(p).predict(s, u))(
        mode_params, GaussianState(means, covs)
    )


def finish_mixture_step(
    post: FilterInfo,
    log_mode_prob: Array,
    log_likelihood: Array,
    prediction: GaussianState,
    log_next_prob: Array,
) -> tuple[IMMState, IMMInfo]:
    """Combine the mode posteriors by moment matching, check health, build state and info."""
    mode_prob = jnp.exp(log_mode_prob)
    mean, cov = moment_match(mode_prob, post.filtered_mean, post.filtered_cov)
    posterior_pd = jax.vmap(lambda c: _linalg.cholesky_is_finite(_linalg.cholesky(c)))(
        post.filtered_cov
    )
    healthy = (
        jnp.all(post.healthy)
        & jnp.all(posterior_pd)
        & jnp.isfinite(log_likelihood)
        & ~jnp.any(jnp.isnan(log_next_prob))
        & jnp.all(jnp.isfinite(mean))
        & jnp.all(jnp.isfinite(prediction.mean))
    )
    dead = jnp.isnan(
        post.innovation[0]
    )  # filters._base: a dead component's innovation is reported as NaN
    info = IMMInfo(
        mode_prob,
        log_mode_prob,
        mean,
        cov,
        post.filtered_mean,
        post.filtered_cov,
        post.log_likelihood,
        log_likelihood,
        healthy,
        dead,
    )
    next_state = IMMState(
        prediction.mean, prediction.cov, log_next_prob.astype(log_mode_prob.dtype)
    )
    return next_state, info
