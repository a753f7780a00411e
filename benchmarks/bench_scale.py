"""Where the parallel-in-time filter/smoother and the recursive GLRT win.

1. Associative-scan (parallel-in-time) KF and RTS smoother against the sequential ones
   on the engine model (7 states, 5 outputs), float64, for T = 10^3 .. 10^5 steps and
   batches of 1, 10 and 100 sequences (jit(vmap) over sequences; what fits in memory).
   Sequential KF: ``run_filter(kalman_filter)`` (one sequence eagerly: the library-call
   path; a batch: jit(vmap), the written-out path); parallel: ``parallel_kalman_filter``.
   Smoothers from the same filter outputs. Every pair is checked to agree first.
2. The windowed GLRT (O(N^2) per step) against the recursive one (O(N)) on 100 runs x
   1000 steps of engine innovations, for windows N = 5 .. 160: cost per step and run.
3. Monte Carlo throughput on 1 and 2 local processes (``jax.distributed``, one CPU
   device each; an engine KF + chi-square study), with the cost of the final gather
   timed alone and the records checked bit-identical (``--only mc``).
4. Start-up in CPU seconds: one-shot processes (jaxfdi cold, jaxfdi with a warm
   compilation cache, filterpy) and each KF driver's compilation (``--only startup``).

Compile time is reported apart from run time (median of repeats of the compiled
executable). Run:
  python benchmarks/bench_scale.py [--quick] [--only parallel|glrt|mc] [--out benchmarks/results_scale.json]
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
if (
    "--mc-worker" in sys.argv
):  # a process of --mc joins the others before any JAX work (bench_filters' import computes)
    from jaxfdi import distributed as _distributed

    _distributed.initialize(timeout_s=300)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_filters import cpu_model, rel_diff, repeat_timing, write_json_atomic

import jaxfdi
from jaxfdi import steady_state_kalman
from jaxfdi.detection import glrt_detector
from jaxfdi.filters import GaussianState, kalman_filter, rts_smoother, run_filter
from jaxfdi.models import engine_model


def block(tree):
    return jax.tree.map(
        lambda x: x.block_until_ready() if hasattr(x, "block_until_ready") else x, tree
    )


def timed(fn, args, repeats, budget):
    """AOT compile (timed apart), warm up, then the median of repeats."""
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    out = block(compiled(*args))
    timing = repeat_timing(lambda: block(compiled(*args)), repeats, budget)
    timing["compile_s"] = compile_s
    return timing, out


def engine_sequences(num: int, T: int, seed: int = 0):
    model = engine_model()
    us = jnp.full((T, 1), 0.01)
    sim = jaxfdi.linear_simulator(model)
    keys = jax.random.split(jax.random.key(seed), num)
    ys = jax.jit(jax.vmap(lambda k: jaxfdi.simulate(sim, jnp.zeros(7), us, k)[1].measurement))(keys)
    return model, ys, us


def bench_parallel(cases, repeats, budget, log, eager=True, on_case=None) -> list[dict]:
    rows = []
    for batch, T in cases:
        model, ys, us = engine_sequences(batch, T)
        prior = GaussianState(jnp.zeros(7), 10.0 * model.Q)
        kf = jaxfdi.filters.kalman_filter(model)

        def sequential(ys):
            info = jax.vmap(lambda y: jaxfdi.filters.run_filter(kf, prior, y, us)[1])(ys)
            smooth = jax.vmap(lambda i: rts_smoother(model, i))(info)
            return (
                info.filtered_mean,
                info.filtered_cov,
                info.log_likelihood,
                smooth.mean,
                smooth.cov,
            )

        def parallel(ys):
            info = jax.vmap(
                lambda y: run_filter(
                    kalman_filter(model, missing_measurements=True), prior, y, us, parallel=True
                )[1]
            )(ys)
            smooth = jax.vmap(lambda i: rts_smoother(model, i, parallel=True))(info)
            return (
                info.filtered_mean,
                info.filtered_cov,
                info.log_likelihood,
                smooth.mean,
                smooth.cov,
            )

        def sequential_filter(ys):
            info = jax.vmap(lambda y: jaxfdi.filters.run_filter(kf, prior, y, us)[1])(ys)
            return info.filtered_mean, info.filtered_cov, info.log_likelihood

        def parallel_filter(ys):
            info = jax.vmap(
                lambda y: run_filter(
                    kalman_filter(model, missing_measurements=True), prior, y, us, parallel=True
                )[1]
            )(ys)
            return info.filtered_mean, info.filtered_cov, info.log_likelihood

        results = {}
        for name, fn in (
            ("sequential KF", sequential_filter),
            ("parallel KF", parallel_filter),
            ("sequential KF+RTS", sequential),
            ("parallel KF+RTS", parallel),
        ):
            timing, out = timed(fn, (ys,), repeats, budget)
            results[name] = out
            rows.append({"batch": batch, "T": T, "impl": name, **timing})
            log(
                f"  batch {batch:4d} T {T:7d} {name:<18} compile {timing['compile_s']:6.2f} s  "
                f"run {timing['run_s'] * 1e3:10.1f} ms"
            )
        agree_filter = max(
            rel_diff(a, b) for a, b in zip(results["parallel KF"], results["sequential KF"])
        )
        agree_smooth = max(
            rel_diff(a, b) for a, b in zip(results["parallel KF+RTS"], results["sequential KF+RTS"])
        )
        rows[-1]["agreement"] = max(agree_filter, agree_smooth)
        log(
            f"  batch {batch:4d} T {T:7d} agreement (max rel diff, filter and smoother): "
            f"{agree_filter:.1e} {agree_smooth:.1e}"
        )
        if (
            batch == 1 and eager
        ):  # one sequence eagerly: the library-call driver, as a one-shot script runs it
            timing = repeat_timing(
                lambda: block(jaxfdi.filters.run_filter(kf, prior, ys[0], us)), repeats, budget
            )
            rows.append(
                {
                    "batch": 1,
                    "T": T,
                    "impl": "sequential KF eager run_filter",
                    **timing,
                    "compile_s": float("nan"),
                }
            )
            log(
                f"  batch    1 T {T:7d} {'eager run_filter':<18} run {timing['run_s'] * 1e3:10.1f} ms"
            )
        if on_case is not None:
            on_case(rows)
    return rows


def bench_glrt(windows, runs, T, repeats, budget, log) -> list[dict]:
    model = engine_model()
    steady = steady_state_kalman(model)
    rng = np.random.default_rng(0)
    chol = np.linalg.cholesky(np.asarray(steady.innovation_cov))
    innovations = jnp.asarray(rng.standard_normal((runs, T, 5)) @ chol.T)
    rows = []
    for N in windows:
        outs = {}
        for name, recursive in (("windowed", False), ("recursive", True)):
            det = glrt_detector(
                model, steady.gain, steady.innovation_cov, N, 50.0, recursive=recursive
            )
            fn = jax.vmap(lambda e, det=det: jax.lax.scan(det.step, det.init(), e)[1])
            timing, out = timed(fn, (innovations,), repeats, budget)
            outs[name] = out
            per_step_us = timing["run_s"] / (runs * T) * 1e6
            rows.append({"window": N, "impl": name, "per_step_and_run_us": per_step_us, **timing})
            log(
                f"  GLRT N {N:4d} {name:<9} compile {timing['compile_s']:6.2f} s  run {timing['run_s'] * 1e3:9.1f} ms  "
                f"{per_step_us:7.3f} us/step/run"
            )
        agree = rel_diff(outs["recursive"].statistic, outs["windowed"].statistic)
        same = bool(np.array_equal(outs["recursive"].label, outs["windowed"].label))
        rows[-1].update(agreement=agree, same_labels=same)
        log(f"  GLRT N {N:4d} statistic agreement {agree:.1e}, labels equal: {same}")
    return rows


# ------------------------------------------------------------ Monte Carlo over processes
def _mc_study(T: int):
    """The engine (7 states, 5 sensors), KF + 4-step chi-square test, a P4 bias of a
    per-run size from step T/2 on odd runs (even runs fault-free); returns run_one."""
    from jaxfdi.models import engine_model as make_engine

    model = make_engine()
    us = jnp.full((T, 1), 0.01)
    onset_step = T // 2
    threshold = jaxfdi.detection.chi2_threshold(4 * 5, 1e-3)

    def run_one(key, size):
        onset = jnp.where(size > 0, onset_step, jaxfdi._simulation.faults.NEVER)
        sim = jaxfdi.linear_simulator(model, jaxfdi.fault("bias", "sensor", 3, onset, size))
        kf = jaxfdi.filters.kalman_filter(model)
        detector = jaxfdi.detection.chi2_detector(threshold, 4)
        return jaxfdi.monitor(
            sim, kf, detector, jnp.zeros(7), kf.init(jnp.zeros(7), model.Q * 10.0), us, key, onset
        ).record

    return run_one


def mc_worker(out: str, runs: int, T: int, per_device: int) -> None:
    """One process of ``--mc``: join the others, time the study (first call with
    compilation, then warm), the gather of its records alone, and its streaming summary."""
    from jaxfdi import distributed, streaming
    from jaxfdi._studies import montecarlo

    info = distributed.ProcessInfo(
        jax.process_index(), jax.process_count(), jax.local_device_count(), jax.device_count()
    )  # joined at import (top of this file)
    run_one = _mc_study(T)
    sizes = np.where(np.arange(runs) % 2 == 0, 0.0, np.linspace(2.0, 10.0, runs))
    chunk = per_device * info.global_devices
    key = jax.random.key(11)
    t0 = time.perf_counter()
    records = jaxfdi.monte_carlo(run_one, key, runs, sizes, chunk_size=chunk)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    records = jaxfdi.monte_carlo(run_one, key, runs, sizes, chunk_size=chunk)
    warm = time.perf_counter() - t0
    t0 = time.perf_counter()
    counts = jaxfdi.monte_carlo(
        run_one,
        key,
        runs,
        sizes,
        chunk_size=chunk,
        reduce=streaming.detection_reducer(T, bin_width=5),
    )
    reduce_s = time.perf_counter() - t0
    gather_s = 0.0
    if (
        info.num_processes > 1
    ):  # the same all-gather monte_carlo ends with, of this process's rows alone
        rows = chunk // info.num_processes
        local = [
            jax.tree.map(lambda a: np.asarray(a)[:rows], records) for _ in range(-(-runs // chunk))
        ]
        t0 = time.perf_counter()
        montecarlo._gather_runs(local, runs)
        gather_s = time.perf_counter() - t0
    digest = (
        __import__("hashlib")
        .sha256(b"".join(np.ascontiguousarray(np.asarray(v)).tobytes() for v in records))
        .hexdigest()
    )
    row = {
        "process_id": info.process_id,
        "processes": info.num_processes,
        "runs": runs,
        "T": T,
        "chunk": chunk,
        "first_s": first,
        "warm_s": warm,
        "reduce_s": reduce_s,
        "gather_s": gather_s,
        "records_sha256": digest,
        "detected_runs": int(counts.detected_runs),
        "false_alarm_runs": int(counts.false_alarm_runs),
    }
    write_json_atomic(f"{out}{info.process_id}.json", row)


def bench_multiprocess(process_counts, runs, T, per_device, log) -> list[dict]:
    """The study on 1 and 2 local processes (``jaxfdi.distributed.launch_local``), one
    CPU device each; the records' digests must agree."""
    import json
    import tempfile

    from jaxfdi import distributed

    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for count in process_counts:
            prefix = os.path.join(folder, f"p{count}_")
            command = [
                sys.executable,
                os.path.abspath(__file__),
                "--mc-worker",
                prefix,
                "--mc-runs",
                str(runs),
                "--mc-steps",
                str(T),
                "--mc-per-device",
                str(per_device),
            ]
            t0 = time.perf_counter()
            distributed.launch_local(command, count, timeout_s=1800)
            wall = time.perf_counter() - t0
            got = [json.load(open(f"{prefix}{rank}.json")) for rank in range(count)]
            warm = max(r["warm_s"] for r in got)
            row = {
                "processes": count,
                "runs": runs,
                "T": T,
                "runs_per_device_per_chunk": per_device,
                "launch_wall_s": wall,
                "first_call_s": max(r["first_s"] for r in got),
                "warm_s": warm,
                "runs_per_s": runs / warm,
                "reduce_s": max(r["reduce_s"] for r in got),
                "gather_s": max(r["gather_s"] for r in got),
                "records_sha256": got[0]["records_sha256"],
                "all_processes_same": len({r["records_sha256"] for r in got}) == 1,
                "detected_runs": got[0]["detected_runs"],
                "false_alarm_runs": got[0]["false_alarm_runs"],
            }
            rows.append(row)
            log(
                f"  {count} process(es): first call {row['first_call_s']:.2f} s, warm {warm:.2f} s "
                f"({row['runs_per_s']:.0f} runs/s), streaming {row['reduce_s']:.2f} s, gather {row['gather_s']:.3f} s, "
                f"records {row['records_sha256'][:12]}"
            )
    same = len({r["records_sha256"] for r in rows}) == 1 and all(
        r["all_processes_same"] for r in rows
    )
    for r in rows:
        r["bit_identical_to_one_process"] = same
    log(f"  records bit-identical across process counts: {same}")
    return rows


