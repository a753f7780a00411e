"""Command line: ``jaxfdi run <scenario>``, ``jaxfdi tune <target>``, ``jaxfdi list``.

Options are checked before anything is computed (``check_options``, then method or parameter names); a bad one: exit
status 2, one stderr line ``jaxfdi: --option: expected ..., got ...``. Files go to a temporary folder inside ``--out``,
published together when done (``jaxfdi._io.files.study_output``); SIGINT, SIGTERM, SIGHUP leave ``--out`` as it
was. A new scenario is a ``Runner`` in ``RUNNERS`` (tuning target: ``TUNERS``): its study's module path, help and
options; the module is imported (``_study``) only when the command runs, so that ``jaxfdi --help``, ``jaxfdi run
--help`` and ``jaxfdi --version`` import no study and no JAX (``import jaxfdi`` imports its names on first use).
"""

from __future__ import annotations

import _thread
import argparse
import contextlib
import importlib
import linecache
import logging
import math
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Iterator, NamedTuple

import numpy as np

import jaxfdi
from jaxfdi import distributed
from jaxfdi._io import files as _io
from jaxfdi._io import progress

#: the CLI's messages (jaxfdi._io.progress.configure_logging sends them to stderr; --quiet drops INFO)
logger = logging.getLogger("jaxfdi")

#: the largest count an option takes (runs, steps, windows: JAX indexes them in int32)
MAX_COUNT = 2**31 - 1
#: the largest seed: ``jaxfdi.checks.MAX_SEED`` (see its comment), written here because ``checks`` imports JAX (a test
#: holds the two equal)
MAX_SEED = 2**32 - 1
#: integer options: dest -> (lowest, highest)
INTEGER_RANGES = {
    "runs": (1, MAX_COUNT),
    "seed": (0, MAX_SEED),
    "window": (1, MAX_COUNT),
    "steps": (1, MAX_COUNT),
    "train_runs": (1, MAX_COUNT),
    "selection_runs": (1, MAX_COUNT),
}
#: real options: dest -> (lowest, highest, lowest allowed, highest allowed); NaN and inf never
FLOAT_RANGES = {
    "pfa": (0.0, 1.0, False, False),
    "detection_weight": (0.0, math.inf, True, False),
    "false_alarm_weight": (0.0, math.inf, True, False),
    "delay_weight": (0.0, math.inf, True, False),
    "isolation_weight": (0.0, math.inf, True, False),
}
#: options only some scenarios read: dest -> default. The parser's default is None, so that an option given to a
#: scenario that does not read it is refused rather than ignored.
RUN_SPECIFIC = {"methods": None, "window": 4, "pfa": 0.005, "estimator": "ekf", "engage_on": "nis"}
TUNE_SPECIFIC = {
    "design": "all",
    "detection_weight": 1.0,
    "isolation_weight": 5.0,
    "confirm_steps": 1,
    "freeze": "",
    "select_thresholds": False,
    "selection_runs": 100,
    "windows": "1,2,4,8",
}
#: engine-imm's --confirm-steps: one length, or one per mode (normal, actuator, RPM, P2, T2, P4, T4)
NUM_ENGINE_MODES = 7


class Runner(NamedTuple):
    """A ``jaxfdi run`` scenario or ``jaxfdi tune`` target: what argparse and the checks need, and the path of the
    study's module, imported (``_study``) only when the command runs.

    - ``run(args, folder)``: computes, prints tables, writes files into ``folder`` (temporary, published into ``--out``
      when it returns); returns the line naming them under ``--out``.
    - ``options``: the scenario-specific options it reads (dest names of ``RUN_SPECIFIC``/``TUNE_SPECIFIC``; others
      refused); ``methods``: the name, in the study's module, of its valid ``--methods`` names (a sequence, or a
      function returning one; ``None``: no ``--methods``); ``check(args)``: further checks needing the study's module,
      raising ``UsageError`` (``expected``); ``module``: the study's module (``jaxfdi.scenarios.<study>``)."""

    run: Callable[[argparse.Namespace, Path], str]
    help: str
    options: tuple[str, ...] = ()
    methods: str | None = None
    check: Callable[[argparse.Namespace], None] | None = None
    module: str | None = None


class UsageError(Exception):
    """A bad option value, exit status 2; the message reads ``--option: expected ..., got ...``."""


def expected(option: str, what: str, got) -> UsageError:
    """``UsageError("<option>: expected <what>, got <got>")``."""
    return UsageError(f"{option}: expected {what}, got {got}")


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread like Ctrl-C, so that clean-up runs."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def _command(args: argparse.Namespace) -> tuple[str, str]:
    """``("run", <scenario>)`` or ``("tune", <target>)``: the command ``args`` names."""
    return ("run", args.scenario) if args.command == "run" else ("tune", args.target)


def _study(args: argparse.Namespace) -> ModuleType:
    """The module of the study that ``args``' command runs (its ``Runner.module`` in ``REGISTRY``), imported now: the
    CLI's one import inside a function (``tests/core/test_layering.py``), so that building the parser (``--help``,
    ``--version``) imports no study and no JAX."""
    kind, name = _command(args)
    return importlib.import_module(REGISTRY[kind][name].module)


def _confirm_steps(text: str):
    """``--confirm-steps``: ``"3"`` -> 3, ``"3,3,3,2,3,3,3"`` -> a tuple, one per mode."""
    values = tuple(int(v) for v in text.split(","))
    return values[0] if len(values) == 1 else values


def _as_lists(mapping: dict) -> dict:
    """A mapping of arrays (and scalars) as JSON-ready nested lists."""
    return {k: np.asarray(v).tolist() for k, v in mapping.items()}


def _named(args: argparse.Namespace, folder: Path, path) -> Path:
    """Where a file written into ``folder`` lands under ``--out``."""
    return Path(args.out) / Path(path).relative_to(folder)


