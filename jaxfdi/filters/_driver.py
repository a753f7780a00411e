"""``run_filter``: the one driver of every filter, and the reason for each of its paths.

A ``Filter`` is ``init`` and ``step``; ``run_filter`` scans ``step`` over ``ys`` (T, m) or (N, T, m). The
result is the same on every path (to round-off); the paths differ in what they compile:

- **one sequence, eager or under ``jit`` alone** (``_scan_filter``): a ``lax.scan`` compiled once per ``Filter``;
  on CPU its covariance algebra calls ``dot`` and LAPACK (``_one_covariance``), fewer and faster ops for one
  recursion than the written-out algebra a batch needs;
- **under ``vmap`` of a filter with a batch kernel** (``_batchable_scan``): ``custom_vmap`` sends the vmapped
  scan to the kernel, so ``jax.vmap(run_filter)`` is as fast as a batch; ``custom_jvp`` keeps the derivative the
  plain scan's (``custom_vmap`` has no transpose rule);
- **under any other transformation** (``grad``, ``vmap`` without a kernel): the scan inlined, written-out algebra
  (``jaxfdi._numerics.linalg``), which every transformation traces;
- **``parallel=True``**: the filter's associative scan (O(log T) depth), vmapped over a batch;
- **a batch (N, T, m)**: the filter's ``BatchKernel`` (structure of arrays, the run axis last) when it has one,
  else ``vmap`` of the scan (``_batch_scan``); a Gaussian filter whose covariances see no run's data (``dce`` of
  the step, ``_covariance_sees_data``) computes them once and returns them without the run axis.
"""

from __future__ import annotations

import contextlib
from functools import partial
from typing import Any, Callable

import jax
import jax.numpy as jnp
from jax import Array
from jax.custom_batching import custom_vmap
from jax.interpreters import partial_eval as pe
from jax.interpreters.partial_eval import DynamicJaxprTracer

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import (
    BatchKernel,
    Filter,
    FilterInfo,
    GaussianState,
    check_filter,
    check_sequences,
)


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
    (``_linalg.library_calls``); on a GPU the written-out algebra (a cuSOLVER call per small factorisation is slower
    than the few fused ops it replaces)."""
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
