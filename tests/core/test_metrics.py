"""Detection metrics and window statistics against brute-force Python references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfdi
from jaxfdi import (
    NEVER,
    DetectionRecord,
    delay_statistics,
    fault_row,
    record_from_alarms,
    step_health,
    summarize_detection,
    unhealthy_warning,
)
from jaxfdi._studies.metrics import confusion_matrix, record_init, record_update
from jaxfdi.detection import chi2_detector, first_crossing, moving_window_sum
from jaxfdi.detection._chi2 import normalized_innovation_squared


def reference_record(alarms, onset):
    first = next((k for k, a in enumerate(alarms) if a), -1)
    detection = next((k for k, a in enumerate(alarms) if a and k >= onset), -1)
    false_alarms = sum(1 for k, a in enumerate(alarms) if a and k < onset)
    return onset, first, detection, false_alarms, sum(1 for k in range(len(alarms)) if k < onset)


@pytest.fixture(scope="module")
def random_alarms():
    rng = np.random.default_rng(0)
    alarms = rng.random((200, 30)) < rng.uniform(0.0, 0.2, size=(200, 1))
    onsets = rng.integers(0, 40, size=200)  # some beyond the horizon: fault-free runs
    onsets[:10] = NEVER
    return alarms, onsets


def test_streaming_record_equals_batch_record_equals_brute_force(random_alarms):
    alarms, onsets = random_alarms

    def streaming(alarm_row, onset):
        def body(record, ka):
            return record_update(record, *ka), None

        return jax.lax.scan(body, record_init(onset), (jnp.arange(alarm_row.shape[0]), alarm_row))[
            0
        ]

    stream = jax.jit(jax.vmap(streaming))(alarms, onsets)
    batch = jax.jit(jax.vmap(record_from_alarms))(alarms, onsets)
    for i in range(alarms.shape[0]):
        ref = reference_record(list(alarms[i]), int(onsets[i]))
        assert tuple(int(x[i]) for x in stream[:5]) == ref
        assert tuple(int(x[i]) for x in batch[:5]) == ref


def test_an_integer_alarm_history_counts_every_nonzero_step_as_an_alarm(random_alarms):
    """Integer alarms (a count, a label) are alarms where nonzero, as the brute force reads them;
    a bitwise ``&`` with the bool masks once dropped even values."""
    alarms, onsets = random_alarms
    labels = np.where(alarms, np.random.default_rng(5).integers(1, 7, alarms.shape), 0)
    batch = jax.vmap(record_from_alarms)(jnp.asarray(labels, jnp.int32), onsets)
    for i in range(alarms.shape[0]):
        ref = reference_record([bool(a) for a in labels[i]], int(onsets[i]))
        assert tuple(int(x[i]) for x in batch[:5]) == ref


def test_first_unhealthy_streaming_and_batch_equal_first_bad_step(random_alarms):
    alarms, onsets = random_alarms
    rng = np.random.default_rng(4)
    healthy = rng.random(alarms.shape) > rng.choice([0.0, 0.0, 0.05], size=(alarms.shape[0], 1))

    def streaming(alarm_row, healthy_row, onset):
        def body(record, step):
            k, alarm, ok = step
            return record_update(record, k, alarm, -1, None, 0, ok), None

        return jax.lax.scan(
            body, record_init(onset), (jnp.arange(alarm_row.shape[0]), alarm_row, healthy_row)
        )[0]

    stream = jax.jit(jax.vmap(streaming))(alarms, healthy, onsets)
    batch = jax.jit(jax.vmap(record_from_alarms))(alarms, onsets, healthy)
    assert (
        int(record_init(5).first_unhealthy) == -1
        and int(record_from_alarms(alarms[0], 5).first_unhealthy) == -1
    )
    for i in range(alarms.shape[0]):
        first_bad = next((k for k, ok in enumerate(healthy[i]) if not ok), -1)
        assert int(stream.first_unhealthy[i]) == first_bad == int(batch.first_unhealthy[i])
        # health does not change the detection fields
        assert tuple(int(x[i]) for x in stream[:5]) == reference_record(
            list(alarms[i]), int(onsets[i])
        )
    assert 0 < np.sum(np.asarray(stream.first_unhealthy) >= 0) < alarms.shape[0]


def test_step_health_is_healthy_and_no_value_nan():
    """NaN is ill health; an infinite statistic is a dead sensor's evidence (an alarm)."""
    finite = (jnp.ones(3), {"s": jnp.asarray(2.0)}, jnp.arange(2))
    assert bool(step_health(True, *finite)) and not bool(step_health(False, *finite))
    assert not bool(step_health(True, jnp.ones(3).at[1].set(jnp.nan), 1.0))
    assert not bool(step_health(jnp.asarray(True), {"s": jnp.asarray(jnp.nan)}))
    for evidence in (jnp.inf, -jnp.inf):
        assert bool(step_health(True, jnp.ones(3).at[1].set(evidence), 1.0))
    assert bool(jax.jit(step_health)(True, jnp.zeros(2))) and bool(step_health(True))