def _write_study(
    study,
    args: argparse.Namespace,
    folder: Path,
    name: str,
    figures: dict[str, Any],
    elapsed: float,
) -> str:
    """Write a study's JSON (config, rows, seconds), its CSV table (``study.to_frame()``, with the rates' intervals) and
    its figures (file name -> captioned ``Figure``, what its ``plot_*`` returns); returns the line naming them."""

    _io.write_json(folder / name, {"config": study.config, "rows": study.rows, "seconds": elapsed})
    csv = Path(name).with_suffix(".csv")
    _io.atomic_write(folder / csv, lambda tmp: study.to_frame().to_csv(tmp, index=False))
    paths = [str(_named(args, folder, p)) for p in _io.save_figures(figures, folder)]
    written = [str(Path(args.out) / name), str(Path(args.out) / csv), *paths]
    return f"wrote {', '.join(written[:-1])} and {written[-1]} ({elapsed:.1f} s)"


def _run_engine_chi2(args: argparse.Namespace, folder: Path) -> str:
    engine_chi2 = _study(args)
    start = time.perf_counter()
    result = engine_chi2.engine_chi2_study(
        runs=args.runs, seed=args.seed, window=args.window, pfa=args.pfa, progress=not args.quiet
    )
    elapsed = time.perf_counter() - start
    print(
        f"engine-chi2: KF chi-square test on the turbojet of Han et al. (2022), {args.runs} runs per fault, "
        f"window {result.config['window']}, Pfa {result.config['pfa']}, threshold {result.config['threshold']:.2f}"
    )
    print(result.table())
    figures = engine_chi2.plot_engine_chi2(result)
    return _write_study(result, args, folder, "engine-chi2.json", figures, elapsed)


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
        rest = rest[len(name) :].lstrip(",").strip()
    return chosen, unknown


def _methods_option(args: argparse.Namespace) -> dict:
    """``{"methods": [...]}`` when the user gave ``--methods`` (checked by ``main``), else ``{}`` (so a study without
    that keyword still runs)."""
    return {} if args.methods is None else {"methods": list(args.methods)}


def _run_engine(args: argparse.Namespace, folder: Path) -> str:
    engine = _study(args)
    start = time.perf_counter()
    study = engine.engine_study(
        runs=args.runs, seed=args.seed, progress=not args.quiet, **_methods_option(args)
    )
    elapsed = time.perf_counter() - start
    print(
        "engine: the turbojet of Han et al. (2022), MM / IMM (two mode designs) / GLRT on the "
        f"same {args.runs} runs per fault, "
        f"mu_T = {study.config['settings']['mu_threshold']}"
    )
    print(study.overview())
    print()
    print(
        "Per method and fault; pre-FA = share of runs with an alarm before the onset (false-alarm runs); delays "
        "[s] over the 'clean' runs only, those without one; 'paper' = Table 3 of Han et al. "
        "(2022), a mean delay (beside our "
        "mean); estimate = median over correctly isolated runs"
    )
    print(study.table())
    return _write_study(study, args, folder, "engine.json", engine.plot_engine(study), elapsed)


def _engine_imm_designs(et: ModuleType, args: argparse.Namespace) -> list[str]:
    return sorted(et.DESIGNS) if args.design == "all" else [args.design]


def _check_engine_imm(args: argparse.Namespace) -> None:
    """``--freeze``: parameter names of every chosen design, leaving one to train."""
    et = _study(args)
    frozen = tuple(name.strip() for name in args.freeze.split(",") if name.strip())
    for name in _engine_imm_designs(et, args):
        params = sorted(et.imm_design(name).parameterization)
        unknown = sorted(set(frozen) - set(params))
        if unknown:
            raise expected(
                "--freeze",
                f"parameter names of design {name}, comma-separated, among {params}",
                f"unknown {unknown}",
            )
        if set(params) <= set(frozen):
            raise expected(
                "--freeze",
                f"at least one parameter of design {name} left to train",
                repr(args.freeze),
            )
    args.freeze = frozen


def _tune_engine_imm(args: argparse.Namespace, folder: Path) -> str:
    et = _study(args)
    api = jaxfdi.tuning  # JAX and optax: the package imports it on first use, here
    constrain, unconstrain, save_params = api.constrain, api.unconstrain, api.save_params
    test_seed = args.seed + 1000
    frozen = args.freeze
    report, paths = {}, []
    weights = et.LossWeights(
        detection=args.detection_weight,
        false_alarm=args.false_alarm_weight,
        delay=args.delay_weight,
        isolation=args.isolation_weight,
    )
    for name in _engine_imm_designs(et, args):
        start = time.perf_counter()
        design = et.imm_design(name)
        logger.info("%s: training", name)  # logging: --quiet drops it
        result = et.tune_engine_imm(
            design,
            steps=args.steps,
            train_runs=args.train_runs,
            seed=args.seed,
            weights=weights,
            progress=not args.quiet,
            confirm_steps=args.confirm_steps,
            frozen=frozen,
        )
        tuned = constrain(design.parameterization, result.raw)
        selection = None
        if args.select_thresholds:
            logger.info(
                f"{name}: selecting one mu_T per mode on {args.selection_runs} runs per fault "
                f"(seed {args.seed + 2})"
            )
            tuned["mu_threshold"], selection = et.select_mode_thresholds(
                design, tuned, args.selection_runs, args.seed + 2, args.confirm_steps
            )
            result = result._replace(raw=unconstrain(design.parameterization, tuned))
        hand_rows, hand_ce = et.evaluate_engine_imm(design, design.hand(), args.runs, test_seed)
        tuned_rows, tuned_ce = et.evaluate_engine_imm(
            design, tuned, args.runs, test_seed, args.confirm_steps
        )
        worse = et.worse_metrics(hand_rows, tuned_rows, hand_ce, tuned_ce)
        elapsed = time.perf_counter() - start
        print(
            f"tune engine-imm, design {name} ({design.method}): {args.steps} Adam steps on {args.train_runs} "
            f"runs per fault (seed {args.seed}, best step {result.history.best_step}); held-out test: "
            f"{args.runs} runs per fault (seed {test_seed}); loss weights {dict(weights._asdict())}; "
            f"tuned detector confirms over {args.confirm_steps} step(s), the paper's over 1; frozen "
            f"{list(frozen) or 'none'}"
        )
        if selection is not None:
            print(
                f"mu_T per mode (normal, actuator, RPM, P2, T2, P4, T4) chosen on {args.selection_runs} runs per "
                f"fault (seed {args.seed + 2}): {np.round(np.asarray(tuned['mu_threshold']), 2).tolist()}; "
                f"shortfall against the paper's there {selection['shortfall']['trained']:.3f} -> "
                f"{selection['shortfall']['selected']:.3f}"
            )
        print(et.comparison_table(hand_rows, hand_ce, tuned_rows, tuned_ce))
        print(f"worse than the paper's: {', '.join(worse) if worse else 'none'}\n")
        paths.append(
            save_params(
                folder / f"engine-imm-{name}-tuned.npz",
                result.raw,
                design.parameterization,
                {
                    "best_step": result.history.best_step,
                    "seed": args.seed,
                    "design": name,
                    "confirm_steps": args.confirm_steps,
                    "provenance": _io.provenance(),
                },
            )
        )
        report[name] = {
            "paper": hand_rows,
            "tuned": tuned_rows,
            "cross_entropy": {"paper": hand_ce, "tuned": tuned_ce},
            "worse": worse,
            "shortfall": et.shortfall(hand_rows, tuned_rows),
            "frozen": list(frozen),
            "threshold_selection": selection,
            "history": _as_lists(result.history._asdict()),
            "paper_params": _as_lists(design.hand()),
            "tuned_params": _as_lists(tuned),
            "seconds": elapsed,
        }
    config = {
        "steps": args.steps,
        "train_runs": args.train_runs,
        "test_runs": args.runs,
        "seed": args.seed,
        "test_seed": test_seed,
        "weights": weights._asdict(),
        "confirm_steps": args.confirm_steps,
        "select_thresholds": args.select_thresholds,
        "selection_runs": args.selection_runs,
    }
    _io.write_json(folder / "engine-imm-tuning.json", {"config": config, "designs": report})
    named = ", ".join(str(_named(args, folder, p)) for p in paths)
    return f"wrote {named} and {Path(args.out) / 'engine-imm-tuning.json'}"


