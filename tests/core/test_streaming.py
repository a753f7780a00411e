"""Streaming detection counts against metrics.summarize_detection on the full records:
counts and rates exact, mean delay exact, median and p90 exact with 1-step bins and
within the stated resolution with wider ones; merging is order-free; monte_carlo folds
chunks into the same counts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfdi
from jaxfdi import DetectionRecord, record_from_alarms, streaming, summarize_detection

HORIZON = 400


def synthetic_records(num_runs: int, seed: int = 0):
    """Records of runs with random onsets (a third fault-free), detections, false alarms,
    isolated labels and unhealthy runs; and the true labels."""
    rng = np.random.default_rng(seed)
    onset = np.where(
        rng.random(num_runs) < 1 / 3,
        jaxfdi._simulation.faults.NEVER,
        rng.integers(0, HORIZON, num_runs),
    )
    faulty = onset < HORIZON
    delay = rng.geometric(0.05, num_runs) - 1
    detected = faulty & (rng.random(num_runs) < 0.9) & (onset + delay < HORIZON)
    detection = np.where(detected, onset + delay, -1)
    pre = np.minimum(onset, HORIZON)
    false_alarms = np.where(rng.random(num_runs) < 0.1, rng.integers(1, 5, num_runs), 0)
    labels = rng.integers(1, 4, num_runs)
    isolated = np.where(
        detected, np.where(rng.random(num_runs) < 0.8, labels, rng.integers(1, 4, num_runs)), -1
    )
    unhealthy = np.where(rng.random(num_runs) < 0.02, rng.integers(0, HORIZON, num_runs), -1)
    record = DetectionRecord(
        onset.astype(np.int32),
        -np.ones(num_runs, np.int32),
        detection.astype(np.int32),
        false_alarms.astype(np.int32),
        pre.astype(np.int32),
        isolated.astype(np.int32),
        -np.ones(num_runs, np.int32),
        np.full(num_runs, np.nan),
        unhealthy.astype(np.int32),
    )
    return record, labels


def _chunks(record, bounds):
    return [jax.tree.map(lambda a: a[lo:hi], record) for lo, hi in zip(bounds[:-1], bounds[1:])]


@pytest.mark.parametrize("Ts", [1.0, 0.02])
def test_merged_counts_equal_the_full_summary(Ts):
    record, labels = synthetic_records(6000)
    bounds = [0, 1, 700, 2500, 2501, 6000]
    parts = [
        streaming.detection_counts(r, HORIZON, 1, labels[lo:hi])
        for r, lo, hi in zip(_chunks(record, bounds), bounds[:-1], bounds[1:])
    ]
    merged = streaming.merge_counts(*parts)
    assert streaming.merge_counts(*parts[::-1])._asdict().keys() == merged._asdict().keys()
    for a, b in zip(streaming.merge_counts(*parts[::-1]), merged):
        np.testing.assert_array_equal(a, b)
    got, want = streaming.summarize_counts(merged, Ts), summarize_detection(record, HORIZON, Ts)
    for name in ("runs", "faulty_runs", "unhealthy_runs", "clean_runs", "delay_runs"):
        assert getattr(got, name) == getattr(want, name), name
    for name in (
        "detection_rate",
        "missed_detection_rate",
        "false_alarm_rate",
        "false_alarm_rate_per_step",
        "pre_onset_alarm_rate",
    ):
        assert getattr(got, name) == getattr(want, name), name
    np.testing.assert_allclose(got.delay_mean, want.delay_mean, rtol=1e-14)
    np.testing.assert_allclose(
        [got.delay_median, got.delay_p90], [want.delay_median, want.delay_p90], rtol=1e-12
    )
    assert streaming.quantile_resolution(merged, Ts) == 0.0
    # isolation against a plain count
    healthy = record.first_unhealthy < 0
    faulty = healthy & (record.onset < HORIZON)
    correct = faulty & (record.detection_step >= 0) & (record.isolated == labels)
    assert int(merged.isolated_runs) == correct.sum() and int(merged.labelled_runs) == faulty.sum()
    assert streaming.isolation_rate(merged) == correct.sum() / faulty.sum()


@pytest.mark.parametrize("bin_width", [3, 10, 64])
def test_wide_bins_quantiles_within_the_resolution(bin_width):
    record, _ = synthetic_records(3000, seed=1)
    counts = streaming.detection_counts(record, HORIZON, bin_width)
    want = summarize_detection(record, HORIZON)
    got = streaming.summarize_counts(counts)
    resolution = streaming.quantile_resolution(counts)
    assert resolution == (bin_width - 1) / 2
    assert abs(got.delay_median - want.delay_median) <= resolution
    assert abs(got.delay_p90 - want.delay_p90) <= resolution
    assert got.delay_mean == pytest.approx(want.delay_mean, rel=1e-14)  # the mean stays exact
    delays = (record.detection_step - record.onset)[
        (record.detection_step >= 0) & (record.first_unhealthy < 0) & (record.onset < HORIZON)
    ]
    for q in (0.0, 0.25, 0.99, 1.0):
        assert abs(streaming.delay_quantile(counts, q) - np.quantile(delays, q)) <= resolution


def test_monte_carlo_reduce_equals_the_records():
    """monte_carlo with a detection_reducer (chunks of 48, 130 runs) returns the counts of
    the records it would have stacked."""
    T = 60

    def run_one(key, onset):
        alarms = jax.random.uniform(key, (T,)) < jnp.where(jnp.arange(T) >= onset, 0.3, 0.01)
        return record_from_alarms(alarms, onset)

    onsets = np.where(np.arange(130) % 3 == 0, jaxfdi._simulation.faults.NEVER, 20).astype(np.int32)
    records = jaxfdi.monte_carlo(run_one, jax.random.key(2), 130, onsets, chunk_size=48)
    counts = jaxfdi.monte_carlo(
        run_one,
        jax.random.key(2),
        130,
        onsets,
        chunk_size=48,
        reduce=streaming.detection_reducer(T, bin_width=2),
    )
    for a, b in zip(counts, streaming.detection_counts(records, T, 2)):
        np.testing.assert_array_equal(a, b)
    assert int(counts.runs) == 130


@pytest.mark.parametrize("chunk_size", [37, 512])
def test_device_summary_equals_the_host_counts_of_the_same_records(chunk_size):
    """The counts summed on the device (``detection_summary``: inside each chunk's
    program, padded runs weighted 0, one transfer at the end) equal ``detection_counts``
    of the same runs' records exactly, for any chunking, labels included (synthetic
    records with unhealthy, fault-free and false-alarm runs); so do the quantiles read
    from the histogram (exact with 1-step bins, within ``quantile_resolution`` with
    4-step bins against NumPy's on the records)."""
    record, labels = synthetic_records(3000, seed=4)
    data = (record, labels)
    for width in (1, 4):
        device = streaming.detection_summary(
            HORIZON, width, record=lambda out: out[0], label=lambda out: out[1]
        )
        kept, totals = jaxfdi.monte_carlo(
            lambda key, d: d,
            jax.random.key(0),
            3000,
            data,
            chunk_size=chunk_size,
            summary=device.summary,
        )
        assert kept is None
        got, want = (
            device.counts(totals),
            streaming.detection_counts(record, HORIZON, width, labels),
        )
        for name, a, b in zip(streaming.DetectionCounts._fields, got, want):
            np.testing.assert_array_equal(a, b, err_msg=name)
        full = summarize_detection(record, HORIZON)
        resolution = streaming.quantile_resolution(got)
        assert resolution == (width - 1) / 2
        summary = streaming.summarize_counts(got)
        assert abs(summary.delay_median - full.delay_median) <= resolution
        assert abs(summary.delay_p90 - full.delay_p90) <= resolution
        # independently of the host counts (the same _counts on NumPy): metrics.summarize_detection on the records and
        # a plain count of correct isolations; the padded runs of the last chunk must weigh nothing in either
        for name in (
            "runs",
            "faulty_runs",
            "unhealthy_runs",
            "clean_runs",
            "delay_runs",
            "detection_rate",
            "false_alarm_rate",
            "false_alarm_rate_per_step",
            "pre_onset_alarm_rate",
        ):
            assert getattr(summary, name) == getattr(full, name), name
        np.testing.assert_allclose(summary.delay_mean, full.delay_mean, rtol=1e-14)
        faulty = (record.first_unhealthy < 0) & (record.onset < HORIZON)
        correct = faulty & (record.detection_step >= 0) & (record.isolated == labels)
        assert int(got.isolated_runs) == correct.sum() and int(got.labelled_runs) == faulty.sum()
    late = record._replace(
        onset=np.zeros(3000, np.int32),
        detection_step=np.full(3000, 450, np.int32),
        first_unhealthy=-np.ones(3000, np.int32),
        false_alarms=np.zeros(3000, np.int32),
    )
    device = streaming.detection_summary(HORIZON)
    _, totals = jaxfdi.monte_carlo(
        lambda key, d: d,
        jax.random.key(0),
        3000,
        late,
        chunk_size=chunk_size,
        summary=device.summary,
    )
    with pytest.raises(ValueError, match="outside"):
        device.counts(totals)


def test_bad_input():
    record, _ = synthetic_records(10)
    with pytest.raises(ValueError, match="bin_width"):
        streaming.detection_counts(record, HORIZON, 0)
    late = record._replace(
        onset=np.zeros(10, np.int32),
        detection_step=np.full(10, 50, np.int32),
        first_unhealthy=-np.ones(10, np.int32),
    )
    with pytest.raises(ValueError, match="horizon"):
        streaming.detection_counts(late, 20)  # a delay of 50 steps in runs of 20
    with pytest.raises(ValueError, match="parts"):
        streaming.merge_counts(streaming.empty_counts(10, 1), streaming.empty_counts(10, 2))
    with pytest.raises(ValueError, match="labels"):
        streaming.detection_counts(record, HORIZON, 1, np.zeros(3))
    with pytest.raises(TypeError, match="reduce"):
        jaxfdi.monte_carlo(lambda k, x: x, jax.random.key(0), 3, np.zeros(3), reduce=object())
    assert np.isnan(streaming.delay_quantile(streaming.empty_counts(10), 0.5))