def test_record_keeps_label_at_detection_and_estimate_after_a_delay():
    rng = np.random.default_rng(5)
    T, delay = 40, 3
    for trial in range(20):
        alarms = rng.random(T) < 0.15
        labels = rng.integers(1, 6, T)
        estimates = rng.normal(size=T)
        onset = int(rng.integers(0, 45))
        record = record_init(onset)
        for k in range(T):
            record = record_update(
                record, k, bool(alarms[k]), int(labels[k]), float(estimates[k]), delay
            )
        first, detection = reference_record(list(alarms), onset)[1:3]
        assert int(record.isolated) == (labels[detection] if detection >= 0 else -1)
        assert int(record.first_label) == (labels[first] if first >= 0 else -1)
        if detection >= 0:  # the last estimate within the delay whose label is the isolated one
            window = range(detection, min(detection + delay, T - 1) + 1)
            last = max(j for j in window if labels[j] == labels[detection])
            assert float(record.estimate) == estimates[last]
        else:
            assert np.isnan(float(record.estimate))


def test_summary_on_hand_made_records():
    # 4 runs of 100 steps, Ts = 0.1 s: onsets 50, 50, 60 and a fault-free run
    onset = np.array([50, 50, 60, NEVER])
    records = DetectionRecord(
        onset=onset,
        first_alarm=np.array([10, 55, -1, 70]),
        detection_step=np.array([52, 55, -1, -1]),
        false_alarms=np.array([1, 0, 0, 3]),
        pre_onset_steps=np.array([50, 50, 60, 100]),
    )
    s = summarize_detection(records, horizon=100, Ts=0.1)
    assert s.runs == 4 and s.faulty_runs == 3
    assert s.detection_rate == pytest.approx(2 / 3) and s.missed_detection_rate == pytest.approx(
        1 / 3
    )
    assert s.false_alarm_rate == pytest.approx(2 / 4)
    assert s.false_alarm_rate_per_step == pytest.approx(4 / 260)
    # run 0's alarm stood before its onset: a false-alarm run, its "delay" 0.2 s is not scored
    assert (
        s.pre_onset_alarm_rate == pytest.approx(1 / 3) and s.clean_runs == 2 and s.delay_runs == 1
    )
    assert s.delay_median == pytest.approx(0.5) and s.delay_mean == pytest.approx(0.5)
    assert s.delay_p90 == pytest.approx(0.5)
    assert s.unhealthy_runs == 0


