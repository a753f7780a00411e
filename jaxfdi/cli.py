"""Command line: ``jaxfdi run <scenario>``, ``jaxfdi tune <target>``, ``jaxfdi list``."""
from __future__ import annotations

import argparse
import sys
import time
from typing import Callable
from pathlib import Path

import numpy as np


def _confirm_steps(text: str):
    """``--confirm-steps``: ``"3"`` -> 3, ``"3,3,3,2,3,3,3"`` -> a tuple, one per mode."""
    values = tuple(int(v) for v in text.split(","))
    return values[0] if len(values) == 1 else values


def _as_lists(mapping: dict) -> dict:
    """A mapping of arrays (and scalars) as JSON-ready nested lists."""
    return {k: np.asarray(v).tolist() for k, v in mapping.items()}


def _write_study(study, json_path: Path, plot: Callable[[], list[str]], elapsed: float) -> int:
    """A scenario study's JSON (config, rows, seconds; written whole or not at all) and
    figures, and the line that names them."""
    from jaxfdi import _io

    _io.write_json(json_path, {"config": study.config, "rows": study.rows, "seconds": elapsed})
    paths = plot()
    print(f"wrote {json_path} and {', '.join(paths)} ({elapsed:.1f} s)")
    return 0


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


def split_methods(text: str, valid: list[str]) -> tuple[list[str], list[str]]:
    """``--methods a,b`` -> ``(chosen, unknown)``; a valid name may itself hold commas
    (``IMM-bias hand-pi confirm 3, P2 2``): the longest valid name at each position wins."""
    chosen, unknown, rest = [], [], text.strip()
    by_length = sorted(valid, key=len, reverse=True)
    while rest:
        name = next((v for v in by_length if rest == v or rest.startswith(v + ",")), None)
        if name is None:
            name = rest.split(",", 1)[0]
            if name.strip():
                unknown.append(name.strip())
        else:
            chosen.append(name)
        rest = rest[len(name):].lstrip(",").strip()
    return chosen, unknown


def _methods_option(args: argparse.Namespace) -> dict:
    """``{"methods": [...]}`` when the user gave ``--methods``, else ``{}`` (so a study
    without that keyword still runs)."""
    if args.methods is None:
        return {}
    return {"methods": [name.strip() for name in args.methods.split(",") if name.strip()]}


def _run_engine(args: argparse.Namespace) -> int:
    from jaxfdi.scenarios.engine import engine_methods, engine_study, plot_engine

    options = {}
    if args.methods is not None:
        valid = list(engine_methods())
        chosen, unknown = split_methods(args.methods, valid)
        if unknown or not chosen:
            print(f"jaxfdi: --methods: unknown {unknown or repr(args.methods)}; valid names (comma-separated): "
                  + "; ".join(valid), file=sys.stderr)
            return 2
        options["methods"] = chosen
    start = time.perf_counter()
    study = engine_study(runs=args.runs, seed=args.seed, figure_runs=min(args.runs, 20), progress=not args.quiet,
                         **options)
    elapsed = time.perf_counter() - start
    out = Path(args.out)
    print(f"engine: seed-003 turbojet, MM / IMM (two mode designs) / GLRT on the same {args.runs} runs per fault, "
          f"mu_T = {study.config['settings']['mu_threshold']}")
    print(study.overview())
    print()
    print("Per method and fault; 'paper' = seed 003 Table 3 median delay [s]; FA = share of runs with an alarm "
          "before the onset; estimate = median over correctly isolated runs")
    print(study.table())
    return _write_study(study, out / "engine.json", lambda: plot_engine(study, out), elapsed)


