"""Side-by-side speed of jaxfdi's KF and UKF against a plain lax.scan, filterpy and dynamax.

Workloads (float64, JAX x64):
  * KF  on the engine model (7 states, 5 outputs, 1 input), T = 1000 steps;
  * UKF on the rigid-body rates model (3 states, 3 torques in, 3 rates out), T = 600,
    scaled UT with alpha = 1e-3, beta = 2, kappa = 0;
each for 1 sequence and for N Monte Carlo sequences (jit(vmap) over sequences for the JAX
implementations, a Python loop for filterpy), plus a Monte Carlo with a different initial
covariance P0 per run and one with a different Q per run (a model per run).

Every JAX implementation returns the same things, (filtered means (T, n), filtered
covariances (T, n, n), total log-likelihood), so the timed work is equal; the script
checks that the results agree before it reports times. Compile time (trace + lower +
XLA compile, by ``jit(...).lower(...).compile()``) is reported apart from the
steady-state run time (median of repeats of the compiled function, blocked until ready).

Also times whole ``python -c`` processes that import the library and filter one engine
sequence end to end (jaxfdi vs filterpy), and jaxfdi with a persistent compilation cache.

Run:  python benchmarks/bench_filters.py            (full, several minutes on 2 cores)
      python benchmarks/bench_filters.py --quick    (smoke test, < 1 minute)
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import functools
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Any, Callable

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from dynamax.linear_gaussian_ssm import (
    ParamsLGSSM,
    ParamsLGSSMDynamics,
    ParamsLGSSMEmissions,
    ParamsLGSSMInitial,
    lgssm_filter,
)
from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, UKFHyperParams, unscented_kalman_filter
from filterpy.kalman import KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from jax.scipy.linalg import cho_solve, cholesky

import jaxfdi
from jaxfdi.models import engine_model
from jaxfdi.models._rigid_body import (
    rigid_body_observation,
    rigid_body_params,
    rigid_body_transition,
)

ALPHA, BETA, KAPPA = 1e-3, 2.0, 0.0
T_KF, T_UKF = 1000, 600
LOG_2PI = math.log(2.0 * math.pi)
# Agreement required between implementations (max |a - b| / max |b| over a field).
TOL_KF = 1e-6  # dynamax adds 1e-9 to the diagonal of S in psd_solve
TOL_UKF = 1e-6  # textbook UT sums with alpha = 1e-3 (weights ~ -1e6) lose ~1e-9 in float64
# dynamax's psd_solve adds 1e-9 to the diagonal of S before solving for the gain. With the
# rigid body's R = 1e-4 I that moves S by ~1e-5 relatively, so its timed UKF covariances
# differ from the others by ~2e-5. The untimed row "dynamax_no_boost" (boost set to 0)
# shows that this is the only difference: it agrees to the tight tolerance.
TOL_DYNAMAX = 1e-4
TARGETS = {  # speed-up of jaxfdi over the other implementation, 100 sequences
    ("kf", "filterpy"): 100.0,
    ("kf", "dynamax"): 1.0,
    ("ukf", "filterpy"): 400.0,
    ("ukf", "dynamax"): 1.2,
}


# ----------------------------------------------------------------------------- problems
def engine_problem(num_sequences: int, seed: int = 0) -> dict:
    model = engine_model()
    k = np.arange(T_KF)
    us = (0.01 + 0.002 * np.sin(2 * np.pi * k / 250.0)).reshape(T_KF, 1)
    sim = jaxfdi.linear_simulator(model)
    keys = jax.random.split(jax.random.key(seed), num_sequences)
    ys = jax.jit(
        jax.vmap(
            lambda key: jaxfdi.simulate(sim, jnp.zeros(7), jnp.asarray(us), key)[1].measurement
        )
    )(keys)
    return dict(model=model, m0=jnp.zeros(7), P0=10.0 * model.Q, ys=ys, us=jnp.asarray(us))


def rigid_body_problem(num_sequences: int, seed: int = 1) -> dict:
    params = rigid_body_params()
    k = np.arange(T_UKF)
    us = np.stack([2000 * np.sin(0.05 * k), 5000 * np.cos(0.03 * k), 3000 * np.ones(T_UKF)], 1)
    Q, R = 1e-6 * jnp.eye(3), 1e-4 * jnp.eye(3)
    sim = jaxfdi.simulator(rigid_body_transition, rigid_body_observation, Q, R, params)
    key_x0, key_noise = jax.random.split(jax.random.key(seed))
    x0s = jnp.array([0.5, -0.3, 0.4]) + 0.1 * jax.random.normal(key_x0, (num_sequences, 3))
    keys = jax.random.split(key_noise, num_sequences)
    ys = jax.jit(
        jax.vmap(lambda x0, key: jaxfdi.simulate(sim, x0, jnp.asarray(us), key)[1].measurement)
    )(x0s, keys)
    return dict(
        params=params, Q=Q, R=R, m0=jnp.zeros(3), P0=0.1 * jnp.eye(3), ys=ys, us=jnp.asarray(us)
    )


# --------------------------------------------------------------------- jaxfdi (library)
def jaxfdi_kf(model, m0, P0, ys, us):
    kf = jaxfdi.filters.kalman_filter(model)
    _, info = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys, us)
    return info.filtered_mean, info.filtered_cov, jnp.sum(info.log_likelihood)


def jaxfdi_kf_full_info(model, m0, P0, ys, us):
    kf = jaxfdi.filters.kalman_filter(model)
    return jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys, us)[1]


def jaxfdi_ukf(Q, R, params, m0, P0, ys, us):
    ukf = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params, ALPHA, BETA, KAPPA
    )
    _, info = jaxfdi.filters.run_filter(ukf, ukf.init(m0, P0), ys, us)
    return info.filtered_mean, info.filtered_cov, jnp.sum(info.log_likelihood)


def jaxfdi_ukf_full_info(Q, R, params, m0, P0, ys, us):
    ukf = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params, ALPHA, BETA, KAPPA
    )
    return jaxfdi.filters.run_filter(ukf, ukf.init(m0, P0), ys, us)[1]


def jaxfdi_kf_batch(model, m0, P0, ys, us):
    """``run_filter``: N sequences at once; the shared covariances come back once."""
    kf = jaxfdi.filters.kalman_filter(model)
    _, info = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys, us)
    return info.filtered_mean, info.filtered_cov, jnp.sum(info.log_likelihood, axis=-1)


def jaxfdi_kf_kernel(model, m0, P0, ys, us):
    """Runs with their own prior (P0 (N, n, n)) or model (Q (N, n, n)): the structure-of-
    arrays batch kernel (``run_filter`` with a per-run prior or a model per run
    with a per-run model)."""
    if P0.ndim == 3:
        kf = jaxfdi.filters.kalman_filter(model)
        _, info = jaxfdi.filters.run_filter(kf, jaxfdi.filters.GaussianState(m0, P0), ys, us)
    else:
        _, info = jaxfdi.filters.run_filter(
            jaxfdi.filters.kalman_filter(model), jaxfdi.filters.GaussianState(m0, P0), ys, us
        )
    return info.filtered_mean, info.filtered_cov, jnp.sum(info.log_likelihood, axis=-1)


def jaxfdi_ukf_batch(Q, R, params, m0, P0, ys, us):
    ukf = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params, ALPHA, BETA, KAPPA
    )
    _, info = jaxfdi.filters.run_filter(ukf, ukf.init(m0, P0), ys, us)
    return info.filtered_mean, info.filtered_cov, jnp.sum(info.log_likelihood, axis=-1)


# ------------------------------------------------------- plain lax.scan (the baseline)
def _gaussian_loglik(chol_S, innovation):
    whitened = jax.scipy.linalg.solve_triangular(chol_S, innovation, lower=True)
    return -0.5 * (
        whitened @ whitened
        + 2.0 * jnp.sum(jnp.log(jnp.diag(chol_S)))
        + innovation.shape[0] * LOG_2PI
    )


def plain_kf(model, m0, P0, ys, us):
    """Textbook KF: update with y[k], predict with u[k]; Cholesky solve for the gain."""
    Phi, Gamma, C, D, Q, R = model

    def step(carry, yu):
        m, P, ll = carry
        y, u = yu
        PCt = P @ C.T
        S = C @ PCt + R
        L = cholesky(S, lower=True)
        K = cho_solve((L, True), PCt.T).T
        r = y - C @ m - D @ u
        m_f = m + K @ r
        P_f = P - K @ S @ K.T
        m_next = Phi @ m_f + Gamma @ u
        P_next = Phi @ P_f @ Phi.T + Q
        return (m_next, P_next, ll + _gaussian_loglik(L, r)), (m_f, P_f)

    (_, _, ll), (means, covs) = jax.lax.scan(step, (m0, P0, jnp.zeros((), m0.dtype)), (ys, us))
    return means, covs, ll


def _ut_weights(n):
    lam = ALPHA**2 * (n + KAPPA) - n
    wm = jnp.full(2 * n + 1, 1.0 / (2 * (n + lam))).at[0].set(lam / (n + lam))
    wc = wm.at[0].add(1.0 - ALPHA**2 + BETA)
    return lam, wm, wc


def plain_ukf(Q, R, params, m0, P0, ys, us):
    """Textbook additive-noise UKF (Wan & van der Merwe 2000), sigma points redrawn before
    the update, as filterpy and jaxfdi do."""
    n = m0.shape[0]
    lam, wm, wc = _ut_weights(n)

    def sigmas(m, P):
        A = jnp.sqrt(n + lam) * cholesky(P, lower=True).T
        return jnp.concatenate([m[None], m + A, m - A])

    def step(carry, yu):
        m, P, ll = carry
        y, u = yu
        X = sigmas(m, P)
        Y = jax.vmap(lambda x: rigid_body_observation(x, u, params))(X)
        y_hat = wm @ Y
        dY, dX = Y - y_hat, X - m
        S = (wc[:, None] * dY).T @ dY + R
        Pxy = (wc[:, None] * dX).T @ dY
        L = cholesky(S, lower=True)
        K = cho_solve((L, True), Pxy.T).T
        r = y - y_hat
        m_f = m + K @ r
        P_f = P - K @ S @ K.T
        X = sigmas(m_f, P_f)
        Xf = jax.vmap(lambda x: rigid_body_transition(x, u, params))(X)
        m_next = wm @ Xf
        dXf = Xf - m_next
        P_next = (wc[:, None] * dXf).T @ dXf + Q
        return (m_next, P_next, ll + _gaussian_loglik(L, r)), (m_f, P_f)

    (_, _, ll), (means, covs) = jax.lax.scan(step, (m0, P0, jnp.zeros((), m0.dtype)), (ys, us))
    return means, covs, ll


# ------------------------------------------------------------------------------ dynamax
def _dynamax_inputs(us):
    """dynamax moves z[t] -> z[t+1] with input t+1 and emits y[t] with input t; jaxfdi
    moves x[k] -> x[k+1] with u[k]. Inputs ``[u[t-1], u[t]]`` give both conventions the
    same model: the dynamics read the first half, the emission the second."""
    previous = jnp.concatenate([us[:1], us[:-1]], axis=0)
    return jnp.concatenate([previous, us], axis=1)


def dynamax_kf(model, m0, P0, ys, us):
    Phi, Gamma, C, D, Q, R = model
    n, nu, m = Phi.shape[0], Gamma.shape[1], C.shape[0]
    params = ParamsLGSSM(
        initial=ParamsLGSSMInitial(mean=m0, cov=P0),
        dynamics=ParamsLGSSMDynamics(
            weights=Phi,
            bias=jnp.zeros(n),
            input_weights=jnp.concatenate([Gamma, jnp.zeros((n, nu))], 1),
            cov=Q,
        ),
        emissions=ParamsLGSSMEmissions(
            weights=C,
            bias=jnp.zeros(m),
            input_weights=jnp.concatenate([jnp.zeros((m, nu)), D], 1),
            cov=R,
        ),
    )
    post = lgssm_filter(params, ys, inputs=_dynamax_inputs(us))
    return post.filtered_means, post.filtered_covariances, post.marginal_loglik


def dynamax_ukf(Q, R, params, m0, P0, ys, us):
    nu = us.shape[1]
    nl_params = ParamsNLGSSM(
        initial_mean=m0,
        initial_covariance=P0,
        dynamics_function=lambda x, u: rigid_body_transition(x, u[:nu], params),
        dynamics_covariance=Q,
        emission_function=lambda x, u: rigid_body_observation(x, u[nu:], params),
        emission_covariance=R,
    )
    post = unscented_kalman_filter(
        nl_params,
        ys,
        UKFHyperParams(alpha=ALPHA, beta=BETA, kappa=KAPPA),
        inputs=_dynamax_inputs(us),
        output_fields=["filtered_means", "filtered_covariances"],
    )
    return post.filtered_means, post.filtered_covariances, post.marginal_loglik


@contextlib.contextmanager
def dynamax_without_diagonal_boost():
    """Temporarily make dynamax's psd_solve solve S exactly (diagonal_boost = 0)."""
    import dynamax.linear_gaussian_ssm.inference as lg
    import dynamax.nonlinear_gaussian_ssm.inference_ukf as ukf
    from dynamax.utils.utils import psd_solve

    saved = lg.psd_solve, ukf.psd_solve
    lg.psd_solve = ukf.psd_solve = functools.partial(psd_solve, diagonal_boost=0.0)
    try:
        yield
    finally:
        lg.psd_solve, ukf.psd_solve = saved


