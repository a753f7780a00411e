"""What every filter has in common: ``Filter(init, step)``, its outputs and its driver.

The carried state is the prior ``x[k|k-1]``: ``step`` conditions it on ``y[k]``, then predicts ``x[k+1|k]`` with
``u[k]`` (matching ``x[k+1] = f(x[k], u[k])``, ``y[k] = h(x[k], u[k])``).

A dead sensor is evidence, never poison: a non-finite component of ``y`` (with ``missing_measurements=True``, where
NaN means 'not measured': an infinite one) never reaches the state (zero innovation); the step reports a NaN
innovation for it and ``nis = +inf``, an alarm for every detector. Without ``missing_measurements`` the covariance
is updated as if it had been measured (data-independent covariances, one for all Monte Carlo runs, optimistic while
the channel is dead); ``missing_measurements=True`` excludes it exactly.
"""

from __future__ import annotations

import contextlib
from functools import partial
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array
from jax.custom_batching import custom_vmap
from jax.interpreters import partial_eval as pe
from jax.interpreters.partial_eval import DynamicJaxprTracer

from jaxfdi import _linalg, checks


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


def run_filter(
    filt: Filter,
    init_state: Any,
    ys: Array,
    us: Array | None = None,
    *,
    parallel: bool = False,
    shared_covariance: bool | str = "auto",
) -> tuple[Any, Any]:
    """Run a filter over one sequence, or over a batch of sequences (Monte Carlo runs).

    One sequence ``ys`` (T, m): a ``lax.scan`` of ``filt.step``, or with ``parallel=True`` the associative scan (O(log
    T) depth; linear KF with ``missing_measurements=True``; same outputs to round-off). A batch (N, T, m): the filter's
    structure-of-arrays kernel (IMM over ``kalman_filter`` modes; linear KF with per-run priors), else vmap; a linear KF
    whose runs share model and initial covariance computes covariances, gains and innovation covariances once, returned
    without the run axis. ``jax.vmap(run_filter)`` over runs reaches the same kernel; its derivative is the scan's.

    Args:
      filt: a ``Filter``.
      init_state: ``filt.init(mean, cov)``, the first prior; for a Gaussian batch also per run,
        ``GaussianState(mean (N, n), cov (N, n, n))`` (either may be shared).
      ys: (T, m) one run, or (N, T, m) N runs (NaN = not measured with ``missing_measurements=True``; any other
        non-finite value: a dead sensor, reported and kept out of the state).
      us: (T, nu) inputs (shared by a batch), (N, T, nu) per run, or ``None`` (no inputs).
      parallel: run the associative scan (``ValueError`` for a filter without one).
      shared_covariance: for a batch: ``True``: ``predicted_cov``, ``filtered_cov``, ``innovation_cov`` and the final
        covariance without the run axis (``ValueError`` if they depend on the run: nonlinear filter,
        ``missing_measurements=True``); ``False``: with it, always; ``"auto"``: shared when they are.

    Returns:
      ``(final_state, info)``: the prior for step T and per-step outputs stacked on a leading time axis
      (``info.filtered_mean`` (T, n)), after a leading run axis N for a batch.
    """
    check_filter(filt)
    check_sequences(ys, us, "(T, m) for one run or (N, T, m) for N runs", "(T, nu) or (N, T, nu)")
    ys = jnp.asarray(ys)
    if ys.ndim == 3:
        return _run_batch(filt, init_state, ys, us, parallel, shared_covariance)
    if ys.ndim != 2:
        raise ValueError(
            f"ys: expected shape (T, m) for one run or (N, T, m) for N runs, got {tuple(ys.shape)}"
        )
    if shared_covariance not in (True, False, "auto"):
        raise ValueError(
            f"shared_covariance: expected True, False or 'auto', got {shared_covariance!r}"
        )
    if parallel:
        return _check_parallel(filt)(init_state, ys, us)
    if us is None:
        us = jnp.zeros((ys.shape[0], 0), ys.dtype)
    us = jnp.asarray(us)
    if us.ndim != 2:
        raise ValueError(f"us: expected shape (T, nu), got {tuple(us.shape)}")
    checks.check_same_length(("ys", "us"), ys, us)
    if not any(
        isinstance(leaf, jax.core.Tracer)
        for leaf in jax.tree_util.tree_leaves((init_state, ys, us))
    ):
        with _one_covariance():
            return _scan_filter(filt, init_state, ys, us)
    closed_over = jax.make_jaxpr(filt.step)(init_state, ys[0], us[0]).consts
    if _only_staged(closed_over) and _only_staged(jax.tree_util.tree_leaves((init_state, ys, us))):
        with _one_covariance():  # under jit alone: still one sequence
            return _scan_filter.__wrapped__(filt, init_state, ys, us)
    if filt.batch is not None and _only_staged(
        closed_over
    ):  # a jax.vmap over runs reaches the kernel
        return _batchable_scan(filt)(init_state, ys, us)
    return _scan_filter.__wrapped__(filt, init_state, ys, us)  # inline, written out (_linalg)


