"""The engine of Han et al. (2022): Monte Carlo study of the Kalman-filter chi-square detector.

- Scenario (Han et al. 2022): steady state, 0.01 kg/s fuel step at t = 0, one step fault at t =
  2 s, 4 s at 100 Hz, 100 runs per fault, plus a fault-free case (false-alarm rate).
- Fault sizes: actuator bias 5 % of the command (0.0005 kg/s); sensor biases 0.5 % of that output's operating point (RPM
  135, P2 16.99, T2 2.21 K, P4 8.285, T4 5.125 K).
- The fault-blind KF starts at the true (zero) perturbation with ``P0 = Q``; windowed NIS sum vs
  ``chi2_threshold(window * 5, pfa)``.

Reference: Han, Kim, Kim & Lee (2022), "Real Time Fault Diagnosis of UAV Engine Using IMM Filter and Generalized
Likelihood Ratio Test" (CITATION.cff).
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxfdi import (
    DetectionRecord,
    Fault,
    MonitorHistory,
    Structure,
    Study,
    cell,
    checks,
    fault,
    fault_row,
    linear_simulator,
    monitor,
    no_fault,
    rate_cell,
    run_study,
    stack_faults,
    study_result,
    summarize_detection,
    unhealthy_rows_warning,
)
from jaxfdi.detection import chi2_detector, chi2_threshold
from jaxfdi.filters import kalman_filter
from jaxfdi.models import ENGINE_OPERATING_POINT as OUTPUT_OPERATING_POINT
from jaxfdi.models import ENGINE_OUTPUT_NAMES as OUTPUT_NAMES
from jaxfdi.models import ENGINE_TS as TS
from jaxfdi.models import engine_model
from jaxfdi.plotting import caption_figure, column_subplots, hypothesis_colors
from jaxfdi.scenarios._common import check_study, require_x64

FUEL_STEP = 0.01  # kg/s
ACTUATOR_BIAS = 0.05 * FUEL_STEP
SENSOR_BIAS_FRACTION = 0.005


def engine_faults(onset_step: int) -> tuple[list[str], list[Fault]]:
    """The faults of Han et al. (2022) in mode order (actuator, RPM, P2, T2, P4, T4) plus 'none'."""
    names = ["actuator", *OUTPUT_NAMES, "none"]
    faults = [fault("bias", "actuator", 0, onset_step, ACTUATOR_BIAS)]
    faults += [
        fault("bias", "sensor", j, onset_step, SENSOR_BIAS_FRACTION * OUTPUT_OPERATING_POINT[j])
        for j in range(len(OUTPUT_NAMES))
    ]
    faults.append(no_fault())
    return names, faults


@study_result
class EngineChi2Result(NamedTuple):
    """The engine chi-square study: configuration, table rows, per-run records and one example run per fault.

    Attributes:
      config: the study's settings
      rows: one per fault: the summary in seconds
      records: (faults * runs,) per-run records
      examples: (faults, T, ...) one run of each fault
    """

    config: dict[str, Any]
    rows: list[dict[str, Any]]
    records: DetectionRecord
    examples: MonitorHistory

    def table(self) -> str:
        """Per fault: ``FA rate``: runs alarming before the onset (``none``: any alarm); delays (mean, median, p90) over
        the ``clean`` runs, the others (``metrics.fault_row``); each rate with its 95 % Clopper-Pearson interval over
        the ``n`` healthy runs (``metrics.rate_interval``)."""
        head = (
            f"{'fault':<9} {'magnitude':>10} {'n':>4} {'det. rate [95 %]':>21} {'FA rate [95 %]':>20} "
            f"{'FA/step':>8} {'clean':>5} {'delay mean [s]':>14} {'delay med [s]':>13} {'delay p90 [s]':>13}"
        )
        lines = [head, "-" * len(head)]
        for r in self.rows:
            clean = "-" if r["fault"] == "none" else str(r.get("clean_runs", "-"))
            n = r["runs"] - r.get("unhealthy_runs", 0)
            lines.append(
                f"{r['fault']:<9} {r['magnitude']:>10.4g} {n:>4} {rate_cell(r['detection_rate'], n, 21, digits=3)} "
                f"{rate_cell(r['false_alarm_rate'], n, 20, digits=3)} "
                f"{cell(r['false_alarm_rate_per_step'], '.4f', 8)} {clean:>5} "
                f"{cell(r.get('delay_mean_s', float('nan')), '.3f', 14)} "
                f"{cell(r['delay_median_s'], '.3f', 13)} {cell(r['delay_p90_s'], '.3f', 13)}"
            )
        warning = unhealthy_rows_warning(self.rows)
        return "\n".join(lines + ([warning] if warning else []))


def engine_chi2_study(
    runs: int = 100,
    seed: int = 0,
    window: int = 4,
    pfa: float = 0.005,
    duration: float = 4.0,
    onset_time: float = 2.0,
    chunk_size: int | None = None,
    progress: bool = False,
    threshold: float | None = None,
    filter_noise: tuple[Any, Any] | None = None,
) -> EngineChi2Result:
    """Run the study; needs float64 (``jaxfdi.enable_x64()``): the engine is stiff.

    ``threshold`` (default ``chi2_threshold(window * 5, pfa)``), ``filter_noise = (Q, R)`` (default the plant's): a
    tuner's detector; the plant always uses its own noise.

    Returns:
      ``EngineChi2Result`` over the seven ``engine_faults`` cases (actuator, RPM, P2, T2, P4, T4, none): ``config``
      (runs, seed, window, pfa, dof, threshold, Ts, steps, onset step, fuel step), ``rows`` (one per case: magnitude,
      detection, missed-detection and false-alarm rates, delays in s, unhealthy, pre-onset-alarm and clean runs),
      ``records`` (a ``DetectionRecord`` of 7 * ``runs`` runs, case-major) and ``examples`` (a ``MonitorHistory`` of one
      extra run per case, leaves (7, T, ...)).
    """
    require_x64("engine_chi2_study (the engine model is stiff)")
    check_study(
        runs, seed, window=window, **({} if chunk_size is None else {"chunk_size": chunk_size})
    )
    checks.check_probability("pfa", pfa)
    checks.check_positive("duration", duration, "a positive run length in seconds")
    checks.check_scalar(
        "onset_time",
        onset_time,
        0.0,
        duration,
        high_open=True,
        meaning="a fault onset time in [0, duration) seconds",
    )
    if threshold is not None:
        checks.check_positive("threshold", threshold, "a positive chi-square threshold")
    model = engine_model()
    steps = int(round(duration / TS))
    onset = int(round(onset_time / TS))
    if window > steps:
        raise ValueError(f"window: expected at most the {steps} steps of a run, got {window}")
    dof = window * model.C.shape[0]
    threshold = chi2_threshold(dof, pfa) if threshold is None else jnp.asarray(threshold)
    filter_model = (
        model
        if filter_noise is None
        else model._replace(Q=jnp.asarray(filter_noise[0]), R=jnp.asarray(filter_noise[1]))
    )
    names, faults = engine_faults(onset)
    run = _chi2_run(steps, window)
    noise = (filter_model.Q[None], filter_model.R[None])
    spec = Study(
        "engine-chi2",
        stack_faults(faults),
        tuple(names),
        (Structure("KF chi-square", run, (noise, jnp.reshape(threshold, (1,))), {"chi2": (0, 0)}),),
    )
    key_mc, key_example = jax.random.split(jax.random.key(seed))
    records = run_study(
        spec, runs, seed, key=key_mc, chunk_size=chunk_size, progress=progress
    ).outputs["chi2"]
    examples = jax.jit(
        jax.vmap(
            lambda f: (
                run(
                    key_example, f, (filter_model.Q, filter_model.R), threshold, keep_history=True
                ).history
            )
        )
    )(stack_faults(faults))

    rows = []
    for i, (name, f) in enumerate(zip(names, faults)):
        part = jax.tree_util.tree_map(lambda x: x[i * runs : (i + 1) * runs], records)
        s = summarize_detection(part, steps, TS)
        columns = fault_row(part, steps, TS)
        rows.append(
            {
                "fault": name,
                "magnitude": float(f.magnitude),
                "runs": s.runs,
                "detection_rate": s.detection_rate,
                "missed_detection_rate": s.missed_detection_rate,
                "false_alarm_rate": s.false_alarm_rate,
                "false_alarm_rate_per_step": s.false_alarm_rate_per_step,
                "delay_mean_s": s.delay_mean,
                "delay_median_s": s.delay_median,
                "delay_p90_s": s.delay_p90,
                "unhealthy_runs": s.unhealthy_runs,
                "pre_onset_alarm_rate": columns["pre_onset_alarm_rate"],
                "clean_runs": columns["clean_runs"],
                "delay_runs": columns["delay_runs"],
            }
        )
    config = {
        "scenario": "engine-chi2",
        "runs_per_fault": runs,
        "seed": seed,
        "window": window,
        "pfa": pfa,
        "dof": dof,
        "threshold": float(threshold),
        "Ts": TS,
        "steps": steps,
        "onset_step": onset,
        "fuel_step": FUEL_STEP,
    }
    return EngineChi2Result(config, rows, records, examples)


@functools.lru_cache(maxsize=16)
def _chi2_run(steps: int, window: int):
    """One run of the KF chi-square detector on the engine (``study.Structure.run``): the filter's ``(Q, R)`` and the
    threshold are arguments, so a tuner's values share the program; one function per (steps, window)."""
    model = engine_model()
    us = jnp.full((steps, 1), FUEL_STEP)
    x0 = jnp.zeros(7)

    def run(key, f, noise, threshold, keep_history=False):
        filter_model = model._replace(Q=noise[0], R=noise[1])
        kf = kalman_filter(filter_model)
        result = monitor(
            linear_simulator(model, f),
            kf,
            chi2_detector(threshold, window),
            x0,
            kf.init(x0, filter_model.Q),
            us,
            key,
            f.onset,
            keep_history,
        )
        return result if keep_history else result.record

    return run


def plot_engine_chi2(result: EngineChi2Result) -> dict[str, Any]:
    """Two panels: one run's windowed statistic per fault, and the delay distributions, captioned; returns the figure
    by file name (``plotting.save_figures`` writes it)."""
    cfg = result.config
    t = np.arange(cfg["steps"]) * cfg["Ts"]
    fig, (ax0, ax1) = column_subplots(3.4, 1, 2)
    stats = np.asarray(result.examples.statistic)
    colors = hypothesis_colors([row["fault"] for row in result.rows])  # the engine figures' colours
    for row, stat in zip(result.rows, stats):
        ax0.semilogy(
            t, np.maximum(stat, 1e-3), lw=0.8, color=colors[row["fault"]], label=row["fault"]
        )
    ax0.axhline(
        cfg["threshold"], color="k", ls="--", lw=1, label=f"threshold {cfg['threshold']:.2f}"
    )
    ax0.axvline(cfg["onset_step"] * cfg["Ts"], color="grey", ls=":", lw=1)
    ax0.set(
        xlabel="time [s]", ylabel=f"windowed NIS (L = {cfg['window']})", title="one run per fault"
    )
    ax0.legend(fontsize=7, ncol=2)
    runs = cfg["runs_per_fault"]
    onset = np.asarray(result.records.onset)
    det = np.asarray(result.records.detection_step)
    healthy = np.asarray(result.records.first_unhealthy) < 0
    delays, labels = [], []
    for i, row in enumerate(result.rows[:-1]):
        sl = slice(i * runs, (i + 1) * runs)
        ok = (det[sl] >= 0) & healthy[sl]
        delays.append((det[sl][ok] - onset[sl][ok]) * cfg["Ts"])
        labels.append(row["fault"])
    ax1.boxplot(delays, tick_labels=labels)
    ax1.set(
        xlabel="fault",
        ylabel="detection delay [s]",
        title=f"{runs} runs per fault, Pfa = {cfg['pfa']}",
    )
    fig = caption_figure(
        fig,
        "Left: one run per fault of the Kalman filter's windowed NIS and its threshold. Right: the "
        f"detection delays of the detected runs, {runs} per fault. The paper's Table 3 has no "
        "chi-square test; this is the baseline its MM, IMM and GLRT improve on.",
    )
    return {"engine-chi2.png": fig}