# ----------------------------------------------------------------------------- filterpy
def filterpy_kf_sequences(model, m0, P0, ys, us):
    """filterpy KalmanFilter (Joseph update) in jaxfdi's order: update y[k], predict u[k].
    filterpy has no feed-through, so D u[k] is subtracted from y[k]."""
    Phi, Gamma, C, D, Q, R = (np.asarray(a) for a in model)
    n, nu, m = Phi.shape[0], Gamma.shape[1], C.shape[0]
    us = np.asarray(us)
    z_all = np.asarray(ys) - (us @ D.T)[None]
    means, covs = [], []
    for z_seq in z_all:
        kf = KalmanFilter(dim_x=n, dim_z=m, dim_u=nu)
        kf.F, kf.B, kf.H, kf.Q, kf.R = Phi, Gamma, C, Q, R
        kf.x, kf.P = np.asarray(m0).reshape(n, 1).copy(), np.asarray(P0).copy()
        seq_means, seq_covs = np.empty((len(z_seq), n)), np.empty((len(z_seq), n, n))
        for k in range(len(z_seq)):
            kf.update(z_seq[k].reshape(m, 1))
            seq_means[k] = kf.x[:, 0]
            seq_covs[k] = kf.P
            kf.predict(u=us[k].reshape(nu, 1))
        means.append(seq_means)
        covs.append(seq_covs)
    return np.array(means), np.array(covs)


