"""Monte Carlo throughput at scale (10^3 .. 10^6 runs): jaxfdi against dynamax and a plain scan.

Each run simulates its own data and filters it inside one compiled program (nothing of
length T is stored), and returns its total log-likelihood:

  * ``kf``:  engine model (7 states, 5 outputs), T = 1000, shared model and P0;
  * ``ukf``: rigid-body rates (3 states), T = 600, alpha = 1e-3, per-run initial state;
  * ``monitor``: the engine chi-square study's fused run (plant -> KF -> 4-step windowed
    chi-square -> detection record) through ``jaxfdi.monte_carlo``, T = 400, P2 bias.

The same PRNG keys drive every implementation, and their log-likelihoods are compared
(max relative difference) before any time is reported. Runs are evaluated in chunks of
``--chunk`` runs by one AOT-compiled ``jit(vmap(...))``; compile time (trace + lower + XLA
compile) is reported apart from run time (median of ``--repeats`` full passes).

Run:  python benchmarks/bench_monte_carlo.py --runs 1000 10000 [--out FILE]
      (on a GPU: --runs 1000 10000 100000 1000000 --chunk 100000)
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bench_filters as bf  # reference implementations: plain scan, dynamax

import jaxfdi
from jaxfdi.models import engine_model
from jaxfdi.models._rigid_body import (
    rigid_body_observation,
    rigid_body_params,
    rigid_body_transition,
)


def kf_runners(T: int):
    model = engine_model()
    k = np.arange(T)
    us = jnp.asarray((0.01 + 0.002 * np.sin(2 * np.pi * k / 250.0)).reshape(T, 1))
    sim = jaxfdi.linear_simulator(model)
    m0, P0 = jnp.zeros(7), 10.0 * model.Q

    def data(key):
        return jaxfdi.simulate(sim, jnp.zeros(7), us, key)[1].measurement

    def jaxfdi_run(key):
        kf = jaxfdi.filters.kalman_filter(model)
        _, info = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), data(key), us)
        return jnp.sum(info.log_likelihood)

    impls = {
        "jaxfdi": jaxfdi_run,
        "plain_scan": lambda key: bf.plain_kf(model, m0, P0, data(key), us)[2],
        "dynamax": lambda key: bf.dynamax_kf(model, m0, P0, data(key), us)[2],
        "simulate_only": lambda key: jnp.sum(data(key)),
    }
    return impls, 1e-6


def ukf_runners(T: int):
    params = rigid_body_params()
    k = np.arange(T)
    us = jnp.asarray(
        np.stack([2000 * np.sin(0.05 * k), 5000 * np.cos(0.03 * k), 3000 * np.ones(T)], 1)
    )
    Q, R = 1e-6 * jnp.eye(3), 1e-4 * jnp.eye(3)
    sim = jaxfdi.simulator(rigid_body_transition, rigid_body_observation, Q, R, params)
    m0, P0 = jnp.zeros(3), 0.1 * jnp.eye(3)

    def data(key):
        key_x0, key_noise = jax.random.split(key)
        x0 = jnp.array([0.5, -0.3, 0.4]) + 0.1 * jax.random.normal(key_x0, (3,))
        return jaxfdi.simulate(sim, x0, us, key_noise)[1].measurement

    def jaxfdi_run(key):
        ukf = jaxfdi.filters.unscented_kalman_filter(
            rigid_body_transition, rigid_body_observation, Q, R, params, bf.ALPHA, bf.BETA, bf.KAPPA
        )
        _, info = jaxfdi.filters.run_filter(ukf, ukf.init(m0, P0), data(key), us)
        return jnp.sum(info.log_likelihood)

    impls = {
        "jaxfdi": jaxfdi_run,
        "plain_scan": lambda key: bf.plain_ukf(Q, R, params, m0, P0, data(key), us)[2],
        "dynamax": lambda key: bf.dynamax_ukf(Q, R, params, m0, P0, data(key), us)[2],
        "simulate_only": lambda key: jnp.sum(data(key)),
    }
    return impls, 1e-4


def monitor_runners(T: int):
    model = engine_model()
    us = jnp.full((T, 1), 0.01)
    threshold = jaxfdi.detection.chi2_threshold(4 * 5, 0.005)
    p2_bias = jaxfdi.fault("bias", "sensor", component=1, onset=T // 2, magnitude=16.99)

    def run(key):
        kf = jaxfdi.filters.kalman_filter(model)
        result = jaxfdi.monitor(
            jaxfdi.linear_simulator(model, p2_bias),
            kf,
            jaxfdi.detection.chi2_detector(threshold, 4),
            jnp.zeros(7),
            kf.init(jnp.zeros(7), model.Q),
            us,
            key,
            p2_bias.onset,
        )
        return result.record.detection_step.astype(jnp.float64)

    return {"jaxfdi": run}, 0.0


def time_chunks(fn, keys: jax.Array, chunk: int, repeats: int):
    """AOT-compile ``jit(vmap(fn))`` for one chunk, then time full passes over ``keys``."""
    batched = jax.jit(jax.vmap(fn))
    size = min(chunk, keys.shape[0])
    t0 = time.perf_counter()
    compiled = batched.lower(keys[:size]).compile()
    compile_s = time.perf_counter() - t0

    def one_pass():
        outs = [compiled(keys[i : i + size]) for i in range(0, keys.shape[0], size)]
        return np.concatenate([np.asarray(jax.block_until_ready(o)) for o in outs])

    t0 = time.perf_counter()
    out = one_pass()
    first_s = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        one_pass()
        times.append(time.perf_counter() - t0)
    return {"compile_s": compile_s, "first_pass_s": first_s, "run_s": statistics.median(times)}, out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--chunk", type=int, default=10000, help="runs per compiled call")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workloads", nargs="+", default=["kf", "ukf", "monitor"])
    parser.add_argument("--out", default="benchmarks/montecarlo_results.json")
    args = parser.parse_args(argv)
    device = jax.devices()[0]
    meta = {
        "command": " ".join(["python"] + sys.argv),
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "backend": jax.default_backend(),
        "device": getattr(device, "device_kind", str(device)),
        "cpu": bf.cpu_model(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "args": vars(args),
    }
    print(
        f"jax {jax.__version__} on {meta['backend']} ({meta['device']}); runs {args.runs}, chunk {args.chunk}",
        flush=True,
    )
    builders = {
        "kf": (kf_runners, 1000),
        "ukf": (ukf_runners, 600),
        "monitor": (monitor_runners, 400),
    }
    rows, ok = [], True
    for workload in args.workloads:
        build, T = builders[workload]
        impls, tol = build(T)
        for num_runs in args.runs:
            keys = jax.random.split(jax.random.key(0), num_runs)
            outs = {}
            for name, fn in impls.items():
                timing, out = time_chunks(fn, keys, args.chunk, args.repeats)
                outs[name] = out
                diff = (
                    0.0
                    if name in ("jaxfdi", "simulate_only")
                    else float(
                        np.max(
                            np.abs(out - outs["jaxfdi"])
                            / np.maximum(np.abs(outs["jaxfdi"]), 1e-300)
                        )
                    )
                )
                agree = diff <= tol
                ok &= agree
                row = {
                    "workload": workload,
                    "T": T,
                    "runs": num_runs,
                    "impl": name,
                    **timing,
                    "runs_per_s": num_runs / timing["run_s"],
                    "max_rel_diff_vs_jaxfdi": diff,
                    "agrees": agree,
                }
                rows.append(row)
                print(
                    f"  {workload:<8} N={num_runs:>8} {name:<14} compile {timing['compile_s']:6.2f} s  "
                    f"run {timing['run_s']:9.4f} s  {row['runs_per_s']:12.0f} runs/s  diff {diff:.1e}",
                    flush=True,
                )
    base = {(r["workload"], r["runs"]): r["run_s"] for r in rows if r["impl"] == "jaxfdi"}
    print(
        "\nworkload  runs      implementation  compile [s]   run [s]     runs/s   x jaxfdi  rel diff"
    )
    for r in rows:
        print(
            f"{r['workload']:<9} {r['runs']:<9} {r['impl']:<15} {r['compile_s']:11.2f} {r['run_s']:9.4f} "
            f"{r['runs_per_s']:10.0f} {r['run_s'] / base[(r['workload'], r['runs'])]:9.2f}  "
            f"{r['max_rel_diff_vs_jaxfdi']:.1e}"
        )
    print(
        "'x jaxfdi' = run time / jaxfdi run time (> 1: jaxfdi faster); simulate_only = the data generation alone"
    )
    tmp = args.out + ".tmp"
    with open(tmp, "w") as fh:
        json.dump({"meta": meta, "rows": rows, "all_agree": ok}, fh, indent=1)
    os.replace(tmp, args.out)
    print(f"all agree: {ok}; written {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "montecarlo_results.json")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