def _tune_engine_chi2(args: argparse.Namespace, folder: Path) -> str:
    ct = _study(args)
    api = jaxfdi.tuning  # JAX and optax: the package imports it on first use, here
    constrain, save_params = api.constrain, api.save_params
    start = time.perf_counter()
    windows = args.windows
    weights = ct.Chi2Weights(false_alarm=args.false_alarm_weight, delay=args.delay_weight)
    tuning = ct.tune_engine_chi2(
        windows,
        steps=args.steps,
        train_runs=args.train_runs,
        seed=args.seed,
        weights=weights,
        progress=not args.quiet,
    )
    tuned = constrain(ct.PARAMETERIZATION, tuning.result.raw)
    test_seed = args.seed + 1000
    hand_rows, hand_loss = ct.evaluate_engine_chi2(
        ct.hand_params(), ct.HAND_WINDOW, args.runs, test_seed, weights
    )
    tuned_rows, tuned_loss = ct.evaluate_engine_chi2(
        tuned, tuning.window, args.runs, test_seed, weights
    )
    elapsed = time.perf_counter() - start
    out = Path(args.out)
    print(
        f"tune engine-chi2: KF chi-square test, Q, R and threshold by {args.steps} Adam steps on "
        f"{args.train_runs} runs per fault (seed {args.seed}) for windows {list(windows)}; validation loss "
        + ", ".join(f"L={w}: {v:.4f}" for w, v in tuning.val_loss.items())
        + f"; held-out test: {args.runs} runs per fault (seed {test_seed})"
    )
    print(
        ct.comparison_table(
            hand_rows, tuned_rows, ct.HAND_WINDOW, tuning.window, hand_loss, tuned_loss
        )
    )
    save_params(
        folder / "engine-chi2-tuned.npz",
        tuning.result.raw,
        ct.PARAMETERIZATION,
        {
            "best_step": tuning.result.history.best_step,
            "seed": args.seed,
            "window": tuning.window,
            "provenance": _io.provenance(),
        },
    )
    _io.write_json(
        folder / "engine-chi2-tuning.json",
        {
            "config": {
                "steps": args.steps,
                "train_runs": args.train_runs,
                "test_runs": args.runs,
                "seed": args.seed,
                "test_seed": test_seed,
                "windows": list(windows),
                "weights": weights._asdict(),
            },
            "window": tuning.window,
            "val_loss": {str(w): v for w, v in tuning.val_loss.items()},
            "hand": hand_rows,
            "tuned": tuned_rows,
            "held_out_loss": {"hand": hand_loss, "tuned": tuned_loss},
            "history": _as_lists(tuning.result.history._asdict()),
            "hand_params": _as_lists(ct.hand_params()),
            "tuned_params": _as_lists(tuned),
            "seconds": elapsed,
        },
    )
    return f"wrote {out / 'engine-chi2-tuned.npz'} and {out / 'engine-chi2-tuning.json'} ({elapsed:.1f} s)"


def _run_vtol(args: argparse.Namespace, folder: Path) -> str:
    vtol = _study(args)
    start = time.perf_counter()
    design = vtol.vtol_design()
    study = vtol.vtol_study(
        runs=args.runs,
        seed=args.seed,
        design=design,
        progress=not args.quiet,
        **_methods_option(args),
    )
    examples = vtol.vtol_examples(study.design, seed=args.seed)
    elapsed = time.perf_counter() - start
    cfg = study.config
    print(
        f"vtol: the VTOL of Lee & Lyou, bank of 12 robust TSKFs (multiplicative + additive per location), "
        f"{args.runs} closed-loop runs per fault with FTC off and on; statistic chi2({cfg['dof']}): "
        f"chi2 thresholds {cfg['chi2_threshold']:.2f} / window {cfg['chi2_window_threshold']:.2f}, paper's "
        f"{cfg['paper_threshold']} / {cfg['paper_window_threshold']}; MDWT M = {cfg['levels']}, c = {cfg['c_mult']}"
    )
    print(
        "'ours' thresholds: per filter, the larger of the chi2 one and the fault-free 99.5 % quantile, then "
        f"per method scaled so that at most {cfg['run_false_alarm']:.0%} of the fault-free runs show a symptom "
        f"({cfg['calibration_runs']} calibration runs, another seed):"
    )
    for method, row in cfg["thresholds"].items():
        print(f"  {method:<8} " + " ".join(f"{name} {value:.1f}" for name, value in row.items()))
    print(
        "Rates over runs; delays in steps (median over the 'clean' runs, those with no symptom before the onset); "
        "detection = some location's filters all alarm (the symptom vector leaves the no-fault column), isolation "
        "= it matches the true fault's column\n"
    )
    print(study.table())
    print()
    print(study.headline())
    return _write_study(
        study, args, folder, "vtol.json", vtol.plot_vtol(study, examples, study.design), elapsed
    )