def _one_covariance():
    """The context for tracing one covariance recursion (one sequence, or runs sharing it): on CPU ``dot`` and LAPACK
    (``_linalg.library_calls``); on a GPU the written-out algebra (a cuSOLVER call per 7x7 factorisation made the
    engine KF slower, ``benchmarks/gpu_vmap_filter.py``)."""
    return _linalg.library_calls() if jax.default_backend() == "cpu" else contextlib.nullcontext()


def _only_staged(values) -> bool:
    """Every tracer among ``values`` is ``jit``'s, none an outer ``vmap``'s or ``grad``'s (written-out algebra)."""
    return all(
        isinstance(v, DynamicJaxprTracer) or not isinstance(v, jax.core.Tracer) for v in values
    )


def _batchable_scan(filt: Filter) -> Callable[[Any, Array, Array], tuple[Any, Any]]:
    """One sequence's scan whose ``jax.vmap`` over runs is the batch kernel; its derivative is the plain scan's
    (``custom_vmap`` has no transpose rule, so ``custom_jvp`` keeps reverse mode on the scan)."""

    def scan(init_state, ys, us):
        return _scan_filter.__wrapped__(filt, init_state, ys, us)

    @custom_vmap
    def batchable(init_state, ys, us):
        return scan(init_state, ys, us)

    @batchable.def_vmap
    def _over_runs(axis_size, in_batched, init_state, ys, us):
        state_batched, ys_batched, us_batched = in_batched
        if not isinstance(init_state, GaussianState) and any(
            jax.tree_util.tree_leaves(state_batched)
        ):
            axes = jax.tree_util.tree_map(lambda batched: 0 if batched else None, state_batched)
            out = jax.vmap(
                scan, in_axes=(axes, 0 if ys_batched else None, 0 if us_batched else None)
            )(
                init_state, ys, us
            )  # a kernel takes one prior for all runs (or a Gaussian one per run)
        else:
            ys = ys if ys_batched else jnp.broadcast_to(ys, (axis_size,) + ys.shape)
            out = _run_batch(filt, init_state, ys, us, False, False)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    @jax.custom_jvp
    def differentiable(init_state, ys, us):
        return batchable(init_state, ys, us)

    differentiable.defjvp(lambda primals, tangents: jax.jvp(scan, primals, tangents))
    return differentiable


def _check_parallel(filt: Filter) -> Callable[[Any, Array, Array | None], tuple[Any, Any]]:
    if filt.parallel is None:
        raise ValueError(
            "parallel: this filter has no parallel-in-time form; the associative scan is the linear "
            "Kalman filter's, kalman_filter(model, missing_measurements=True)"
        )
    return filt.parallel


_COVARIANCE_FIELDS = ("predicted_cov", "filtered_cov", "innovation_cov")