def _tune_engine_imm(args: argparse.Namespace) -> int:
    from jaxfdi import _io
    from jaxfdi.scenarios import engine_tuning as et
    from jaxfdi.tuning import constrain, save_params, unconstrain

    out = Path(args.out)
    test_seed = args.seed + 1000
    names = sorted(et.DESIGNS) if args.design == "all" else [args.design]
    report, paths = {}, []
    for name in names:
        start = time.perf_counter()
        design = et.imm_design(name)
        if not args.quiet:
            print(f"{name}: training", file=sys.stderr, flush=True)
        weights = et.LossWeights(detection=args.detection_weight, false_alarm=args.false_alarm_weight,
                                 delay=args.delay_weight, isolation=args.isolation_weight)
        frozen = tuple(name for name in args.freeze.split(",") if name)
        if set(frozen) - set(design.parameterization):
            print(f"jaxfdi: --freeze: design {name} has no parameter(s) {sorted(set(frozen) - set(design.parameterization))}; "
                  f"it has {sorted(design.parameterization)}", file=sys.stderr)
            return 2
        result = et.tune_engine_imm(design, steps=args.steps, train_runs=args.train_runs, seed=args.seed,
                                    weights=weights, progress=not args.quiet, confirm_steps=args.confirm_steps,
                                    frozen=frozen)
        tuned = constrain(design.parameterization, result.raw)
        selection = None
        if args.select_thresholds:
            if not args.quiet:
                print(f"{name}: selecting one mu_T per mode on {args.selection_runs} runs per fault "
                      f"(seed {args.seed + 2})", file=sys.stderr, flush=True)
            tuned["mu_threshold"], selection = et.select_mode_thresholds(
                design, tuned, args.selection_runs, args.seed + 2, args.confirm_steps)
            result = result._replace(raw=unconstrain(design.parameterization, tuned))
        hand_rows, hand_ce = et.evaluate_engine_imm(design, design.hand(), args.runs, test_seed)
        tuned_rows, tuned_ce = et.evaluate_engine_imm(design, tuned, args.runs, test_seed, args.confirm_steps)
        worse = et.worse_metrics(hand_rows, tuned_rows, hand_ce, tuned_ce)
        elapsed = time.perf_counter() - start
        print(f"tune engine-imm, design {name} ({design.method}): {args.steps} Adam steps on {args.train_runs} "
              f"runs per fault (seed {args.seed}, best step {result.history.best_step}); held-out test: "
              f"{args.runs} runs per fault (seed {test_seed}); loss weights {dict(weights._asdict())}; "
              f"tuned detector confirms over {args.confirm_steps} step(s), the paper's over 1; frozen "
              f"{list(frozen) or 'none'}")
        if selection is not None:
            print(f"mu_T per mode (normal, actuator, RPM, P2, T2, P4, T4) chosen on {args.selection_runs} runs per "
                  f"fault (seed {args.seed + 2}): {np.round(np.asarray(tuned['mu_threshold']), 2).tolist()}; "
                  f"shortfall against the paper's there {selection['shortfall']['trained']:.3f} -> "
                  f"{selection['shortfall']['selected']:.3f}")
        print(et.comparison_table(hand_rows, hand_ce, tuned_rows, tuned_ce))
        print(f"worse than the paper's: {', '.join(worse) if worse else 'none'}\n")
        paths.append(save_params(out / f"engine-imm-{name}-tuned.npz", result.raw, design.parameterization,
                                 {"best_step": result.history.best_step, "seed": args.seed, "design": name,
                                  "confirm_steps": args.confirm_steps}))
        report[name] = {
            "paper": hand_rows, "tuned": tuned_rows, "cross_entropy": {"paper": hand_ce, "tuned": tuned_ce},
            "worse": worse, "shortfall": et.shortfall(hand_rows, tuned_rows), "frozen": list(frozen),
            "threshold_selection": selection,
            "history": _as_lists(result.history._asdict()), "paper_params": _as_lists(design.hand()),
            "tuned_params": _as_lists(tuned), "seconds": elapsed}
    config = {"steps": args.steps, "train_runs": args.train_runs, "test_runs": args.runs, "seed": args.seed,
              "test_seed": test_seed, "weights": weights._asdict(), "confirm_steps": args.confirm_steps,
              "select_thresholds": args.select_thresholds, "selection_runs": args.selection_runs}
    _io.write_json(out / "engine-imm-tuning.json", {"config": config, "designs": report})
    print(f"wrote {', '.join(map(str, paths))} and {out / 'engine-imm-tuning.json'}")
    return 0


