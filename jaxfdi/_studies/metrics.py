"""Detection and isolation metrics, accumulated inside the scan or summarised over runs.

Definitions (``../shared/spec/README.md``): detection delay = first "fault" decision at or after the onset minus the
onset; false alarm = a "fault" decision before the onset (anywhere in a fault-free run, onset ``faults.NEVER``);
missed detection = no alarm at or after the onset; isolation correct = isolated label equals the injected one.
**Delays are scored only in clean runs** (no alarm before the onset): an alarm standing at the onset is the false
alarm, not a zero-delay detection. Table columns per fault: ``fault_row`` and ``DetectionSummary``.

``DetectionRecord`` is a small per-run carry (10^5 runs keep a few numbers each, not histories); for isolating
detectors (IMM mode probabilities, GLRT, signature matching) it keeps the label at the detection step (the first
mode that crosses) and the estimate (e.g. fault magnitude) ``estimate_delay`` steps later.

Health: a run whose filter lost positive-definiteness or whose statistic went NaN is *unhealthy* from that step
(``first_unhealthy``; pass ``healthy = step_health(info.healthy, statistic)``); summaries count it in ``runs`` and
``unhealthy_runs`` only (a NaN statistic never crosses: an all-NaN run is not a clean "no false alarm, missed
detection" run). An *infinite* statistic is evidence: filters report a dead sensor as ``nis = +inf``
(``filters._base``), detectors alarm on it, and it is scored like any fault (detected, isolated, delay).

Several episodes per run (``EpisodeRecord``; e.g. a GPS/INS flight with four satellite faults): episode ``e``
(``faults.episodes``: onset, end, label) owns ``[onset_e, close_e)``, ``close_e = min(end_e + grace, next onset)``
(earliest later onset of another episode), so a late alarm is credited to the episode active then. Its first alarm
there detects it (delay = step - onset; isolated = the label then). ``grace`` (steps, default 0): the detector's
memory (a windowed test alarms about a window after a transient fault clears). Alarm steps outside all windows are
false alarms (count, first step). Same-onset episodes share a window: detected by the same alarm, each isolated only
by its own label.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.faults import NEVER


class DetectionRecord(NamedTuple):
    """One run's detection outcome: onset, first alarm, detection step, false alarms, isolation and health.

    Attributes:
      onset: () int, fault onset step (NEVER when fault-free)
      first_alarm: () int, first alarm anywhere, -1 if none
      detection_step: () int, first alarm at/after onset, -1 if none
      false_alarms: () int, number of alarm steps before the onset
      pre_onset_steps: () int, number of steps seen before the onset
      isolated: () int, label at the detection step (-1: none / not isolating)
      first_label: () int, label at the first alarm (a false alarm's label)
      estimate: () float, estimate of the isolated fault, latest within estimate_delay steps
          after detection
      first_unhealthy: () int, first step that was not healthy, -1 if the run stayed healthy
    """

    onset: Array
    first_alarm: Array
    detection_step: Array
    false_alarms: Array
    pre_onset_steps: Array
    isolated: Array = -1
    first_label: Array = -1
    estimate: Array = float("nan")
    first_unhealthy: Array = -1


def step_health(healthy: Array, *values) -> Array:
    """() bool: ``healthy`` and no NaN in any leaf of ``values`` (e.g. ``step_health(info.healthy, statistic)``);
    an infinite value (a dead sensor's statistic) is evidence, not ill health.

    Returns:
      bool array of ``healthy``'s shape (() for a scalar flag): ``healthy`` and no NaN anywhere in ``values``.
    """
    ok = jnp.asarray(healthy, bool)
    for leaf in jax.tree.leaves(values):
        ok = ok & ~jnp.any(jnp.isnan(jnp.asarray(leaf)))
    return ok


def record_init(onset: Array, dtype=None) -> DetectionRecord:
    """An empty record of a run whose fault starts at step ``onset`` (int >= 0; ``faults.NEVER``: fault-free)."""
    checks.check_int_array(
        "onset", onset, 0, meaning="a fault onset step >= 0 (faults.NEVER: fault-free)"
    )
    minus_one = jnp.asarray(-1, jnp.int32)
    zero = jnp.asarray(0, jnp.int32)
    nan = jnp.asarray(jnp.nan, dtype or jnp.result_type(float))
    return DetectionRecord(
        jnp.asarray(onset, jnp.int32),
        minus_one,
        minus_one,
        zero,
        zero,
        minus_one,
        minus_one,
        nan,
        minus_one,
    )


def record_update(
    record: DetectionRecord,
    k: Array,
    alarm: Array,
    label: Array = -1,
    estimate: Array | None = None,
    estimate_delay: int = 0,
    healthy: Array = True,
) -> DetectionRecord:
    """Fold step ``k``'s decision (alarm, label, estimate) into the record; ``healthy`` False marks the run
    unhealthy from ``k`` on (``step_health``)."""
    checks.check_int_array("estimate_delay", estimate_delay, 0, meaning="a number of steps >= 0")
    k = jnp.asarray(k, jnp.int32)
    label = jnp.asarray(label, jnp.int32)
    before = k < record.onset
    new_first = (record.first_alarm < 0) & alarm
    new_detection = (record.detection_step < 0) & alarm & ~before
    detection = jnp.where(new_detection, k, record.detection_step)
    estimate_value = record.estimate
    if estimate is not None:
        # the estimate of the isolated fault: steps whose label has moved on do not count
        isolated = jnp.where(new_detection, label, record.isolated)
        keep_updating = (detection >= 0) & (k <= detection + estimate_delay) & (label == isolated)
        estimate_value = jnp.where(
            keep_updating, jnp.asarray(estimate, record.estimate.dtype), record.estimate
        )
    return DetectionRecord(
        record.onset,
        jnp.where(new_first, k, record.first_alarm),
        detection,
        record.false_alarms + (alarm & before).astype(jnp.int32),
        record.pre_onset_steps + before.astype(jnp.int32),
        jnp.where(new_detection, label, record.isolated),
        jnp.where(new_first, label, record.first_label),
        estimate_value,
        _first_unhealthy(record.first_unhealthy, k, healthy),
    )


def _first_unhealthy(first: Array, k: Array, healthy: Array) -> Array:
    first = jnp.asarray(first, jnp.int32)
    return jnp.where((first < 0) & ~jnp.asarray(healthy, bool), k, first)


def record_from_alarms(
    alarms: Array, onset: Array, healthy: Array | None = None
) -> DetectionRecord:
    """The same record from a whole (T,) alarm history (bool, or integers: nonzero is an alarm; and optional (T,)
    bool ``healthy``) at once.

    Returns:
      ``DetectionRecord`` of scalar int32 fields (first alarm, detection step, false alarms, pre-onset steps,
      first unhealthy step); ``isolated`` and ``first_label`` -1 and ``estimate`` NaN (no labels or estimates).
    """
    if checks._kind(alarms) not in "biu":
        raise TypeError(
            f"alarms: expected a (T,) bool alarm history, got {checks.received(alarms)}"
        )
    checks.check_shape("alarms", alarms, (None,), "a (T,) alarm history")
    checks.check_int_array(
        "onset", onset, 0, meaning="a fault onset step >= 0 (faults.NEVER: fault-free)"
    )
    if healthy is not None:
        checks.check_shape(
            "healthy", healthy, checks.shape_of(alarms), "one flag per step of alarms"
        )
    alarms = jnp.asarray(alarms) != 0  # an integer history: any nonzero entry is an alarm
    k = jnp.arange(alarms.shape[0])
    before = k < onset
    after = alarms & ~before

    def first(mask):
        return jnp.where(jnp.any(mask), jnp.argmax(mask), -1).astype(jnp.int32)

    minus_one = jnp.asarray(-1, jnp.int32)
    return DetectionRecord(
        jnp.asarray(onset, jnp.int32),
        first(alarms),
        first(after),
        jnp.sum(alarms & before).astype(jnp.int32),
        jnp.sum(before).astype(jnp.int32),
        minus_one,
        minus_one,
        jnp.asarray(jnp.nan),
        minus_one if healthy is None else first(~jnp.asarray(healthy, bool)),
    )


class DetectionSummary(NamedTuple):
    """Summary over runs (host-side NumPy); delays in the unit of ``Ts``; rates and delays over healthy runs only.

    Attributes:
      runs: all runs, healthy or not
      faulty_runs: healthy runs with an onset within the horizon
      detection_rate: detected / faulty runs
      missed_detection_rate: 1 - detection_rate
      false_alarm_rate: healthy runs with >= 1 alarm before onset / healthy runs
      false_alarm_rate_per_step: alarm steps before onset / steps before onset (healthy runs)
      delay_mean: over the clean detected runs (no alarm before the onset)
      delay_median: median over the same runs
      delay_p90: 90th percentile over the same runs
      unhealthy_runs: runs with a step that was not healthy (left out of the rates)
      pre_onset_alarm_rate: faulty runs with an alarm before the onset / faulty runs
      clean_runs: faulty runs with no alarm before the onset
      delay_runs: clean runs that were detected: the delays' sample size
    """

    runs: int
    faulty_runs: int
    detection_rate: float
    missed_detection_rate: float
    false_alarm_rate: float
    false_alarm_rate_per_step: float
    delay_mean: float
    delay_median: float
    delay_p90: float
    unhealthy_runs: int = 0
    pre_onset_alarm_rate: float = float("nan")
    clean_runs: int = 0
    delay_runs: int = 0

    def to_frame(self, level: float = 0.95):
        """The summary as a one-row pandas DataFrame, each run rate beside its two-sided ``level`` Clopper-Pearson
        interval (``_low``, ``_high``; ``rate_interval``) over its own denominator: ``faulty_runs`` for the detection,
        missed-detection and pre-onset alarm rates, the healthy runs (``runs - unhealthy_runs``) for the false-alarm
        rate; NaN where the rate has none. The per-step rate has no interval (its steps are not independent)."""
        import pandas as pd

        over = {
            "detection_rate": self.faulty_runs,
            "missed_detection_rate": self.faulty_runs,
            "false_alarm_rate": self.runs - self.unhealthy_runs,
            "pre_onset_alarm_rate": self.faulty_runs,
        }
        row = {}
        for name, value in self._asdict().items():
            row[name] = value
            if name in over:
                row[f"{name}_low"], row[f"{name}_high"] = rate_bounds(value, over[name], level)
        return pd.DataFrame([row])

    def _repr_html_(self) -> str:
        return self.to_frame().to_html(index=False, na_rep="-", float_format="{:.4g}".format)


def summarize_detection(record: DetectionRecord, horizon: int, Ts: float = 1.0) -> DetectionSummary:
    """Summarise stacked records (leading run axis) of runs ``horizon`` steps long.

    Unhealthy runs (``first_unhealthy >= 0``) count in ``runs`` and ``unhealthy_runs`` only. Raises ``ValueError``
    if a record saw a step at or after ``horizon`` (an alarm, or more pre-onset steps): the runs are longer, and
    faults with an onset past a too-short horizon would be scored as fault-free.

    Returns:
      ``DetectionSummary`` of Python ints and floats; NaN where a rate or delay has no runs.
    """
    checks.check_int("horizon", horizon, 1, meaning="a positive number of steps per run")
    checks.check_positive("Ts", Ts, "a positive sample period")
    seen = np.maximum(np.asarray(record.pre_onset_steps), np.asarray(record.first_alarm) + 1)
    if np.any(seen > horizon):
        raise ValueError(
            f"horizon: expected the runs' length, got {horizon}, but {int(np.sum(seen > horizon))} "
            f"record(s) saw {int(np.max(seen))} steps"
        )
    onset = np.asarray(record.onset)
    healthy = np.broadcast_to(np.asarray(record.first_unhealthy) < 0, onset.shape)
    detection = np.asarray(record.detection_step)
    false_alarms = np.broadcast_to(np.asarray(record.false_alarms), onset.shape)[healthy]
    faulty = (onset < horizon) & healthy
    detected = faulty & (detection >= 0)
    pre_alarm = faulty & (np.broadcast_to(np.asarray(record.false_alarms), onset.shape) > 0)
    clean = faulty & ~pre_alarm
    scored = clean & detected
    delays = (detection[scored] - onset[scored]) * Ts
    n_faulty = int(faulty.sum())
    pre_steps = int(np.broadcast_to(np.asarray(record.pre_onset_steps), onset.shape)[healthy].sum())
    nan = float("nan")
    rate = detected.sum() / n_faulty if n_faulty else nan
    return DetectionSummary(
        runs=int(onset.size),
        faulty_runs=n_faulty,
        detection_rate=float(rate),
        missed_detection_rate=float(1 - rate) if n_faulty else nan,
        false_alarm_rate=float(np.mean(false_alarms > 0)) if false_alarms.size else nan,
        false_alarm_rate_per_step=float(false_alarms.sum() / pre_steps) if pre_steps else nan,
        delay_mean=float(delays.mean()) if delays.size else nan,
        delay_median=float(np.median(delays)) if delays.size else nan,
        delay_p90=float(np.percentile(delays, 90)) if delays.size else nan,
        unhealthy_runs=int((~healthy).sum()),
        pre_onset_alarm_rate=float(pre_alarm.sum() / n_faulty) if n_faulty else nan,
        clean_runs=int(clean.sum()),
        delay_runs=int(scored.sum()),
    )


def delay_statistics(onset, first_alarm, detection_step, Ts: float = 1.0) -> dict:
    """The delay columns from per-run (R,) arrays of faulty runs (host-side, for studies with their own records):
    ``onset``, ``first_alarm`` (anywhere, -1 none), ``detection_step`` (at/after the onset, -1 none).

    Returns:
      dict of ``pre_onset_alarm_rate`` (float), ``clean_runs``, ``delay_runs`` (int) and ``delay_mean``,
      ``delay_median``, ``delay_p90`` (floats, unit of ``Ts``) over the clean detected runs; NaN where there are none.
    """
    checks.check_positive("Ts", Ts, "a positive sample period")
    onset, first, detection = (
        np.asarray(a).astype(np.int64).ravel() for a in (onset, first_alarm, detection_step)
    )
    if not onset.shape == first.shape == detection.shape:
        raise ValueError(
            f"onset, first_alarm, detection_step: expected three (R,) arrays, got shapes "
            f"{onset.shape}, {first.shape}, {detection.shape}"
        )
    pre_alarm = (first >= 0) & (first < onset)
    scored = ~pre_alarm & (detection >= 0)
    delays = (detection[scored] - onset[scored]) * Ts
    nan = float("nan")
    return {
        "pre_onset_alarm_rate": float(pre_alarm.mean()) if onset.size else nan,
        "clean_runs": int((~pre_alarm).sum()),
        "delay_runs": int(scored.sum()),
        "delay_mean": float(delays.mean()) if delays.size else nan,
        "delay_median": float(np.median(delays)) if delays.size else nan,
        "delay_p90": float(np.percentile(delays, 90)) if delays.size else nan,
    }


def fault_row(
    record: DetectionRecord, horizon: int, Ts: float = 1.0, label: int | None = None
) -> dict:
    """The per-fault table columns from stacked records of one fault's (or the fault-free) runs: ``runs``,
    ``unhealthy_runs``, ``detection_rate``, ``isolation_rate`` (faulty runs detected with ``record.isolated ==
    label`` / faulty runs; NaN without ``label`` or fault-free), ``false_alarm_rate`` (runs alarming before the onset
    / healthy runs; for faulty runs = ``pre_onset_alarm_rate``), ``pre_onset_alarm_rate``, ``clean_runs``,
    ``delay_runs``, ``delay_mean_s``, ``delay_median_s``, ``delay_p90_s`` (unit of ``Ts``; as ``DetectionSummary``).

    Returns:
      dict of those eleven columns, in that order: Python ints (counts) and floats (rates, delays), NaN where a
      rate or delay has no runs.
    """
    s = summarize_detection(record, horizon, Ts)
    onset = np.asarray(record.onset)
    healthy = np.broadcast_to(np.asarray(record.first_unhealthy) < 0, onset.shape)
    faulty = (onset < horizon) & healthy
    isolation = float("nan")
    if label is not None and faulty.any():
        isolated = np.broadcast_to(np.asarray(record.isolated), onset.shape)
        detected = np.broadcast_to(np.asarray(record.detection_step), onset.shape) >= 0
        isolation = float(np.mean((isolated == label) & detected, where=faulty))
    return {
        "runs": s.runs,
        "unhealthy_runs": s.unhealthy_runs,
        "detection_rate": s.detection_rate,
        "isolation_rate": isolation,
        "false_alarm_rate": s.false_alarm_rate,
        "pre_onset_alarm_rate": s.pre_onset_alarm_rate,
        "clean_runs": s.clean_runs,
        "delay_runs": s.delay_runs,
        "delay_mean_s": s.delay_mean,
        "delay_median_s": s.delay_median,
        "delay_p90_s": s.delay_p90,
    }


def unhealthy_warning(unhealthy: int, runs: int, detail: str = "", what: str = "") -> str:
    """The console line a study prints when runs went numerically bad ("" if none); ``detail`` (e.g. the count
    per fault) goes in the brackets, ``what`` (e.g. the method) before the count.

    Returns:
      str: ``"WARNING: <what>: <unhealthy> of <runs> runs went numerically bad (...)"``, or ``""`` when
      ``unhealthy`` is 0.
    """
    if not unhealthy:
        return ""
    detail = f": {detail}" if detail else ""
    what = f"{what}: " if what else ""
    return (
        f"WARNING: {what}{unhealthy} of {runs} runs went numerically bad (filter unhealthy or non-finite "
        f"statistic{detail}); they are excluded from the rates above"
    )


def unhealthy_rows_warning(rows: list[dict], what: str = "") -> str:
    """``unhealthy_warning`` for table rows (dicts with ``runs``, ``fault``, maybe ``unhealthy_runs``), per fault.

    Returns:
      str: the warning line over all rows, the unhealthy count of each such fault in the brackets; ``""`` when no
      row has unhealthy runs.
    """
    bad = [r for r in rows if r.get("unhealthy_runs")]
    return unhealthy_warning(
        sum(r["unhealthy_runs"] for r in bad),
        sum(r["runs"] for r in rows),
        ", ".join(f"{r['fault']} {r['unhealthy_runs']}" for r in bad),
        what,
    )


def confusion_matrix(true_labels: Array, predicted_labels: Array, num_classes: int) -> Array:
    """``M[i, j]`` = number of runs with true label ``i`` isolated as ``j``, (num_classes, num_classes + 1).

    The last column counts negative predictions (nothing isolated). A label outside ``[0, num_classes)`` (true, or
    a prediction >= num_classes) is refused, not dropped: every run counts once.
    """
    num_classes = checks.check_int(
        "num_classes", num_classes, 1, meaning="a positive number of classes"
    )
    checks.check_int_array("true_labels", true_labels, 0, num_classes - 1, "class labels")
    checks.check_int_array(
        "predicted_labels",
        predicted_labels,
        None,
        num_classes - 1,
        "class labels (negative: nothing isolated)",
    )
    if checks.shape_of(true_labels) != checks.shape_of(predicted_labels):
        raise ValueError(
            f"predicted_labels: expected the shape of true_labels {checks.shape_of(true_labels)}, got "
            f"{checks.shape_of(predicted_labels)}"
        )
    true_labels = jnp.asarray(true_labels, jnp.int32)
    predicted = jnp.asarray(predicted_labels, jnp.int32)
    predicted = jnp.where(predicted < 0, num_classes, predicted)
    flat = true_labels * (num_classes + 1) + predicted
    counts = jnp.bincount(flat.ravel(), length=num_classes * (num_classes + 1))
    return counts.reshape(num_classes, num_classes + 1)


class EpisodeRecord(NamedTuple):
    """Per-run record of several fault episodes (E of them; see the module docstring).

    Attributes:
      onset: (E,) int, episode onsets (NEVER: no episode)
      close: (E,) int, first step after each episode's detection window
      label: (E,) int, true label of each episode
      detection_step: (E,) int, first alarm in [onset, close), -1 if none
      isolated: (E,) int, label at the detection step, -1 if none
      false_alarms: () int, alarm steps outside every window
      first_false_alarm: () int, first such step, -1 if none
      outside_steps: () int, steps seen outside every window
      steps: () int, steps seen
      first_unhealthy: () int, first step that was not healthy, -1 if none
    """

    onset: Array
    close: Array
    label: Array
    detection_step: Array
    isolated: Array
    false_alarms: Array
    first_false_alarm: Array
    outside_steps: Array
    steps: Array
    first_unhealthy: Array

    @property
    def delay(self) -> Array:
        """(E,) int: detection step - onset, -1 where the episode was not detected."""
        return jnp.where(self.detection_step >= 0, self.detection_step - self.onset, -1)


def episode_record_init(onsets: Array, ends: Array, labels: Array, grace: int = 0) -> EpisodeRecord:
    """An empty record for episodes ``(onsets, ends, labels)``, each (E,) (``faults.episodes``).

    Window of episode ``e``: ``[onset_e, min(end_e + grace, min{onset_j > onset_e}))``.
    """
    checks.check_int_array("grace", grace, 0, meaning="a number of steps >= 0")
    checks.check_int_array(
        "onsets", onsets, 0, meaning="episode onset steps >= 0 (faults.NEVER: no episode)"
    )
    onsets, ends, labels = (jnp.asarray(a, jnp.int32) for a in (onsets, ends, labels))
    if onsets.ndim != 1 or ends.shape != onsets.shape or labels.shape != onsets.shape:
        raise ValueError(
            f"onsets, ends, labels: expected three (E,) arrays, got shapes "
            f"{onsets.shape}, {ends.shape}, {labels.shape}"
        )
    if isinstance(grace, (int, np.integer)) and grace < 0:
        raise ValueError(f"grace: expected an integer >= 0 (steps), got {grace}")
    later = onsets[None, :] > onsets[:, None]
    next_onset = jnp.min(jnp.where(later, onsets[None, :], NEVER), axis=1, initial=NEVER)
    close = jnp.minimum(jnp.minimum(ends, NEVER) + jnp.asarray(grace, jnp.int32), next_onset)
    minus_one, zero = jnp.asarray(-1, jnp.int32), jnp.asarray(0, jnp.int32)
    none = jnp.full(onsets.shape, -1, jnp.int32)
    return EpisodeRecord(
        onsets, close.astype(jnp.int32), labels, none, none, zero, minus_one, zero, zero, minus_one
    )


def episode_record_update(
    record: EpisodeRecord, k: Array, alarm: Array, label: Array = -1, healthy: Array = True
) -> EpisodeRecord:
    """Fold the decision of step ``k`` (alarm, isolated label, health) into the record."""
    k = jnp.asarray(k, jnp.int32)
    alarm = jnp.asarray(alarm, bool)
    inside = (k >= record.onset) & (k < record.close)
    new_detection = (record.detection_step < 0) & alarm & inside
    outside = ~jnp.any(inside)
    false_alarm = alarm & outside
    return EpisodeRecord(
        record.onset,
        record.close,
        record.label,
        jnp.where(new_detection, k, record.detection_step),
        jnp.where(new_detection, jnp.asarray(label, jnp.int32), record.isolated),
        record.false_alarms + false_alarm.astype(jnp.int32),
        jnp.where((record.first_false_alarm < 0) & false_alarm, k, record.first_false_alarm),
        record.outside_steps + outside.astype(jnp.int32),
        record.steps + 1,
        _first_unhealthy(record.first_unhealthy, k, healthy),
    )


class EpisodeSummary(NamedTuple):
    """Summary of stacked ``EpisodeRecord``s (host-side NumPy) per episode index ``e`` ((E,) arrays), over healthy
    runs in which ``e`` began (unhealthy: ``runs``, ``unhealthy_runs`` only); delays in the unit of ``Ts``.

    Attributes:
      runs: all runs
      unhealthy_runs: runs with a step that was not healthy (left out of the rates)
      episodes: (E,) healthy runs in which episode e began (onset < steps)
      detection_rate: (E,) detected / episodes
      isolation_rate: (E,) isolated as its label / episodes
      delay_mean: (E,) over detected episodes
      delay_median: (E,) median over detected episodes
      delay_p90: (E,) 90th percentile over detected episodes
      false_alarm_runs: healthy runs with >= 1 alarm outside every window
      false_alarm_rate: false_alarm_runs / healthy runs
      false_alarm_rate_per_step: false-alarm steps / steps outside every window (healthy runs)
    """

    runs: int
    unhealthy_runs: int
    episodes: np.ndarray
    detection_rate: np.ndarray
    isolation_rate: np.ndarray
    delay_mean: np.ndarray
    delay_median: np.ndarray
    delay_p90: np.ndarray
    false_alarm_runs: int
    false_alarm_rate: float
    false_alarm_rate_per_step: float


def summarize_episodes(records: EpisodeRecord, Ts: float = 1.0) -> EpisodeSummary:
    """Summarise stacked records (leading run axis R; episode leaves (R, E)).

    Returns:
      ``EpisodeSummary``: Python ints and floats for the run counts and false-alarm rates, (E,) NumPy arrays per
      episode (delays in the unit of ``Ts``); NaN where a rate or delay has no runs.
    """
    checks.check_positive("Ts", Ts, "a positive sample period")
    onset, label = np.asarray(records.onset), np.asarray(records.label)
    detection, isolated = np.asarray(records.detection_step), np.asarray(records.isolated)
    runs = onset.shape[0]
    healthy = np.asarray(records.first_unhealthy) < 0
    began = (onset < np.asarray(records.steps)[:, None]) & healthy[:, None]
    detected = began & (detection >= 0)
    correct = began & detected & (isolated == label)
    count = began.sum(axis=0)
    nan = float("nan")
    with np.errstate(invalid="ignore", divide="ignore"):
        detection_rate = np.where(count > 0, detected.sum(axis=0) / np.maximum(count, 1), nan)
        isolation_rate = np.where(count > 0, correct.sum(axis=0) / np.maximum(count, 1), nan)
    stats = []
    for e in range(onset.shape[1]):
        delays = (detection[detected[:, e], e] - onset[detected[:, e], e]) * Ts
        stats.append(
            (delays.mean(), np.median(delays), np.percentile(delays, 90))
            if delays.size
            else (nan,) * 3
        )
    stats = np.asarray(stats, float).reshape(onset.shape[1], 3)
    false_alarms = np.asarray(records.false_alarms)[healthy]
    outside = int(np.asarray(records.outside_steps)[healthy].sum())
    return EpisodeSummary(
        runs=int(runs),
        unhealthy_runs=int((~healthy).sum()),
        episodes=count,
        detection_rate=detection_rate,
        isolation_rate=isolation_rate,
        delay_mean=stats[:, 0],
        delay_median=stats[:, 1],
        delay_p90=stats[:, 2],
        false_alarm_runs=int((false_alarms > 0).sum()),
        false_alarm_rate=float(np.mean(false_alarms > 0)) if false_alarms.size else nan,
        false_alarm_rate_per_step=float(false_alarms.sum() / outside) if outside else nan,
    )


def binomial_interval(trials: int, p: float, level: float = 0.99) -> tuple[int, int]:
    """Central ``level`` interval ``[low, high]`` of a Binomial(``trials``, ``p``) count (``scipy.stats.binom``),
    e.g. the alarm counts of a detector with design false-alarm probability ``p``: ``low`` / ``high`` the smallest
    k with ``P(X <= k) >= (1 - level) / 2`` / ``>= 1 - (1 - level) / 2``.

    Returns:
      ``(low, high)``: two ints in ``[0, trials]``, counts.
    """
    from scipy import stats

    trials = checks.check_int("trials", trials, 0, meaning="a number of trials >= 0")
    checks.check_probability("p", p, open_interval=False)
    checks.check_probability("level", level)
    tail = (1.0 - level) / 2.0
    return int(stats.binom.ppf(tail, trials, p)), int(stats.binom.ppf(1.0 - tail, trials, p))


def rate_interval(successes: int, trials: int, level: float = 0.99) -> tuple[float, float]:
    """Two-sided Clopper-Pearson (1934) ``level`` interval of a rate, ``k = successes`` of ``n = trials``.

    ``[B^-1(a/2; k, n-k+1), B^-1(1-a/2; k+1, n-k)]``, ``a = 1 - level``, ``B^-1`` the beta quantile
    (``scipy.stats.beta.ppf``); 0 when ``k = 0``, 1 when ``k = n``. Every binomial bound of the library is this one.

    Returns:
      ``(low, high)``: floats in [0, 1] bounding the rate ``k / n``; both NaN without trials.
    """
    from scipy import stats

    trials = checks.check_int("trials", trials, 0, meaning="a number of trials >= 0")
    successes = checks.check_int(
        "successes", successes, 0, trials, meaning=f"a count in [0, trials = {trials}]"
    )
    checks.check_probability("level", level)
    if trials == 0:
        return float("nan"), float("nan")
    tail = (1.0 - level) / 2.0
    low = 0.0 if successes == 0 else float(stats.beta.ppf(tail, successes, trials - successes + 1))
    high = (
        1.0
        if successes == trials
        else float(stats.beta.ppf(1.0 - tail, successes + 1, trials - successes))
    )
    return low, high


def rate_bounds(rate: Any, n: Any, level: float) -> tuple[float, float]:
    """``rate_interval`` of ``rate`` over ``n`` runs; NaN without a rate or runs, or where ``rate * n`` is no count."""
    nan = float("nan")
    if (
        rate is None
        or n is None
        or isinstance(rate, (str, bool))
        or not math.isfinite(rate)
        or not n > 0
    ):
        return nan, nan
    count = rate * n
    if abs(count - round(count)) > 1e-6:
        return nan, nan
    return rate_interval(int(round(count)), int(n), level)


def mean_interval(values, level: float = 0.95) -> tuple[float, float, float]:
    """``(mean, low, high)`` of (R,) per-run values: the normal ``level`` interval of the mean over runs,
    ``mean +- z sd / sqrt(R)`` (``z`` the ``(1 + level) / 2`` normal quantile, ``sd`` with ``ddof = 1``); NaN bounds
    with fewer than two runs or a non-finite run, NaN mean without runs.

    Returns:
      three floats.
    """
    from scipy import stats

    values = np.asarray(values, float).ravel()
    nan = float("nan")
    mean = float(values.mean()) if values.size else nan
    if values.size < 2 or not math.isfinite(mean):
        return mean, nan, nan
    half = float(stats.norm.ppf(0.5 + level / 2) * values.std(ddof=1) / math.sqrt(values.size))
    return mean, mean - half, mean + half


def rate_text(successes: int, trials: int, level: float = 0.95, digits: int = 2) -> str:
    """``"0.97 [0.93,0.99]"``: the rate (``digits`` decimals) and its two-sided Clopper-Pearson ``level`` interval
    (``rate_interval``); ``"-"`` without trials."""
    if trials == 0:
        return "-"
    low, high = rate_interval(successes, trials, level)
    return f"{successes / trials:.{digits}f} [{low:.2f},{high:.2f}]"


def rate_cell(rate, trials: int, width: int = 16, digits: int = 2) -> str:
    """``rate_text`` (95 % interval) of ``rate`` over ``trials`` runs, right-aligned in ``width``; ``-`` with no
    rate (NaN, no runs), blank for ``None`` (a method that does not decide that).

    Returns:
      str of at least ``width`` characters, e.g. ``"0.97 [0.93,0.99]"`` (the count is ``round(rate * trials)``).
    """
    if rate is None:
        return " " * width
    if rate != rate or not trials:
        return f"{'-':>{width}}"
    return f"{rate_text(round(rate * trials), trials, digits=digits):>{width}}"


def cell(value, spec: str = ".3f", width: int = 0, missing: str = "-") -> str:
    """``format(value, spec)`` right-aligned in ``width``; ``missing`` for ``None`` or a non-finite number.

    Returns:
      str of at least ``width`` characters.
    """
    absent = value is None or (
        isinstance(value, (int, float, np.number)) and not np.isfinite(value)
    )
    return f"{missing if absent else format(value, spec):>{width}}"


def binomial_lower_bound(successes: int, trials: int, confidence: float = 0.95) -> float:
    """One-sided Clopper-Pearson lower bound ``B^-1(1 - confidence; k, n-k+1)`` (``rate_interval`` at level
    ``2 confidence - 1``); 0 when none succeeded, NaN without trials.

    Returns:
      float in [0, 1]: a bound below the rate ``successes / trials`` at ``confidence``.
    """
    return _one_sided_interval(successes, trials, confidence)[0]


def binomial_upper_bound(successes: int, trials: int, confidence: float = 0.95) -> float:
    """One-sided Clopper-Pearson upper bound ``B^-1(confidence; k+1, n-k)`` (``rate_interval`` at level
    ``2 confidence - 1``); 1 when all succeeded, NaN without trials."""
    return _one_sided_interval(successes, trials, confidence)[1]


def _one_sided_interval(successes: int, trials: int, confidence: float) -> tuple[float, float]:
    checks.check_scalar(
        "confidence",
        confidence,
        0.5,
        1.0,
        low_open=True,
        high_open=True,
        meaning="a one-sided confidence in (0.5, 1)",
    )
    return rate_interval(successes, trials, 2.0 * confidence - 1.0)