def format_multiprocess(rows) -> str:
    lines = [
        "Monte Carlo over local processes (engine KF + chi-square monitor; one CPU device per process)",
        f"{'processes':>9} {'runs':>6} {'T':>5} {'first call [s]':>14} {'warm [s]':>9} {'runs/s':>8} "
        f"{'streaming [s]':>13} {'gather [s]':>10} {'bit-identical':>13}",
    ]
    for r in rows:
        lines.append(
            f"{r['processes']:9d} {r['runs']:6d} {r['T']:5d} {r['first_call_s']:14.2f} {r['warm_s']:9.2f} "
            f"{r['runs_per_s']:8.0f} {r['reduce_s']:13.2f} {r['gather_s']:10.3f} "
            f"{str(r['bit_identical_to_one_process']):>13}"
        )
    return "\n".join(lines)


# ------------------------------------------------------------------------ start-up (CPU time)
def bench_startup(repeats: int, log) -> dict:
    """The one-shot processes of ``bench_filters.py`` (import, build the engine KF, filter
    one 1000-step sequence; filterpy the same) and each KF driver's compilation, timed in
    CPU seconds (user + system, the process and its threads): on a machine shared with
    other jobs the wall clock measures the others too."""
    import resource
    import statistics
    import subprocess
    import tempfile

    from bench_filters import _ONESHOT_FILTERPY, _ONESHOT_JAXFDI, engine_problem

    def cpu_of(script, *argv):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-c", script, *argv], check=True, capture_output=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)

    prob = engine_problem(2)
    rows = {"filterpy": [], "jaxfdi_cold": [], "jaxfdi_cache_warm": []}
    with tempfile.TemporaryDirectory(prefix="jaxfdi_startup_") as tmp:
        data = os.path.join(tmp, "engine.npz")
        np.savez(
            data,
            ys=np.asarray(prob["ys"][0]),
            us=np.asarray(prob["us"]),
            m0=np.asarray(prob["m0"]),
            P0=np.asarray(prob["P0"]),
            **{k: np.asarray(v) for k, v in prob["model"]._asdict().items()},
        )
        for i in range(repeats):
            cache = os.path.join(tmp, f"cache{i}")
            os.makedirs(cache)
            rows["filterpy"].append(cpu_of(_ONESHOT_FILTERPY, data))
            rows["jaxfdi_cold"].append(cpu_of(_ONESHOT_JAXFDI, data, "-"))
            cpu_of(_ONESHOT_JAXFDI, data, cache)  # fills the cache
            rows["jaxfdi_cache_warm"].append(cpu_of(_ONESHOT_JAXFDI, data, cache))
            log(
                f"  one-shot CPU s, repeat {i + 1}: "
                + ", ".join(f"{k} {v[-1]:.2f}" for k, v in rows.items())
            )
    out = {k: statistics.median(v) for k, v in rows.items()}
    out["ratio_warm_over_filterpy"] = out["jaxfdi_cache_warm"] / out["filterpy"]
    # compile CPU time of the drivers, in this process (caches cleared before each)
    from jaxfdi._numerics import linalg as _linalg
    from jaxfdi.filters._driver import _scan_filter

    model, m0, P0, ys, us = prob["model"], prob["m0"], prob["P0"], prob["ys"], prob["us"]
    kf = jaxfdi.filters.kalman_filter(model)
    P0s = jnp.broadcast_to(P0, (2,) + P0.shape) * 1.5
    drivers = {
        "run_filter eager (one sequence, full info)": lambda: _scan_filter.lower(
            kf, kf.init(m0, P0), ys[0], us
        ),
        "run_filter P0 per run (batch kernel)": lambda: jax.jit(
            lambda p: jaxfdi.filters.run_filter(kf, jaxfdi.filters.GaussianState(m0, p), ys, us)
        ).lower(P0s),
        "run_filter, Q per run (batch kernel)": lambda: jax.jit(
            lambda q: jaxfdi.filters.run_filter(
                jaxfdi.filters.kalman_filter(model._replace(Q=q)),
                jaxfdi.filters.GaussianState(m0, P0),
                ys,
                us,
            )
        ).lower(P0s),
        "jit(vmap(run_filter)) (written-out algebra)": lambda: jax.jit(
            jax.vmap(lambda y: jaxfdi.filters.run_filter(kf, kf.init(m0, P0), y, us))
        ).lower(ys),
    }
    out["driver_compile_cpu_s"] = {}
    for name, lower in drivers.items():
        jax.clear_caches()
        t0 = time.process_time()
        if name.startswith("run_filter eager"):
            with _linalg.library_calls():
                lowered = lower()
        else:
            lowered = lower()
        lowered.compile()
        out["driver_compile_cpu_s"][name] = time.process_time() - t0
        log(f"  compile {name:<46} {out['driver_compile_cpu_s'][name]:6.2f} CPU s")
    return out