def _rigid_body_transition_numpy(inertia, dt):
    """The rigid-body RK4 step in NumPy, as a filterpy user would write ``fx``."""
    Ix, Iy, Iz = inertia

    def deriv(w, tau):
        p, q, r = w
        # (tau - w x (I w)) / I
        return np.array(
            [
                (tau[0] - (q * Iz * r - r * Iy * q)) / Ix,
                (tau[1] - (r * Ix * p - p * Iz * r)) / Iy,
                (tau[2] - (p * Iy * q - q * Ix * p)) / Iz,
            ]
        )

    def fx(w, _dt, u):
        k1 = deriv(w, u)
        k2 = deriv(w + 0.5 * dt * k1, u)
        k3 = deriv(w + 0.5 * dt * k2, u)
        k4 = deriv(w + dt * k3, u)
        return w + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    return fx


def filterpy_ukf_sequences(Q, R, params, m0, P0, ys, us):
    n = np.asarray(m0).shape[0]
    dt = float(params.dt)
    fx = _rigid_body_transition_numpy(np.asarray(params.inertia), dt)
    us = np.asarray(us)
    means, covs = [], []
    for y_seq in np.asarray(ys):
        points = MerweScaledSigmaPoints(n, ALPHA, BETA, KAPPA)
        ukf = UnscentedKalmanFilter(n, y_seq.shape[1], dt, hx=lambda x: x, fx=fx, points=points)
        ukf.x, ukf.P, ukf.Q, ukf.R = (
            np.asarray(m0).copy(),
            np.asarray(P0).copy(),
            np.asarray(Q),
            np.asarray(R),
        )
        ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)  # first update starts from N(m0, P0)
        seq_means, seq_covs = np.empty((len(y_seq), n)), np.empty((len(y_seq), n, n))
        for k in range(len(y_seq)):
            ukf.update(y_seq[k])
            seq_means[k] = ukf.x
            seq_covs[k] = ukf.P
            ukf.predict(u=us[k])
        means.append(seq_means)
        covs.append(seq_covs)
    return np.array(means), np.array(covs)


# ------------------------------------------------------------------------------ timing
def block(tree):
    return jax.tree_util.tree_map(
        lambda x: x.block_until_ready() if hasattr(x, "block_until_ready") else x, tree
    )


def compiled_timing(
    fn: Callable[..., Any], args: tuple, repeats: int, budget_s: float = 60.0
) -> tuple[dict, Any]:
    """Compile ``jit(fn)`` for ``args`` (timed apart), run it once for its output, then time
    it (``repeat_timing``); adds XLA's temporary and output buffer sizes in bytes."""
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    out = block(compiled(*args))
    timing = repeat_timing(lambda: block(compiled(*args)), repeats, budget_s)
    memory = compiled.memory_analysis()
    timing.update(
        compile_s=compile_s,
        temp_bytes=int(getattr(memory, "temp_size_in_bytes", -1)),
        output_bytes=int(getattr(memory, "output_size_in_bytes", -1)),
    )
    return timing, out


def repeat_timing(fn: Callable[[], Any], repeats: int, budget_s: float) -> dict:
    """Median and min wall time of ``fn()`` over ``repeats`` calls (fewer, but at least 3,
    once ``budget_s`` is spent)."""
    times = []
    while len(times) < repeats:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if len(times) >= 3 and sum(times) > budget_s:
            break
    return {"run_s": statistics.median(times), "run_min_s": min(times), "repeats": len(times)}


def time_jax(fn: Callable, args: tuple, in_axes, repeats: int, budget_s: float) -> tuple[dict, Any]:
    """AOT-compile ``jit(fn)`` or ``jit(vmap(fn, in_axes))``, then time the executable."""
    f = jax.jit(fn if in_axes is None else jax.vmap(fn, in_axes=in_axes))
    t0 = time.perf_counter()
    lowered = f.lower(*args)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    out = block(compiled(*args))  # warm-up (first call of the executable)
    t3 = time.perf_counter()
    timing = repeat_timing(lambda: block(compiled(*args)), repeats, budget_s)
    timing.update(
        trace_lower_s=t1 - t0, xla_compile_s=t2 - t1, compile_s=t2 - t0, first_run_s=t3 - t2
    )
    return timing, out


