"""Streaming detection summaries: exact counts and a delay histogram, merged across Monte Carlo chunks and hosts,
for studies too large to keep every run's record.

``detection_counts`` folds a chunk of ``DetectionRecord`` s (leading run axis) into integer counts (runs, unhealthy,
faulty, detections, correct isolations, false-alarm runs and steps, pre-onset steps) and a histogram of detection
delays in steps, bins ``[b w, (b + 1) w)``, ``w = bin_width``, over ``[0, horizon)``. Counts merge by addition
(``merge_counts``): the study's summary does not depend on chunks or hosts. ``summarize_counts`` gives
``metrics.summarize_detection``'s ``DetectionSummary``: counts, rates and mean delay exact (integer sum), median and
90th percentile from the histogram; delays of the clean detected runs (no alarm before the onset).

Quantiles: NumPy's "linear" definition on sorted delays ``d_0 <= ... <= d_{n-1}``, ``d_j + (h - j)(d_{j+1} - d_j)``,
``h = (n - 1) q``, ``j = floor(h)``. The histogram gives each ``d_j``'s bin; ``d_j`` is taken as the middle of its
integer delays, ``b w + (w - 1) / 2``: within ``(w - 1) / 2`` steps of NumPy (``quantile_resolution``), exact at w=1.

``detection_reducer``: for ``monte_carlo(..., reduce=...)``, folding each chunk on the host. ``detection_summary``:
the same counts on the device in each chunk's program (``monte_carlo(..., summary=...)``), moved to the host once:
no round-trip per chunk, no per-run output kept (a GPU study of 10^8 runs holds a histogram, not 10^8 records).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxfdi import checks
from jaxfdi._studies.metrics import DetectionRecord, DetectionSummary

__all__ = ["detection_reducer", "detection_summary", "summarize_counts"]


class DetectionCounts(NamedTuple):
    """Exact counts over runs (host-side NumPy int64); merge with ``merge_counts``.

    Attributes:
      runs: () all runs
      unhealthy_runs: () runs with a step that was not healthy
      faulty_runs: () healthy runs with an onset within the horizon
      detected_runs: () of those, with an alarm at or after the onset
      labelled_runs: () faulty runs whose true label was given
      isolated_runs: () of those, detected and isolated as their label
      false_alarm_runs: () healthy runs with an alarm before the onset
      false_alarm_steps: () alarm steps before the onset (healthy runs)
      pre_onset_steps: () steps before the onset (healthy runs)
      delay_sum: () sum of the detection delays of clean detected runs, in steps
      delay_histogram: (B,) clean detected runs with delay in [b w, (b + 1) w) steps
      pre_alarm_runs: () faulty runs with an alarm before the onset (not clean)
      delay_runs: () clean detected runs (the delays' sample size)
      horizon: () steps per run
      bin_width: () w, steps per bin
    """

    runs: np.ndarray
    unhealthy_runs: np.ndarray
    faulty_runs: np.ndarray
    detected_runs: np.ndarray
    labelled_runs: np.ndarray
    isolated_runs: np.ndarray
    false_alarm_runs: np.ndarray
    false_alarm_steps: np.ndarray
    pre_onset_steps: np.ndarray
    delay_sum: np.ndarray
    delay_histogram: np.ndarray
    pre_alarm_runs: np.ndarray
    delay_runs: np.ndarray
    horizon: np.ndarray
    bin_width: np.ndarray


class Reducer(NamedTuple):
    """How ``monte_carlo`` folds outputs instead of stacking them: ``init() -> state``, ``update(state, outputs) ->
    state`` per chunk (NumPy, leading run axis), ``merge(states) -> state`` across hosts (associative)."""

    init: Callable[[], Any]
    update: Callable[[Any, Any], Any]
    merge: Callable[[list], Any]


def empty_counts(horizon: int, bin_width: int = 1) -> DetectionCounts:
    """Counts of no runs, for runs ``horizon`` steps long and delay bins ``bin_width`` wide."""
    horizon = checks.check_int("horizon", horizon, 1, meaning="a positive number of steps per run")
    bin_width = checks.check_int(
        "bin_width", bin_width, 1, meaning="a positive number of steps per delay bin"
    )
    zero = np.zeros((), np.int64)
    return DetectionCounts(
        *(zero,) * 10,
        np.zeros(-(-horizon // bin_width), np.int64),
        zero,
        zero,
        np.int64(horizon),
        np.int64(bin_width),
    )


def detection_counts(
    record: DetectionRecord, horizon: int, bin_width: int = 1, labels: Any = None
) -> DetectionCounts:
    """Counts of stacked records (leading run axis), definitions as ``summarize_detection``.

    Args:
      record: ``DetectionRecord`` with a leading run axis.
      horizon: steps per run (delays fall in ``[0, horizon)``).
      bin_width: steps per delay-histogram bin.
      labels: optional (runs,) true labels; ``isolated_runs`` counts detected faulty runs with ``record.isolated ==
        label``.
    """
    empty = empty_counts(horizon, bin_width)
    onset = np.asarray(record.onset)
    if labels is not None and np.shape(labels) != onset.shape:
        raise ValueError(
            f"labels: expected one label per run, shape {onset.shape}, got {np.shape(labels)}"
        )
    totals = _counts(np, record, np.ones(onset.shape, bool), labels, horizon, bin_width, np.int64)
    return _finish(totals, empty)


def _counts(
    xp, record: DetectionRecord, valid, labels, horizon: int, bin_width: int, integer
) -> dict:
    """``DetectionCounts`` counts (and ``delays_outside``) of the ``valid`` runs of ``record``, ``xp`` NumPy (host,
    int64) or ``jax.numpy`` (in a program)."""
    onset = xp.asarray(record.onset).astype(integer)
    valid = xp.asarray(valid, bool)
    healthy = valid & (xp.broadcast_to(xp.asarray(record.first_unhealthy), onset.shape) < 0)
    detection = xp.broadcast_to(xp.asarray(record.detection_step), onset.shape).astype(integer)
    false_alarms = xp.broadcast_to(xp.asarray(record.false_alarms), onset.shape).astype(integer)
    pre_steps = xp.broadcast_to(xp.asarray(record.pre_onset_steps), onset.shape).astype(integer)
    first_alarm = xp.broadcast_to(xp.asarray(record.first_alarm), onset.shape).astype(integer)
    longer = valid & (
        xp.maximum(pre_steps, first_alarm + 1) > horizon
    )  # the runs are longer than horizon
    faulty = (onset < horizon) & healthy
    detected = faulty & (detection >= 0)
    pre_alarm = faulty & (false_alarms > 0)
    scored = detected & ~pre_alarm  # delays of clean runs only (metrics.summarize_detection)
    delay = xp.where(scored, detection - onset, 0)
    inside = scored & (delay >= 0) & (delay < horizon)

    def count(mask):
        return xp.sum(mask, dtype=integer)

    def total(values, mask):
        return xp.sum(xp.where(mask, values, 0), dtype=integer)

    if labels is None:
        labelled = isolated = xp.zeros((), integer)
    else:
        labelled = count(faulty)
        same = xp.broadcast_to(xp.asarray(record.isolated), onset.shape) == xp.asarray(labels)
        isolated = count(detected & same)
    bins = -(-horizon // bin_width)
    index = xp.where(inside, delay // bin_width, 0)
    histogram = (
        np.bincount(index, weights=inside, minlength=bins).astype(integer)
        if xp is np
        else jax.ops.segment_sum(inside.astype(integer), index, num_segments=bins)
    )
    return dict(
        runs=count(valid),
        unhealthy_runs=count(valid & ~healthy),
        faulty_runs=count(faulty),
        detected_runs=count(detected),
        labelled_runs=labelled,
        isolated_runs=isolated,
        false_alarm_runs=count(healthy & (false_alarms > 0)),
        false_alarm_steps=total(false_alarms, healthy),
        pre_onset_steps=total(pre_steps, healthy),
        delay_sum=total(delay, inside),
        delay_histogram=histogram,
        pre_alarm_runs=count(pre_alarm),
        delay_runs=count(scored),
        delays_outside=count(scored & ~inside),
        runs_longer=count(longer),
    )


def _finish(totals: dict, empty: DetectionCounts) -> DetectionCounts:
    """``DetectionCounts`` of ``_counts``' totals (host int64); a delay outside the horizon raises (runs longer)."""
    host = {name: np.asarray(value, np.int64) for name, value in totals.items()}
    longer = int(host.pop("runs_longer"))
    if (
        longer
    ):  # as metrics.summarize_detection: an onset past a short horizon would count as fault-free
        raise ValueError(
            f"horizon: expected the runs' length, got {int(empty.horizon)}, but {longer} record(s) saw "
            f"more steps (an alarm or steps before the onset at or after step {int(empty.horizon)})"
        )
    outside = int(host.pop("delays_outside"))
    if outside:
        raise ValueError(
            f"record: {outside} detection delays outside [0, horizon = {int(empty.horizon)}); is "
            f"horizon the runs' length?"
        )
    return DetectionCounts(**host, horizon=empty.horizon, bin_width=empty.bin_width)


def merge_counts(*parts: DetectionCounts) -> DetectionCounts:
    """The counts of the union of the runs of ``parts`` (same horizon and bin width)."""
    if not parts:
        raise ValueError("parts: expected at least one DetectionCounts")
    for part in parts:
        if not isinstance(part, DetectionCounts):
            raise TypeError(
                f"parts: expected DetectionCounts (streaming.detection_counts), got "
                f"{checks.received(part)}"
            )
    first = parts[0]
    for part in parts[1:]:
        if int(part.horizon) != int(first.horizon) or int(part.bin_width) != int(first.bin_width):
            raise ValueError(
                f"parts: counts of runs of {int(first.horizon)} steps in bins of {int(first.bin_width)} "
                f"cannot be merged with {int(part.horizon)} steps in bins of {int(part.bin_width)}"
            )
    summed = [
        np.sum([np.asarray(getattr(p, name), np.int64) for p in parts], axis=0)
        for name in DetectionCounts._fields[:-2]
    ]
    return DetectionCounts(*summed, first.horizon, first.bin_width)


def quantile_resolution(counts: DetectionCounts, Ts: float = 1.0) -> float:
    """Largest gap between ``delay_quantile`` and NumPy's quantile: ``(bin_width - 1) / 2`` steps, unit of ``Ts``."""
    return (int(counts.bin_width) - 1) / 2 * Ts


def delay_quantile(counts: DetectionCounts, q: float, Ts: float = 1.0) -> float:
    """The ``q`` quantile of the detection delays from the histogram (module doc); NaN if nothing was detected."""
    checks.check_scalar("q", q, 0.0, 1.0, meaning="a quantile level in [0, 1]")
    histogram = np.asarray(counts.delay_histogram, np.int64)
    total = int(histogram.sum())
    if total == 0:
        return float("nan")
    width = int(counts.bin_width)
    cumulative = np.cumsum(histogram)

    def order_statistic(j: int) -> float:  # d_j, j = 0..total-1, as the middle of its bin
        bin_index = int(np.searchsorted(cumulative, j, side="right"))
        return bin_index * width + (width - 1) / 2

    h = (total - 1) * float(q)
    j = int(np.floor(h))
    low = order_statistic(j)
    high = order_statistic(min(j + 1, total - 1))
    return float(low + (h - j) * (high - low)) * Ts


def summarize_counts(counts: DetectionCounts, Ts: float = 1.0) -> DetectionSummary:
    """The ``DetectionSummary`` of a ``detection_reducer``'s final counts: every count and rate exact, as
    ``summarize_detection`` of the records; the median and 90th-percentile delays from the histogram, within
    ``(bin_width - 1) / 2`` steps.

    Returns:
      ``DetectionSummary`` of Python ints and floats (delays in the unit of ``Ts``); NaN where a rate or delay has no
      runs.
    """
    checks.check_positive("Ts", Ts, "a positive sample period")
    nan = float("nan")
    faulty, detected, scored = (
        int(counts.faulty_runs),
        int(counts.detected_runs),
        int(counts.delay_runs),
    )
    healthy = int(counts.runs) - int(counts.unhealthy_runs)
    pre_steps = int(counts.pre_onset_steps)
    rate = detected / faulty if faulty else nan
    return DetectionSummary(
        runs=int(counts.runs),
        faulty_runs=faulty,
        detection_rate=float(rate),
        missed_detection_rate=float(1 - rate) if faulty else nan,
        false_alarm_rate=int(counts.false_alarm_runs) / healthy if healthy else nan,
        false_alarm_rate_per_step=int(counts.false_alarm_steps) / pre_steps if pre_steps else nan,
        delay_mean=int(counts.delay_sum) / scored * Ts if scored else nan,
        delay_median=delay_quantile(counts, 0.5, Ts),
        delay_p90=delay_quantile(counts, 0.9, Ts),
        unhealthy_runs=int(counts.unhealthy_runs),
        pre_onset_alarm_rate=int(counts.pre_alarm_runs) / faulty if faulty else nan,
        clean_runs=faulty - int(counts.pre_alarm_runs),
        delay_runs=scored,
    )


def isolation_rate(counts: DetectionCounts) -> float:
    """Correctly isolated / labelled faulty runs (NaN when no labels were given)."""
    labelled = int(counts.labelled_runs)
    return int(counts.isolated_runs) / labelled if labelled else float("nan")


def detection_reducer(
    horizon: int,
    bin_width: int = 1,
    record: Callable[[Any], DetectionRecord] | None = None,
    label: Callable[[Any], Any] | None = None,
) -> Reducer:
    """A ``Reducer`` of ``DetectionCounts`` for ``monte_carlo(..., reduce=...)``; ``record(outputs)`` picks the
    records from ``run_one``'s outputs (default: the outputs), ``label(outputs)`` the true labels (optional).

    Returns:
      ``Reducer(init, update, merge)``: ``init()`` gives empty ``DetectionCounts`` (``ceil(horizon / bin_width)``
      delay bins); ``update(counts, outputs)`` adds a chunk's ``detection_counts``; ``merge(states)`` sums hosts'
      counts (``merge_counts``). ``summarize_counts`` turns the final counts into a ``DetectionSummary``.
    """
    empty_counts(horizon, bin_width)  # checks the arguments now
    pick = record or (lambda outputs: outputs)

    def update(counts: DetectionCounts, outputs) -> DetectionCounts:
        labels = None if label is None else label(outputs)
        return merge_counts(counts, detection_counts(pick(outputs), horizon, bin_width, labels))

    return Reducer(
        lambda: empty_counts(horizon, bin_width), update, lambda states: merge_counts(*states)
    )


class DeviceSummary(NamedTuple):
    """Detection counts summed on the device by ``monte_carlo(..., summary=...)``.

    Attributes:
      summary: ``summary(outputs, weight) -> (None, totals)``, what ``monte_carlo``'s ``summary`` takes
      counts: ``counts(totals) -> DetectionCounts``, the counts of ``monte_carlo``'s ``totals``
    """

    summary: Callable[[Any, Any], Any]
    counts: Callable[[Any], DetectionCounts]


def detection_summary(
    horizon: int,
    bin_width: int = 1,
    record: Callable[[Any], DetectionRecord] | None = None,
    label: Callable[[Any], Any] | None = None,
) -> DeviceSummary:
    """``detection_counts`` on the device: ``monte_carlo(run_one, key, n, summary=s.summary)`` returns
    ``(None, totals)``, ``s.counts(totals)`` the ``DetectionCounts`` of all ``n`` runs, equal to ``detection_counts``
    of their records (last chunk's padding weighs 0). ``record``/``label`` as in ``detection_reducer``. Counts in
    JAX's default integer (int64 with ``jaxfdi.enable_x64()``, else int32: exact up to 2^31 - 1 steps); a delay
    outside ``[0, horizon)`` cannot raise in the program, so it is counted apart and ``counts`` raises
    ``detection_counts``' ``ValueError``.

    Returns:
      ``DeviceSummary(summary, counts)``; ``summarize_counts(s.counts(totals))`` is the ``DetectionSummary``.
    """
    empty = empty_counts(horizon, bin_width)  # checks the arguments now
    pick = record or (lambda outputs: outputs)

    def summary(outputs, weight):
        labels = None if label is None else label(outputs)
        return None, _counts(
            jnp, pick(outputs), weight, labels, horizon, bin_width, jnp.result_type(int)
        )

    return DeviceSummary(summary, lambda totals: _finish(totals, empty))