def format_startup(res) -> str:
    lines = [
        "Start-up, CPU seconds (user + system), median of repeats",
        f"  one-shot filterpy {res['filterpy']:.2f}, jaxfdi cold {res['jaxfdi_cold']:.2f}, "
        f"jaxfdi cache warm {res['jaxfdi_cache_warm']:.2f} (warm / filterpy {res['ratio_warm_over_filterpy']:.2f}; "
        f"target <= 1)",
    ]
    for name, sec in res["driver_compile_cpu_s"].items():
        lines.append(f"  compile {name:<46} {sec:6.2f} CPU s (target <= 0.5)")
    return "\n".join(lines)


def format_parallel(rows) -> str:
    lines = [
        "Parallel-in-time (associative scan) vs sequential KF and KF+RTS, engine, float64",
        f"{'batch':>5} {'T':>7} {'implementation':<32} {'compile [s]':>11} {'run [ms]':>10} "
        f"{'per step x seq [us]':>20}",
    ]
    for r in rows:
        lines.append(
            f"{r['batch']:5d} {r['T']:7d} {r['impl']:<32} {r['compile_s']:11.2f} {r['run_s'] * 1e3:10.1f} "
            f"{r['run_s'] / (r['batch'] * r['T']) * 1e6:20.3f}"
        )
    lines.append("ratio parallel / sequential run time (> 1: sequential wins):")
    by = {}
    for r in rows:
        by[(r["batch"], r["T"], r["impl"])] = r["run_s"]
    for (batch, T, impl), run in by.items():
        if impl.startswith("parallel"):
            seq = by[(batch, T, impl.replace("parallel", "sequential"))]
            lines.append(f"  batch {batch:4d} T {T:7d} {impl:<16} {run / seq:6.2f}")
    return "\n".join(lines)


