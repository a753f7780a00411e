"""IMM on the engine (7 modes, 1000 steps) against filterpy's IMMEstimator, and the GLRT's
cost per step against the window length N.

IMM workloads (float64): the seed-003 engine with the Zhang & Li noise-inflation modes
(7 modes sharing 7 states) and with the fault-bias modes (7 modes sharing 13 states),
the paper's transition matrix, a P2 sensor bias from step 500. One sequence and 100 Monte
Carlo sequences: jaxfdi is ``jit(run_filter)`` / ``jit(vmap(run_filter))``, filterpy a
Python loop of ``IMMEstimator.update``/``predict`` over 7 ``KalmanFilter`` objects (its
KF has no feed-through, so it is given ``y - D u``). Both return the mode probabilities
and the combined mean of every step; the script checks they agree before timing.
Compile time is reported apart from the run time (median of repeats).

GLRT workload: the online detector (``glrt_detector``) over the innovations of 100
sequences x 1000 steps, N = 10, 20, 40: run time per step and per sequence.

Run:  python benchmarks/bench_imm.py [--sequences 100] [--repeats 5] [--filterpy-sequences 10]
Writes benchmarks/results_imm.json.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from filterpy.kalman import IMMEstimator, KalmanFilter

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_filters import cpu_model, rel_diff, time_jax, write_json_atomic

import jaxfdi
from jaxfdi.models import bias_mode_initial_state, bias_modes, engine_model, noise_inflation_modes
from jaxfdi.scenarios.engine import PAPER_TRANSITION, EngineSettings

T = 1000
TOL = 1e-7


def engine_data(num_sequences: int, seed: int = 0):
    model = engine_model()
    us = jnp.full((T, 1), 0.01)
    p2 = jaxfdi.fault("bias", "sensor", 1, 500, 16.99)
    sim = jaxfdi.linear_simulator(model, p2)
    keys = jax.random.split(jax.random.key(seed), num_sequences)
    ys = jax.vmap(lambda k: jaxfdi.simulate(sim, jnp.zeros(7), us, k)[1].measurement)(keys)
    return model, np.asarray(ys), np.asarray(us)


def designs(model):
    s = EngineSettings()
    zl = noise_inflation_modes(model, s.sensor_inflation, s.actuator_noise)
    bm = bias_modes(model, jnp.asarray(s.bias_walk), jnp.asarray(s.bias_prior))
    z0, Z0 = bias_mode_initial_state(model, jnp.zeros(7), model.Q, jnp.asarray(s.bias_prior))
    return {
        "zhang-li (7 states)": (zl, jnp.zeros(7), model.Q),
        "fault-bias (13 states)": (bm, z0, Z0),
    }


def jaxfdi_imm(modes, m0, P0):
    imm = jaxfdi.filters.interacting_multiple_model(
        jaxfdi.filters.kalman_filter, modes, PAPER_TRANSITION
    )
    mu0 = jnp.asarray(PAPER_TRANSITION[0] @ PAPER_TRANSITION)  # filterpy's first prior: mu0 @ pi

    def run(ys, us):
        _, info = jaxfdi.filters.run_filter(imm, imm.init(m0, P0, mu0), ys, us)
        return info.mode_prob, info.mean

    return run


def jaxfdi_imm_batch(modes, m0, P0):
    """``run_filter``: the whole batch in one call (ys (N, T, m), shared us)."""
    imm = jaxfdi.filters.interacting_multiple_model(
        jaxfdi.filters.kalman_filter, modes, PAPER_TRANSITION
    )
    mu0 = jnp.asarray(PAPER_TRANSITION[0] @ PAPER_TRANSITION)

    def run(ys, us):
        _, info = jaxfdi.filters.run_filter(imm, imm.init(m0, P0, mu0), ys, us)
        return info.mode_prob, info.mean

    return run, imm.batch is not None


def filterpy_imm(modes, m0, P0, ys, us):
    """Python loop, one sequence at a time: (S, T, M) mode probabilities, (S, T, n) means."""
    M = modes.Phi.shape[0]
    arrays = {k: np.asarray(getattr(modes, k)) for k in ("Phi", "Gamma", "C", "D", "Q", "R")}
    all_mu, all_x = [], []
    for y_seq in ys:
        filters = []
        for j in range(M):
            kf = KalmanFilter(dim_x=arrays["Phi"].shape[1], dim_z=arrays["C"].shape[1], dim_u=1)
            kf.F, kf.B, kf.H = arrays["Phi"][j], arrays["Gamma"][j], arrays["C"][j]
            kf.Q, kf.R = arrays["Q"][j], arrays["R"][j]
            kf.x, kf.P = np.asarray(m0).copy(), np.asarray(P0).copy()
            filters.append(kf)
        imm = IMMEstimator(filters, PAPER_TRANSITION[0].copy(), PAPER_TRANSITION)
        mu, x = [], []
        D = arrays["D"][0]
        for k in range(T):
            imm.update(y_seq[k] - D @ us[k])
            mu.append(imm.mu.copy())
            x.append(imm.x.copy())
            imm.predict(us[k])
        all_mu.append(mu)
        all_x.append(x)
    return np.array(all_mu), np.array(all_x)


def bench_imm(args, log) -> list[dict]:
    rows = []
    model, ys, us = engine_data(args.sequences)
    for name, (modes, m0, P0) in designs(model).items():
        run = jaxfdi_imm(modes, m0, P0)
        one, out_one = time_jax(run, (ys[0], us), None, args.repeats, 20.0)
        many, out_many = time_jax(run, (ys, us), (0, None), args.repeats, 60.0)
        run_batch, has_kernel = jaxfdi_imm_batch(modes, m0, P0)
        batch, out_batch = time_jax(run_batch, (ys, us), None, args.repeats, 60.0)
        S = min(args.filterpy_sequences, args.sequences)
        t0 = time.perf_counter()
        ref_mu, ref_x = filterpy_imm(modes, m0, P0, ys[:S], us)
        filterpy_per_seq = (time.perf_counter() - t0) / S
        err_mu = rel_diff(np.asarray(out_many[0])[:S], ref_mu)
        err_x = rel_diff(np.asarray(out_many[1])[:S], ref_x)
        err_mu = max(err_mu, rel_diff(np.asarray(out_batch[0])[:S], ref_mu))
        err_x = max(err_x, rel_diff(np.asarray(out_batch[1])[:S], ref_x))
        if max(err_mu, err_x) > TOL:
            raise SystemExit(
                f"{name}: jaxfdi and filterpy disagree (mode prob {err_mu:.2e}, mean {err_x:.2e})"
            )
        row = {
            "design": name,
            "steps": T,
            "sequences": args.sequences,
            "filterpy_sequences_timed": S,
            "jaxfdi_1_s": one["run_s"],
            "jaxfdi_1_compile_s": one["compile_s"],
            "jaxfdi_N_s": many["run_s"],
            "jaxfdi_N_compile_s": many["compile_s"],
            "filterpy_1_s": filterpy_per_seq,
            "filterpy_N_s": filterpy_per_seq * args.sequences,
            "speedup_1": filterpy_per_seq / one["run_s"],
            "speedup_N": filterpy_per_seq * args.sequences / many["run_s"],
            "jaxfdi_batch_N_s": batch["run_s"],
            "jaxfdi_batch_N_compile_s": batch["compile_s"],
            "batch_kernel": has_kernel,
            "speedup_batch_N": filterpy_per_seq * args.sequences / batch["run_s"],
            "agreement_mode_prob": err_mu,
            "agreement_mean": err_x,
        }
        log(
            f"IMM {name}: 1 seq jaxfdi {one['run_s'] * 1e3:.1f} ms (compile {one['compile_s']:.2f} s), filterpy "
            f"{filterpy_per_seq * 1e3:.0f} ms -> {row['speedup_1']:.0f}x; {args.sequences} seq jaxfdi "
            f"{many['run_s'] * 1e3:.0f} ms (compile {many['compile_s']:.2f} s), filterpy "
            f"{row['filterpy_N_s']:.1f} s (extrapolated from {S}) -> {row['speedup_N']:.0f}x; "
            f"run_filter ({'structure-of-arrays kernel' if has_kernel else 'vmap, no kernel'}) "
            f"{batch['run_s'] * 1e3:.0f} ms (compile {batch['compile_s']:.2f} s) -> {row['speedup_batch_N']:.0f}x; "
            f"agreement {max(err_mu, err_x):.1e}"
        )
        rows.append(row)
    return rows


def bench_glrt(args, log) -> list[dict]:
    model, ys, us = engine_data(args.sequences, seed=1)
    steady = jaxfdi.filters.steady_state_kalman(model)
    kf = jaxfdi.filters.kalman_filter(model)
    _, info = jaxfdi.filters.run_filter(kf, kf.init(jnp.zeros(7), steady.predicted_cov), ys, us)
    innovations = jnp.asarray(info.innovation)
    rows = []
    for N in (10, 20, 40):
        det = jaxfdi.detection.glrt_detector(model, steady.gain, steady.innovation_cov, N, 200.0)

        def run(e, det=det):
            return jax.lax.scan(det.step, det.init(), e)[1].statistic

        timing, _ = time_jax(run, (innovations,), 0, args.repeats, 30.0)
        per_step = timing["run_s"] / (args.sequences * T)
        rows.append(
            {
                "window": N,
                "sequences": args.sequences,
                "steps": T,
                "run_s": timing["run_s"],
                "compile_s": timing["compile_s"],
                "per_step_per_sequence_us": per_step * 1e6,
            }
        )
        log(
            f"GLRT N={N}: {args.sequences} x {T} steps in {timing['run_s'] * 1e3:.1f} ms "
            f"({per_step * 1e6:.3f} us per step per sequence), compile {timing['compile_s']:.2f} s"
        )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sequences", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--filterpy-sequences",
        type=int,
        default=10,
        help="filterpy sequences actually run; its N-sequence time is this per-sequence time x N",
    )
    parser.add_argument(
        "--out",
        default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results_imm.json"),
    )
    args = parser.parse_args(argv)
    log = lambda msg: print(msg, flush=True)
    log(
        f"jax {jax.__version__} on {jax.devices()[0].device_kind} ({cpu_model()}, {os.cpu_count()} cores)"
    )
    result = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "jax": jax.__version__,
        "device": jax.devices()[0].device_kind,
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "command": " ".join(["python", *sys.argv]),
        "imm": bench_imm(args, log),
        "glrt": bench_glrt(args, log),
    }
    write_json_atomic(args.out, result)
    log(f"wrote {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_imm.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