def _run_reaction_wheels(args: argparse.Namespace, folder: Path) -> str:
    wheels = _study(args)
    start = time.perf_counter()
    study = wheels.wheel_study(
        runs=args.runs,
        seed=args.seed,
        calibration_runs=max(20, 2 * args.runs),
        estimator=args.estimator,
        engage_on=args.engage_on,
        progress=not args.quiet,
        **_methods_option(args),
    )
    design = wheels.wheel_design()._replace(detection_threshold=study.config["fdp_threshold"])
    examples = wheels.wheel_examples(
        design, seed=args.seed, estimator=args.estimator, engage_on=args.engage_on
    )
    elapsed = time.perf_counter() - start
    cfg = study.config
    print(
        f"reaction-wheels: KITSAT-3 (Choi & Park 2009) with a 4-wheel pyramid, {cfg['slew_deg']:.0f} deg slew in 40 s, "
        f"60 s at 10 Hz, {args.runs} runs per case (noise and onset uniform in 15-25 s); estimation filter "
        f"{args.estimator.upper()}, banks engaged on the {'NIS test' if args.engage_on == 'nis' else 'dual filter F'}"
    )
    print(
        f"thresholds: F_T = {cfg['fdp_threshold']:.3e} ({cfg['fdp_margin']} x the largest F of "
        f"{cfg['calibration_runs']} fault-free runs, another seed); NIS over {cfg['nis_window']} steps "
        f"{cfg['nis_threshold']:.2f} (chi2, Pfa 1e-5); relative credit {cfg['credit_threshold']}; "
        f"mu_T {cfg['mode_threshold']}; isolators confirm over {cfg['confirm_steps']} steps"
    )
    print(
        "det = decided at or after the onset; isol = its first decision names the faulty wheel or gyro (- : "
        "the method never names one: F and NIS for a wheel); <=2s = detected (F, NIS) or isolated (credit, MM, gyro "
        "health test) within 2 s of the onset, in the runs with no decision before it; delays over those runs "
        "(mean, median, p90); FA = share of runs with a decision before the onset, clean = the others; gyro cases "
        f"the x gyro dead (NaN) or frozen, gyro health test = stuck-at test over {cfg['health_window']} "
        f"samples, P_fa {cfg['health_pfa_per_window']:g} per window and gyro\n"
    )
    print(study.table())
    print()
    print(study.headline())
    return _write_study(
        study, args, folder, "reaction-wheels.json", wheels.plot_wheels(study, examples), elapsed
    )


def _study_runner(
    study: str,
    name: str,
    plot: str | None,
    header: Callable[[dict, argparse.Namespace], str] | None,
    runs: str = "runs",
) -> Callable[[argparse.Namespace, Path], str]:
    """A runner for a study: the study's module's function ``study`` called as ``study(<runs>=--runs, seed,
    progress)``, its one-line header (``None``: none; the table says it) and table printed, its JSON, CSV and
    figures (the module's ``plot(study)``; ``None``: no figures) written."""

    def run(args: argparse.Namespace, folder: Path) -> str:
        module = _study(args)
        start = time.perf_counter()
        result = getattr(module, study)(
            **{runs: args.runs}, seed=args.seed, progress=not args.quiet
        )
        elapsed = time.perf_counter() - start
        if header is not None:
            print(header(result.config, args))
        print(result.table())
        figures = {} if plot is None else getattr(module, plot)(result)
        return _write_study(result, args, folder, name, figures, elapsed)

    return run


def _f16_flight_header(cfg: dict, args: argparse.Namespace) -> str:
    trim = cfg["design_trim"]
    return (
        f"f16-flight: F-16 of Park et al. (2004) (Stevens & Lewis 2nd-ed. tables), climb "
        f"{cfg['plan']['climb_rate_ft_s']:.0f} ft/s for 0-5 s, then altitude hold and a "
        f"{cfg['plan']['bank_angle_deg']:.0f} deg bank turn to {cfg['duration_s']:.0f} s; design trim "
        f"{trim['airspeed_ft_s']:.0f} ft/s, sea level, xcg {trim['xcg']}; {cfg['flights']} flights, RK4 at "
        f"{cfg['dt_s']} s"
    )


def _f16_header(cfg: dict, args: argparse.Namespace) -> str:
    return (
        f"f16: hybrid FDI of Park et al. (2004), three 2-DOF rate sensors (sigma {cfg['rate_sigma_rad_s']:g} "
        f"rad/s) on the closed-loop F-16, parity space + UKF on demand (restart {cfg['restart_lag_steps']} steps "
        f"back, Cl/Cm/Cn errors {cfg['coefficient_error_Cl_Cm_Cn']}); {args.runs} runs per case"
    )


def _gnss_campus_header(cfg: dict, args: argparse.Namespace) -> str:
    return (
        f"gnss-campus: GPS RAIM of Yoo et al. (2010) from {cfg['start']} (broadcast ephemerides "
        f"{cfg['ephemeris']}), 1 Hz, {cfg['mask_deg']:.0f} deg mask, P_fa {cfg['pfa']:.2e}, P_md {cfg['pmd']:g}, "
        f"NPA HAL 556 m; {args.runs} runs per case"
    )