def _tune_engine_chi2(args: argparse.Namespace) -> int:
    from jaxfdi import _io
    from jaxfdi.scenarios import engine_chi2_tuning as ct
    from jaxfdi.tuning import constrain, save_params

    start = time.perf_counter()
    windows = tuple(int(w) for w in args.windows.split(","))
    weights = ct.Chi2Weights(false_alarm=args.false_alarm_weight, delay=args.delay_weight)
    tuning = ct.tune_engine_chi2(windows, steps=args.steps, train_runs=args.train_runs, seed=args.seed,
                                 weights=weights, progress=not args.quiet)
    tuned = constrain(ct.PARAMETERIZATION, tuning.result.raw)
    test_seed = args.seed + 1000
    hand_rows, hand_loss = ct.evaluate_engine_chi2(ct.hand_params(), ct.HAND_WINDOW, args.runs, test_seed, weights)
    tuned_rows, tuned_loss = ct.evaluate_engine_chi2(tuned, tuning.window, args.runs, test_seed, weights)
    elapsed = time.perf_counter() - start
    out = Path(args.out)
    print(f"tune engine-chi2: KF chi-square test, Q, R and threshold by {args.steps} Adam steps on "
          f"{args.train_runs} runs per fault (seed {args.seed}) for windows {list(windows)}; validation loss "
          + ", ".join(f"L={w}: {v:.4f}" for w, v in tuning.val_loss.items())
          + f"; held-out test: {args.runs} runs per fault (seed {test_seed})")
    print(ct.comparison_table(hand_rows, tuned_rows, ct.HAND_WINDOW, tuning.window, hand_loss, tuned_loss))
    path = save_params(out / "engine-chi2-tuned.npz", tuning.result.raw, ct.PARAMETERIZATION,
                       {"best_step": tuning.result.history.best_step, "seed": args.seed, "window": tuning.window})
    _io.write_json(out / "engine-chi2-tuning.json", {
        "config": {"steps": args.steps, "train_runs": args.train_runs, "test_runs": args.runs, "seed": args.seed,
                   "test_seed": test_seed, "windows": list(windows), "weights": weights._asdict()},
        "window": tuning.window, "val_loss": {str(w): v for w, v in tuning.val_loss.items()},
        "hand": hand_rows, "tuned": tuned_rows, "held_out_loss": {"hand": hand_loss, "tuned": tuned_loss},
        "history": _as_lists(tuning.result.history._asdict()), "hand_params": _as_lists(ct.hand_params()),
        "tuned_params": _as_lists(tuned), "seconds": elapsed})
    print(f"wrote {path} and {out / 'engine-chi2-tuning.json'} ({elapsed:.1f} s)")
    return 0


def _run_vtol(args: argparse.Namespace) -> int:
    from jaxfdi.scenarios.vtol import plot_vtol, vtol_design, vtol_examples, vtol_study

    start = time.perf_counter()
    design = vtol_design()
    study = vtol_study(runs=args.runs, seed=args.seed, design=design, progress=not args.quiet, **_methods_option(args))
    examples = vtol_examples(study.design, seed=args.seed)
    elapsed = time.perf_counter() - start
    cfg = study.config
    out = Path(args.out)
    print(f"vtol: seed-001 VTOL, bank of 12 robust TSKFs (multiplicative + additive per location), "
          f"{args.runs} closed-loop runs per fault with FTC off and on; statistic chi2({cfg['dof']}): "
          f"chi2 thresholds {cfg['chi2_threshold']:.2f} / window {cfg['chi2_window_threshold']:.2f}, paper's "
          f"{cfg['paper_threshold']} / {cfg['paper_window_threshold']}; MDWT M = {cfg['levels']}, c = {cfg['c_mult']}")
    print("'ours' thresholds: per filter, the larger of the chi2 one and the fault-free 99.5 % quantile, then "
          f"per method scaled so that at most {cfg['run_false_alarm']:.0%} of the fault-free runs show a symptom "
          f"({cfg['calibration_runs']} calibration runs, another seed):")
    for method, row in cfg["thresholds"].items():
        print(f"  {method:<8} " + " ".join(f"{name} {value:.1f}" for name, value in row.items()))
    print("Rates over runs; delays in steps (median); detection = some location's filters all alarm (the "
          "symptom vector leaves the no-fault column), isolation = it matches the true fault's column\n")
    print(study.table())
    print()
    print(study.headline())
    return _write_study(study, out / "vtol.json", lambda: plot_vtol(study, examples, study.design, out), elapsed)