def format_glrt(rows) -> str:
    lines = [
        "GLRT cost per step and run vs window N (100 runs x 1000 steps, 6 directions, 5 outputs)",
        f"{'N':>5} {'windowed [us]':>14} {'recursive [us]':>15} {'windowed/recursive':>19} {'agreement':>10}",
    ]
    by = {}
    for r in rows:
        by.setdefault(r["window"], {})[r["impl"]] = r
    for N, r in by.items():
        w, rec = r["windowed"]["per_step_and_run_us"], r["recursive"]["per_step_and_run_us"]
        lines.append(
            f"{N:5d} {w:14.3f} {rec:15.3f} {w / rec:19.2f} {r['recursive'].get('agreement', float('nan')):10.1e}"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller cases, a smoke test")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument(
        "--budget", type=float, default=20.0, help="seconds after which a timing stops repeating"
    )
    parser.add_argument("--out", default="benchmarks/results_scale.json")
    parser.add_argument(
        "--only",
        choices=["parallel", "glrt", "mc", "startup"],
        action="append",
        help="run only these sections (repeatable; default all)",
    )
    parser.add_argument(
        "--cases",
        default=None,
        help="--parallel: BATCHxT cases, comma-separated (e.g. 1x1000,1x100000,100x10000)",
    )
    parser.add_argument(
        "--skip-eager", action="store_true", help="--parallel: no eager run_filter row"
    )
    parser.add_argument("--mc-runs", type=int, default=2000, help="--mc: runs of the study")
    parser.add_argument("--mc-steps", type=int, default=200, help="--mc: steps per run")
    parser.add_argument(
        "--mc-per-device", type=int, default=500, help="--mc: runs per device per chunk"
    )
    parser.add_argument("--mc-worker", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.mc_worker:
        mc_worker(args.mc_worker, args.mc_runs, args.mc_steps, args.mc_per_device)
        return 0
    sections = set(args.only or ["parallel", "glrt", "mc", "startup"])
    repeats = args.repeats or (2 if args.quick else 5)
    if args.quick:
        cases, windows = [(1, 1000), (1, 10_000), (10, 1000)], [5, 20, 80]
    else:
        cases = [(1, 1000), (1, 10_000), (1, 100_000), (10, 1000), (10, 10_000), (100, 1000)]
        windows = [5, 10, 20, 40, 80, 160]
    if args.cases:
        cases = [tuple(int(v) for v in case.split("x")) for case in args.cases.split(",")]

    def log(msg):
        print(msg, flush=True)

    meta = {
        "command": " ".join([os.path.basename(sys.executable)] + sys.argv),
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "jax_backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "python": platform.python_version(),
        "jax": jax.__version__,
    }
    log(
        f"jax {jax.__version__} on {jax.default_backend()} ({meta['cpu']}, {meta['cpu_count']} cores)"
    )
    started = time.perf_counter()
    payload = {"meta": meta}
    if "parallel" in sections:
        log("[parallel-in-time KF and RTS smoother]")

        def save(
            rows,
        ):  # after each case, so that a stopped run keeps what it measured (each write complete)
            write_json_atomic(args.out, {**payload, "parallel": rows})

        payload["parallel"] = bench_parallel(
            cases, repeats, args.budget, log, eager=not args.skip_eager, on_case=save
        )
        write_json_atomic(args.out, payload)
    if "glrt" in sections:
        log("[GLRT: windowed vs recursive]")
        payload["glrt"] = bench_glrt(windows, 100, 1000, repeats, args.budget, log)
        write_json_atomic(args.out, payload)
    if "mc" in sections:
        log("[Monte Carlo over 1 and 2 local processes]")
        runs = 200 if args.quick else args.mc_runs
        payload["multiprocess"] = bench_multiprocess(
            [1, 2], runs, args.mc_steps, min(args.mc_per_device, runs // 2), log
        )
    if "startup" in sections:
        log("[start-up, CPU time]")
        payload["startup"] = bench_startup(1 if args.quick else 3, log)
    payload["elapsed_s"] = time.perf_counter() - started
    write_json_atomic(args.out, payload)
    for name, fmt in (
        ("parallel", format_parallel),
        ("glrt", format_glrt),
        ("multiprocess", format_multiprocess),
        ("startup", format_startup),
    ):
        if name in payload:
            print()
            print(fmt(payload[name]))
    print(f"\nelapsed {payload['elapsed_s']:.0f} s; written {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_scale.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