def _gnss_real_header(cfg: dict, args: argparse.Namespace) -> str:
    return (
        f"gnss-real: GPS integrity on real receivers, GEONET stations {' and '.join(cfg['stations'])} "
        f"({cfg['data']}, 30 s), RTKLIB's single-point model, {cfg['mask_deg']:.0f} deg mask, parity test "
        f"P_fa {cfg['pfa']:g}, slope PLs P_md {cfg['pmd']:g}, solution-separation PLs (ARAIM LPV-200); faults "
        f"injected into station {cfg['fault_station']}, {args.runs} trials per size and rate; "
        f"{len(cfg['phones'])} smartphone traces (GSDC 2021-2023), every constellation, a clock per "
        "constellation, beside Google's fixes and gnss_lib_py's FDE"
    )


def _gps_ins_header(cfg: dict, args: argparse.Namespace) -> str:
    return (
        f"gps-ins: INS/GPS integrity of Yoo et al. (2010), park flight {cfg['flight_s']} s from {cfg['start']}, "
        f"HG1900-class IMU {cfg['imu_rate_hz']} Hz, GPS 1 Hz (RAIM-passed fixes only), 15-state error-state EKF; "
        f"chi-square {cfg['chi2']['threshold']:.2f} (60 dof), SCST {cfg['scst']['threshold']:.2f} (15 dof, "
        f"propagators reset every {cfg['scst']['period_s']} s); {args.runs} runs per case"
    )


_run_f16_flight = _study_runner(
    "f16_flight_study", "f16-flight.json", "plot_f16_flight", _f16_flight_header, "flights"
)
_run_f16 = _study_runner("f16_fdi_study", "f16.json", "plot_f16_fdi", _f16_header)
_run_gnss_campus = _study_runner(
    "gnss_campus_study", "gnss-campus.json", "plot_gnss_campus", _gnss_campus_header
)
_run_gps_ins = _study_runner("gps_ins_study", "gps-ins.json", "plot_gps_ins", _gps_ins_header)
_run_engine_fault_sizes = _study_runner("fault_size_study", "engine-fault-sizes.json", None, None)
_run_f16_fault_kinds = _study_runner("fault_kind_study", "f16-fault-kinds.json", None, None)
_run_vtol_fault_kind = _study_runner("fault_kind_study", "vtol-fault-kind.json", None, None)
_run_gnss_real = _study_runner(
    "gnss_real_study", "gnss-real.json", "plot_gnss_real", _gnss_real_header
)


#: the registry: ``jaxfdi run <scenario>`` -> its ``Runner`` (help, options, the study's module, imported when it runs)
RUNNERS = {
    "engine": Runner(
        _run_engine,
        "Han et al. (2022) turbojet: MM, IMM (two fault-mode designs) and windowed GLRT beside "
        "the paper's Table 3",
        methods="engine_method_names",
        module="jaxfdi.scenarios.engine",
    ),
    "engine-chi2": Runner(
        _run_engine_chi2,
        "Han et al. (2022) turbojet: the Kalman-filter chi-square test (--window, --pfa)",
        options=("window", "pfa"),
        module="jaxfdi.scenarios.engine_chi2",
    ),
    "reaction-wheels": Runner(
        _run_reaction_wheels,
        "Choi & Park (2009) satellite, 4-wheel pyramid: dual filter F, NIS, "
        "credits, MM isolator (--estimator, --engage-on)",
        options=("estimator", "engage_on"),
        methods="METHODS",
        module="jaxfdi.scenarios.reaction_wheels",
    ),
    "engine-fault-sizes": Runner(
        _run_engine_fault_sizes,
        "Han et al. (2022) turbojet: each method's delay against the fault's size, and the size at which "
        "it equals Table 3's",
        module="jaxfdi.scenarios.engine",
    ),
    "f16-fault-kinds": Runner(
        _run_f16_fault_kinds,
        "Park et al. (2004) F-16: every rate-sensor fault kind (bias, drift, scale, stuck, dead) in full "
        "flights under no FDI, the paper's hybrid rule and the verified rule",
        module="jaxfdi.scenarios.f16_fdi",
    ),
    "f16": Runner(
        _run_f16,
        "Park et al. (2004) F-16 rate sensors: parity space with the UKF's analytic redundancy on "
        "demand, the paper's case, direction x magnitude sweep, envelope, sensor layout",
        module="jaxfdi.scenarios.f16_fdi",
    ),
    "f16-flight": Runner(
        _run_f16_flight,
        "Park et al. (2004) F-16: book trim tables beside ours, modes, LQR SAS with "
        "altitude and bank hold flying the paper's climb and bank turn",
        module="jaxfdi.scenarios.f16_flight",
    ),
    "gps-ins": Runner(
        _run_gps_ins,
        "Yoo et al. (2010) INS/GPS: 15-state EKF, windowed chi-square and SCST, Table 3 (gyro bias)",
        module="jaxfdi.scenarios.gps_ins",
    ),
    "gnss-campus": Runner(
        _run_gnss_campus,
        "Yoo et al. (2010) GPS RAIM: campus HDOP/HPL availability with a blocked sky, "
        "park satellite faults detected, isolated and excluded",
        module="jaxfdi.scenarios.gnss_campus",
    ),
    "gnss-real": Runner(
        _run_gnss_real,
        "GEONET stations (real GPS, one hour): positions beside RTKLIB's, slope and "
        "solution-separation PLs (Stanford diagrams), injected step and ramp faults; "
        "smartphones (every constellation) beside Google and gnss_lib_py",
        module="jaxfdi.scenarios.gnss_real",
    ),
    "vtol": Runner(
        _run_vtol,
        "Lee & Lyou VTOL: robust two-stage KF bank, chi-square/MDWT tests, LQR-PI "
        "fault-tolerant control",
        methods="METHODS",
        module="jaxfdi.scenarios.vtol",
    ),
    "vtol-fault-kind": Runner(
        _run_vtol_fault_kind,
        "Lee & Lyou VTOL: can the TSKF bank tell an additive fault from a multiplicative one "
        "(windowed likelihoods of the two filters at the location, FTC off)",
        module="jaxfdi.scenarios.vtol",
    ),
}
#: ``jaxfdi tune <target>`` -> its ``Runner``
TUNERS = {
    "engine-chi2": Runner(
        _tune_engine_chi2,
        "Q, R and the threshold of the engine chi-square test by gradient, window by validation",
        options=("windows",),
        module="jaxfdi.scenarios.engine_chi2_tuning",
    ),
    "engine-imm": Runner(
        _tune_engine_imm,
        "the engine IMMs' transition matrix, mode noise and mu_T by gradient (--design)",
        options=(
            "design",
            "detection_weight",
            "isolation_weight",
            "confirm_steps",
            "freeze",
            "select_thresholds",
            "selection_runs",
        ),
        check=_check_engine_imm,
        module="jaxfdi.scenarios.engine_tuning",
    ),
}
#: the command's kind -> its half of the registry
REGISTRY = {"run": RUNNERS, "tune": TUNERS}
#: one line per scenario and tuning target, for ``jaxfdi --help``
RUN_HELP = {name: runner.help for name, runner in RUNNERS.items()}
TUNE_HELP = {name: runner.help for name, runner in TUNERS.items()}