def test_unhealthy_runs_are_counted_apart_and_never_scored_clean():
    """The same four runs plus two unhealthy ones: an all-NaN run that shows no alarm
    (which would otherwise be a clean missed detection and no false alarm) and an
    unhealthy fault-free run. Every rate and delay equals the healthy four's."""
    onset = np.array([50, 50, 60, NEVER, 50, NEVER])
    records = DetectionRecord(
        onset=onset,
        first_alarm=np.array([10, 55, -1, 70, -1, -1]),
        detection_step=np.array([52, 55, -1, -1, -1, -1]),
        false_alarms=np.array([1, 0, 0, 3, 0, 0]),
        pre_onset_steps=np.array([50, 50, 60, 100, 50, 100]),
        first_unhealthy=np.array([-1, -1, -1, -1, 0, 37]),
    )
    s = summarize_detection(records, horizon=100, Ts=0.1)
    first_four = jax.tree.map(lambda a: np.asarray(a)[:4] if np.ndim(a) else a, records)
    healthy_only = summarize_detection(first_four, horizon=100, Ts=0.1)
    assert s.runs == 6 and s.unhealthy_runs == 2 and s.faulty_runs == 3
    assert s._replace(runs=4, unhealthy_runs=0) == healthy_only
    assert s.detection_rate == pytest.approx(2 / 3) and s.false_alarm_rate == pytest.approx(2 / 4)
    assert s.false_alarm_rate_per_step == pytest.approx(4 / 260)
    all_bad = summarize_detection(records._replace(first_unhealthy=np.zeros(6, int)), horizon=100)
    assert all_bad.unhealthy_runs == 6 and all_bad.faulty_runs == 0
    assert all(
        np.isnan(getattr(all_bad, name))
        for name in ("detection_rate", "false_alarm_rate", "delay_median")
    )
    assert unhealthy_warning(0, 6) == ""
    assert unhealthy_warning(2, 6).startswith("WARNING: 2 of 6 runs went numerically bad")


@pytest.fixture(scope="module")
def nan_run():
    """A KF (no missing_measurements) chi-square monitor (window 2) on the engine fed one
    NaN measurement on sensor 2 at step 20 (a one-step dead sensor), with its history."""
    from jaxfdi import fault, monitor, sensor_labels
    from jaxfdi.models import engine_model

    model = engine_model()
    kf = jaxfdi.filters.kalman_filter(model)
    # fault() refuses a NaN magnitude; the corrupted sensor is built by hand on purpose
    f = fault("bias", "sensor", 2, 20, 0.0, end=21)._replace(magnitude=jnp.asarray(jnp.nan))
    run = jax.jit(
        lambda key: monitor(
            jaxfdi.linear_simulator(model, f),
            kf,
            chi2_detector(30.0, 2),
            jnp.zeros(7),
            kf.init(jnp.zeros(7), model.Q),
            jnp.full((40, 1), 0.01),
            key,
            20,
            True,
            channel_labels=sensor_labels(*model.dims[1:]),
        )
    )
    return run(jax.random.key(0))


def test_a_dead_sensor_sample_is_a_detected_and_isolated_fault(nan_run):
    """The NaN sample is evidence: the filter stays healthy, the step alarms with
    ``statistic = +inf`` and the simulator's label of the dead sensor, the window holds
    the alarm one more step and then recovers; scored, the run is a healthy detection
    with delay 0 and the dead sensor isolated (the record folded by hand agrees)."""
    record, history = nan_run
    statistic, alarm = np.asarray(history.statistic), np.asarray(history.alarm)
    assert np.isnan(np.asarray(history.truth.measurement)[20, 2])  # the premise
    assert np.asarray(history.info.healthy).all()
    assert np.all(statistic[20:22] == np.inf) and alarm[20:22].all()
    assert np.all(np.isfinite(statistic[:20])) and np.all(np.isfinite(statistic[22:]))  # recovered
    assert int(history.label[20]) == int(history.truth.mode[20]) > 0
    folded = record_init(20)
    for k in range(40):
        ok = step_health(history.info.healthy[k], history.statistic[k])
        folded = record_update(folded, k, history.alarm[k], history.label[k], None, 0, ok)
    assert int(folded.first_unhealthy) == int(record.first_unhealthy) == -1
    assert int(folded.first_alarm) == int(record.first_alarm) == 20 and int(record.isolated) == int(
        history.truth.mode[20]
    )
    s = summarize_detection(jax.tree.map(lambda a: np.asarray(a)[None], record), 40)
    assert s.runs == 1 and s.unhealthy_runs == 0 and s.faulty_runs == 1 and s.detection_rate == 1.0
    assert s.delay_median == 0.0


