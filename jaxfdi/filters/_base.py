"""What every filter has in common: ``Filter(init, step)``, its outputs and the checks of its inputs (its driver:
``_driver.run_filter``).

The carried state is the prior ``x[k|k-1]``: ``step`` conditions it on ``y[k]``, then predicts ``x[k+1|k]`` with
``u[k]`` (matching ``x[k+1] = f(x[k], u[k])``, ``y[k] = h(x[k], u[k])``).

A dead sensor is evidence, never poison: a non-finite component of ``y`` (with ``missing_measurements=True``, where
NaN means 'not measured': an infinite one) never reaches the state (zero innovation); the step reports a NaN
innovation for it and ``nis = +inf``, an alarm for every detector. Without ``missing_measurements`` the covariance
is updated as if it had been measured (data-independent covariances, one for all Monte Carlo runs, optimistic while
the channel is dead); ``missing_measurements=True`` excludes it exactly.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg


class GaussianState(NamedTuple):
    """Gaussian belief carried by the scan: the prior ``N(mean, cov)`` of the next step.

    Attributes:
      mean: (n,) the mean x[k|k-1]
      cov: (n, n) the covariance P[k|k-1]
    """

    mean: Array
    cov: Array


class FilterInfo(NamedTuple):
    """Per-step outputs of every Gaussian filter (KF, EKF, UKF); also a measurement update's result
    (``predicted_*``: its prior; ``healthy``: S positive definite, x[k|k] finite; the step adds P[k|k], prediction).

    Attributes:
      predicted_mean: (n,) x[k|k-1]
      predicted_cov: (n, n) P[k|k-1]
      filtered_mean: (n,) x[k|k]
      filtered_cov: (n, n) P[k|k]
      innovation: (m,) y[k] - y_hat[k|k-1] (0 where y is missing, NaN where it is dead)
      innovation_cov: (m, m) S[k] (unit variance where y is missing)
      log_likelihood: () log N(innovation; 0, S) over the components the update used
      nis: () normalised innovation squared r^T S^-1 r; +inf when a component is dead
      num_observed: () number of finite components of y[k]
      healthy: () bool: the filter's numerics: S and P[k|k] positive definite, state finite
    """

    predicted_mean: Array
    predicted_cov: Array
    filtered_mean: Array
    filtered_cov: Array
    innovation: Array
    innovation_cov: Array
    log_likelihood: Array
    nis: Array
    num_observed: Array
    healthy: Array

    @property
    def posterior(self) -> GaussianState:
        """``N(filtered_mean, filtered_cov)``, the belief about x[k] given y[0..k]: what ``Filter.predict`` takes."""
        return GaussianState(self.filtered_mean, self.filtered_cov)


class BatchKernel(NamedTuple):
    """A filter's step for N runs in a layout of its own (e.g. structure of arrays); ``run_filter`` uses it instead of
    ``vmap``.

    - ``pack(state, N)``: lays out the prior shared by the N runs; ``step(carry, y, u)``: ``y`` (m, N), ``u`` (nu, N) or
      (nu, 1); ``unpack_state(carry)``, ``unpack_info(info stacked over time)``: what ``vmap(run_filter)`` gives (a
      leading run axis on every field).
    - ``per_run_only``: only for runs with their own prior (``pack`` also takes a ``GaussianState`` with a run axis);
      shared-prior runs keep ``vmap`` (the linear KF's, whose covariances XLA computes once).
    - ``info_runs_first``: ``step`` returns info as (N, ...), written into (N, T, ...) buffers; ``unpack_info`` unused
      (transposing the stacked info's innermost axis costs a KF on 100 runs of 1000 steps).
    """

    pack: Callable[[Any, int], Any]
    step: Callable[[Any, Array, Array], tuple[Any, Any]]
    unpack_state: Callable[[Any], Any]
    unpack_info: Callable[[Any], Any]
    per_run_only: bool = False
    info_runs_first: bool = False


#: a nonlinear model, ``x[k+1] = f(x, u, params)`` or ``y = h(x, u, params)``: (n,), (nu,), pytree -> array
ModelFunction = Callable[[Array, Array, Any], Array]


class Filter(NamedTuple):
    """A filter as pure functions; Gaussian filters (KF, EKF, UKF) also expose ``step``'s halves, which multiple-model
    filters mix between: ``step`` is ``predict(update(...))`` plus the ``FilterInfo``.

    Attributes:
      init: ``init(mean, cov) -> state``, the prior of the first step (some filters take more arguments)
      step: ``step(state, y, u) -> (state, info)``: conditions on ``y[k]`` (m,), predicts with ``u[k]`` (nu,); the next
        prior and the step's outputs (``FilterInfo`` for the Gaussian filters)
      update: ``update(state, y, u) -> FilterInfo``, or ``None``
      predict: ``predict(posterior: GaussianState, u) -> GaussianState``, or ``None``
      batch: ``BatchKernel`` for N runs at once (what ``run_filter`` runs for a batch), or ``None``
      parallel: ``parallel(init_state, ys, us) -> (final, info)``, the associative scan over (T, m) measurements
        (``run_filter(..., parallel=True)``), or ``None``
    """

    init: Callable[..., Any]
    step: Callable[[Any, Array, Array], tuple[Any, Any]]
    update: Callable[[Any, Array, Array], FilterInfo] | None = None
    predict: Callable[[GaussianState, Array], GaussianState] | None = None
    batch: BatchKernel | None = None
    parallel: Callable[[Any, Array, Array | None], tuple[Any, Any]] | None = None


def gaussian_filter(
    n: int,
    update: Callable[[GaussianState, Array, Array], FilterInfo],
    predict: Callable[[GaussianState, Array], GaussianState],
    unroll_factorizations: bool = True,
) -> Filter:
    """A ``Filter`` from its measurement and time updates (state size ``n``); ``unroll_factorizations``: P[k|k]'s
    PD check."""

    def step(state: GaussianState, y: Array, u: Array):
        post = update(state, y, u)
        prediction = predict(post.posterior, u)
        # the step's health adds P[k|k] positive definite, a finite prediction and likelihood (an overflowing outlier)
        chol_P = _linalg.cholesky(post.filtered_cov, unroll_factorizations)
        healthy = (
            post.healthy
            & _linalg.cholesky_is_finite(chol_P)
            & jnp.all(jnp.isfinite(prediction.mean))
            & ~jnp.isnan(post.nis)
            & jnp.isfinite(post.log_likelihood)
        )
        return prediction, post._replace(healthy=healthy)

    return Filter(gaussian_init(n), step, update, predict)


def gaussian_init(n: int, name: str = "filter") -> Callable[[Array, Array], GaussianState]:
    """An ``init`` that validates ``(mean, cov)`` against the state size ``n``."""

    def init(mean: Array, cov: Array) -> GaussianState:
        return GaussianState(*check_gaussian(mean, cov, n))

    return init


def check_gaussian(
    mean: Array, cov: Array, n: int, names: tuple[str, str] = ("mean", "cov")
) -> tuple[Array, Array]:
    """A prior ``N(mean, cov)``: real finite ``mean`` (n,), covariance ``cov`` (n, n), returned in one float dtype (an
    integer mean must not make the covariance integer)."""
    checks.check_real(names[0], mean, "a real initial state mean")
    checks.check_shape(names[0], mean, (n,), "initial state mean")
    checks.check_finite(names[0], mean, "initial state mean")
    checks.check_covariance(names[1], cov, n)
    dtype = checks.float_dtype(mean, cov)
    return jnp.asarray(mean, dtype), jnp.asarray(cov, dtype)


def check_step_inputs(y: Array, u: Array, m: int, nu: int | None) -> None:
    """Trace-time checks of one step's measurement and input (real, of the right shape)."""
    checks.check_real("y", y, "a real measurement")
    checks.check_shape("y", y, (m,), "one measurement; use NaN for a missing one")
    checks.check_real("u", u, "a real input")
    checks.check_shape("u", u, (nu,), "one input")


def check_filter(filt: Any, name: str = "filt") -> None:
    """``filt`` is a ``Filter`` (what ``kalman_filter`` and friends return)."""
    if not isinstance(filt, Filter):
        raise TypeError(
            f"{name}: expected a Filter(init, step, ...) such as kalman_filter(model) returns, "
            f"got {checks.received(filt)}"
        )


def check_sequences(ys: Any, us: Any, ys_shape: str, us_shapes: str) -> None:
    """Trace-time checks of a driver's sequences: real (NaN in ``ys``: 'missing'; ``us`` finite when concrete)."""
    checks.check_real("ys", ys, f"real measurements of shape {ys_shape}")
    if us is not None:
        checks.check_real("us", us, f"real inputs of shape {us_shapes}")
        checks.check_finite("us", us, "inputs")


def observed_mask(y: Array) -> tuple[Array, Array, Array]:
    """``(mask, y with zeros where missing, number observed)``: NaN means 'not measured'."""
    mask = jnp.isfinite(y)
    return mask, jnp.where(mask, y, 0.0), jnp.sum(mask)


def dead_components(y: Array, missing_measurements: bool) -> Array:
    """Dead-sensor components of ``y``: non-finite ones, or with ``missing_measurements`` (NaN: 'not measured') the
    infinite ones."""
    return jnp.isinf(y) if missing_measurements else ~jnp.isfinite(y)


def used_innovation(y: Array, y_pred: Array) -> Array:
    """``y - y_pred`` where ``y`` is finite, else 0 (the prediction): a dead sensor never reaches the state."""
    finite = jnp.isfinite(y)
    return jnp.where(finite, y, 0.0) - jnp.where(finite, y_pred, 0.0)


def report_dead(innovation: Array, nis: Array, dead: Array, axis: int = 0) -> tuple[Array, Array]:
    """A step's report of dead components (``dead_components``, unused by the state): NaN innovation (names the channel)
    and ``nis = +inf`` (zero likelihood, above every threshold)."""
    return jnp.where(dead, jnp.nan, innovation), jnp.where(jnp.any(dead, axis=axis), jnp.inf, nis)


def observed_rows(mask: Array, C: Array, R: Array) -> tuple[Array, Array]:
    """``(C, R)`` with missing components' rows (and ``R``'s columns) zeroed: out of the state and ``S`` (then
    ``mask_innovation_cov``)."""
    return jnp.where(mask[:, None], C, 0.0), jnp.where(mask[:, None] & mask[None, :], R, 0.0)


def mask_innovation_cov(S: Array, mask: Array) -> Array:
    """Decouple missing components: their rows/columns become those of the identity."""
    both = mask[:, None] & mask[None, :]
    return jnp.where(both, S, jnp.eye(S.shape[0], dtype=S.dtype))