def _means_and_loglik(fn):
    def selected(*args):
        out = fn(*args)
        return out[0], out[2]

    return selected


def rel_diff(actual, expected) -> float:
    """max |a - b| / max |b| per sequence, the worst over sequences."""
    a, b = np.asarray(actual, np.float64), np.asarray(expected, np.float64)
    if a.ndim == 0 or b.ndim == 0 or a.shape != b.shape:
        a, b = a.reshape(1, -1), b.reshape(1, -1)
    a, b = a.reshape(a.shape[0], -1), b.reshape(b.shape[0], -1)
    return float(np.max(np.max(np.abs(a - b), axis=1) / np.max(np.abs(b), axis=1)))


def agreement(reference_name, ref, others: dict, tol: float) -> list[dict]:
    """Compare means, covariances (and log-likelihoods when both have them) to ``ref``."""
    rows = []
    for name, out in others.items():
        row_tol = TOL_DYNAMAX if name == "dynamax" else tol
        fields = {"filtered_mean": rel_diff(out[0], ref[0])}
        if out[1] is not None and ref[1] is not None:
            fields["filtered_cov"] = rel_diff(out[1], ref[1])
        if len(out) > 2 and len(ref) > 2:
            fields["log_likelihood"] = rel_diff(out[2], ref[2])
        worst = max(fields.values())
        rows.append(
            {
                "impl": name,
                "reference": reference_name,
                **fields,
                "max_rel_diff": worst,
                "tol": row_tol,
                "ok": bool(worst < row_tol),
            }
        )
    return rows


# --------------------------------------------------------------------------- scenarios
def bench_filter(kind: str, prob: dict, args, log) -> dict:
    """KF or UKF: N = 1 and N sequences for jaxfdi, plain scan, dynamax, filterpy; then
    per-run P0 and per-run Q Monte Carlo for jaxfdi and plain scan."""
    N = prob["ys"].shape[0]
    reps, budget = args.repeats, args.budget
    if kind == "kf":
        lib, lib_full, plain, dmx, fpy = (
            jaxfdi_kf,
            jaxfdi_kf_full_info,
            plain_kf,
            dynamax_kf,
            filterpy_kf_sequences,
        )
        lib_batch = jaxfdi_kf_batch
        head = (prob["model"],)
        n_head = 1
        tol = TOL_KF
    else:
        lib, lib_full, plain, dmx, fpy = (
            jaxfdi_ukf,
            jaxfdi_ukf_full_info,
            plain_ukf,
            dynamax_ukf,
            filterpy_ukf_sequences,
        )
        lib_batch = jaxfdi_ukf_batch
        head = (prob["Q"], prob["R"], prob["params"])
        n_head = 3
        tol = TOL_UKF
    m0, P0, ys, us = prob["m0"], prob["P0"], prob["ys"], prob["us"]
    shared = (None,) * n_head + (None, None, 0, None)  # vmap over sequences only
    impls = {"jaxfdi": lib, "plain_scan": plain, "dynamax": dmx}
    if not args.quick:
        impls["jaxfdi_full_info"] = lib_full
    result = {"T": int(ys.shape[1]), "N": N, "rows": [], "agreement": []}

    for label, batch, in_axes in (("1 sequence", False, None), (f"{N} sequences", True, shared)):
        outs = {}
        for name, fn in impls.items():
            call_args = head + (m0, P0, ys if batch else ys[0], us)
            timing, out = time_jax(fn, call_args, in_axes, reps, budget)
            outs[name] = out
            result["rows"].append(
                {"case": label, "impl": name, "sequences_timed": N if batch else 1, **timing}
            )
            log(
                f"  {kind} {label:>13} {name:<17} compile {timing['compile_s']:7.3f} s   run "
                f"{timing['run_s'] * 1e3:10.3f} ms"
            )
        if batch:  # the library's batch driver: takes (N, T, m), returns shared covariances once
            timing, out = time_jax(lib_batch, head + (m0, P0, ys, us), None, reps, budget)
            mean, cov, loglik = out
            outs["jaxfdi_batch"] = (
                mean,
                jnp.broadcast_to(cov, mean.shape[:1] + cov.shape[-3:]),
                loglik,
            )
            result["rows"].append(
                {
                    "case": label,
                    "impl": "jaxfdi_batch",
                    "sequences_timed": N,
                    **timing,
                    "note": "run_filter; shared covariances returned once"
                    if cov.ndim == 3
                    else "run_filter; covariances per run (they depend on the data)",
                }
            )
            log(
                f"  {kind} {label:>13} {'jaxfdi_batch':<17} compile {timing['compile_s']:7.3f} s  "
                f" run {timing['run_s'] * 1e3:10.3f} ms"
            )
        # filterpy: a Python loop, on fewer sequences for the batch (scaled linearly)
        n_fp = min(args.filterpy_sequences, N) if batch else 1
        fp_ys = ys[:n_fp] if batch else ys[:1]
        fp_holder = {}
        timing = repeat_timing(
            lambda: fp_holder.update(out=fpy(*head, m0, P0, fp_ys, us)),
            args.filterpy_repeats,
            budget,
        )
        scale = (N / n_fp) if batch else 1.0
        timing_scaled = {
            "run_s": timing["run_s"] * scale,
            "run_min_s": timing["run_min_s"] * scale,
            "repeats": timing["repeats"],
            "compile_s": 0.0,
        }
        fp_row = {
            "case": label,
            "impl": "filterpy",
            "sequences_timed": n_fp,
            "scaled_from_sequences": n_fp if batch and n_fp < N else None,
            **timing_scaled,
        }
        result["rows"].append(fp_row)
        log(
            f"  {kind} {label:>13} {'filterpy':<17} (timed {n_fp} seq{', scaled x%.0f' % scale if scale != 1 else ''})"
            f"   run {timing_scaled['run_s'] * 1e3:10.3f} ms"
        )
        # correctness: all against jaxfdi (filterpy on the sequences it ran)
        ref = outs["jaxfdi"]
        ref_fp = (
            tuple(np.asarray(x)[:n_fp] for x in ref[:2])
            if batch
            else tuple(np.asarray(x) for x in ref[:2])
        )
        result["agreement"] += [
            dict(case=label, **row)
            for row in agreement("jaxfdi", ref_fp, {"filterpy": fp_holder["out"]}, tol)
        ]
        others = {k: v for k, v in outs.items() if k in ("plain_scan", "dynamax", "jaxfdi_batch")}
        with dynamax_without_diagonal_boost():  # untimed, fresh trace
            f = (
                jax.jit(lambda *a: dmx(*a))
                if not batch
                else jax.jit(jax.vmap(lambda *a: dmx(*a), in_axes=shared))
            )
            others["dynamax_no_boost"] = f(*head, m0, P0, ys if batch else ys[0], us)
        if "jaxfdi_full_info" in outs:
            full = outs["jaxfdi_full_info"]
            others["jaxfdi_full_info"] = (
                full.filtered_mean,
                full.filtered_cov,
                jnp.sum(full.log_likelihood, axis=-1),
            )
        result["agreement"] += [
            dict(case=label, **row) for row in agreement("jaxfdi", ref, others, tol)
        ]

    # N sequences again, returning only what a Monte Carlo statistic needs (means and
    # log-likelihood). With a shared P0 and model the covariances of the plain scan and
    # dynamax do not depend on the data, so vmap keeps them unbatched and returning them
    # costs a broadcast to N copies; here nobody pays for that.
    label = f"{N} seq, means+loglik"
    outs = {}
    for name, fn in (("jaxfdi", lib), ("plain_scan", plain), ("dynamax", dmx)):
        timing, out = time_jax(_means_and_loglik(fn), head + (m0, P0, ys, us), shared, reps, budget)
        outs[name] = (out[0], None, out[1])
        result["rows"].append({"case": label, "impl": name, "sequences_timed": N, **timing})
        log(
            f"  {kind} {label} {name:<10} compile {timing['compile_s']:7.3f} s   run {timing['run_s'] * 1e3:10.3f} ms"
        )
    result["rows"].append(
        {**fp_row, "case": label, "note": "same filterpy timing as the full-output case"}
    )
    result["agreement"] += [
        dict(case=label, **row)
        for row in agreement(
            "jaxfdi", outs["jaxfdi"], {k: v for k, v in outs.items() if k != "jaxfdi"}, tol
        )
    ]

    # Monte Carlo with a covariance per run: P0 per run, then Q per run (a model per run)
    key_p, key_q = jax.random.split(jax.random.key(42))
    P0s = P0[None] * jnp.exp(jax.random.uniform(key_p, (N, 1, 1), minval=-1.0, maxval=1.0))
    q_scale = jnp.exp(jax.random.uniform(key_q, (N, 1, 1), minval=-0.5, maxval=0.5))
    if kind == "kf":
        model = prob["model"]
        Q_head = (model._replace(Q=model.Q[None] * q_scale),)
        Q_axes = (model._replace(Phi=None, Gamma=None, C=None, D=None, Q=0, R=None),)
    else:
        Q_head = (prob["Q"][None] * q_scale, prob["R"], prob["params"])
        Q_axes = (0, None, None)
    variants = (
        (f"{N} runs, P0 per run", head + (m0, P0s, ys, us), (None,) * n_head + (None, 0, 0, None)),
        (f"{N} runs, Q per run", Q_head + (m0, P0, ys, us), Q_axes + (None, None, 0, None)),
    )
    for label, call_args, in_axes in variants:
        outs = {}
        for name, fn in (("jaxfdi", lib), ("plain_scan", plain), ("dynamax", dmx)):
            timing, out = time_jax(fn, call_args, in_axes, reps, budget)
            outs[name] = out
            result["rows"].append({"case": label, "impl": name, "sequences_timed": N, **timing})
            log(
                f"  {kind} {label:>20} {name:<10} compile {timing['compile_s']:7.3f} s   run "
                f"{timing['run_s'] * 1e3:10.3f} ms"
            )
        if kind == "kf":  # the batch kernel: the model/prior per run carries its run axis, no vmap
            timing, out = time_jax(jaxfdi_kf_kernel, call_args, None, reps, budget)
            outs["jaxfdi_batch"] = out
            result["rows"].append(
                {
                    "case": label,
                    "impl": "jaxfdi_batch",
                    "sequences_timed": N,
                    **timing,
                    "note": "structure-of-arrays kernel (run_filter, a prior or a model per run)",
                }
            )
            log(
                f"  {kind} {label:>20} {'jaxfdi_batch':<10} compile {timing['compile_s']:7.3f} s  "
                f" run {timing['run_s'] * 1e3:10.3f} ms"
            )
        result["rows"].append(
            {**fp_row, "case": label, "note": "same filterpy timing as the 100-sequence case"}
        )
        result["agreement"] += [
            dict(case=label, **row)
            for row in agreement(
                "jaxfdi", outs["jaxfdi"], {k: v for k, v in outs.items() if k != "jaxfdi"}, tol
            )
        ]
    return result