def _run_reaction_wheels(args: argparse.Namespace) -> int:
    from jaxfdi.scenarios.reaction_wheels import plot_wheels, wheel_design, wheel_examples, wheel_study

    start = time.perf_counter()
    study = wheel_study(runs=args.runs, seed=args.seed, calibration_runs=max(20, 2 * args.runs),
                        estimator=args.estimator, engage_on=args.engage_on, progress=not args.quiet,
                        **_methods_option(args))
    design = wheel_design()._replace(detection_threshold=study.config["fdp_threshold"])
    examples = wheel_examples(design, seed=args.seed, estimator=args.estimator, engage_on=args.engage_on)
    elapsed = time.perf_counter() - start
    cfg = study.config
    out = Path(args.out)
    print(f"reaction-wheels: seed-004 KITSAT-3 with a 4-wheel pyramid, {cfg['slew_deg']:.0f} deg slew in 40 s, "
          f"60 s at 10 Hz, {args.runs} runs per case (noise and onset uniform in 15-25 s); estimation filter "
          f"{args.estimator.upper()}, banks engaged on the {'NIS test' if args.engage_on == 'nis' else 'dual filter F'}")
    print(f"thresholds: F_T = {cfg['fdp_threshold']:.3e} ({cfg['fdp_margin']} x the largest F of "
          f"{cfg['calibration_runs']} fault-free runs, another seed); NIS over {cfg['nis_window']} steps "
          f"{cfg['nis_threshold']:.2f} (chi2, Pfa 1e-5); relative credit {cfg['credit_threshold']}; "
          f"mu_T {cfg['mode_threshold']}; isolators confirm over {cfg['confirm_steps']} steps")
    print("rate = detected (F, NIS) or isolated to the right wheel (credit, MM); <=2s = the same within 2 s of "
          "the onset; delays over those runs; FA = share of runs with a decision before the onset\n")
    print(study.table())
    print()
    print(study.headline())
    return _write_study(study, out / "reaction-wheels.json", lambda: plot_wheels(study, examples, out), elapsed)


RUNNERS = {"engine": _run_engine, "engine-chi2": _run_engine_chi2, "reaction-wheels": _run_reaction_wheels,
           "vtol": _run_vtol}
TUNERS = {"engine-chi2": _tune_engine_chi2, "engine-imm": _tune_engine_imm}
#: one line per scenario and tuning target, for ``jaxfdi --help``
RUN_HELP = {
    "engine": "seed-003 turbojet: MM, IMM (two fault-mode designs) and windowed GLRT beside the paper's Table 3",
    "engine-chi2": "seed-003 turbojet: the Kalman-filter chi-square test (--window, --pfa)",
    "reaction-wheels": "seed-004 satellite, 4-wheel pyramid: dual filter F, NIS, credits, MM isolator "
                       "(--estimator, --engage-on)",
    "vtol": "seed-001 VTOL: robust two-stage KF bank, chi-square/MDWT tests, LQR-PI fault-tolerant control",
}
TUNE_HELP = {
    "engine-chi2": "Q, R and the threshold of the engine chi-square test by gradient, window by validation",
    "engine-imm": "the engine IMMs' transition matrix, mode noise and mu_T by gradient (--design)",
}


