"""What every filter in jaxfdi has in common: its shape, its outputs and its driver.

A filter is a ``Filter(init, step)`` of pure functions (optax/blackjax style). The
state carried between steps is the *prior* of the current step, ``x[k|k-1]``: ``step``
conditions it on ``y[k]`` and then predicts ``x[k+1|k]`` with ``u[k]``. This matches
``x[k+1] = f(x[k], u[k])``, ``y[k] = h(x[k], u[k])`` with no off-by-one in the inputs.
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import _checks


class GaussianState(NamedTuple):
    """Gaussian belief carried by the scan: the prior ``N(mean, cov)`` of the next step."""

    mean: Array  # (n,)
    cov: Array   # (n, n)


class FilterInfo(NamedTuple):
    """Per-step outputs shared by all Gaussian filters (KF, EKF, UKF), so that detectors,
    metrics and the contract tests treat them alike."""

    predicted_mean: Array   # (n,)   x[k|k-1]
    predicted_cov: Array    # (n, n) P[k|k-1]
    filtered_mean: Array    # (n,)   x[k|k]
    filtered_cov: Array     # (n, n) P[k|k]
    innovation: Array       # (m,)   y[k] - y_hat[k|k-1]  (0 where y is missing)
    innovation_cov: Array   # (m, m) S[k]  (unit variance where y is missing)
    log_likelihood: Array   # ()     log N(innovation; 0, S) over the observed components
    nis: Array              # ()     normalised innovation squared r^T S^-1 r
    num_observed: Array     # ()     number of finite components of y[k]
    healthy: Array          # ()     bool: S and P[k|k] positive definite and all finite


class Filter(NamedTuple):
    """A filter as two pure functions.

    ``init(mean, cov) -> state`` builds the prior of the first step;
    ``step(state, y, u) -> (state, info)`` conditions on ``y[k]`` and predicts with ``u[k]``.
    """

    init: Callable[..., Any]
    step: Callable[[Any, Array, Array], tuple[Any, Any]]


def gaussian_init(n: int, name: str = "filter") -> Callable[[Array, Array], GaussianState]:
    """An ``init`` that validates ``(mean, cov)`` against the state size ``n``."""

    def init(mean: Array, cov: Array) -> GaussianState:
        _checks.check_shape("mean", mean, (n,), "initial state mean")
        _checks.check_covariance("cov", cov, n)
        mean = jnp.asarray(mean)
        return GaussianState(mean, jnp.asarray(cov, dtype=mean.dtype))

    return init


def check_step_inputs(y: Array, u: Array, m: int, nu: int | None) -> None:
    """Trace-time shape checks of one step's measurement and input."""
    _checks.check_shape("y", y, (m,), "one measurement; use NaN for a missing one")
    _checks.check_shape("u", u, (nu,), "one input")


def observed_mask(y: Array) -> tuple[Array, Array, Array]:
    """``(mask, y with zeros where missing, number observed)``: NaN means 'not measured'."""
    mask = jnp.isfinite(y)
    return mask, jnp.where(mask, y, 0.0), jnp.sum(mask)


def mask_innovation_cov(S: Array, mask: Array) -> Array:
    """Decouple missing components: their rows/columns become those of the identity."""
    both = mask[:, None] & mask[None, :]
    return jnp.where(both, S, jnp.eye(S.shape[0], dtype=S.dtype))


def run_filter(
    filt: Filter,
    init_state: Any,
    ys: Array,
    us: Array | None = None,
) -> tuple[Any, Any]:
    """Run a filter over a whole sequence with one ``lax.scan``.

    Args:
      filt: a ``Filter``.
      init_state: ``filt.init(mean, cov)``, the prior of the first step.
      ys: (T, m) measurements; NaN entries are treated as missing.
      us: (T, nu) inputs, or ``None`` for a model without inputs.

    Returns:
      ``(final_state, info)``: the prior for step T and the per-step outputs stacked
      along a leading time axis (e.g. ``info.filtered_mean`` is (T, n)).
    """
    ys = jnp.asarray(ys)
    if ys.ndim != 2:
        raise ValueError(f"ys: expected shape (T, m), got {tuple(ys.shape)}")
    if us is None:
        us = jnp.zeros((ys.shape[0], 0), ys.dtype)
    us = jnp.asarray(us)
    if us.ndim != 2:
        raise ValueError(f"us: expected shape (T, nu), got {tuple(us.shape)}")
    _checks.check_same_length(("ys", "us"), ys, us)

    def body(state, yu):
        return filt.step(state, *yu)

    return jax.lax.scan(body, init_state, (ys, us))