def bench_driver_compile(prob: dict, log, rounds: int = 3) -> list[dict]:
    """Compile time (trace + lower + XLA compile) of each KF driver on the engine, the
    plain scan beside them: eager ``run_filter`` (what a one-shot script calls; traced
    with library calls, ``_linalg.library_calls``), ``jit(run_filter)`` (the inlined,
    written-out path of ``vmap``), ``run_filter`` shared and per-run P0, and
    ``run_filter`` with a per-run Q; every ``FilterInfo`` field returned. Beside them the one-sequence call that returns
    what the plain scan and dynamax return (means, covariances, log-likelihood), and dynamax's. The drivers are compiled
    in turn, ``rounds`` times, caches cleared before each compile, and each keeps its fastest round: the first compile
    in a process also pays JAX's one-time set-up, so a single pass favours whichever driver comes later."""
    from jaxfdi._numerics import linalg as _linalg
    from jaxfdi.filters._driver import _scan_filter

    model, m0, P0, ys, us = prob["model"], prob["m0"], prob["P0"], prob["ys"], prob["us"]
    N = ys.shape[0]
    kf = jaxfdi.filters.kalman_filter(model)
    P0s = jnp.broadcast_to(P0, (N,) + P0.shape) * 1.5
    cases = {
        "plain scan, 1 sequence (means, covs, loglik)": lambda: jax.jit(plain_kf).lower(
            model, m0, P0, ys[0], us
        ),
        "dynamax, 1 sequence (means, covs, loglik)": lambda: jax.jit(dynamax_kf).lower(
            model, m0, P0, ys[0], us
        ),
        "jit(run_filter), 1 sequence (means, covs, loglik)": lambda: jax.jit(jaxfdi_kf).lower(
            model, m0, P0, ys[0], us
        ),
        "run_filter eager, 1 sequence (full info)": lambda: _scan_filter.lower(
            kf, kf.init(m0, P0), ys[0], us
        ),
        "jit(run_filter), 1 sequence (full info)": lambda: jax.jit(jaxfdi_kf_full_info).lower(
            model, m0, P0, ys[0], us
        ),
        f"run_filter shared, {N} seq (full info)": lambda: jax.jit(
            lambda y: jaxfdi.filters.run_filter(kf, kf.init(m0, P0), y, us)
        ).lower(ys),
        f"run_filter P0 per run, {N} runs (full info)": lambda: jax.jit(
            lambda p: jaxfdi.filters.run_filter(kf, jaxfdi.filters.GaussianState(m0, p), ys, us)
        ).lower(P0s),
        f"run_filter Q per run, {N} runs (full info)": lambda: jax.jit(
            lambda q: jaxfdi.filters.run_filter(
                jaxfdi.filters.kalman_filter(model._replace(Q=q)),
                jaxfdi.filters.GaussianState(m0, P0),
                ys,
                us,
            )
        ).lower(P0s),
    }
    best: dict[str, dict] = {}
    for round_ in range(rounds):
        for name, lower in cases.items():
            jax.clear_caches()
            t0 = time.perf_counter()
            if name.startswith("run_filter eager"):
                with _linalg.library_calls():
                    lowered = lower()
            else:
                lowered = lower()
            t1 = time.perf_counter()
            compiled = lowered.compile()
            t2 = time.perf_counter()
            row = {
                "driver": name,
                "trace_lower_s": t1 - t0,
                "xla_compile_s": t2 - t1,
                "compile_s": t2 - t0,
                "hlo_lines": len(compiled.as_text().splitlines()),
                "rounds": rounds,
            }
            if name not in best or row["compile_s"] < best[name]["compile_s"]:
                best[name] = row
            log(
                f"  compile (round {round_}) {name:<52} {t2 - t0:6.3f} s  ({row['hlo_lines']} HLO lines)"
            )
    return list(best.values())


