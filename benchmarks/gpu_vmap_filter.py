"""On a GPU: does the path users write, ``jax.vmap(run_filter)`` over Monte Carlo runs,
still pay there? On CPU its batching rule runs the linear KF's structure-of-arrays kernel
(3.3x a vmapped plain scan, 100 runs, ``benchmarks/RESULTS.md``); this compares, on
whatever backend JAX has, for the engine KF (T = 1000, a prior P0 per run):

- ``vmap(run_filter)``: the path users write (the batching rule -> the batch kernel);
- ``run_filter(ys (N, T, m))``: the batch call (the same kernel);
- ``vmap(scan of kf.step)``: what ``vmap`` would do without the rule;
- one sequence: ``jit(run_filter)`` against a plain ``lax.scan`` of ``kf.step``.

Compile and run apart (median of the repeats after one warm call), float64; prints one
line per measurement and writes ``--out`` (JSON, atomically).

    python benchmarks/gpu_vmap_filter.py --runs 100 10000 100000 --out $OUT/gpu_vmap_filter.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxfdi
from jaxfdi.models import engine_model

T = 1000


def _problem(num_runs: int):
    model = engine_model()
    us = jnp.asarray((0.01 + 0.002 * np.sin(2 * np.pi * np.arange(T) / 250.0)).reshape(T, 1))
    sim = jaxfdi.linear_simulator(model)
    keys = jax.random.split(jax.random.key(0), num_runs)
    ys = jax.jit(jax.vmap(lambda key: jaxfdi.simulate(sim, jnp.zeros(7), us, key)[1].measurement))(
        keys
    )
    scales = jnp.linspace(5.0, 20.0, num_runs)[:, None, None]
    return model, us, ys, jnp.zeros((num_runs, 7)), scales * model.Q


def _timed(fn, args, repeats: int) -> dict:
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(*args))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        times.append(time.perf_counter() - start)
    return dict(compile_s=compile_s, run_ms=1e3 * statistics.median(times))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, nargs="+", default=[100, 10000])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default="benchmarks/results_gpu_vmap_filter.json")
    args = parser.parse_args()
    jaxfdi.enable_x64()
    device = str(jax.devices()[0])
    print("backend", jax.default_backend(), device, "jax", jax.__version__, flush=True)
    rows = []
    model = engine_model()
    kf = jaxfdi.filters.kalman_filter(model)

    def outputs(info):
        return info.filtered_mean, info.filtered_cov, jnp.sum(info.log_likelihood, axis=-1)

    def users_path(m0, P0, ys, us):
        return outputs(
            jax.vmap(
                lambda m, P, y: jaxfdi.filters.run_filter(
                    kf, jaxfdi.filters.GaussianState(m, P), y, us
                )[1]
            )(m0, P0, ys)
        )

    def batch_call(m0, P0, ys, us):
        return outputs(
            jaxfdi.filters.run_filter(kf, jaxfdi.filters.GaussianState(m0, P0), ys, us)[1]
        )

    def plain_vmap(m0, P0, ys, us):
        def one(m, P, y):
            return jax.lax.scan(
                lambda s, yu: kf.step(s, *yu), jaxfdi.filters.GaussianState(m, P), (y, us)
            )[1]

        return outputs(jax.vmap(one)(m0, P0, ys))

    for num_runs in args.runs:
        _, us, ys, m0, P0 = _problem(num_runs)
        results = {}
        for name, fn in (
            ("vmap(run_filter)", users_path),
            ("run_filter(batch)", batch_call),
            ("vmap(plain scan)", plain_vmap),
        ):
            row = dict(runs=num_runs, path=name, **_timed(fn, (m0, P0, ys, us), args.repeats))
            results[name] = jax.jit(fn)(m0, P0, ys, us)
            rows.append(row)
            print(
                f"N={num_runs:>7} {name:<18} compile {row['compile_s']:6.2f} s  run {row['run_ms']:9.2f} ms",
                flush=True,
            )
        ref = results["vmap(plain scan)"]
        for name in ("vmap(run_filter)", "run_filter(batch)"):
            diff = max(
                float(jnp.max(jnp.abs(a - b) / (1e-12 + jnp.abs(b))))
                for a, b in zip(results[name], ref)
            )
            print(
                f"N={num_runs:>7} {name} vs vmap(plain scan): max relative difference {diff:.1e}",
                flush=True,
            )
    _, us, ys, m0, P0 = _problem(1)

    def one_sequence(y):
        return outputs(jaxfdi.filters.run_filter(kf, kf.init(m0[0], P0[0]), y, us)[1])

    def one_plain(y):
        return outputs(
            jax.lax.scan(lambda s, yu: kf.step(s, *yu), kf.init(m0[0], P0[0]), (y, us))[1]
        )

    for name, fn in (("jit(run_filter) 1 seq", one_sequence), ("plain scan 1 seq", one_plain)):
        row = dict(runs=1, path=name, **_timed(fn, (ys[0],), args.repeats))
        rows.append(row)
        print(
            f"N=      1 {name:<22} compile {row['compile_s']:6.2f} s  run {row['run_ms']:9.2f} ms",
            flush=True,
        )
    payload = dict(
        device=device, backend=jax.default_backend(), jax=jax.__version__, T=T, rows=rows
    )
    folder = os.path.dirname(os.path.abspath(args.out))
    with tempfile.NamedTemporaryFile("w", dir=folder, delete=False, suffix=".tmp") as handle:
        json.dump(payload, handle, indent=1)
    os.replace(handle.name, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
