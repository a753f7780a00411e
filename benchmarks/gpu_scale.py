"""The F-16 hybrid FDI at scale on one accelerator (issue 36 item 6): flights per second of
``run_fdi_flight`` through the study engine's chunked Monte Carlo (``f16_fdi._fly``, the
chunk the backend's default) at each ``--flights``, and, to find why one ``jit(vmap)`` of
all flights at once did not finish at 10^5 on an H200 (2026-11-26, 170 s limit), the same
flights as one batch: its compiled program's memory (``memory_analysis``) before it runs,
then its run. Each line is printed as it is measured, so a run stopped by its time limit
still says how far it got.

    python benchmarks/gpu_scale.py --flights 10000 100000 --single 30000 100000
    python benchmarks/gpu_scale.py --flights 64 128 --single 64 --chunk 64   # a CPU check
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_f16_fdi import fdi_flights, random_cases

from jaxfdi._studies.montecarlo import default_chunk_size
from jaxfdi.detection import FOLLOW
from jaxfdi.scenarios import f16_fdi as sf
from jaxfdi.scenarios.f16_flight import GUST_SIGMA, dispersions, flight_setup


def _flights(setup, n: int):
    keys = jax.random.split(jax.random.key(2), n)
    disp = dispersions(jax.random.key(3), setup, n)
    return keys, disp, random_cases(n, 2, setup.x0.dtype)


def chunked(setup, fdi, n: int, chunk: int | None) -> None:
    _, disp, cases = _flights(setup, n)
    per_run = (disp, cases, jnp.full((n,), FOLLOW["hybrid"], jnp.int32), jnp.zeros((n,), jnp.int32))
    start = time.perf_counter()
    out = sf._fly(setup, fdi, jax.random.key(4), per_run, None, chunk, False, "flights")
    wall = time.perf_counter() - start
    d = out.fdi
    isolated = int(np.sum(np.asarray(d.hybrid) == np.asarray(cases.sensor) + 1))
    print(
        f"chunked {n:>7} flights (chunk {chunk or default_chunk_size()}): {wall:.2f} s with compilation, "
        f"{n / wall:.0f} flights/s; healthy {int(np.sum(np.asarray(out.healthy)))}, hybrid isolated {isolated}, "
        f"UKF used {int(np.sum(np.asarray(d.filter_used)))}",
        flush=True,
    )


def single(setup, fdi, n: int) -> None:
    keys, disp, cases = _flights(setup, n)
    start = time.perf_counter()
    compiled = jax.jit(fdi_flights).lower(setup, fdi, keys, disp, cases).compile()
    compile_s = time.perf_counter() - start
    memory = compiled.memory_analysis()
    temp = getattr(memory, "temp_size_in_bytes", float("nan")) / 2**30
    stats = jax.devices()[0].memory_stats() or {}
    limit = stats.get("bytes_limit", float("nan")) / 2**30
    print(
        f"one batch {n:>7} flights: compiled in {compile_s:.1f} s; scratch {temp:.2f} GiB "
        f"({temp / n * 2**20:.1f} KiB per flight) of {limit:.1f} GiB on the device",
        flush=True,
    )
    for repeat in range(2):
        start = time.perf_counter()
        out = jax.block_until_ready(compiled(setup, fdi, keys, disp, cases))
        run_s = time.perf_counter() - start
        print(
            f"one batch {n:>7} flights: run {repeat + 1} {run_s:.2f} s, {n / run_s:.0f} flights/s; "
            f"UKF used {int(np.sum(np.asarray(out.fdi.filter_used)))}",
            flush=True,
        )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--flights", type=int, nargs="*", default=[10000, 100000])
    parser.add_argument("--single", type=int, nargs="*", default=[30000, 100000])
    parser.add_argument(
        "--chunk", type=int, default=None, help="runs per chunk (default: the backend's)"
    )
    args = parser.parse_args()
    print(
        f"jax {jax.__version__} on {jax.default_backend()}: {[d.device_kind for d in jax.devices()]}",
        flush=True,
    )
    setup, _ = flight_setup(gust_sigma=GUST_SIGMA)
    fdi, _ = sf.fdi_setup(setup)
    for n in args.flights:
        chunked(setup, fdi, n, args.chunk)
    for n in args.single:
        single(setup, fdi, n)
    return 0


if __name__ == "__main__":
    sys.exit(main())
