"""Issue 38's engine question: each Table 3 method's mean delay against the fault's size
(sensor faults at k noise sigmas, the actuator's at multiples of the paper's 5 %), the size
at which our delay equals the paper's, and Table 3 at the spec's reading of "0.5 %" and at
the one the GLRT settles on (``scenarios.engine.fault_size_study``); the table and the rows
as JSON.

    python benchmarks/engine_fault_sizes.py --runs 100 --seed 4242
"""

from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

from jaxfdi import _io
from jaxfdi.scenarios.engine import fault_size_study


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=100)
    parser.add_argument("--seed", type=int, default=4242)
    parser.add_argument("--out", default="benchmarks/results_engine_fault_sizes.json")
    args = parser.parse_args()
    start = time.perf_counter()
    study = fault_size_study(runs=args.runs, seed=args.seed, progress=True)
    wall = time.perf_counter() - start
    print(study.table())
    print(f"{wall:.1f} s")
    _io.write_json(
        args.out,
        {
            "config": study.config,
            "rows": study.rows,
            "seconds": wall,
            "command": f"python benchmarks/engine_fault_sizes.py --runs {args.runs} --seed {args.seed}",
        },
    )


if __name__ == "__main__":
    main()
