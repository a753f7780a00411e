"""Seed 001's 6-filter TSKF bank (a1, a2 effectiveness; s1..s4 scaling) over Monte Carlo runs.

Data: the VTOL under its nominal LQR-PI loop (true state fed back), the airspeed
uncertainty as the unknown input ``E d`` and the paper's noise, T = 300 steps, one
sequence per run (numpy, seeded). Three implementations of the same bank:

* jaxfdi: ``run_tskf_bank`` (one filter vmapped over the 6 directions), ``jit(vmap)``
  over runs; robust (decoupling E) and optimal (no unknown input);
* numpy loop: the same robust two-stage recursions written directly in NumPy, one run,
  one filter, one step at a time (the baseline; ``--numpy-runs`` of them are timed and
  the per-run time scaled to all runs);
* augmented-state KF bank: the Kalman filter on ``[x; b]`` (time-varying ``Fa`` and
  ``Fs``) in JAX, ``jit(vmap)`` over filters and runs. It cannot decouple ``d``, so it
  is compared with the optimal TSKF.

Every comparison first checks that the implementations agree (statistics and bias
estimates, relative 1e-8). Compile time is reported apart from run time (median of
repeats); memory is XLA's temporary-buffer size plus the outputs for the JAX programs
and ``tracemalloc``'s peak for the NumPy loop (per timed run).

Run:  python benchmarks/bench_tskf_bank.py                (1000 runs; ~2 minutes on 2 cores)
      python benchmarks/bench_tskf_bank.py --runs 100 --numpy-runs 2 --repeats 2   (quick)
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
import tracemalloc

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from bench_filters import compiled_timing, cpu_model, rel_diff, write_json_atomic

from jaxfdi.control import lqr_pi
from jaxfdi.filters import actuator_direction, sensor_direction, stack_directions
from jaxfdi.filters._tskf import run_tskf_bank
from jaxfdi.models import _vtol as vtol
from jaxfdi.scenarios.vtol import BIAS_WALK, COMMAND, INIT_BIAS_COV, INIT_COV, LQR_Q, LQR_R, TRACKED

T = 300
TOL = 1e-8


def vtol_data(runs: int, seed: int = 0):
    """(runs, T, 4) measurements and (runs, T, 2) inputs of the nominal closed loop with
    the uncertainty ``d = [0, 0.5, 0, 1] x`` on the pitch row."""
    model = vtol.vtol_model()
    Phi, Gamma, C = (np.asarray(a) for a in (model.Phi, model.Gamma, model.C))
    E = np.asarray(vtol.vtol_unknown_input())
    H = TRACKED["paper"]
    K = np.asarray(lqr_pi(Phi, Gamma, H, LQR_Q, LQR_R, vtol.TS).gain)
    rng = np.random.default_rng(seed)
    x = np.tile(vtol.X0, (runs, 1))
    z = np.zeros((runs, 2))
    ys, us = np.empty((runs, T, 4)), np.empty((runs, T, 2))
    for k in range(T):
        ys[:, k] = x @ C.T + vtol.MEASUREMENT_NOISE_STD * rng.standard_normal((runs, 4))
        u = -np.concatenate([x, z], axis=1) @ K.T  # u = -K [x; z]
        us[:, k] = u
        z = z + vtol.TS * (COMMAND - x @ H.T)
        d = x @ vtol.UNCERTAINTY_GAIN.T  # (runs, 1)
        x = (
            x @ Phi.T
            + u @ Gamma.T
            + d @ E.T
            + vtol.PROCESS_NOISE_STD * rng.standard_normal((runs, 4))
        )
    return model, E, ys, us


def paper_bank(model):
    directions = [actuator_direction(model, i, "effectiveness") for i in range(2)]
    directions += [sensor_direction(model, j, "scaling") for j in range(4)]
    return stack_directions(directions)


def jaxfdi_bank(model, directions, unknown_input):
    def run(ys, us):
        info = run_tskf_bank(
            model,
            directions,
            jnp.full((1, 1), BIAS_WALK),
            jnp.asarray(vtol.X0),
            INIT_COV * jnp.eye(4),
            jnp.full((1, 1), INIT_BIAS_COV),
            ys,
            us,
            unknown_input,
        )
        return info.statistic, info.bias_mean[..., 0]  # (F, T) each

    return jax.vmap(run)


def augmented_bank(model, directions):
    """Kalman filter on [x; b] per direction (time-varying Fa, Fs), vmapped over filters."""
    Phi, Gamma, C, Q, R = model.Phi, model.Gamma, model.C, model.Q, model.R

    def one(direction, ys, us):
        def step(carry, yu):
            m, P = carry
            y, u = yu
            Fs = direction.output[:, 0] + (C @ m[:4]) * direction.output_scaled[:, 0]
            H = jnp.concatenate([C, Fs[:, None]], axis=1)
            S = H @ P @ H.T + R
            K = jnp.linalg.solve(S, H @ P).T
            r = y - H @ m
            stat = r @ jnp.linalg.solve(S, r)
            m = m + K @ r
            I_KH = jnp.eye(5) - K @ H
            P = I_KH @ P @ I_KH.T + K @ R @ K.T
            b = m[4]
            Fa = direction.state[:, 0] + Gamma @ (direction.input_scaled[:, 0] * u)
            F = jnp.block([[Phi, Fa[:, None]], [jnp.zeros((1, 4)), jnp.ones((1, 1))]])
            Qa = jnp.block(
                [[Q, jnp.zeros((4, 1))], [jnp.zeros((1, 4)), jnp.full((1, 1), BIAS_WALK)]]
            )
            m = F @ m + jnp.concatenate([Gamma @ u, jnp.zeros(1)])
            P = F @ P @ F.T + Qa
            return (m, P), (stat, b)

        m0 = jnp.concatenate([jnp.asarray(vtol.X0), jnp.zeros(1)])
        P0 = jnp.diag(jnp.array([INIT_COV] * 4 + [INIT_BIAS_COV]))
        return jax.lax.scan(step, (m0, P0), (ys, us))[1]

    bank = jax.vmap(jax.vmap(one, in_axes=(0, None, None)), in_axes=(None, 0, 0))
    return lambda ys, us: bank(directions, ys, us)  # (runs, F, T) each


def numpy_tskf(model, direction, E, ys, us):
    """The robust TSKF of ``jaxfdi.filters._tskf`` in plain NumPy, one run: (T,) statistics
    and bias estimates."""
    Phi, Gamma, C, Q, R = (
        np.asarray(a) for a in (model.Phi, model.Gamma, model.C, model.Q, model.R)
    )
    st, iu, out, os_ = (np.asarray(a)[:, 0] for a in direction)
    n, m = 4, 4
    x_bar, P_bar = vtol.X0.copy(), INIT_COV * np.eye(n)
    b, Pb, V = 0.0, INIT_BIAS_COV, np.zeros(n)
    stats, biases = np.empty(len(ys)), np.empty(len(ys))
    F = C @ E
    for k, (y, u) in enumerate(zip(ys, us)):
        prior = x_bar + V * b
        Fs = out + (C @ prior) * os_
        Hb = C @ V + Fs
        S = C @ P_bar @ C.T + R
        L = np.linalg.cholesky(S)
        Si = np.linalg.inv(S)
        K0 = P_bar @ C.T @ Si
        Fw = np.linalg.solve(L, F)
        Qf, Rf = np.linalg.qr(Fw, mode="complete")
        q = F.shape[1]
        K = K0 + (np.eye(n) - K0 @ C) @ E @ np.linalg.solve(Rf[:q], Qf[:, :q].T) @ np.linalg.inv(L)
        N = Qf[:, q:]
        r_bar = y - C @ x_bar
        x_bar = x_bar + K @ r_bar
        I_KC = np.eye(n) - K @ C
        P_bar = I_KC @ P_bar @ I_KC.T + K @ R @ K.T
        V = V - K @ Hb
        G = N.T @ np.linalg.solve(L, Hb)
        e = N.T @ np.linalg.solve(L, r_bar - Hb * b)
        Sb = Pb * np.outer(G, G) + np.eye(m - q)
        Kb = Pb * np.linalg.solve(Sb, G)
        b = b + Kb @ e
        Pb = (1 - Kb @ G) ** 2 * Pb + Kb @ Kb
        stats[k] = e @ np.linalg.solve(Sb, e)
        biases[k] = b
        Fa = st + Gamma @ (iu * u)
        U = Phi @ V + Fa
        Pb_next = Pb + BIAS_WALK
        V_next = U * Pb / Pb_next
        x_bar = Phi @ x_bar + Gamma @ u + (U - V_next) * b
        P_bar = Phi @ P_bar @ Phi.T + Q + Pb * np.outer(U, U) - Pb_next * np.outer(V_next, V_next)
        Pb, V = Pb_next, V_next
    return stats, biases


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument(
        "--numpy-runs", type=int, default=5, help="runs of the NumPy loop actually timed"
    )
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--out", default=os.path.join(os.path.dirname(__file__), "results_tskf_bank.json")
    )
    args = parser.parse_args(argv)
    log = lambda *a: print(*a, file=sys.stderr, flush=True)

    model, E, ys, us = vtol_data(args.runs)
    directions = paper_bank(model)
    ys_j, us_j = jnp.asarray(ys), jnp.asarray(us)
    log(f"data: {args.runs} runs x {T} steps; device {jax.devices()[0].device_kind}")

    robust, (stat_r, bias_r) = compiled_timing(
        jaxfdi_bank(model, directions, jnp.asarray(E)), (ys_j, us_j), args.repeats, 120.0
    )
    log(f"jaxfdi robust bank: run {robust['run_s']:.3f} s, compile {robust['compile_s']:.1f} s")
    optimal, (stat_o, bias_o) = compiled_timing(
        jaxfdi_bank(model, directions, None), (ys_j, us_j), args.repeats, 120.0
    )
    log(f"jaxfdi optimal bank: run {optimal['run_s']:.3f} s, compile {optimal['compile_s']:.1f} s")
    augmented, (stat_a, bias_a) = compiled_timing(
        augmented_bank(model, directions), (ys_j, us_j), args.repeats, 120.0
    )
    log(
        f"augmented KF bank: run {augmented['run_s']:.3f} s, compile {augmented['compile_s']:.1f} s"
    )
    agree_aug = max(
        rel_diff(np.asarray(stat_a), np.asarray(stat_o)),
        rel_diff(np.asarray(bias_a), np.asarray(bias_o)),
    )
    if agree_aug > TOL:
        raise SystemExit(f"augmented KF and optimal TSKF disagree: {agree_aug:.2e}")

    S = min(args.numpy_runs, args.runs)
    tracemalloc.start()
    t0 = time.perf_counter()
    np_stats = np.empty((S, 6, T))
    np_bias = np.empty((S, 6, T))
    for r in range(S):
        for f in range(6):
            direction = jax.tree_util.tree_map(lambda leaf, f=f: np.asarray(leaf)[f], directions)
            np_stats[r, f], np_bias[r, f] = numpy_tskf(model, direction, E, ys[r], us[r])
    numpy_per_run = (time.perf_counter() - t0) / S
    numpy_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    agree_np = max(
        rel_diff(np.asarray(stat_r)[:S], np_stats), rel_diff(np.asarray(bias_r)[:S], np_bias)
    )
    if agree_np > TOL:
        raise SystemExit(f"numpy loop and jaxfdi robust bank disagree: {agree_np:.2e}")
    log(f"numpy loop: {numpy_per_run:.3f} s per run ({S} runs timed)")

    numpy_all = numpy_per_run * args.runs
    result = {
        "date": datetime.date.today().isoformat(),
        "machine": cpu_model(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "device": jax.devices()[0].device_kind,
        "runs": args.runs,
        "steps": T,
        "filters": 6,
        "jaxfdi_robust": robust,
        "jaxfdi_optimal": optimal,
        "augmented_kf": augmented,
        "numpy_loop": {
            "per_run_s": numpy_per_run,
            "runs_timed": S,
            "all_runs_s_scaled": numpy_all,
            "peak_bytes_per_run_loop": numpy_peak,
        },
        "agreement": {"numpy_vs_jaxfdi_robust": agree_np, "augmented_vs_jaxfdi_optimal": agree_aug},
        "speedup": {
            "robust_vs_numpy": numpy_all / robust["run_s"],
            "optimal_vs_augmented": augmented["run_s"] / optimal["run_s"],
        },
    }
    write_json_atomic(args.out, result)
    print(f"6-filter bank, {args.runs} runs x {T} steps ({result['device']}):")
    print(
        f"  jaxfdi robust TSKF bank   run {robust['run_s']:.3f} s  compile {robust['compile_s']:.1f} s  "
        f"temp {robust['temp_bytes'] / 2**20:.1f} MiB  out {robust['output_bytes'] / 2**20:.1f} MiB"
    )
    print(
        f"  numpy loop (same bank)    {numpy_all:.1f} s scaled from {S} runs ({numpy_per_run * 1e3:.0f} ms/run)  "
        f"peak {numpy_peak / 2**20:.2f} MiB  -> jaxfdi {numpy_all / robust['run_s']:.0f}x faster"
    )
    print(
        f"  jaxfdi optimal TSKF bank  run {optimal['run_s']:.3f} s  compile {optimal['compile_s']:.1f} s  "
        f"temp {optimal['temp_bytes'] / 2**20:.1f} MiB"
    )
    print(
        f"  augmented-state KF bank   run {augmented['run_s']:.3f} s  compile {augmented['compile_s']:.1f} s  "
        f"temp {augmented['temp_bytes'] / 2**20:.1f} MiB  -> TSKF/augmented time ratio "
        f"{optimal['run_s'] / augmented['run_s']:.2f}"
    )
    print(f"  agreement: numpy vs jaxfdi {agree_np:.1e}, augmented vs optimal TSKF {agree_aug:.1e}")
    print(f"wrote {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_tskf_bank.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