#: ``jaxfdi --help``'s account of the checks and exit statuses (no line may start with two spaces: the help test reads
#: those as tuning targets)
CHECKS_HELP = """\
Options are checked before anything is computed: integers in range (--runs, --train-runs,
--selection-runs, --steps, --window, --windows, --confirm-steps >= 1; --seed in
[0, 4294967295]), real numbers finite (--pfa in (0, 1), loss weights >= 0), --methods and
--freeze names, --out a writable folder or one that can be created (not a file), and
options the scenario does not read are refused; so are values the library rejects.

Exit status: 0 done; 2 bad usage or option value, one line on stderr
'jaxfdi: --option: expected ..., got ...', nothing computed or written; 1 an error (a
traceback). On SIGINT, SIGTERM or SIGHUP it cleans up, prints one line and ends by that
signal (a shell shows 130, 143, 129). A study's files are written into a temporary
folder inside --out and moved into place together when it is done (JSON last), with the
usual permissions (0666 minus the umask); an interrupted or failed study leaves --out as
it was. --traceback: a traceback instead of the one line."""


def _listing(title: str, entries: dict[str, str]) -> str:
    width = max(map(len, entries)) + 2
    return "\n".join(
        [title, *(f"  {name:<{width}}{text}" for name, text in sorted(entries.items()))]
    )


def _version_line() -> str:
    """``jaxfdi --version``: jaxfdi's version (from the package metadata, without importing JAX)."""
    from importlib import metadata

    try:
        version = metadata.version("jaxfdi")
    except metadata.PackageNotFoundError:
        version = "unknown"
    return f"jaxfdi {version}"


def _select_agg_backend() -> None:
    """The CLI draws figures into files: select matplotlib's Agg backend unless a backend was chosen explicitly
    (``MPLBACKEND``); the library's plotting functions never change the backend themselves."""
    if os.environ.get("MPLBACKEND"):
        return
    try:
        import matplotlib
    except ImportError:
        return
    matplotlib.use("Agg")


