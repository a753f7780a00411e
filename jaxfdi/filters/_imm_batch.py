"""The IMM over linear Kalman modes, one step for a whole batch of runs, structure-of-arrays layout: what
``run_filter`` runs for ``interacting_multiple_model(kalman_filter, LinearGaussianModel modes, pi)``.

Same recursion and outputs as ``imm.py`` (Han et al. 2022, eqs. 6-12; Blom & Bar-Shalom 1988). Two differences, for
CPU speed (100 runs x 7 modes = 700 small covariance recursions a step):

- layout: matrix axes first, batch axes ``(M, N)`` (modes, runs) last (covariances ``(n, n, M, N)``), so each
  ``P[i, j]`` is a contiguous vector of ``M N`` values for ``_linalg.soa_*`` (``vmap``: 7-element strided rows);
- covariance update ``P+ = P - G G^T``, ``G = P C^T L^-T`` (``S = L L^T``), not Joseph (two batched ``n x n x n``
  products per mode): equal for the optimal gain (Bar-Shalom et al. 2001, eq. 5.2.3-15); the posterior is
  symmetrised and factorised, lost positive definiteness makes ``healthy`` false as on the vmapped path. Mean
  ``x + K r = x + G w``, ``w = L^-1 r``: the gain is never formed.

Above ``_linalg.UNROLL_MAX`` states (13-state bias design, up to ``KERNEL_MAX_STATES``) XLA:CPU fuses chains of
written-out products and solves into consumers and recomputes them per element (the kernel then loses to ``vmap``
on 13 states); ``_linalg.materialize`` stores the gain factor, mode posteriors, mixed covariances and ``Phi P`` once
each (the kernel then beats ``vmap``). Engine timings (7 modes, 100 runs x 1000 steps): ``benchmarks/bench_imm.py``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import BatchKernel, check_step_inputs, used_innovation
from jaxfdi.filters._mixture import IMMInfo, IMMState, bayes_mode_update, mixing
from jaxfdi.models import LinearGaussianModel

mm, mv, tr = _linalg.soa_matmul, _linalg.soa_matvec, _linalg.soa_transpose


def soa_modes(modes: LinearGaussianModel) -> LinearGaussianModel:
    """Mode models (M, rows, cols) -> (rows, cols, M, 1): mode axis behind the matrix axes, broadcast over runs."""
    return LinearGaussianModel(
        *(jnp.moveaxis(jnp.asarray(leaf), 0, -1)[..., None] for leaf in modes)
    )


def soa_symmetrize(a: Array) -> Array:
    return 0.5 * (a + tr(a))


def soa_moment_match(weights: Array, means: Array, covs: Array) -> tuple[Array, Array]:
    """``x_j = sum_i w_ij x_i``, ``P_j = sum_i w_ij [P_i + (x_i - x_j)(x_i - x_j)^T]``; weights ``(M, J, N)``, means
    ``(n, M, N)``, covariances ``(n, n, M, N)`` -> ``(n, J, N)``, ``(n, n, J, N)``."""
    M = weights.shape[0]
    mean = sum(weights[i] * means[:, i, None] for i in range(M))
    cov = 0.0
    for i in range(M):
        deviation = means[:, i, None] - mean
        cov = cov + weights[i] * (covs[:, :, i, None] + deviation[:, None] * deviation[None, :])
    return mean, soa_symmetrize(cov)


#: largest state size the kernel takes (outputs and inputs: up to ``_linalg.UNROLL_MAX``).
KERNEL_MAX_STATES = 16


def supports(modes: LinearGaussianModel) -> bool:
    """True when the kernel takes these stacked modes: every dimension >= 1, at most ``KERNEL_MAX_STATES`` states and
    ``_linalg.UNROLL_MAX`` outputs and inputs."""
    n, nu, m = modes.Phi.shape[-1], modes.Gamma.shape[-1], modes.C.shape[-2]
    return (
        1 <= n <= KERNEL_MAX_STATES
        and 1 <= nu <= _linalg.UNROLL_MAX
        and 1 <= m <= _linalg.UNROLL_MAX
    )


def kalman_imm_batch_kernel(modes: LinearGaussianModel, log_transition: Array) -> BatchKernel:
    """``BatchKernel`` of the IMM over ``kalman_filter`` modes (axis M) with ``log_transition = log pi`` (M, M)."""
    soa = soa_modes(modes)
    n, nu, m = soa.Phi.shape[0], soa.Gamma.shape[1], soa.C.shape[0]
    large = n > _linalg.UNROLL_MAX  # materialise the chains XLA would recompute (module doc)
    materialize = _linalg.materialize if large else jax.lax.optimization_barrier
    log_pi = log_transition[:, :, None]  # (M_i, M_j, 1)

    def pack(state: IMMState, num_runs: int) -> IMMState:
        M = state.log_mode_prob.shape[0]
        mean = jnp.broadcast_to(jnp.moveaxis(state.mode_mean, 0, -1)[..., None], (n, M, num_runs))
        cov = jnp.broadcast_to(jnp.moveaxis(state.mode_cov, 0, -1)[..., None], (n, n, M, num_runs))
        return IMMState(mean, cov, jnp.broadcast_to(state.log_mode_prob[:, None], (M, num_runs)))

    def step(state: IMMState, y: Array, u: Array) -> tuple[IMMState, IMMInfo]:
        """``y`` (m, N), ``u`` (nu, N) or (nu, 1)."""
        check_step_inputs(y[:, 0], u[:, 0], m, nu)
        x, P = state.mode_mean, state.mode_cov
        u = u[:, None]
        # 1. every mode's measurement update (standard form, see the module doc)
        innovation = used_innovation(y[:, None], mv(soa.C, x) + mv(soa.D, u))
        cross_cov = mm(P, tr(soa.C))  # P C^T      (n, m, M, N)
        chol_S = _linalg.soa_cholesky(soa_symmetrize(mm(soa.C, cross_cov) + soa.R))
        G_t = _linalg.soa_solve_lower(chol_S, tr(cross_cov))  # G^T = L^-1 C P  (m, n, M, N)
        whitened = _linalg.soa_solve_lower(chol_S, innovation)
        if large:
            G_t, whitened = _linalg.materialize((G_t, whitened))
        post_mean = x + mv(tr(G_t), whitened)
        post_cov = soa_symmetrize(P - mm(tr(G_t), G_t))
        # materialised, or XLA fuses the update into each reader and recomputes it there
        post_mean, post_cov = materialize((post_mean, post_cov))
        log_det = 2.0 * sum(jnp.log(chol_S[i, i]) for i in range(m))
        mode_log_lik = -0.5 * (jnp.sum(whitened**2, axis=0) + log_det + m * math.log(2.0 * math.pi))
        # 2. mode probabilities; 3. mixing; 4. every mode's time update
        log_mu, log_lik = bayes_mode_update(state.log_mode_prob, mode_log_lik, axis=0)
        log_cbar, weights = mixing(log_mu, log_pi.astype(log_mu.dtype))
        mixed_mean, mixed_cov = soa_moment_match(weights, post_mean, post_cov)
        if large:
            mixed_cov = _linalg.materialize(mixed_cov)
        next_mean = mv(soa.Phi, mixed_mean) + mv(soa.Gamma, u)
        Phi_mixed = mm(soa.Phi, mixed_cov)
        if large:
            Phi_mixed = _linalg.materialize(Phi_mixed)
        next_cov = soa_symmetrize(mm(Phi_mixed, tr(soa.Phi)) + soa.Q)
        mode_prob = jnp.exp(log_mu)
        mean, cov = soa_moment_match(mode_prob[:, None], post_mean, post_cov)
        healthy = (
            jnp.all(jnp.isfinite(chol_S), axis=(0, 1, 2))
            & jnp.all(jnp.isfinite(_linalg.soa_cholesky(post_cov)), axis=(0, 1, 2))
            & jnp.all(jnp.isfinite(post_mean), axis=(0, 1))
            & jnp.isfinite(log_lik)
            & ~jnp.any(jnp.isnan(log_cbar), axis=0)
            & jnp.all(jnp.isfinite(mean[:, 0]), axis=0)
            & jnp.all(jnp.isfinite(next_mean), axis=(0, 1))
        )
        info = IMMInfo(
            mode_prob,
            log_mu,
            mean[:, 0],
            cov[:, :, 0],
            post_mean,
            post_cov,
            mode_log_lik,
            log_lik,
            healthy,
            ~jnp.isfinite(y),
        )
        return IMMState(next_mean, next_cov, log_cbar.astype(log_mu.dtype)), info

    def unpack_state(state: IMMState) -> IMMState:
        return IMMState(
            jnp.transpose(state.mode_mean, (2, 1, 0)),
            jnp.transpose(state.mode_cov, (3, 2, 0, 1)),
            state.log_mode_prob.T,
        )

    def unpack_info(info: IMMInfo) -> IMMInfo:
        """(T, ..., N) -> (N, T, ...) with the per-run field shapes of ``IMMInfo``."""
        run_first = lambda a: jnp.moveaxis(a, -1, 0)
        return IMMInfo(
            mode_prob=run_first(info.mode_prob),
            log_mode_prob=run_first(info.log_mode_prob),
            mean=run_first(info.mean),
            cov=run_first(info.cov),
            mode_mean=jnp.transpose(info.mode_mean, (3, 0, 2, 1)),
            mode_cov=jnp.transpose(info.mode_cov, (4, 0, 3, 1, 2)),
            mode_log_likelihood=run_first(info.mode_log_likelihood),
            log_likelihood=run_first(info.log_likelihood),
            healthy=run_first(info.healthy),
            dead=run_first(info.dead),
        )

    return BatchKernel(pack, step, unpack_state, unpack_info)
