"""The shared closed-loop scan (``jaxfdi._simulation.loop``, issue 21) against the loops it replaced.

Two workloads, each timed with the current tree and with a baseline commit (default
f54c9a7, the last commit with the private loops) in the same run:

  * ``engine-monitor``: the fused open-loop engine study's run (plant -> KF -> 4-step
    windowed chi-square -> detection record), ``jit(vmap(monitor))`` over N runs,
    T = 400, P2 bias at step 200 (``monitor`` is now the loop's feed-forward case);
  * ``engine-imm-monitor``: the same with the engine study's IMM (7 noise-inflation
    modes, mode-probability detector), whose health check is now live (item 4);
  * ``vtol-closed-loop``: seed 001's closed loop (TSKF bank, MDWT, reconfiguring PI),
    ``jit(vmap(run_closed_loop))`` over N runs, T = 300, a2 effectiveness loss, FTC on.

Each implementation runs in its own subprocess (``git worktree`` of the baseline on
``PYTHONPATH``), alternating old/new ``--rounds`` times; compile time (trace + lower +
XLA compile) apart from run time (median of ``--repeats`` calls). Both must give
identical records (checked: the baseline's and the new records are compared).

Run:  python benchmarks/bench_loop.py [--runs 1000] [--baseline f54c9a7] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def worker(workload: str, runs: int, repeats: int, out: str) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import jaxfdi

    keys = jax.random.split(jax.random.key(0), runs)
    if workload == "engine-monitor":
        from jaxfdi.models import engine_model

        model = engine_model()
        kf = jaxfdi.filters.kalman_filter(model)
        detector = jaxfdi.detection.chi2_detector(jaxfdi.detection.chi2_threshold(4 * 5, 0.005), 4)
        f = jaxfdi.fault("bias", "sensor", 1, 200, 16.99)
        us = jnp.full((400, 1), 0.01)

        def one(key):
            return jaxfdi.monitor(
                jaxfdi.linear_simulator(model, f),
                kf,
                detector,
                jnp.zeros(7),
                kf.init(jnp.zeros(7), model.Q),
                us,
                key,
                200,
            ).record
    elif workload == "engine-imm-monitor":
        from jaxfdi.models import engine_model
        from jaxfdi.scenarios.engine import engine_methods, run_monitor

        model = engine_model()
        method = engine_methods()["IMM"]
        f = jaxfdi.fault("bias", "sensor", 1, 200, 16.99)
        us = jnp.full((400, 1), 0.01)

        def one(key):
            return run_monitor(method, model, us, key, f).record
    else:
        from jaxfdi.scenarios.vtol import vtol_design
        from jaxfdi.scenarios.vtol_loop import run_closed_loop

        design = vtol_design()
        f = jaxfdi.fault("effectiveness", "actuator", 1, 100, 0.5)

        def one(key):
            history = run_closed_loop(design, key, f, jnp.asarray(True), 300)
            return (history.state[-1], history.fdi.statistic[-1], history.fdi.isolated[-1])

    start = time.perf_counter()
    compiled = jax.jit(jax.vmap(one)).lower(keys).compile()
    compile_s = time.perf_counter() - start
    result = jax.block_until_ready(compiled(keys))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(compiled(keys))
        times.append(time.perf_counter() - start)
    leaves = [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(result)]
    with open(out, "w") as fh:
        json.dump(
            {
                "compile_s": compile_s,
                "run_s": statistics.median(times),
                "result": [leaf.tolist() for leaf in leaves[:8]],
            },
            fh,
        )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--baseline", default="f54c9a7")
    parser.add_argument("--out", default=os.path.join(HERE, "results_loop.json"))
    parser.add_argument(
        "--worker", nargs=3, metavar=("WORKLOAD", "RUNS", "OUT"), help=argparse.SUPPRESS
    )
    args = parser.parse_args()
    if args.worker:
        workload, runs, out = args.worker
        worker(workload, int(runs), args.repeats, out)
        return

    baseline_dir = tempfile.mkdtemp(prefix="jaxfdi-baseline-")
    subprocess.run(
        ["git", "-C", ROOT, "worktree", "add", "--detach", baseline_dir, args.baseline],
        check=True,
        capture_output=True,
    )
    try:
        report = {
            "runs": args.runs,
            "baseline": args.baseline,
            "repeats": args.repeats,
            "rounds": args.rounds,
            "workloads": {},
        }
        for workload in ("engine-monitor", "engine-imm-monitor", "vtol-closed-loop"):
            samples = {"old": [], "new": []}
            for _ in range(args.rounds):
                for which, path in (("old", baseline_dir), ("new", ROOT)):
                    out = os.path.join(baseline_dir, f"{workload}-{which}.json")
                    env = dict(os.environ, PYTHONPATH=path, JAX_ENABLE_X64="1")
                    subprocess.run(
                        [
                            sys.executable,
                            os.path.abspath(__file__),
                            "--repeats",
                            str(args.repeats),
                            "--worker",
                            workload,
                            str(args.runs),
                            out,
                        ],
                        check=True,
                        env=env,
                        cwd=path,
                    )
                    with open(out) as fh:
                        samples[which].append(json.load(fh))
                    print(
                        f"{workload:<17} {which}: compile {samples[which][-1]['compile_s']:.2f} s, "
                        f"run {1e3 * samples[which][-1]['run_s']:.1f} ms",
                        file=sys.stderr,
                    )
            same = all(
                s["result"] == samples["old"][0]["result"] for s in samples["old"] + samples["new"]
            )
            old_run = min(s["run_s"] for s in samples["old"])
            new_run = min(s["run_s"] for s in samples["new"])
            old_compile = min(s["compile_s"] for s in samples["old"])
            new_compile = min(s["compile_s"] for s in samples["new"])
            report["workloads"][workload] = {
                "old_run_ms": 1e3 * old_run,
                "new_run_ms": 1e3 * new_run,
                "run_ratio_old_over_new": old_run / new_run,
                "old_compile_s": old_compile,
                "new_compile_s": new_compile,
                "compile_ratio_old_over_new": old_compile / new_compile,
                "identical_results": same,
            }
            print(
                f"{workload:<17} run old/new = {old_run / new_run:.3f} ({1e3 * old_run:.1f} / {1e3 * new_run:.1f} ms), "
                f"compile old/new = {old_compile / new_compile:.3f} ({old_compile:.2f} / {new_compile:.2f} s), "
                f"identical results: {same}"
            )
        tmp = args.out + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(report, fh, indent=1)
        os.replace(tmp, args.out)
    finally:
        subprocess.run(
            ["git", "-C", ROOT, "worktree", "remove", "--force", baseline_dir], capture_output=True
        )
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_loop.json")


if __name__ == "__main__":
    main()