def _add_process_options(run: argparse.ArgumentParser) -> None:
    """Multi-host Monte Carlo (``jaxfdi.distributed``): every process runs the same command; only process 0 writes
    ``--out``."""
    group = run.add_argument_group("several processes (one study over hosts; jaxfdi.distributed)")
    group.add_argument(
        "--num-processes",
        default=None,
        help="processes of the study (default: JAXFDI_NUM_PROCESSES, else 1)",
    )
    group.add_argument(
        "--process-id",
        default=None,
        help="this process's index in [0, N) (default: JAXFDI_PROCESS_ID)",
    )
    group.add_argument(
        "--coordinator",
        default=None,
        help="HOST:PORT of process 0 (default: JAX_COORDINATOR_ADDRESS)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxfdi",
        description="Fault detection and isolation studies in JAX",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="\n\n".join(
            [
                _listing("scenarios (jaxfdi run <scenario>):", RUN_HELP),
                _listing("tuning targets (jaxfdi tune <target>):", TUNE_HELP),
                "jaxfdi run -h / jaxfdi tune -h: the options",
                CHECKS_HELP,
            ]
        ),
    )
    parser.add_argument("--version", action="version", version=_version_line())
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser(
        "run",
        help="run a paper scenario end to end",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="\n\n".join([_listing("scenarios:", RUN_HELP), CHECKS_HELP]),
    )
    run.add_argument("scenario", choices=sorted(RUNNERS))
    run.add_argument(
        "--methods",
        default=None,
        help="run only these methods, comma-separated (engine, vtol, reaction-wheels; default all; "
        "an unknown name lists the valid ones)",
    )
    run.add_argument(
        "--runs", type=int, default=100, help="Monte Carlo runs per fault, >= 1 (default 100)"
    )
    run.add_argument("--seed", type=int, default=0, help="PRNG seed in [0, 2**32 - 1] (default 0)")
    run.add_argument(
        "--out", default="results", help="output folder for JSON and PNG (default ./results)"
    )
    run.add_argument(
        "--window",
        type=int,
        default=None,
        help="engine-chi2: window length in steps, >= 1 (default 4)",
    )
    run.add_argument(
        "--pfa",
        type=float,
        default=None,
        help="engine-chi2: design false-alarm probability in (0, 1) (default 0.005)",
    )
    run.add_argument(
        "--estimator",
        default=None,
        choices=["ekf", "ukf"],
        help="reaction-wheels: the estimation filter (default ekf, the paper's)",
    )
    run.add_argument(
        "--engage-on",
        default=None,
        choices=["nis", "fdp"],
        help="reaction-wheels: the detector that engages the hypothesis banks (default nis; fdp = "
        "the paper's F)",
    )
    run.add_argument("--quiet", action="store_true", help="no progress display")
    run.add_argument(
        "--traceback",
        action="store_true",
        help="on an error the library reports as a bad argument, a traceback instead of one line",
    )
    _add_process_options(run)
    tune = sub.add_parser(
        "tune",
        help="tune a scenario's filter and detector by gradient, then compare on held-out runs",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="\n\n".join([_listing("tuning targets:", TUNE_HELP), CHECKS_HELP]),
    )
    tune.add_argument("target", choices=sorted(TUNERS))
    tune.add_argument("--steps", type=int, default=150, help="optimiser steps, >= 1 (default 150)")
    tune.add_argument(
        "--train-runs", type=int, default=16, help="training runs per fault, >= 1 (default 16)"
    )
    tune.add_argument(
        "--runs", type=int, default=100, help="held-out test runs per fault, >= 1 (default 100)"
    )
    tune.add_argument(
        "--seed",
        type=int,
        default=0,
        help="training seed in [0, 2**32 - 1]; validation seed+1, test seed+1000",
    )
    tune.add_argument("--out", default="results", help="output folder (default ./results)")
    tune.add_argument(
        "--design",
        default=None,
        choices=["all", "bias", "zhang-li"],
        help="engine-imm: which IMM mode design (default all)",
    )
    tune.add_argument(
        "--detection-weight",
        type=float,
        default=None,
        help="engine-imm: weight of the soft detection loss against the mode cross-entropy "
        "(default 1; 0 trains on the cross-entropy alone)",
    )
    tune.add_argument(
        "--false-alarm-weight",
        type=float,
        default=5.0,
        help="loss weight of P(alarm before the onset), finite, >= 0 (default 5)",
    )
    tune.add_argument(
        "--delay-weight",
        type=float,
        default=1.0,
        help="loss weight of the expected delay / steps after the onset, finite, >= 0 (default 1)",
    )
    tune.add_argument(
        "--confirm-steps",
        type=_confirm_steps,
        default=None,
        help="engine-imm: the tuned detector alarms once the same fault mode has led at or above "
        "mu_T for this many steps; trained for it (default 1, the paper's rule); or 7 "
        "comma-separated lengths, one per mode (normal, actuator, RPM, P2, T2, P4, T4)",
    )
    tune.add_argument(
        "--freeze",
        default=None,
        help="engine-imm: parameters kept at their hand-set values, comma-separated "
        "(e.g. mu_threshold)",
    )
    tune.add_argument(
        "--select-thresholds",
        action="store_true",
        default=None,
        help="engine-imm: after training, choose one mu_T per fault mode on selection runs "
        "(seed+2) so that no reported metric is worse than the paper's there",
    )
    tune.add_argument(
        "--selection-runs",
        type=int,
        default=None,
        help="engine-imm: runs per fault for --select-thresholds, >= 1 (default 100)",
    )
    tune.add_argument(
        "--isolation-weight",
        type=float,
        default=None,
        help="engine-imm: loss weight of P(first alarm names the wrong fault), finite, >= 0 (default 5)",
    )
    tune.add_argument(
        "--windows",
        default=None,
        help="engine-chi2: window lengths to try, comma-separated (default 1,2,4,8)",
    )
    tune.add_argument("--quiet", action="store_true", help="no progress display")
    tune.add_argument(
        "--traceback",
        action="store_true",
        help="on an error the library reports as a bad argument, a traceback instead of one line",
    )
    sub.add_parser("list", help="list the scenarios")
    return parser


def _interval(low: float, high: float, low_ok: bool, high_ok: bool) -> str:
    if high == math.inf:
        return f">= {low:g}" if low_ok else f"> {low:g}"
    return f"{'[' if low_ok else '('}{low:g}, {high:g}{']' if high_ok else ')'}"


def _counts(option: str, text: str) -> tuple[int, ...]:
    """Comma-separated integers in [1, MAX_COUNT] (``--windows``)."""
    parts = [part.strip() for part in text.split(",")]
    if not all(part.isdigit() and 1 <= int(part) <= MAX_COUNT for part in parts):
        raise expected(option, f"integers in [1, {MAX_COUNT}] separated by commas", repr(text))
    return tuple(int(part) for part in parts)


def check_options(args: argparse.Namespace, kind: str, name: str, runner: Runner) -> None:
    """``UsageError`` for what ``jaxfdi <kind> <name>`` cannot use: an option it does not read, an out-of-range integer,
    a non-finite or out-of-range real, a malformed list, an unwritable ``--out`` (probe file); fills in the
    scenario-specific defaults. Pure Python: nothing imported, computed or left behind."""
    specific = RUN_SPECIFIC if kind == "run" else TUNE_SPECIFIC
    registry = REGISTRY[kind]
    reads = set(runner.options) | ({"methods"} if runner.methods is not None else set())
    for dest, default in specific.items():
        value = getattr(args, dest)
        if value is None:
            setattr(args, dest, default)
        elif dest not in reads:
            if dest == "methods":
                raise expected("--methods", f"none: {name} has one method", repr(value))
            users = sorted(n for n, r in registry.items() if dest in r.options)
            raise expected(
                _flag(dest),
                f"no value: {kind} {name} does not read it (read by {', '.join(users)})",
                repr(value),
            )
    for dest, (low, high) in INTEGER_RANGES.items():
        value = getattr(args, dest, None)
        if value is not None and not low <= value <= high:
            raise expected(_flag(dest), f"an integer in [{low}, {high}]", value)
    for dest, bounds in FLOAT_RANGES.items():
        value = getattr(args, dest, None)
        if value is None:
            continue
        low, high, low_ok, high_ok = bounds
        inside = (value >= low if low_ok else value > low) and (
            value <= high if high_ok else value < high
        )
        if not (math.isfinite(value) and inside):
            raise expected(
                _flag(dest),
                f"a finite number {'in ' if high < math.inf else ''}{_interval(*bounds)}",
                value,
            )
    if kind == "tune":
        steps = args.confirm_steps
        values = steps if isinstance(steps, tuple) else (steps,)
        if len(values) not in (1, NUM_ENGINE_MODES) or not all(1 <= v <= MAX_COUNT for v in values):
            raise expected(
                "--confirm-steps",
                f"one integer >= 1 or {NUM_ENGINE_MODES} of them, comma-separated (one per mode)",
                repr(",".join(map(str, values))),
            )
        args.windows = _counts("--windows", args.windows)
    try:
        _io.check_output_dir(args.out, "--out")
    except ValueError as e:
        raise UsageError(str(e)) from None