def _run_batch(
    filt: Filter,
    init_state: Any,
    ys: Array,
    us: Array | None,
    parallel: bool,
    shared_covariance: bool | str,
) -> tuple[Any, Any]:
    """``run_filter`` over N runs, ``ys`` (N, T, m)."""
    if us is None:
        us = jnp.zeros(ys.shape[1:2] + (0,), ys.dtype)
    us = jnp.asarray(us)
    if us.ndim not in (2, 3):
        raise ValueError(
            f"us: expected shape (T, nu) shared or (N, T, nu) per run, got {tuple(us.shape)}"
        )
    if us.ndim == 3 and us.shape[0] != ys.shape[0]:
        raise ValueError(f"us: expected {ys.shape[0]} runs like ys, got shape {tuple(us.shape)}")
    if shared_covariance not in (True, False, "auto"):
        raise ValueError(
            f"shared_covariance: expected True, False or 'auto', got {shared_covariance!r}"
        )
    us_axis = 0 if us.ndim == 3 else None
    if parallel:
        return jax.vmap(_check_parallel(filt), in_axes=(None, 0, us_axis))(init_state, ys, us)
    gaussian = isinstance(init_state, GaussianState)
    if shared_covariance is True and not gaussian:
        raise ValueError(
            f"shared_covariance: only Gaussian filters (KF) can share covariances across runs, "
            f"got a {type(init_state).__name__}; use shared_covariance=False or 'auto'"
        )
    init_axes = _prior_axes(init_state, ys.shape[0]) if gaussian else None
    per_run_prior = init_axes is not None and init_axes != GaussianState(None, None)
    if per_run_prior and shared_covariance is True and init_axes.cov is not None:
        raise ValueError(
            "shared_covariance: the runs have their own initial covariance, so their covariances "
            "differ; use shared_covariance=False or 'auto'"
        )
    # no runs or no steps: vmap's path gives empty results (a batch kernel indexes its runs)
    empty = 0 in ys.shape[:2]
    if filt.batch is not None and not empty and (per_run_prior or not filt.batch.per_run_only):
        return _kernel_scan(filt.batch, init_state, ys, us)
    init_axes = init_axes if per_run_prior else None
    per_run_cov = per_run_prior and init_axes.cov is not None
    # one step's measurement and input, for tracing only (a batch may hold no runs or no steps)
    y = jnp.zeros(ys.shape[2:], ys.dtype)
    u = jnp.zeros(us.shape[-1:], us.dtype)
    shared = (
        shared_covariance is not False
        and gaussian
        and not per_run_cov
        and not _covariance_sees_data(filt, init_state, y, u, us_axis == 0)
    )
    if shared_covariance is True and not shared:
        raise ValueError(
            "shared_covariance: the covariances depend on the run (nonlinear filter, "
            "missing_measurements=True or per-run model); use shared_covariance=False"
        )
    return _batch_scan(filt, init_state, ys, us, us_axis, shared, init_axes)


def _covariance_sees_data(
    filt: Filter, prior: GaussianState, y: Array, u: Array, per_run_inputs: bool
) -> bool:
    """Whether a Gaussian filter's covariances depend on a run's data: ``dce_jaxpr`` of the step says which inputs the
    covariances need; none of mean, ``y``, per-run inputs: shared by all runs with one ``P0`` (linear KF)."""
    mean, cov = (jnp.asarray(leaf) for leaf in prior)
    step = lambda mean, cov, y, u: filt.step(GaussianState(mean, cov), y, u)
    one_mean = jnp.zeros(mean.shape[-1:], mean.dtype)  # one run's mean, for tracing only
    closed, out_shape = jax.make_jaxpr(step, return_shape=True)(one_mean, cov, y, u)
    structure = jax.tree.structure(out_shape)
    state, info = jax.tree.unflatten(structure, range(structure.num_leaves))
    covariances = {state.cov, *(getattr(info, name) for name in _COVARIANCE_FIELDS)}
    _, needed = pe.dce_jaxpr(closed.jaxpr, [i in covariances for i in range(structure.num_leaves)])
    return bool(needed[0] or needed[2] or (per_run_inputs and needed[3]))