def format_driver_compile(rows: list[dict]) -> str:
    lines = [
        f"Driver compile time (engine KF, T = 1000; trace + lower + XLA compile, caches cleared before each; "
        f"fastest of {rows[0]['rounds']} interleaved rounds)",
        f"{'driver':<54} {'trace+lower [s]':>15} {'XLA [s]':>8} {'total [s]':>9} {'HLO lines':>10}",
    ]
    for r in rows:
        lines.append(
            f"{r['driver']:<54} {r['trace_lower_s']:15.3f} {r['xla_compile_s']:8.3f} {r['compile_s']:9.3f} "
            f"{r['hlo_lines']:10d}"
        )
    return "\n".join(lines)


# ------------------------------------------------------------------ one-shot processes
_ONESHOT_JAXFDI = r"""
import sys, time, json
t0 = time.perf_counter()
import numpy as np
import jax
jax.config.update('jax_enable_x64', True)
if sys.argv[2] != '-':
    jax.config.update('jax_compilation_cache_dir', sys.argv[2])
    jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)
    jax.config.update('jax_persistent_cache_min_entry_size_bytes', -1)
import jaxfdi
from jaxfdi.models import engine_model
t1 = time.perf_counter()
d = np.load(sys.argv[1])
model = jax.block_until_ready(engine_model())
t_model = time.perf_counter()
kf = jaxfdi.filters.kalman_filter(model)
_, info = jaxfdi.filters.run_filter(kf, kf.init(d['m0'], d['P0']), d['ys'], d['us'])
means = np.asarray(info.filtered_mean)
t2 = time.perf_counter()
print(json.dumps({'import_s': t1 - t0, 'build_and_run_s': t2 - t1, 'model_s': t_model - t1, 'filter_s': t2 - t_model,
                  'checksum': float(means.sum()), 'last': means[-1].tolist()}))
"""

_ONESHOT_FILTERPY = r"""
import sys, time, json
t0 = time.perf_counter()
import numpy as np
from filterpy.kalman import KalmanFilter
t1 = time.perf_counter()
d = np.load(sys.argv[1])
Phi, Gamma, C, D, Q, R = (d[k] for k in ('Phi', 'Gamma', 'C', 'D', 'Q', 'R'))
n, nu, m = Phi.shape[0], Gamma.shape[1], C.shape[0]
kf = KalmanFilter(dim_x=n, dim_z=m, dim_u=nu)
kf.F, kf.B, kf.H, kf.Q, kf.R = Phi, Gamma, C, Q, R
kf.x, kf.P = d['m0'].reshape(n, 1).copy(), d['P0'].copy()
ys, us = d['ys'], d['us']
means = np.empty((len(ys), n))
for k in range(len(ys)):
    kf.update((ys[k] - D @ us[k]).reshape(m, 1))
    means[k] = kf.x[:, 0]
    kf.predict(u=us[k].reshape(nu, 1))
t2 = time.perf_counter()
print(json.dumps({'import_s': t1 - t0, 'build_and_run_s': t2 - t1, 'checksum': float(means.sum()),
                  'last': means[-1].tolist()}))
"""