def _listing(title: str, entries: dict[str, str]) -> str:
    width = max(map(len, entries)) + 2
    return "\n".join([title, *(f"  {name:<{width}}{text}" for name, text in sorted(entries.items()))])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxfdi", description="Fault detection and isolation studies in JAX",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="\n\n".join([_listing("scenarios (jaxfdi run <scenario>):", RUN_HELP),
                             _listing("tuning targets (jaxfdi tune <target>):", TUNE_HELP),
                             "jaxfdi run -h / jaxfdi tune -h: the options"]))
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a paper scenario end to end", formatter_class=argparse.RawDescriptionHelpFormatter,
                         epilog=_listing("scenarios:", RUN_HELP))
    run.add_argument("scenario", choices=sorted(RUNNERS))
    run.add_argument("--methods", default=None,
                     help="run only these methods, comma-separated (engine, vtol, reaction-wheels; default all; "
                          "an unknown name lists the valid ones)")
    run.add_argument("--runs", type=int, default=100, help="Monte Carlo runs per fault (default 100)")
    run.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    run.add_argument("--out", default="results", help="output folder for JSON and PNG (default ./results)")
    run.add_argument("--window", type=int, default=4, help="engine-chi2: window length in steps (default 4)")
    run.add_argument("--pfa", type=float, default=0.005, help="engine-chi2: design false-alarm probability (default 0.005)")
    run.add_argument("--estimator", default="ekf", choices=["ekf", "ukf"],
                     help="reaction-wheels: the estimation filter (default ekf, the paper's)")
    run.add_argument("--engage-on", default="nis", choices=["nis", "fdp"],
                     help="reaction-wheels: the detector that engages the hypothesis banks (default nis; fdp = "
                          "the paper's F)")
    run.add_argument("--quiet", action="store_true", help="no progress display")
    tune = sub.add_parser("tune", help="tune a scenario's filter and detector by gradient, then compare on held-out runs",
                          formatter_class=argparse.RawDescriptionHelpFormatter,
                          epilog=_listing("tuning targets:", TUNE_HELP))
    tune.add_argument("target", choices=sorted(TUNERS))
    tune.add_argument("--steps", type=int, default=150, help="optimiser steps (default 150)")
    tune.add_argument("--train-runs", type=int, default=16, help="training runs per fault (default 16)")
    tune.add_argument("--runs", type=int, default=100, help="held-out test runs per fault (default 100)")
    tune.add_argument("--seed", type=int, default=0, help="training seed; validation seed+1, test seed+1000")
    tune.add_argument("--out", default="results", help="output folder (default ./results)")
    tune.add_argument("--design", default="all", choices=["all", "bias", "zhang-li"],
                      help="engine-imm: which IMM mode design (default all)")
    tune.add_argument("--detection-weight", type=float, default=1.0,
                      help="engine-imm: weight of the soft detection loss against the mode cross-entropy "
                           "(default 1; 0 trains on the cross-entropy alone)")
    tune.add_argument("--false-alarm-weight", type=float, default=5.0,
                      help="loss weight of P(alarm before the onset) (default 5)")
    tune.add_argument("--delay-weight", type=float, default=1.0,
                      help="loss weight of the expected delay / steps after the onset (default 1)")
    tune.add_argument("--confirm-steps", type=_confirm_steps, default=1,
                      help="engine-imm: the tuned detector alarms once the same fault mode has led at or above "
                           "mu_T for this many steps; trained for it (default 1, the paper's rule); or 7 "
                           "comma-separated lengths, one per mode (normal, actuator, RPM, P2, T2, P4, T4)")
    tune.add_argument("--freeze", default="",
                      help="engine-imm: parameters kept at their hand-set values, comma-separated "
                           "(e.g. mu_threshold)")
    tune.add_argument("--select-thresholds", action="store_true",
                      help="engine-imm: after training, choose one mu_T per fault mode on selection runs "
                           "(seed+2) so that no reported metric is worse than the paper's there")
    tune.add_argument("--selection-runs", type=int, default=100,
                      help="engine-imm: runs per fault for --select-thresholds (default 100)")
    tune.add_argument("--isolation-weight", type=float, default=5.0,
                      help="engine-imm: loss weight of P(first alarm names the wrong fault) (default 5)")
    tune.add_argument("--windows", default="1,2,4,8",
                      help="engine-chi2: window lengths to try, comma-separated (default 1,2,4,8)")
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
        if min(args.detection_weight, args.false_alarm_weight, args.delay_weight, args.isolation_weight) < 0:
            print("jaxfdi: the loss weights must be >= 0", file=sys.stderr)
            return 2
        if args.selection_runs < 1:
            print(f"jaxfdi: --selection-runs must be >= 1, got {args.selection_runs}", file=sys.stderr)
            return 2
        if min(np.atleast_1d(args.confirm_steps)) < 1 or np.size(args.confirm_steps) not in (1, 7):
            print(f"jaxfdi: --confirm-steps must be one integer >= 1 or 7 of them (one per mode), got "
                  f"{args.confirm_steps}", file=sys.stderr)
            return 2
        if not all(w.strip().isdigit() and int(w) >= 1 for w in args.windows.split(",")):
            print(f"jaxfdi: --windows must be positive integers separated by commas, got {args.windows!r}",
                  file=sys.stderr)
            return 2
        import jaxfdi

        jaxfdi.enable_x64()
        jaxfdi.enable_compilation_cache()
        return TUNERS[args.target](args)
    if not (0.0 < args.pfa < 1.0):
        print("jaxfdi: --pfa must lie in (0, 1)", file=sys.stderr)
        return 2
    if args.methods is not None and args.scenario == "engine-chi2":
        print("jaxfdi: --methods: engine-chi2 has one method (the KF chi-square test)", file=sys.stderr)
        return 2
    import jaxfdi

    jaxfdi.enable_x64()
    jaxfdi.enable_compilation_cache()
    return RUNNERS[args.scenario](args)


if __name__ == "__main__":
    sys.exit(main())