def _prior_axes(init_state: GaussianState, num_runs: int) -> GaussianState:
    """Which of ``mean``/``cov`` carry a run axis (0) or are shared (None), checked against the run count."""
    mean_shape, cov_shape = checks.shape_of(init_state.mean), checks.shape_of(init_state.cov)
    if len(mean_shape) not in (1, 2) or len(cov_shape) not in (2, 3):
        raise ValueError(
            f"init_state: expected mean (n,) or (N, n) and cov (n, n) or (N, n, n), got shapes "
            f"{mean_shape} and {cov_shape}"
        )
    for name, shape, per_run_ndim in (("mean", mean_shape, 2), ("cov", cov_shape, 3)):
        if len(shape) == per_run_ndim and shape[0] != num_runs:
            raise ValueError(
                f"init_state.{name}: a per-run prior needs a leading axis of {num_runs} runs (as ys), "
                f"got shape {shape}"
            )
    return GaussianState(0 if len(mean_shape) == 2 else None, 0 if len(cov_shape) == 3 else None)


@partial(jax.jit, static_argnums=(0, 4, 5, 6))
def _batch_scan(
    filt: Filter, init_state: Any, ys: Array, us: Array, us_axis, shared: bool, init_axes=None
):
    """``vmap`` of the scan over runs; with ``shared`` covariances their recursion is one sequence's
    (``_one_covariance``: on CPU a smaller program, faster to compile and to run)."""
    if shared:
        final_axes = GaussianState(0, None)
        info_axes = FilterInfo(
            *(None if name in _COVARIANCE_FIELDS else 0 for name in FilterInfo._fields)
        )
    else:
        final_axes = info_axes = 0
    with _one_covariance() if shared else contextlib.nullcontext():
        if init_axes is None:
            run_one = partial(_scan_filter.__wrapped__, filt, init_state)
            return jax.vmap(run_one, in_axes=(0, us_axis), out_axes=(final_axes, info_axes))(ys, us)
        run_one = partial(_scan_filter.__wrapped__, filt)
        return jax.vmap(run_one, in_axes=(init_axes, 0, us_axis), out_axes=(final_axes, info_axes))(
            init_state, ys, us
        )


@partial(jax.jit, static_argnums=0)
def _kernel_scan(kernel: BatchKernel, init_state: Any, ys: Array, us: Array):
    return kernel_scan(kernel, init_state, ys, us)


def kernel_scan(kernel: BatchKernel, init_state: Any, ys: Array, us: Array):
    """A ``BatchKernel``'s scan over ``ys`` (N, T, m), ``us`` (T, nu) or (N, T, nu): what ``vmap(run_filter)`` returns
    (not jitted: callers jit)."""
    num_runs, num_steps = ys.shape[:2]
    ys = jnp.moveaxis(ys, 0, -1)  # (T, m, N)
    us = jnp.moveaxis(us, 0, -1) if us.ndim == 3 else us[..., None]  # (T, nu, N or 1)
    carry = kernel.pack(init_state, num_runs)
    if not kernel.info_runs_first:
        final, info = jax.lax.scan(lambda state, yu: kernel.step(state, *yu), carry, (ys, us))
        return kernel.unpack_state(final), kernel.unpack_info(info)
    info_shapes = jax.eval_shape(
        lambda state, y, u: kernel.step(state, y, u)[1], carry, ys[0], us[0]
    )
    buffers = jax.tree.map(
        lambda a: jnp.zeros((a.shape[0], num_steps) + a.shape[1:], a.dtype), info_shapes
    )

    def body(state_and_buffers, yuk):
        state, buffers = state_and_buffers
        y, u, k = yuk
        state, info = kernel.step(state, y, u)
        buffers = jax.tree.map(
            lambda b, v: jax.lax.dynamic_update_index_in_dim(b, v, k, 1), buffers, info
        )
        return (state, buffers), None

    (final, info), _ = jax.lax.scan(body, (carry, buffers), (ys, us, jnp.arange(num_steps)))
    return kernel.unpack_state(final), info


@partial(jax.jit, static_argnums=0)
def _scan_filter(filt: Filter, init_state: Any, ys: Array, us: Array) -> tuple[Any, Any]:
    """The scan, compiled once per ``Filter`` eagerly (else retraced every call); inlined under an outer transformation
    (a nested ``jit`` slowed vmapped runs)."""

    def body(state, yu):
        return filt.step(state, *yu)

    return jax.lax.scan(body, init_state, (ys, us))