def _run_oneshot(script: str, *argv: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_COMPILATION_CACHE")}
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", script, *argv], capture_output=True, text=True, env=env, check=False
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"one-shot process failed:\n{proc.stderr[-3000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["wall_s"] = wall
    return out


def bench_oneshot(prob: dict, repeats: int, log) -> dict:
    """Whole ``python -c`` processes filtering one engine sequence (T = 1000) end to end."""
    model = prob["model"]
    with tempfile.TemporaryDirectory(prefix="jaxfdi_bench_") as tmp:
        data = os.path.join(tmp, "engine.npz")
        np.savez(
            data,
            ys=np.asarray(prob["ys"][0]),
            us=np.asarray(prob["us"]),
            m0=np.asarray(prob["m0"]),
            P0=np.asarray(prob["P0"]),
            **{k: np.asarray(v) for k, v in model._asdict().items()},
        )
        runs = {
            "jaxfdi": [],
            "filterpy": [],
            "jaxfdi_cache_first_start": [],
            "jaxfdi_cache_second_start": [],
        }
        for i in range(repeats):
            runs["filterpy"].append(_run_oneshot(_ONESHOT_FILTERPY, data))
            runs["jaxfdi"].append(_run_oneshot(_ONESHOT_JAXFDI, data, "-"))
            cache = os.path.join(tmp, f"cache{i}")
            os.makedirs(cache)
            runs["jaxfdi_cache_first_start"].append(_run_oneshot(_ONESHOT_JAXFDI, data, cache))
            runs["jaxfdi_cache_second_start"].append(_run_oneshot(_ONESHOT_JAXFDI, data, cache))
            log(
                f"  one-shot repeat {i + 1}/{repeats}: "
                + ", ".join(f"{k} {v[-1]['wall_s']:.2f} s" for k, v in runs.items())
            )
    summary = {}
    for name, rs in runs.items():
        summary[name] = {
            "wall_s": statistics.median(r["wall_s"] for r in rs),
            "import_s": statistics.median(r["import_s"] for r in rs),
            "build_and_run_s": statistics.median(r["build_and_run_s"] for r in rs),
            "repeats": len(rs),
        }
        if "model_s" in rs[0]:  # jaxfdi: engine_model() (eager c2d/expm) vs filter init + run
            summary[name]["model_s"] = statistics.median(r["model_s"] for r in rs)
            summary[name]["filter_s"] = statistics.median(r["filter_s"] for r in rs)
    last_j = np.array(runs["jaxfdi"][0]["last"])
    last_f = np.array(runs["filterpy"][0]["last"])
    summary["agreement_last_mean_rel_diff"] = float(
        np.max(np.abs(last_j - last_f)) / np.max(np.abs(last_f))
    )
    summary["ratio_jaxfdi_over_filterpy_wall"] = (
        summary["jaxfdi"]["wall_s"] / summary["filterpy"]["wall_s"]
    )
    summary["ratio_cache_second_over_first_wall"] = (
        summary["jaxfdi_cache_second_start"]["wall_s"]
        / summary["jaxfdi_cache_first_start"]["wall_s"]
    )
    return summary


# ------------------------------------------------------------------------------ output
def ratios(result: dict) -> list[dict]:
    """Run-time ratio other / jaxfdi per case (> 1: jaxfdi is faster)."""
    rows = []
    by_case: dict[str, dict[str, dict]] = {}
    for row in result["rows"]:
        by_case.setdefault(row["case"], {})[row["impl"]] = row
    for case, impls in by_case.items():
        base = impls["jaxfdi"]["run_s"]
        for impl, row in impls.items():
            if impl != "jaxfdi":
                rows.append(
                    {"case": case, "impl": impl, "ratio_other_over_jaxfdi": row["run_s"] / base}
                )
    return rows


def format_table(kind: str, result: dict) -> str:
    lines = [
        f"{kind.upper()}  (T = {result['T']}, float64)",
        f"{'case':<22} {'implementation':<17} {'compile [s]':>11} {'run [ms]':>12} "
        f"{'per seq [ms]':>13} {'x jaxfdi':>9}  note",
    ]
    base = {row["case"]: row["run_s"] for row in result["rows"] if row["impl"] == "jaxfdi"}
    for row in result["rows"]:
        n_seq = result["N"] if row["case"] != "1 sequence" else 1
        note = row.get("note", "")
        if row.get("scaled_from_sequences") and not note:
            note = f"timed on {row['scaled_from_sequences']} seq, scaled x{n_seq / row['scaled_from_sequences']:.0f}"
        if row["impl"] == "filterpy":
            note = (note + "; " if note else "") + "Python loop, no compile"
        compile_s = f"{row['compile_s']:.3f}" if row["impl"] != "filterpy" else "-"
        lines.append(
            f"{row['case']:<22} {row['impl']:<17} {compile_s:>11} {row['run_s'] * 1e3:12.3f} "
            f"{row['run_s'] * 1e3 / n_seq:13.4f} {row['run_s'] / base[row['case']]:9.2f}  {note}"
        )
    lines.append("'x jaxfdi' = run time / jaxfdi run time in the same case (> 1: jaxfdi faster).")
    return "\n".join(lines)


def format_agreement(kind: str, result: dict) -> str:
    lines = [
        f"{kind.upper()} agreement with jaxfdi (max |a-b|/max|b| per sequence; tol "
        f"{result['agreement'][0]['tol']:.0e}, "
        f"dynamax {TOL_DYNAMAX:.0e}: its psd_solve adds 1e-9 to diag(S); dynamax_no_boost = same without it, untimed)",
        f"{'case':<22} {'implementation':<17} {'mean':>10} {'cov':>10} {'loglik':>10}  ok",
    ]
    for row in result["agreement"]:
        ll = f"{row['log_likelihood']:.1e}" if "log_likelihood" in row else "-"
        cov = f"{row['filtered_cov']:.1e}" if "filtered_cov" in row else "-"
        lines.append(
            f"{row['case']:<22} {row['impl']:<17} {row['filtered_mean']:10.1e} {cov:>10} {ll:>10} "
            f" {'yes' if row['ok'] else 'NO'} (tol {row['tol']:.0e})"
        )
    return "\n".join(lines)


def format_targets(results: dict) -> tuple[str, list[dict]]:
    lines = ["Targets (100-sequence case, speed-up = other run time / jaxfdi run time)"]
    checks = []
    for (kind, other), target in TARGETS.items():
        res = results[kind]
        readings = [
            (f"{res['N']} sequences", "jaxfdi"),
            (f"{res['N']} sequences", "jaxfdi_batch"),
            (f"{res['N']} seq, means+loglik", "jaxfdi"),
        ]
        for case, mine in readings:
            rows = {r["impl"]: r for r in res["rows"] if r["case"] == case}
            if mine not in rows:
                continue
            speedup = rows[other]["run_s"] / rows[mine]["run_s"]
            ok = speedup >= target
            checks.append(
                {
                    "filter": kind,
                    "other": other,
                    "case": case,
                    "jaxfdi_driver": mine,
                    "target_speedup": target,
                    "speedup": speedup,
                    "met": bool(ok),
                }
            )
            lines.append(
                f"  {kind.upper():<4} {mine:<13} vs {other:<9} {case:<22} target >= {target:6.1f}x   "
                f"measured {speedup:9.2f}x   {'MET' if ok else 'MISSED'}"
            )
    lines.append(
        "  (the target is stated for '%d sequences': vmap(run_filter) returning N copies of every field, and "
        "run_filter returning shared covariances once; means+loglik is a third reading)" % res["N"]
    )
    res = results["kf"]
    for case in (f"{res['N']} runs, P0 per run", f"{res['N']} runs, Q per run"):
        rows = {r["impl"]: r for r in res["rows"] if r["case"] == case}
        if "jaxfdi_batch" not in rows:
            continue
        for other, target in (
            ("plain_scan", 3.0),
            ("jaxfdi", None),
            ("dynamax", None),
            ("filterpy", None),
        ):
            speedup = rows[other]["run_s"] / rows["jaxfdi_batch"]["run_s"]
            ok = target is None or speedup >= target
            checks.append(
                {
                    "filter": "kf",
                    "other": other,
                    "case": case,
                    "jaxfdi_driver": "jaxfdi_batch",
                    "target_speedup": target,
                    "speedup": speedup,
                    "met": bool(ok),
                }
            )
            goal = f"target >= {target:6.1f}x" if target else "(no target)    "
            lines.append(
                f"  KF   jaxfdi_batch  vs {other:<10} {case:<22} {goal}   measured {speedup:9.2f}x   "
                f"{'MET' if ok and target else ('MISSED' if target else '')}"
            )
    return "\n".join(lines), checks


def format_oneshot(s: dict) -> str:
    lines = [
        "One-shot processes: `python -c` that imports, builds the engine KF and filters one sequence (T = 1000)",
        f"{'process':<28} {'wall [s]':>9} {'import [s]':>11} {'build+run [s]':>14} "
        f"{'of which model [s]':>19} {'filter [s]':>11}",
    ]
    for name in ("filterpy", "jaxfdi", "jaxfdi_cache_first_start", "jaxfdi_cache_second_start"):
        r = s[name]
        parts = (
            f"{r['model_s']:19.3f} {r['filter_s']:11.3f}"
            if "model_s" in r
            else f"{'-':>19} {'-':>11}"
        )
        lines.append(
            f"{name:<28} {r['wall_s']:9.3f} {r['import_s']:11.3f} {r['build_and_run_s']:14.3f} {parts}"
        )
    lines.append(
        f"jaxfdi / filterpy wall time: {s['ratio_jaxfdi_over_filterpy_wall']:.2f}x;  "
        f"persistent cache, second start / first start: {s['ratio_cache_second_over_first_wall']:.2f}x;  "
        f"results agree to {s['agreement_last_mean_rel_diff']:.1e} (median of {s['jaxfdi']['repeats']})"
    )
    return "\n".join(lines)


def write_json_atomic(path: str, payload: dict) -> None:
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".results-", suffix=".json.tmp", dir=directory)
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(payload, fh, indent=2)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def cpu_model() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--sequences",
        type=int,
        default=None,
        help="Monte Carlo sequences N (default 100; 100 with --quick too)",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="timed repeats per measurement, median reported (default 10; 3 with --quick)",
    )
    parser.add_argument(
        "--filterpy-sequences",
        type=int,
        default=None,
        help="sequences filterpy runs for the N-sequence case, scaled to N (default 20; 2 with --quick)",
    )
    parser.add_argument(
        "--filterpy-repeats",
        type=int,
        default=None,
        help="repeats of each filterpy timing (default 3; 1 with --quick)",
    )
    parser.add_argument(
        "--oneshot-repeats",
        type=int,
        default=None,
        help="repeats of the one-shot process timings (default 3; 1 with --quick)",
    )
    parser.add_argument(
        "--budget",
        type=float,
        default=None,
        help="seconds after which a measurement stops repeating (at least 3 repeats)",
    )
    parser.add_argument("--quick", action="store_true", help="smoke test, < 1 minute")
    parser.add_argument(
        "--skip-oneshot", action="store_true", help="skip the one-shot process timings"
    )
    parser.add_argument(
        "--out", default="benchmarks/results.json", help="JSON results (written atomically)"
    )
    args = parser.parse_args(argv)
    q = args.quick
    args.sequences = args.sequences or 100
    args.repeats = args.repeats or (3 if q else 10)
    args.filterpy_sequences = args.filterpy_sequences or (2 if q else 20)
    args.filterpy_repeats = args.filterpy_repeats or (1 if q else 3)
    args.oneshot_repeats = args.oneshot_repeats or (1 if q else 3)
    args.budget = args.budget or (2.0 if q else 20.0)

    def log(msg):
        print(msg, flush=True)

    started = time.perf_counter()
    import dynamax
    import filterpy

    meta = {
        "command": " ".join([os.path.basename(sys.executable)] + sys.argv),
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "jax_backend": jax.default_backend(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxfdi": jaxfdi.__version__,
        "dynamax": getattr(dynamax, "__version__", "?"),
        "filterpy": filterpy.__version__,
        "numpy": np.__version__,
        "args": vars(args),
        "alpha_beta_kappa": [ALPHA, BETA, KAPPA],
    }
    payload: dict[str, Any] = {"meta": meta}
    log(
        f"jax {jax.__version__} on {jax.default_backend()} ({meta['cpu']}, {meta['cpu_count']} cores); "
        f"N = {args.sequences}, repeats = {args.repeats}, filterpy on {args.filterpy_sequences} sequences"
    )

    engine = engine_problem(args.sequences)
    rigid = rigid_body_problem(args.sequences)
    for kind, prob in (("kf", engine), ("ukf", rigid)):
        log(f"[{kind}]")
        payload[kind] = bench_filter(kind, prob, args, log)
        payload[kind]["ratios"] = ratios(payload[kind])
        write_json_atomic(args.out, payload)
    log("[driver compile times]")
    payload["driver_compile"] = bench_driver_compile(engine, log)
    write_json_atomic(args.out, payload)
    if not args.skip_oneshot:
        log("[one-shot processes]")
        payload["oneshot"] = bench_oneshot(engine, args.oneshot_repeats, log)

    target_text, payload["targets"] = format_targets(payload)
    payload["all_agree"] = all(
        r["ok"] for kind in ("kf", "ukf") for r in payload[kind]["agreement"]
    )
    payload["elapsed_s"] = time.perf_counter() - started
    write_json_atomic(args.out, payload)

    print()
    for kind in ("kf", "ukf"):
        print(format_table(kind, payload[kind]))
        print()
        print(format_agreement(kind, payload[kind]))
        print()
    print(target_text)
    print()
    print(format_driver_compile(payload["driver_compile"]))
    if "oneshot" in payload:
        print()
        print(format_oneshot(payload["oneshot"]))
    print(
        f"\nall implementations agree within tolerance: {payload['all_agree']};  "
        f"elapsed {payload['elapsed_s']:.0f} s;  results written to {args.out}"
    )
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results.json")
    return 0 if payload["all_agree"] else 1


if __name__ == "__main__":
    sys.exit(main())