def test_a_nan_statistic_is_unhealthy_and_never_clean():
    """A NaN statistic (broken numerics, not data) never alarms, so scored as an alarm
    sequence it would be a clean run; step_health marks the run unhealthy from that step
    and the summary leaves it out of every rate."""
    statistic = np.concatenate([np.full(20, 1.0), np.full(20, np.nan)])
    record = record_init(20)
    for k in range(40):
        record = record_update(
            record, k, statistic[k] > 30.0, -1, None, 0, step_health(True, statistic[k])
        )
    assert int(record.first_unhealthy) == 20 and int(record.first_alarm) == -1
    s = summarize_detection(jax.tree.map(lambda a: np.asarray(a)[None], record), 40)
    assert (
        s.runs == 1 and s.unhealthy_runs == 1 and s.faulty_runs == 0 and np.isnan(s.detection_rate)
    )
    assert np.isnan(s.false_alarm_rate) and np.isnan(s.delay_median)


def test_a_horizon_shorter_than_the_runs_is_refused():
    """Runs of 40 steps with onsets at 10 and 30: summarised over a horizon of 20, the
    onset 30 would be scored as a fault-free run; the records say they saw more steps."""
    alarms = np.zeros((2, 40), bool)
    alarms[:, 35] = True
    records = jax.vmap(record_from_alarms)(jnp.asarray(alarms), jnp.asarray([10, 30]))
    assert summarize_detection(records, 40).detection_rate == 1.0
    with pytest.raises(
        ValueError, match="horizon: expected the runs' length, got 20, but 2 record"
    ):
        summarize_detection(records, 20)


def test_confusion_matrix_equals_counting():
    rng = np.random.default_rng(1)
    true = rng.integers(0, 4, 500)
    predicted = np.where(rng.random(500) < 0.7, true, rng.integers(-1, 4, 500))
    M = np.asarray(confusion_matrix(true, predicted, 4))
    brute = np.zeros((4, 5), int)
    for t, p in zip(true, predicted):
        brute[t, 4 if p < 0 else p] += 1
    np.testing.assert_array_equal(M, brute)


def test_window_sum_first_crossing_and_online_detector_equal_references():
    rng = np.random.default_rng(2)
    x = rng.chisquare(3, size=(50, 4))
    for window in (1, 3, 7):
        expected = np.stack([x[max(0, k - window + 1) : k + 1].sum(0) for k in range(50)])
        np.testing.assert_allclose(moving_window_sum(jnp.asarray(x), window), expected, rtol=1e-12)
        threshold = 3.0 * window + 4.0
        crossing = np.asarray(first_crossing(jnp.asarray(expected), threshold, start=5))
        for j in range(4):
            hits = [k for k in range(5, 50) if expected[k, j] > threshold]
            assert crossing[j] == (hits[0] if hits else -1)
        detector = chi2_detector(threshold, window)

        def body(state, value):
            return detector.step(state, value)

        _, decision = jax.lax.scan(body, detector.init(), jnp.asarray(x[:, 0]))
        np.testing.assert_allclose(decision.statistic, expected[:, 0], rtol=1e-12)
        np.testing.assert_array_equal(decision.alarm, expected[:, 0] > threshold)


def test_nis_equals_explicit_inverse():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(10, 4, 4))
    S = A @ np.swapaxes(A, 1, 2) + np.eye(4)
    r = rng.normal(size=(10, 4))
    expected = np.einsum("ki,kij,kj->k", r, np.linalg.inv(S), r)
    np.testing.assert_allclose(
        normalized_innovation_squared(jnp.asarray(r), jnp.asarray(S)), expected, rtol=1e-10
    )


