"""The linear Kalman filter for a whole batch of runs in one step, structure-of-arrays layout: what ``run_filter``
runs for N runs of ``kalman_filter(model)`` with their own prior or model (leaves with a leading run axis).

Same recursion and outputs as ``kalman.py`` (Kalman 1960); two differences, as in ``imm_batch.py``, for CPU speed:

- layout: matrix axes first, run axis ``N`` last (covariances ``(n, n, N)``), so each ``P[i, j]`` is a contiguous
  vector of ``N`` values over which ``_linalg.soa_*`` vectorises (``vmap`` puts runs first: 7-element rows);
- covariance update ``P+ = P - G^T G``, ``G = L^-1 C P`` (``S = L L^T``), not Joseph: equal for the optimal gain
  (Bar-Shalom et al. 2001, eq. 5.2.3-15) and exactly symmetric. ``P+`` is still factorised for ``healthy``. Mean:
  ``x + K r = x + G^T w``, ``w = L^-1 r``.

Products with a shared matrix (``C``, ``Phi``) are matrix products of the whole stack (``_left_product``), computed
once (written-out chains would be fused into loops recomputing the inner product per element); ``G`` is stored once
(``_linalg.materialize``). Info goes run-first into (N, T, ...) buffers (``BatchKernel.info_runs_first``).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import (
    BatchKernel,
    FilterInfo,
    GaussianState,
    check_step_inputs,
    report_dead,
    used_innovation,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model

tr = _linalg.soa_transpose

#: largest state size the kernel takes (the INS has 15 states).
KERNEL_MAX_STATES = 16


def _left_product(a: Array, b: Array) -> Array:
    """``a @ b`` per run, ``a`` (p, k, 1 or N), ``b`` (k, q, N) -> (p, q, N). A shared ``a`` multiplies the whole
    stack as one GEMM ((p, k) by (k, q N)), which XLA:CPU never fuses into its consumer, so it is computed once;
    written out, ``Phi P Phi^T`` fuses into one loop recomputing the inner product per outer element (n^4 instead of
    2 n^3; ``optimization_barrier`` does not prevent it on CPU)."""
    if a.shape[-1] == 1:
        return jnp.tensordot(a[..., 0], b, axes=(1, 0))
    return _linalg.soa_matmul(a, b)


def _matvec(a: Array, x: Array) -> Array:
    return _linalg.soa_matvec(a, x)


def _congruence(a: Array, sym: Array) -> Array:
    """``a sym a^T`` per run for a symmetric ``sym`` (k, k, N): ``a (a sym)^T``."""
    return _left_product(a, tr(_left_product(a, sym)))


def soa_model(model: LinearGaussianModel, per_run: LinearGaussianModel) -> LinearGaussianModel:
    """Leaves ``(rows, cols)`` -> ``(rows, cols, 1)``; ``per_run`` leaves ``(N, rows, cols)`` -> ``(rows, cols, N)``."""
    return LinearGaussianModel(
        *(
            jnp.moveaxis(leaf, 0, -1) if batched else leaf[..., None]
            for leaf, batched in zip(model, per_run)
        )
    )


def kalman_step_soa(model: LinearGaussianModel, state: GaussianState, y: Array, u: Array):
    """One Kalman step (update with ``y[k]``, predict with ``u[k]``) for every run at once: ``model`` with
    ``soa_model`` leaves (rows, cols, N or 1), ``state`` mean (n, N), cov (n, n, N), ``y`` (m, N), ``u`` (nu, N or
    1). Returns ``(next_state, FilterInfo)``, run axis last on every field."""
    x, P = state
    m = model.C.shape[0]
    innovation = used_innovation(y, _matvec(model.C, x) + _matvec(model.D, u))
    CP = _left_product(model.C, P)  # C P = (P C^T)^T, (m, n, N)
    S = _linalg.soa_symmetrize(_left_product(model.C, tr(CP)) + model.R)
    chol_S = _linalg.soa_cholesky(S)
    G = _linalg.materialize(_linalg.soa_solve_lower(chol_S, CP))  # L^-1 C P, (m, n, N)
    whitened = _linalg.soa_solve_lower(chol_S, innovation)
    post_mean = x + _matvec(tr(G), whitened)
    post_cov = P - _linalg.soa_matmul(tr(G), G)  # exactly symmetric
    next_mean = _matvec(model.Phi, post_mean) + _matvec(model.Gamma, u)
    next_cov = _linalg.soa_symmetrize(_congruence(model.Phi, post_cov) + model.Q)
    nis = jnp.sum(whitened**2, axis=0)
    log_det = 2.0 * sum(jnp.log(chol_S[i, i]) for i in range(m))
    log_likelihood = -0.5 * (nis + log_det + m * math.log(2.0 * math.pi))
    healthy = (
        jnp.all(jnp.isfinite(chol_S), axis=(0, 1))
        & jnp.all(jnp.isfinite(post_mean), axis=0)
        & jnp.all(jnp.isfinite(_linalg.soa_cholesky(post_cov)), axis=(0, 1))
        & jnp.all(jnp.isfinite(next_mean), axis=0)
        & jnp.isfinite(nis)
        & jnp.isfinite(log_likelihood)
    )
    num_observed = jnp.sum(jnp.isfinite(y), axis=0).astype(jnp.int32)
    innovation, nis = report_dead(innovation, nis, ~jnp.isfinite(y))
    info = FilterInfo(
        x, P, post_mean, post_cov, innovation, S, log_likelihood, nis, num_observed, healthy
    )
    return GaussianState(next_mean, next_cov), info


def kalman_batch_kernel(
    model: LinearGaussianModel, per_run: LinearGaussianModel | None = None
) -> BatchKernel:
    """``BatchKernel`` of ``kalman_filter(model)`` for runs with their own prior (``pack`` takes a shared or per-run
    ``GaussianState``); ``per_run`` marks ``model``'s leaves with a leading run axis (default none). No array work
    at build time, so ``kalman_filter`` always attaches it."""
    per_run = per_run or LinearGaussianModel(*(False,) * 6)
    n, nu, m = model.Phi.shape[-1], model.Gamma.shape[-1], model.C.shape[-2]

    def pack(state: GaussianState, num_runs: int) -> GaussianState:
        for name, leaf, batched in zip(model._fields, model, per_run):
            if batched and leaf.shape[0] != num_runs:
                raise ValueError(
                    f"model.{name}: a per-run leaf needs a leading axis of {num_runs} runs (as ys), "
                    f"got shape {tuple(leaf.shape)}"
                )
        return pack_prior(state, n, num_runs)

    def step(state: GaussianState, y: Array, u: Array):
        """``y`` (m, N), ``u`` (nu, N or 1); the info comes out as (N, ...)."""
        check_step_inputs(y[:, 0], u[:, 0], m, nu)
        state, info = kalman_step_soa(soa_model(model, per_run), state, y, u)
        return state, FilterInfo(*(jnp.moveaxis(leaf, -1, 0) for leaf in info))

    def unpack_info(info: FilterInfo) -> FilterInfo:
        """(T, N, ...) -> (N, T, ...): not used by the driver (``info_runs_first``)."""
        return FilterInfo(*(jnp.swapaxes(leaf, 0, 1) for leaf in info))

    return BatchKernel(
        pack, step, unpack_state, unpack_info, per_run_only=not any(per_run), info_runs_first=True
    )


def pack_prior(state: GaussianState, n: int, num_runs: int) -> GaussianState:
    """A shared or per-run prior in the kernel's layout: mean (n, N), cov (n, n, N)."""
    mean, cov = jnp.asarray(state.mean), jnp.asarray(state.cov)
    mean = jnp.moveaxis(mean, 0, -1) if mean.ndim == 2 else mean[:, None]
    cov = jnp.moveaxis(cov, 0, -1) if cov.ndim == 3 else cov[..., None]
    dtype = jnp.result_type(mean, cov)
    return GaussianState(
        jnp.broadcast_to(mean, (n, num_runs)).astype(dtype),
        jnp.broadcast_to(cov, (n, n, num_runs)).astype(dtype),
    )