def _raised_by_jaxfdi(error: BaseException) -> bool:
    """Whether ``error`` comes from a ``raise`` statement in jaxfdi's own code (its argument checks), not from inside
    JAX, NumPy or Python (a bug: shown as a traceback)."""
    tb = error.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    path = Path(tb.tb_frame.f_code.co_filename)
    package = Path(__file__).resolve().parent
    inside = path.resolve().is_relative_to(package) if path.is_absolute() else False
    return inside and linecache.getline(str(path), tb.tb_lineno).lstrip().startswith("raise")


@contextlib.contextmanager
def _signals_raise() -> Iterator[None]:
    """SIGTERM and SIGHUP raise ``Terminated`` (SIGINT: ``KeyboardInterrupt``) in the main thread, so
    ``_io.study_output``'s clean-up runs; an ignored signal (``nohup``) stays ignored; old handlers restored on exit.
    A handler raising in a GC callback or ``__del__`` (JAX's ``_xla_gc_callback``) is printed and dropped, so a dropped
    ``KeyboardInterrupt`` is delivered again 10 ms later (``_thread.interrupt_main``, timer thread) until it lands."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def raise_terminated(signum, frame):
        raise Terminated(signum)

    def deliver_again(unraisable):
        error = unraisable.exc_value
        if isinstance(error, KeyboardInterrupt):  # from another thread: not inside this hook again
            signum = error.signum if isinstance(error, Terminated) else signal.SIGINT
            threading.Timer(0.01, _thread.interrupt_main, (signum,)).start()
        else:
            previous_hook(unraisable)

    previous = {}
    for name in ("SIGTERM", "SIGHUP"):
        signum = getattr(signal, name, None)
        if signum is not None and signal.getsignal(signum) == signal.SIG_DFL:
            previous[signum] = signal.signal(signum, raise_terminated)
    previous_hook, sys.unraisablehook = sys.unraisablehook, deliver_again
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _fail(message: str, status: int) -> int:
    print(f"jaxfdi: {' '.join(message.split())}", file=sys.stderr)
    return status


def _die_by(signum: int) -> None:
    """End the process by ``signum``'s default action now: the parent sees it killed by the signal (shell: 128 + signum,
    the SIGINT convention), and no interpreter shutdown while XLA may compile in a worker (that can crash)."""
    sys.stdout.flush()
    sys.stderr.flush()
    signal.signal(signum, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signum})
    os.kill(os.getpid(), signum)
    os._exit(128 + signum)  # not reached unless the signal is ignored after all


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit status (0 done, 2 bad usage or option value).

    Interrupted by SIGINT, SIGTERM or SIGHUP, it cleans up (``--out`` as it was), prints one line, then: run as the
    program (``argv`` None: ``jaxfdi``, ``python -m jaxfdi``) it ends by that signal (``_die_by``); called with ``argv``
    it returns 128 + signum."""
    args = build_parser().parse_args(argv)
    if args.command == "list":
        print("\n".join([*sorted(RUNNERS), *(f"tune {name}" for name in sorted(TUNERS))]))
        return 0
    kind, name = _command(args)
    runner = REGISTRY[kind][name]
    try:
        check_options(args, kind, name, runner)
        processes = _process_options(args) if kind == "run" else None
    except UsageError as e:
        return _fail(str(e), 2)
    jaxfdi.enable_x64()
    jaxfdi.enable_compilation_cache()
    _select_agg_backend()
    progress.configure_logging(quiet=args.quiet)
    scratch = _join_processes(args, processes)
    try:
        with _signals_raise(), _io.recording(argv, args.seed):
            if runner.methods is not None and args.methods is not None:
                names = getattr(_study(args), runner.methods)
                valid = list(names() if callable(names) else names)
                chosen, unknown = split_methods(args.methods, valid)
                if unknown or not chosen:
                    raise expected(
                        "--methods",
                        "names among " + "; ".join(valid) + " (comma-separated)",
                        f"unknown {unknown}" if unknown else repr(args.methods),
                    )
                args.methods = chosen
            if runner.check is not None:
                runner.check(args)
            with _io.study_output(args.out) as folder:
                wrote = runner.run(args, folder)
    except UsageError as e:
        return _fail(str(e), 2)
    except KeyboardInterrupt as e:
        signum = e.signum if isinstance(e, Terminated) else signal.SIGINT
        status = _fail(
            f"interrupted by {signal.Signals(signum).name}; {args.out} left as it was", 128 + signum
        )
        if argv is None:
            _die_by(signum)
        return status
    except (ValueError, TypeError) as e:
        if args.traceback or not _raised_by_jaxfdi(e):
            raise
        return _fail(f"{e} (nothing written to {args.out}; --traceback for where)", 2)
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
    if wrote and scratch is None:
        print(wrote)
    return 0


def _process_options(args: argparse.Namespace) -> tuple:
    """``--num-processes/--process-id/--coordinator`` (or the environment), checked (pure Python);
    ``(None, None, None)`` for one process."""
    try:
        return distributed.resolve_options(args.num_processes, args.process_id, args.coordinator)
    except ValueError as e:
        raise UsageError(str(e)) from None


def _join_processes(args: argparse.Namespace, processes) -> str | None:
    """Join the other processes (``jax.distributed``, before any JAX work); processes other than 0 write into a scratch
    folder, removed at the end (process 0 writes ``--out``: every process has the whole gathered study). Returns that
    folder."""
    if processes is None or processes[0] is None or processes[0] <= 1:
        return None
    distributed.initialize(*processes)
    if processes[1] == 0:
        return None
    scratch = tempfile.mkdtemp(prefix=f"jaxfdi-process{processes[1]}-")
    args.out = os.path.join(scratch, "out")
    return scratch


if __name__ == "__main__":
    sys.exit(main())
