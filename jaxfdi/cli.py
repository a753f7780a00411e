"""Command line: ``jaxfdi run <scenario>``, ``jaxfdi list``."""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def _enable_compilation_cache() -> None:
    """Persistent XLA cache so a repeated run skips most compilation."""
    import jax

    cache = os.environ.get("JAXFDI_CACHE_DIR", str(Path.home() / ".cache" / "jaxfdi" / "xla"))
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def _run_engine_chi2(args: argparse.Namespace) -> int:
    from jaxfdi import _io
    from jaxfdi.scenarios.engine_chi2 import engine_chi2_study, plot_engine_chi2

    start = time.perf_counter()
    result = engine_chi2_study(
        runs=args.runs, seed=args.seed, window=args.window, pfa=args.pfa, progress=not args.quiet,
    )
    elapsed = time.perf_counter() - start
    out = Path(args.out)
    print(f"engine-chi2: KF chi-square test on the seed-003 turbojet, {args.runs} runs per fault, "
          f"window {result.config['window']}, Pfa {result.config['pfa']}, threshold {result.config['threshold']:.2f}")
    print(result.table())
    _io.write_json(out / "engine-chi2.json", {"config": result.config, "rows": result.rows, "seconds": elapsed})
    _io.atomic_write(out / "engine-chi2.png", lambda tmp: plot_engine_chi2(result, tmp))
    print(f"wrote {out / 'engine-chi2.json'} and {out / 'engine-chi2.png'} ({elapsed:.1f} s)")
    return 0


def _run_engine(args: argparse.Namespace) -> int:
    from jaxfdi import _io
    from jaxfdi.scenarios.engine import engine_study, plot_engine

    start = time.perf_counter()
    study = engine_study(runs=args.runs, seed=args.seed, figure_runs=min(args.runs, 20), progress=not args.quiet)
    elapsed = time.perf_counter() - start
    out = Path(args.out)
    print(f"engine: seed-003 turbojet, MM / IMM (two mode designs) / GLRT on the same {args.runs} runs per fault, "
          f"mu_T = {study.config['settings']['mu_threshold']}")
    print(study.overview())
    print()
    print("Per method and fault; 'paper' = seed 003 Table 3 median delay [s]; FA = share of runs with an alarm "
          "before the onset; estimate = median over correctly isolated runs")
    print(study.table())
    _io.write_json(out / "engine.json", {"config": study.config, "rows": study.rows, "seconds": elapsed})
    paths = plot_engine(study, out)
    print(f"wrote {out / 'engine.json'} and {', '.join(paths)} ({elapsed:.1f} s)")
    return 0


def _tune_engine_imm(args: argparse.Namespace) -> int:
    from jaxfdi import _io
    from jaxfdi.scenarios import engine_tuning as et
    from jaxfdi.tuning import constrain, save_params

    start = time.perf_counter()
    result, parameterization = et.tune_engine_imm(
        steps=args.steps, train_runs=args.train_runs, seed=args.seed, progress=not args.quiet)
    tuned = constrain(parameterization, result.raw)
    test_seed = args.seed + 1000
    hand_rows, hand_ce = et.evaluate_engine_imm(et.hand_params(), args.runs, test_seed)
    tuned_rows, tuned_ce = et.evaluate_engine_imm(tuned, args.runs, test_seed)
    elapsed = time.perf_counter() - start
    out = Path(args.out)
    print(f"tune engine-imm: Zhang & Li IMM, {args.steps} Adam steps on {args.train_runs} runs per fault "
          f"(seed {args.seed}); held-out test: {args.runs} runs per fault (seed {test_seed})")
    print(et.comparison_table(hand_rows, hand_ce, tuned_rows, tuned_ce))
    params_path = save_params(out / "engine-imm-tuned.npz", result.raw, parameterization,
                              {"best_step": result.history.best_step, "seed": args.seed})
    _io.write_json(out / "engine-imm-tuning.json", {
        "paper": hand_rows, "tuned": tuned_rows, "cross_entropy": {"paper": hand_ce, "tuned": tuned_ce},
        "history": {k: v.tolist() if hasattr(v, "tolist") else v for k, v in result.history._asdict().items()},
        "tuned_params": {k: v.tolist() for k, v in tuned.items()}, "seconds": elapsed})
    print(f"wrote {params_path} and {out / 'engine-imm-tuning.json'} ({elapsed:.1f} s)")
    return 0


RUNNERS = {"engine": _run_engine, "engine-chi2": _run_engine_chi2}
TUNERS = {"engine-imm": _tune_engine_imm}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="jaxfdi", description="Fault detection and isolation studies in JAX")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a paper scenario end to end")
    run.add_argument("scenario", choices=sorted(RUNNERS))
    run.add_argument("--runs", type=int, default=100, help="Monte Carlo runs per fault (default 100)")
    run.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    run.add_argument("--out", default="results", help="output folder for JSON and PNG (default ./results)")
    run.add_argument("--window", type=int, default=4, help="engine-chi2: window length in steps (default 4)")
    run.add_argument("--pfa", type=float, default=0.005, help="engine-chi2: design false-alarm probability (default 0.005)")
    run.add_argument("--quiet", action="store_true", help="no progress display")
    tune = sub.add_parser("tune", help="tune a scenario's filter and detector by gradient, then compare on held-out runs")
    tune.add_argument("target", choices=sorted(TUNERS))
    tune.add_argument("--steps", type=int, default=150, help="optimiser steps (default 150)")
    tune.add_argument("--train-runs", type=int, default=16, help="training runs per fault (default 16)")
    tune.add_argument("--runs", type=int, default=100, help="held-out test runs per fault (default 100)")
    tune.add_argument("--seed", type=int, default=0, help="training seed; validation seed+1, test seed+1000")
    tune.add_argument("--out", default="results", help="output folder (default ./results)")
    tune.add_argument("--quiet", action="store_true", help="no progress display")
    sub.add_parser("list", help="list the scenarios")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "list":
        print("\n".join([*sorted(RUNNERS), *(f"tune {name}" for name in sorted(TUNERS))]))
        return 0
    if args.runs < 1:
        print("jaxfdi: --runs must be a positive integer", file=sys.stderr)
        return 2
    if args.command == "tune":
        if args.steps < 0 or args.train_runs < 1:
            print("jaxfdi: --steps must be >= 0 and --train-runs >= 1", file=sys.stderr)
            return 2
        import jax

        jax.config.update("jax_enable_x64", True)
        _enable_compilation_cache()
        return TUNERS[args.target](args)
    if not (0.0 < args.pfa < 1.0):
        print("jaxfdi: --pfa must lie in (0, 1)", file=sys.stderr)
        return 2
    import jax

    jax.config.update("jax_enable_x64", True)
    _enable_compilation_cache()
    return RUNNERS[args.scenario](args)


if __name__ == "__main__":
    sys.exit(main())
