"""Issue 38's F-16 question at scale: every fault kind at the paper's size (bias and drift
at FNR 10, scale 0.5, stuck, dead), ``--runs`` full flights each under no FDI, the
paper's hybrid rule and the verified rule (``scenarios.f16_fdi.fault_kind_study``), with
misisolations and envelope exits and their 99 % intervals; the table, the wall time and
the flights per second, and the rows as JSON.

    python benchmarks/f16_fault_kinds.py --runs 1000 --out benchmarks/results_f16_fault_kinds.json        # CPU
    python3 benchmarks/f16_fault_kinds.py --runs 10000 --chunk 0 --out $OUT/results_f16_fault_kinds_gpu.json  # GPU
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

from jaxfdi import _io
from jaxfdi.scenarios.f16_fdi import KIND_FOLLOWS, KIND_SIZES, fault_kind_study


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument(
        "--chunk", type=int, default=1024, help="flights per call; 0: the backend's default"
    )
    parser.add_argument("--out", default="benchmarks/results_f16_fault_kinds.json")
    args = parser.parse_args()
    device = jax.devices()[0]
    print(
        f"jax {jax.__version__} on {device.platform} ({device.device_kind}); {args.runs} flights per kind and view, "
        f"seed {args.seed}",
        flush=True,
    )
    start = time.perf_counter()
    study = fault_kind_study(
        runs=args.runs, seed=args.seed, progress=True, chunk_size=args.chunk or None
    )
    wall = time.perf_counter() - start
    flights = args.runs * (len(KIND_SIZES) * len(KIND_FOLLOWS) + 1)
    print(study.table())
    print(
        f"{flights} flights of 15 s in {wall:.1f} s with compilation: {flights / wall:.0f} flights/s",
        flush=True,
    )
    _io.write_json(
        args.out,
        {
            "config": study.config,
            "rows": study.rows,
            "seconds": wall,
            "flights": flights,
            "device": f"{device.platform} ({device.device_kind})",
            "jax": jax.__version__,
            "command": f"python benchmarks/f16_fault_kinds.py --runs {args.runs} --seed {args.seed} "
            f"--chunk {args.chunk}",
        },
    )


if __name__ == "__main__":
    main()