def brute_force_columns(alarms, onset, labels, true_label, horizon, Ts):
    """Issue 27's per-fault columns by a plain loop over each run's alarm sequence."""
    faulty = detected = isolated = pre = 0
    delays = []
    for row, o, lab in zip(alarms, onset, labels):
        if o >= horizon:
            continue
        faulty += 1
        before = any(row[k] for k in range(min(o, len(row))))
        after = [k for k in range(o, len(row)) if row[k]]
        pre += before
        if after:
            detected += 1
            isolated += lab[after[0]] == true_label
            if not before:
                delays.append((after[0] - o) * Ts)
    nan = float("nan")
    return {
        "detection_rate": detected / faulty,
        "isolation_rate": isolated / faulty,
        "pre_onset_alarm_rate": pre / faulty,
        "clean_runs": faulty - pre,
        "delay_runs": len(delays),
        "delay_mean_s": float(np.mean(delays)) if delays else nan,
        "delay_median_s": float(np.median(delays)) if delays else nan,
        "delay_p90_s": float(np.percentile(delays, 90)) if delays else nan,
    }


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_delays_scored_only_in_runs_without_a_pre_onset_alarm_equal_brute_force(seed):
    """Random alarm sequences (alarm rates 0-30 % a step, some runs alarming from step 0),
    random onsets and labels: ``fault_row`` (through the scan's ``record_update``) and
    ``delay_statistics`` equal a plain loop that scores a delay only in runs with no alarm
    before the onset."""
    rng = np.random.default_rng(seed)
    runs, T, Ts, true_label = 300, 40, 0.01, 2
    alarms = rng.random((runs, T)) < rng.uniform(0.0, 0.3, size=(runs, 1))
    alarms[:20, 0] = True  # an alarm standing from the first step
    onset = rng.integers(0, T, size=runs)
    labels = rng.integers(0, 4, size=(runs, T))

    def streaming(alarm_row, label_row, o):
        def body(record, kal):
            return record_update(record, *kal), None

        return jax.lax.scan(body, record_init(o), (jnp.arange(T), alarm_row, label_row))[0]

    records = jax.jit(jax.vmap(streaming))(alarms, labels, onset)
    got = fault_row(records, T, Ts, label=true_label)
    want = brute_force_columns(alarms, onset, labels, true_label, T, Ts)
    assert (
        0 < want["pre_onset_alarm_rate"] < 1 and want["delay_runs"] > 10
    )  # both kinds of run are there
    for key, value in want.items():
        assert got[key] == pytest.approx(value, rel=1e-12), key
    stats = delay_statistics(onset, records.first_alarm, records.detection_step, Ts)
    for key in ("pre_onset_alarm_rate", "clean_runs", "delay_runs"):
        assert stats[key] == want[key], key
    for key in ("delay_mean", "delay_median", "delay_p90"):
        assert stats[key] == pytest.approx(want[key + "_s"], rel=1e-12), key
    # the old definition (every detected run) differs on these runs: the change is real
    old = [(int(d) - o) * Ts for d, o in zip(records.detection_step, onset) if d >= 0]
    assert np.mean(old) < want["delay_mean_s"]


def test_fault_row_of_fault_free_runs_and_of_runs_all_alarming_before_the_onset():
    never = np.full(5, NEVER)
    alarms = np.zeros((5, 20), bool)
    alarms[:2, 3] = True
    records = jax.vmap(record_from_alarms)(jnp.asarray(alarms), jnp.asarray(never))
    row = fault_row(records, 20, label=1)
    assert row["false_alarm_rate"] == pytest.approx(0.4) and np.isnan(row["isolation_rate"])
    assert (
        np.isnan(row["detection_rate"]) and row["clean_runs"] == 0 and np.isnan(row["delay_mean_s"])
    )
    standing = jax.vmap(record_from_alarms)(jnp.ones((4, 20), bool), jnp.full(4, 10))
    row = fault_row(standing, 20, 0.1)
    assert row["detection_rate"] == 1.0 and row["pre_onset_alarm_rate"] == 1.0
    assert row["clean_runs"] == 0 and row["delay_runs"] == 0 and np.isnan(row["delay_median_s"])
    with pytest.raises(ValueError, match="onset, first_alarm, detection_step"):
        delay_statistics(np.zeros(3), np.zeros(2), np.zeros(3))


@pytest.mark.parametrize("trials, p", [(50, 0.1), (1000, 0.005), (7, 0.5), (200, 0.9)])
def test_binomial_interval_equals_the_brute_force_cdf(trials, p):
    """``binomial_interval`` against the exact CDF summed term by term in fractions of
    ``math.comb`` (no SciPy): the smallest counts at which it reaches each tail level."""
    import math
    from fractions import Fraction

    from jaxfdi import binomial_interval

    q = Fraction(p).limit_denominator(10**6)
    cdf, acc = [], Fraction(0)
    for k in range(trials + 1):
        acc += math.comb(trials, k) * q**k * (1 - q) ** (trials - k)
        cdf.append(acc)
    low = next(k for k, c in enumerate(cdf) if c >= Fraction(5, 1000))
    high = next(k for k, c in enumerate(cdf) if c >= Fraction(995, 1000))
    assert binomial_interval(trials, p, 0.99) == (low, high)


