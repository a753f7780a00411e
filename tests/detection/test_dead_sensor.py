"""A dead sensor is a fault (issue 37): non-finite data gives an alarm and the channel's
label in every detector, recursive statistics recover after it, and a frozen channel is
caught by its own test.

References: the simulator's own fault labels (not the detectors' label arithmetic); the
same detectors on the same data without the bad samples (the delay a real fault has
without them); brute-force window sums; ``scipy.stats.chi2.ppf`` for the frozen test's
threshold, and its false-alarm rate tested with a binomial test on independent windows.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

import jaxfdi
from jaxfdi import fault, simulate, steady_state_kalman
from jaxfdi.detection import _parity as ps
from jaxfdi.detection import (
    block_alarms,
    chi2_detector,
    corrected_glrt,
    frozen_channel_detector,
    frozen_threshold,
    glrt_detector,
    glrt_threshold,
    known_change_detector,
    moving_window_sum,
)
from jaxfdi.detection._credits import credit_isolator
from jaxfdi.models import engine_model

T, ONSET, WINDOW, BURST = 120, 60, 10, slice(20, 25)


@pytest.fixture(scope="module")
def engine():
    """The engine, its steady-state KF and one run with a 4-sigma bias on sensor 0 from
    step 60; the same run with sensor 1 dead (NaN) over steps 20-24; the simulator's
    label of a sensor-1 fault."""
    model = engine_model()
    steady = steady_state_kalman(model)
    n = model.dims[0]
    us = jnp.full((T, 1), 0.01)
    sigma = np.sqrt(np.diag(np.asarray(model.R)))
    sim = jaxfdi.linear_simulator(model, fault("bias", "sensor", 0, ONSET, 4 * sigma[0]))
    ys = np.asarray(simulate(sim, jnp.zeros(n), us, jax.random.key(1))[1].measurement)
    burst = ys.copy()
    burst[BURST, 1] = np.nan
    dead_sim = jaxfdi.linear_simulator(model, fault("dead", "sensor", 1, 0))
    dead_trace = simulate(dead_sim, jnp.zeros(n), us[:2], jax.random.key(0))[1]
    return model, steady, us, sigma, ys, burst, int(dead_trace.mode[0]), dead_trace


def test_a_dead_fault_is_nan_on_its_component_alone(engine):
    *_, label, trace = engine
    y = np.asarray(trace.measurement)
    assert np.all(np.isnan(y[:, 1])) and np.all(np.isfinite(np.delete(y, 1, axis=1))) and label > 0
    with pytest.raises(ValueError, match="kind: DEAD"):
        fault("dead", "actuator", 0, 10)


def _detectors(model, steady, sigma):
    nu, m = model.dims[1:]
    threshold = glrt_threshold(1e-4, nu + m, WINDOW)
    sizes = jnp.asarray(np.r_[np.full(nu, 0.01), 4 * sigma])
    return {
        "windowed GLRT": glrt_detector(
            model, steady.gain, steady.innovation_cov, WINDOW, threshold
        ),
        "recursive GLRT": glrt_detector(
            model, steady.gain, steady.innovation_cov, WINDOW, threshold, recursive=True
        ),
        "CUSUM (known change, tail)": known_change_detector(
            model, steady.gain, steady.innovation_cov, sizes, WINDOW, 8.0, tail=True
        ),
        "corrected GLRT": threshold,
    }


@pytest.mark.parametrize(
    "name", ["windowed GLRT", "recursive GLRT", "CUSUM (known change, tail)", "corrected GLRT"]
)
def test_a_nan_burst_alarms_on_its_channel_and_a_later_fault_is_detected_as_without_it(
    engine, name
):
    """Steps 20-24 alarm with statistic +inf and the simulator's label of sensor 1; the
    detector then recovers: no alarm from the end of the burst to the fault's onset, and
    the real fault is detected with the delay (and label) it has on the same data without
    the burst, within one window."""
    model, steady, us, sigma, ys, burst, dead_label, _ = engine
    detector = _detectors(model, steady, sigma)[name]
    kf = jaxfdi.filters.kalman_filter(model)
    kf0 = kf.init(jnp.zeros(7), steady.predicted_cov)

    def decisions(y):
        if name == "corrected GLRT":
            glrt = corrected_glrt(model, WINDOW, detector)
            _, info = jax.lax.scan(
                lambda s, yu: glrt.step(s, *yu),
                glrt.init(jnp.zeros(7), steady.predicted_cov),
                (jnp.asarray(y), us),
            )
            assert bool(info.healthy.all())
            return info.decision
        _, info = jaxfdi.filters.run_filter(kf, kf0, y, us)
        assert bool(info.healthy.all())
        return jax.lax.scan(detector.step, detector.init(), info.innovation)[1]

    clean, bad = decisions(ys), decisions(burst)
    alarm, label, statistic = (np.asarray(a) for a in (bad.alarm, bad.label, bad.statistic))
    assert (
        alarm[BURST].all()
        and np.all(statistic[BURST] == np.inf)
        and np.all(label[BURST] == dead_label)
    )
    assert not np.any(np.asarray(clean.alarm)[:ONSET]) and not np.any(alarm[BURST.stop : ONSET])
    assert np.all(np.isfinite(statistic[BURST.stop :]))
    first = [ONSET + int(np.argmax(np.asarray(d.alarm)[ONSET:])) for d in (clean, bad)]
    assert np.asarray(clean.alarm)[first[0]] and alarm[first[1]], "the real fault was missed"
    assert (
        abs(first[1] - first[0]) <= WINDOW and label[first[1]] == np.asarray(clean.label)[first[0]]
    )


def test_chi2_window_alarms_while_a_dead_nis_is_in_it_and_recovers():
    nis = np.array([1.0, 2.0, np.inf, 3.0, 1.0, 0.5, np.nan, 2.0, 1.0, 1.0])
    detector = chi2_detector(100.0, window=3)
    _, decision = jax.lax.scan(detector.step, detector.init(), jnp.asarray(nis))
    bad = np.array(
        [False, False, True, True, True, False, True, True, True, False]
    )  # a bad value in the window
    np.testing.assert_array_equal(np.asarray(decision.alarm), bad)
    statistic = np.asarray(decision.statistic)
    assert np.all(statistic[bad] == np.inf) and np.all(np.isfinite(statistic[~bad]))
    # moving_window_sum against brute force: +inf where the window holds a non-finite value
    windows = [nis[max(0, k - 2) : k + 1] for k in range(len(nis))]
    brute = [np.inf if not np.all(np.isfinite(w)) else w.sum() for w in windows]
    np.testing.assert_allclose(moving_window_sum(jnp.asarray(nis), 3), brute, rtol=1e-15)


def test_parity_tests_isolate_a_dead_channel_and_equal_eqs_8_9_otherwise():
    rng = np.random.default_rng(4)
    space = ps.parity_space(
        jnp.asarray(rng.normal(size=(6, 3))), jnp.asarray([[0, 1], [2, 3], [4, 5]])
    )
    m = rng.normal(size=(6,))
    fd, fi = ps.parity_tests(space, m)
    parity = ps.parity_vector(space, m)
    np.testing.assert_allclose(fd, float(np.sum(np.asarray(parity) ** 2)), rtol=1e-13)
    np.testing.assert_allclose(fi, ps.isolation_functions(space, parity), rtol=1e-13)
    for bad in (np.nan, np.inf):
        dead = m.copy()
        dead[3] = bad
        fd, fi = ps.parity_tests(space, dead)
        assert float(fd) == np.inf and np.array_equal(np.asarray(fi), [0.0, 1.0, 0.0])
        assert np.all(
            np.isnan(ps.isolation_functions(space, ps.parity_vector(space, dead)))
        )  # never a silent 0


def test_block_alarms_and_credits_alarm_on_non_finite_values():
    x = jnp.asarray([0.1, 0.2, 0.1, 0.0, 0.1, np.nan, 0.2, 0.1])
    np.testing.assert_array_equal(
        block_alarms(x, 5.0, 2), [False, False, False, False, False, False, False, True]
    )
    isolator = credit_isolator(0.5)
    _, decision = isolator.step(isolator.init(), jnp.asarray([1.0, np.nan, 2.0]))
    assert (
        bool(decision.alarm) and float(decision.statistic) == np.inf and int(decision.label) == -1
    )


def test_frozen_threshold_is_the_lower_chi2_quantile():
    for window in (2, 5, 10, 30):
        for pfa in (1e-6, 1e-3, 0.05):
            np.testing.assert_allclose(
                frozen_threshold(window, pfa), scipy.stats.chi2.ppf(pfa, window - 1), rtol=1e-9
            )
    # below eps, 1 - pfa is 1: the error names pfa and the least value, not the 1.0 it became
    with pytest.raises(ValueError, match=r"pfa: expected a probability >= 2.22e-16 .* got 1e-17"):
        frozen_threshold(5, 1e-17)


@pytest.mark.parametrize("signal", ["constant", "ramp"])
def test_frozen_test_false_alarm_rate_is_at_most_pfa(signal):
    """4000 independent windows of 8 samples, noise sigma, pfa 0.05: with a constant signal
    the alarm count is Binomial(4000, 0.05) (two-sided binomial test, p > 1e-3); with a
    ramp (a moving plant) it is not above that (one-sided)."""
    window, pfa, runs = 8, 0.05, 4000
    sigma = jnp.asarray([0.5, 2.0])
    detector = frozen_channel_detector(
        sigma, window, pfa / 2
    )  # 2 channels: pfa/2 each, union bound
    noise = jax.random.normal(jax.random.key(7), (runs, window, 2)) * sigma
    slope = 0.0 if signal == "constant" else 0.3
    ys = noise + 10.0 + slope * jnp.arange(window)[None, :, None]
    run = jax.jit(jax.vmap(lambda y: jax.lax.scan(detector.step, detector.init(), y)[1].alarm[-1]))
    alarms = int(np.sum(np.asarray(run(ys))))
    exact = 1 - (1 - pfa / 2) ** 2  # the two channels' union, independent
    if signal == "constant":
        assert scipy.stats.binomtest(alarms, runs, exact).pvalue > 1e-3, alarms
    else:
        assert scipy.stats.binomtest(alarms, runs, exact, alternative="greater").pvalue > 1e-3, (
            alarms
        )


def test_a_frozen_channel_is_caught_within_a_window_with_its_label_and_recovers_after_a_dead_sample():
    rng = np.random.default_rng(0)
    window = 8
    ys = rng.normal(size=(60, 2)) * np.array([1.0, 2.0])
    ys[:, 0] += np.linspace(0.0, 50.0, 60)  # a moving, healthy channel
    ys[10, 0] = np.nan  # a dead sample
    ys[30:, 1] = ys[30, 1]  # STUCK from step 30: the onset value held
    detector = frozen_channel_detector(jnp.asarray([1.0, 2.0]), window, 1e-3, jnp.asarray([3, 4]))
    _, decision = jax.lax.scan(detector.step, detector.init(), jnp.asarray(ys))
    alarm, label = np.asarray(decision.alarm), np.asarray(decision.label)
    assert alarm[10] and label[10] == 3  # the dead sample: channel 0's label
    assert not alarm[11:30].any() and np.all(np.isfinite(np.asarray(decision.statistic)[11:]))
    first = 30 + int(np.argmax(alarm[30:]))
    assert (
        first <= 30 + window - 1 and alarm[30 + window - 1 :].all() and np.all(label[first:] == 4)
    )
