"""Detection and isolation metrics, accumulated inside the scan or summarised over runs.

Definitions (``../shared/spec/README.md``): the detection delay is the first step at or
after the fault onset whose decision is "fault", minus the onset; a false alarm is a
"fault" decision before the onset (or anywhere in a fault-free run, whose onset is
``faults.NEVER``); a run with no alarm at or after the onset is a missed detection.
Isolation is correct when the isolated label equals the injected one.

``DetectionRecord`` is a tiny per-run carry, so a Monte Carlo study of 10^5 runs keeps
a handful of numbers a run instead of whole histories. A detector that also isolates
(IMM mode probabilities, GLRT, signature matching) reports a label with each decision;
the record keeps the label at the detection step (isolation = the first mode that
crosses) and the detector's estimate (e.g. a fault magnitude) ``estimate_delay`` steps
after it.
"""
from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array


class DetectionRecord(NamedTuple):
    onset: Array            # () int, fault onset step (NEVER when fault-free)
    first_alarm: Array      # () int, first alarm anywhere, -1 if none
    detection_step: Array   # () int, first alarm at/after onset, -1 if none
    false_alarms: Array     # () int, number of alarm steps before the onset
    pre_onset_steps: Array  # () int, number of steps seen before the onset
    isolated: Array = -1    # () int, label at the detection step (-1: none / not isolating)
    first_label: Array = -1  # () int, label at the first alarm (a false alarm's label)
    estimate: Array = float("nan")  # () float, estimate of the isolated fault, latest within estimate_delay steps after detection


def record_init(onset: Array, dtype=None) -> DetectionRecord:
    minus_one = jnp.asarray(-1, jnp.int32)
    zero = jnp.asarray(0, jnp.int32)
    nan = jnp.asarray(jnp.nan, dtype or jnp.result_type(float))
    return DetectionRecord(jnp.asarray(onset, jnp.int32), minus_one, minus_one, zero, zero, minus_one, minus_one, nan)


def record_update(
    record: DetectionRecord, k: Array, alarm: Array, label: Array = -1, estimate: Array | None = None,
    estimate_delay: int = 0,
) -> DetectionRecord:
    """Fold the decision of step ``k`` (alarm, isolated label, estimate) into the record."""
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
        estimate_value = jnp.where(keep_updating, jnp.asarray(estimate, record.estimate.dtype), record.estimate)
    return DetectionRecord(
        record.onset,
        jnp.where(new_first, k, record.first_alarm),
        detection,
        record.false_alarms + (alarm & before).astype(jnp.int32),
        record.pre_onset_steps + before.astype(jnp.int32),
        jnp.where(new_detection, label, record.isolated),
        jnp.where(new_first, label, record.first_label),
        estimate_value,
    )


def record_from_alarms(alarms: Array, onset: Array) -> DetectionRecord:
    """The same record computed from a whole (T,) alarm history at once."""
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
    )


class DetectionSummary(NamedTuple):
    """Summary over runs (host-side NumPy). Delays in the unit of ``Ts``."""

    runs: int
    faulty_runs: int
    detection_rate: float          # detected / faulty runs
    missed_detection_rate: float   # 1 - detection_rate
    false_alarm_rate: float        # runs with >= 1 alarm before onset / runs
    false_alarm_rate_per_step: float  # alarm steps before onset / steps before onset
    delay_mean: float
    delay_median: float
    delay_p90: float


def summarize_detection(record: DetectionRecord, horizon: int, Ts: float = 1.0) -> DetectionSummary:
    """Summarise stacked records (leading run axis) of runs ``horizon`` steps long."""
    onset = np.asarray(record.onset)
    detection = np.asarray(record.detection_step)
    faulty = onset < horizon
    detected = faulty & (detection >= 0)
    delays = (detection[detected] - onset[detected]) * Ts
    n_faulty = int(faulty.sum())
    pre_steps = int(np.asarray(record.pre_onset_steps).sum())
    nan = float("nan")
    rate = detected.sum() / n_faulty if n_faulty else nan
    return DetectionSummary(
        runs=int(onset.size),
        faulty_runs=n_faulty,
        detection_rate=float(rate),
        missed_detection_rate=float(1 - rate) if n_faulty else nan,
        false_alarm_rate=float(np.mean(np.asarray(record.false_alarms) > 0)) if onset.size else nan,
        false_alarm_rate_per_step=float(np.asarray(record.false_alarms).sum() / pre_steps) if pre_steps else nan,
        delay_mean=float(delays.mean()) if delays.size else nan,
        delay_median=float(np.median(delays)) if delays.size else nan,
        delay_p90=float(np.percentile(delays, 90)) if delays.size else nan,
    )


def confusion_matrix(true_labels: Array, predicted_labels: Array, num_classes: int) -> Array:
    """``M[i, j]`` = number of runs with true label ``i`` isolated as ``j``.

    Negative predictions (nothing isolated) are counted in an extra last column, so
    ``M`` is (num_classes, num_classes + 1).
    """
    true_labels = jnp.asarray(true_labels, jnp.int32)
    predicted = jnp.asarray(predicted_labels, jnp.int32)
    predicted = jnp.where(predicted < 0, num_classes, predicted)
    flat = true_labels * (num_classes + 1) + predicted
    counts = jnp.bincount(flat.ravel(), length=num_classes * (num_classes + 1))
    return counts.reshape(num_classes, num_classes + 1)


def isolation_accuracy(confusion: Array) -> Array:
    """Per true class, the fraction of runs isolated as that class."""
    confusion = jnp.asarray(confusion)
    diagonal = jnp.diagonal(confusion[:, : confusion.shape[0]])
    return diagonal / jnp.maximum(confusion.sum(axis=1), 1)