def test_rate_interval_is_the_clopper_pearson_beta_quantiles():
    """Two-sided Clopper-Pearson: ``[Beta.ppf(a/2; k, n-k+1), Beta.ppf(1-a/2; k+1, n-k)]``,
    0 and 1 at the ends (SciPy's beta distribution)."""
    from scipy import stats

    from jaxfdi._studies.metrics import rate_interval, rate_text

    for k, n, level in (
        (0, 10, 0.99),
        (3, 10, 0.95),
        (10, 10, 0.99),
        (454, 10000, 0.99),
        (1, 1, 0.5),
    ):
        low, high = rate_interval(k, n, level)
        a = 1.0 - level
        np.testing.assert_allclose(
            low, 0.0 if k == 0 else stats.beta.ppf(a / 2, k, n - k + 1), atol=1e-12
        )
        np.testing.assert_allclose(
            high, 1.0 if k == n else stats.beta.ppf(1 - a / 2, k + 1, n - k), atol=1e-12
        )
    assert all(np.isnan(rate_interval(0, 0)))
    low, high = rate_interval(97, 100, 0.95)
    assert rate_text(97, 100) == f"0.97 [{low:.2f},{high:.2f}]" and rate_text(0, 0) == "-"
    with pytest.raises(ValueError, match="successes"):
        rate_interval(11, 10)
    with pytest.raises(ValueError, match="level"):
        rate_interval(1, 10, 1.5)


def test_table_cells_show_a_dash_where_there_is_no_number():
    """``cell``: ``format`` right-aligned, the ``missing`` text for None, NaN and +-inf;
    ``rate_cell``: ``rate_text`` of ``round(rate n)`` of ``n`` right-aligned, ``-`` for a
    NaN rate or no runs, blank for ``None`` (no such rate)."""
    from jaxfdi._studies.metrics import cell, rate_cell, rate_text

    assert (
        cell(1.23456, ".2f", 7) == "   1.23"
        and cell(7, ".4g") == "7"
        and cell(np.float32(0.5), ".1f") == "0.5"
    )
    for missing in (None, float("nan"), np.inf, -np.inf, np.float32("nan")):
        assert cell(missing, ".2f", 4) == "   -" and cell(missing, ".0f", missing="n/a") == "n/a"
    assert rate_cell(0.97, 100) == f"{rate_text(97, 100):>16}" and len(rate_cell(0.97, 100)) == 16
    assert rate_cell(0.3333, 3, 0, digits=3) == rate_text(1, 3, digits=3)
    for rate, n in ((float("nan"), 10), (0.5, 0)):
        assert rate_cell(rate, n, 19) == " " * 18 + "-"
    assert rate_cell(None, 10, 19) == " " * 19


def test_one_sided_bounds_are_the_beta_quantiles():
    """Lower ``Beta.ppf(1-c; k, n-k+1)``, upper ``Beta.ppf(c; k+1, n-k)``, 0 and 1 at the ends."""
    from scipy import stats

    from jaxfdi._studies.metrics import binomial_lower_bound, binomial_upper_bound

    for k, n, c in ((0, 10, 0.95), (3, 10, 0.95), (10, 10, 0.99), (7, 1000, 0.95)):
        low, high = binomial_lower_bound(k, n, c), binomial_upper_bound(k, n, c)
        np.testing.assert_allclose(
            low, 0.0 if k == 0 else stats.beta.ppf(1 - c, k, n - k + 1), atol=1e-12
        )
        np.testing.assert_allclose(
            high, 1.0 if k == n else stats.beta.ppf(c, k + 1, n - k), atol=1e-12
        )
    assert np.isnan(binomial_upper_bound(0, 0))
    with pytest.raises(ValueError, match="confidence"):
        binomial_upper_bound(1, 3, 0.4)