def unpack_state(state: GaussianState) -> GaussianState:
    return GaussianState(jnp.moveaxis(state.mean, -1, 0), jnp.moveaxis(state.cov, -1, 0))


def supports(model: LinearGaussianModel) -> bool:
    """True when the kernel takes ``model``: at most ``KERNEL_MAX_STATES`` states, ``UNROLL_MAX`` outputs (static)."""
    n, m = model.Phi.shape[-1], model.C.shape[-2]
    return n <= KERNEL_MAX_STATES and m <= _linalg.UNROLL_MAX


def per_run_leaves(model: LinearGaussianModel) -> LinearGaussianModel:
    """Which leaves of ``model`` carry a leading run axis (3-D instead of a matrix)."""
    return LinearGaussianModel(*(len(checks.shape_of(leaf)) == 3 for leaf in model))


def check_per_run_model(
    model: LinearGaussianModel,
) -> tuple[LinearGaussianModel, LinearGaussianModel, int]:
    """A model with a run axis on some leaves: ``(model in one float dtype, per_run, N)``; every leaf checked
    against the shared shapes and one ``N``."""
    per_run = per_run_leaves(model)
    sizes = {checks.shape_of(leaf)[0] for leaf, batched in zip(model, per_run) if batched}
    num_runs = max(sizes)
    for name, leaf in zip(model._fields, model):
        shape = checks.shape_of(leaf)
        if len(shape) not in (2, 3):
            raise ValueError(
                f"model.{name}: expected a matrix, or one per run with a leading axis of "
                f"{num_runs}, got shape {shape}"
            )
        if len(shape) == 3 and shape[0] != num_runs:
            raise ValueError(
                f"model.{name}: every per-run leaf needs the same leading axis of runs "
                f"({sorted(sizes)} given), got shape {shape}"
            )
    first = LinearGaussianModel(
        *(
            jnp.asarray(leaf)[0] if batched else jnp.asarray(leaf)
            for leaf, batched in zip(model, per_run)
        )
    )
    validate_linear_model(first)
    for name, leaf, batched, ref in zip(model._fields, model, per_run, first):
        if batched and checks.shape_of(leaf)[1:] != checks.shape_of(ref):
            raise ValueError(
                f"model.{name}: expected shape ({num_runs}, *{checks.shape_of(ref)}), got "
                f"{checks.shape_of(leaf)}"
            )
    if not supports(first):
        n, m = checks.shape_of(first.Phi)[-1], checks.shape_of(first.C)[0]
        raise ValueError(
            f"model: a model per run runs the batch kernel, which takes up to {KERNEL_MAX_STATES} "
            f"states and {_linalg.UNROLL_MAX} outputs, got {n} states and {m} outputs; use "
            "jax.vmap over kalman_filter of each run's model"
        )
    dtype = checks.float_dtype(*model)
    return LinearGaussianModel(*(jnp.asarray(leaf, dtype) for leaf in model)), per_run, num_runs
