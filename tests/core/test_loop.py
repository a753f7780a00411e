"""The closed-loop scan (``jaxfdi._simulation.loop``) and the time-varying simulator and filter,
against independent references: the open-loop pipeline written step by step in Python,
the closed-form closed-loop response, the original filter run, filterpy driven matrix by
matrix, and sample statistics."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import KalmanFilter
from scipy import stats

import jaxfdi
from jaxfdi._simulation import loop
from jaxfdi._simulation.monitor import filter_detector
from jaxfdi.filters import time_varying
from jaxfdi.filters._time_varying import model_at
from jaxfdi.models import LinearGaussianModel, engine_model

T = 60
ONSET = 30


@pytest.fixture(scope="module")
def engine():
    model = engine_model()
    kf = jaxfdi.filters.kalman_filter(model)
    threshold = jaxfdi.detection.chi2_threshold(2 * 5, 0.01)
    detector = jaxfdi.detection.chi2_detector(threshold, 2)
    return model, kf, detector, threshold


def test_feedforward_loop_equals_the_open_loop_pipeline(engine):
    """run_loop(feedforward) == simulate, then run_filter, then the windowed test and the
    record computed in plain Python from the alarm sequence (identical integers)."""
    model, kf, detector, threshold = engine
    us = jnp.full((T, 1), 0.01)
    faults = jaxfdi.stack_faults(
        [
            jaxfdi.fault("bias", "sensor", 1, ONSET, 30.0),
            jaxfdi.fault("bias", "actuator", 0, ONSET, 2e-3),
        ]
    )
    keys = jax.random.split(jax.random.key(0), 2)
    scorer = loop.detection_scorer(ONSET, lambda out: out[1], lambda out: out[0].healthy)

    def closed(f, key):
        return loop.run_loop(
            jaxfdi.linear_simulator(model, f),
            filter_detector(kf, detector),
            loop.feedforward(),
            jnp.zeros(7),
            (kf.init(jnp.zeros(7), model.Q), detector.init()),
            key,
            exogenous=us,
            scorer=scorer,
            keep_history=True,
        )

    results = jax.jit(jax.vmap(closed))(faults, keys)
    truths = jax.jit(
        jax.vmap(
            lambda f, key: jaxfdi.simulate(
                jaxfdi.linear_simulator(model, f), jnp.zeros(7), us, key
            )[1]
        )
    )(faults, keys)
    for run in range(2):
        result = jax.tree_util.tree_map(lambda leaf: leaf[run], results)
        truth = jax.tree_util.tree_map(lambda leaf: leaf[run], truths)
        _, info = jaxfdi.filters.run_filter(
            kf, kf.init(jnp.zeros(7), model.Q), truth.measurement, us
        )
        nis = np.asarray(info.nis)
        statistic = np.array([nis[max(0, k - 1) : k + 1].sum() for k in range(T)])
        alarms = statistic > float(threshold)
        np.testing.assert_array_equal(result.history.sensed.measurement, truth.measurement)
        np.testing.assert_allclose(result.history.output[1].statistic, statistic, rtol=1e-12)
        record = result.score
        first = lambda mask: int(np.argmax(mask)) if mask.any() else -1
        after = alarms & (np.arange(T) >= ONSET)
        assert int(record.first_alarm) == first(alarms)
        assert int(record.detection_step) == first(after)
        assert int(record.false_alarms) == int(alarms[:ONSET].sum())
        assert int(record.pre_onset_steps) == ONSET
        assert int(record.first_unhealthy) == -1
        assert int(record.detection_step) >= ONSET  # the faults are large: detected


def test_monitor_is_the_feedforward_loop(engine):
    model, kf, detector, _ = engine
    us = jnp.full((T, 1), 0.01)
    f = jaxfdi.fault("bias", "sensor", 1, ONSET, 30.0)
    result = jaxfdi.monitor(
        jaxfdi.linear_simulator(model, f),
        kf,
        detector,
        jnp.zeros(7),
        kf.init(jnp.zeros(7), model.Q),
        us,
        jax.random.key(0),
        ONSET,
        keep_history=True,
    )
    _, truth, moved = jaxfdi.simulate(
        jaxfdi.linear_simulator(model, f), jnp.zeros(7), us, jax.random.key(0)
    )
    for ours, theirs in ((result.history.truth, truth), (result.history.moved, moved)):
        for field in theirs._fields:
            np.testing.assert_array_equal(getattr(ours, field), getattr(theirs, field))
    assert int(result.record.detection_step) >= ONSET


def _lqr(Phi, Gamma, Qx, Ru):
    """SciPy's discrete LQR: u = -K x, K = (R + B'XB)^-1 B'XA."""
    X = scipy.linalg.solve_discrete_are(Phi, Gamma, Qx, Ru)
    return np.linalg.solve(Ru + Gamma.T @ X @ Gamma, Gamma.T @ X @ Phi)


def test_closed_loop_lqr_with_a_perfect_sensor_is_the_closed_form_response():
    rng = np.random.default_rng(0)
    n, nu = 4, 2
    Phi = rng.normal(size=(n, n)) * 0.6
    Gamma = rng.normal(size=(n, nu))
    K = _lqr(Phi, Gamma, np.eye(n), np.eye(nu))
    model = LinearGaussianModel(
        jnp.asarray(Phi),
        jnp.asarray(Gamma),
        jnp.eye(n),
        jnp.zeros((n, nu)),
        jnp.zeros((n, n)),
        jnp.zeros((n, n)),
    )
    passthrough = jaxfdi.FDI(lambda: None, lambda state, k, y, u: (state, None))
    x0 = jnp.asarray(rng.normal(size=n))
    result = loop.run_loop(
        jaxfdi.linear_simulator(model),
        passthrough,
        loop.state_feedback(K),
        x0,
        passthrough.init(),
        jax.random.key(0),
        40,
        u0=jnp.zeros(nu),
        keep_history=True,
    )
    expected = [np.asarray(x0)]
    for _ in range(39):
        expected.append((Phi - Gamma @ K) @ expected[-1])
    np.testing.assert_allclose(result.history.sensed.state, np.array(expected), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        result.history.control, -np.array(expected) @ K.T, rtol=0, atol=1e-12
    )
    assert (
        np.max(np.abs(np.linalg.eigvals(Phi))) > 1
    )  # open loop unstable: the loop is what holds it


def test_closed_loop_feedthrough_sees_the_held_input():
    """In closed loop the sensors sample before the controller acts: the feed-through
    term of y[k] carries u[k-1] (zero-order hold), u0 at step 0."""
    model = LinearGaussianModel(
        jnp.eye(1) * 0.5,
        jnp.eye(1),
        jnp.eye(1),
        jnp.eye(1) * 2.0,
        jnp.zeros((1, 1)),
        jnp.zeros((1, 1)),
    )
    counter = jaxfdi.Controller(lambda: jnp.zeros(1), lambda s, k, view, exo: (s + 1.0, s + 1.0))
    passthrough = jaxfdi.FDI(lambda: None, lambda s, k, y, u: (s, None))
    result = loop.run_loop(
        jaxfdi.linear_simulator(model),
        passthrough,
        counter,
        jnp.zeros(1),
        passthrough.init(),
        jax.random.key(0),
        5,
        u0=jnp.full(1, 7.0),
        keep_history=True,
    )
    u = np.asarray(result.history.control)[:, 0]
    x = np.asarray(result.history.sensed.state)[:, 0]
    held = np.concatenate([[7.0], u[:-1]])
    np.testing.assert_allclose(
        np.asarray(result.history.sensed.measurement)[:, 0], x + 2.0 * held, rtol=1e-15
    )


def test_replay_over_the_ring_buffer_equals_the_original_estimates():
    """An FDI that keeps (y, u, prior) of its last L steps re-runs its KF from the prior L
    steps back; with nothing changed it lands on the filter's own estimate (1e-12)."""
    L = 3
    rng = np.random.default_rng(1)
    n, m = 3, 2
    model = LinearGaussianModel(
        jnp.asarray(np.eye(n) * 0.9 + 0.05 * rng.normal(size=(n, n))),
        jnp.ones((n, 1)),
        jnp.asarray(rng.normal(size=(m, n))),
        jnp.zeros((m, 1)),
        0.01 * jnp.eye(n),
        0.1 * jnp.eye(m),
    )
    kf = jaxfdi.filters.kalman_filter(model)
    prior0 = kf.init(jnp.zeros(n), jnp.eye(n))
    example = (jnp.zeros(m), jnp.zeros(1), prior0)

    def step(state, k, y, u):
        prior, buffer = state
        buffer = buffer.push((y, u, prior))
        post, info = kf.step(prior, y, u)
        (ys, us, priors), valid = buffer.ordered()
        start = jax.tree_util.tree_map(lambda leaf: leaf[0], priors)
        _, replayed = jaxfdi.filters.replay_filter(kf, start, ys, us, valid)
        last = jnp.sum(valid) - 1
        return (post, buffer), (info.filtered_mean, replayed.filtered_mean[last], buffer.count)

    fdi = jaxfdi.FDI(lambda: (prior0, jaxfdi.filters.ring_buffer(L, example)), step)
    us = jnp.asarray(rng.normal(size=(25, 1)))
    result = loop.run_loop(
        jaxfdi.linear_simulator(model),
        fdi,
        loop.feedforward(),
        jnp.zeros(n),
        fdi.init(),
        jax.random.key(3),
        exogenous=us,
        keep_history=True,
    )
    original, replayed, count = result.history.output
    np.testing.assert_allclose(replayed, original, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(count, np.arange(1, 26))
    # and the buffer really holds the last L steps, oldest first
    _, buffer = result.final[1]
    (ys, _, _), valid = buffer.ordered()
    np.testing.assert_array_equal(ys, result.history.sensed.measurement[-L:])
    assert bool(jnp.all(valid))


def test_ring_buffer_before_it_fills():
    buffer = jaxfdi.filters.ring_buffer(4, jnp.zeros(()))
    for value in (1.0, 2.0):
        buffer = buffer.push(jnp.asarray(value))
    entries, valid = buffer.ordered()
    np.testing.assert_array_equal(valid, [True, True, False, False])
    np.testing.assert_array_equal(entries[:2], [1.0, 2.0])
    for value in (3.0, 4.0, 5.0, 6.0, 7.0):
        buffer = buffer.push(jnp.asarray(value))
    entries, valid = buffer.ordered()
    np.testing.assert_array_equal(entries, [4.0, 5.0, 6.0, 7.0])
    with pytest.raises(ValueError, match="length"):
        jaxfdi.filters.ring_buffer(0, jnp.zeros(()))


def test_time_varying_kalman_filter_matches_filterpy_matrix_by_matrix():
    rng = np.random.default_rng(2)
    n, m, nu, steps = 3, 2, 1, 30
    model = LinearGaussianModel(
        jnp.asarray(np.eye(n) + 0.1 * rng.normal(size=(n, n))),
        jnp.asarray(rng.normal(size=(n, nu))),
        jnp.zeros((m, n)),
        jnp.zeros((m, nu)),
        jnp.eye(n),
        jnp.eye(m),
    )
    Cs = rng.normal(size=(steps, m, n))
    Qs = np.stack([np.diag(rng.uniform(0.01, 0.2, n)) for _ in range(steps)])
    Rs = np.stack([np.diag(rng.uniform(0.05, 1.0, m)) for _ in range(steps)])
    ys = rng.normal(size=(steps, m))
    us = rng.normal(size=(steps, nu))
    at = model_at(model, C=Cs, Q=Qs, R=Rs)
    filt = time_varying(lambda k: jaxfdi.filters.kalman_filter(at(k)))
    _, info = jaxfdi.filters.run_filter(
        filt, filt.init(jnp.zeros(n), jnp.eye(n)), jnp.asarray(ys), jnp.asarray(us)
    )

    kf = KalmanFilter(dim_x=n, dim_z=m, dim_u=nu)
    kf.F, kf.B = np.asarray(model.Phi), np.asarray(model.Gamma)
    kf.x, kf.P = np.zeros((n, 1)), np.eye(n)
    means, covs = [], []
    for k in range(steps):
        kf.H, kf.R = Cs[k], Rs[k]
        kf.update(ys[k].reshape(m, 1))
        means.append(kf.x.ravel().copy())
        covs.append(kf.P.copy())
        kf.Q = Qs[k]
        kf.predict(u=us[k].reshape(nu, 1))
    np.testing.assert_allclose(info.filtered_mean, np.array(means), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(info.filtered_cov, np.array(covs), rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="Q"):
        model_at(model, Q=Qs[:, :2])


@pytest.fixture(scope="module")
def small_plant():
    model = LinearGaussianModel(
        0.5 * jnp.eye(2), jnp.eye(2), jnp.eye(2), jnp.zeros((2, 2)), jnp.zeros((2, 2)), jnp.eye(2)
    )
    return model


def test_per_step_covariances_as_tables_and_callables_agree(small_plant):
    steps = 20
    Rs = jnp.stack([jnp.eye(2) * (1.0 + k) for k in range(steps)])
    us = jnp.zeros((steps, 2))
    table = jaxfdi.simulator(lambda x, u, p: 0.5 * x + u, lambda x, u, p: x, jnp.zeros((2, 2)), Rs)
    function = jaxfdi.simulator(
        lambda x, u, p: 0.5 * x + u,
        lambda x, u, p: x,
        jnp.zeros((2, 2)),
        lambda k: jnp.eye(2) * (1.0 + k),
    )
    _, a, _ = jaxfdi.simulate(table, jnp.zeros(2), us, jax.random.key(0))
    _, b, _ = jaxfdi.simulate(function, jnp.zeros(2), us, jax.random.key(0))
    np.testing.assert_allclose(a.measurement, b.measurement, rtol=1e-13)
    with pytest.raises(ValueError, match="R"):
        jaxfdi.simulator(
            lambda x, u, p: x, lambda x, u, p: x, jnp.zeros((2, 2)), jnp.zeros((steps, 2, 3))
        )


def test_per_step_measurement_noise_has_its_step_variance():
    """Sample variance of y[k] across 4000 runs vs R_k = (1 + k) I: chi-square bounds (1e-3 each)."""
    steps, runs = 4, 4000
    sim = jaxfdi.simulator(
        lambda x, u, p: x, lambda x, u, p: x, jnp.zeros((1, 1)), lambda k: jnp.eye(1) * (1.0 + k)
    )
    keys = jax.random.split(jax.random.key(9), runs)
    _, truth, _ = jax.vmap(
        lambda key: jaxfdi.simulate(sim, jnp.zeros(1), jnp.zeros((steps, 0)), key)
    )(keys)
    y = np.asarray(truth.measurement)[:, :, 0]
    for k in range(steps):
        scaled = (runs - 1) * y[:, k].var(ddof=1) / (1.0 + k)
        assert stats.chi2.ppf(5e-4, runs - 1) < scaled < stats.chi2.ppf(1 - 5e-4, runs - 1), k


def test_input_noise_time_argument_noise_gain_and_availability():
    """The applied input carries N(0, Q_u) noise (sample covariance within chi-square
    bounds); f sees k; G routes process noise to the first state only; unavailable
    components are NaN."""
    runs = 3000
    Qu = jnp.array([[0.04, 0.01], [0.01, 0.09]])
    sim = jaxfdi.simulator(
        lambda x, u, k, p: jnp.array([x[0] + u[0], x[1] + k]),
        lambda x, u, k, p: x,
        jnp.eye(1),
        jnp.zeros((2, 2)),
        time_varying=True,
        noise_gain=jnp.array([[1.0], [0.0]]),
        input_noise=Qu,
        available=lambda k, x: jnp.array([True, k % 2 == 0]),
    )
    us = jnp.ones((3, 2))
    keys = jax.random.split(jax.random.key(4), runs)
    _, truth, moved = jax.vmap(lambda key: jaxfdi.simulate(sim, jnp.zeros(2), us, key))(keys)
    noise = np.asarray(moved.actuator_fault)[:, 0, :]  # applied - commanded
    for i in range(2):
        scaled = (runs - 1) * noise[:, i].var(ddof=1) / float(Qu[i, i])
        assert stats.chi2.ppf(5e-4, runs - 1) < scaled < stats.chi2.ppf(1 - 5e-4, runs - 1)
    corr = np.corrcoef(noise.T)[0, 1]
    assert abs(np.arctanh(corr) - np.arctanh(0.01 / 0.06)) < 3.3 / np.sqrt(runs - 3)
    x = np.asarray(truth.state)
    np.testing.assert_array_equal(
        x[:, :, 1], np.broadcast_to([0.0, 0.0, 1.0], (runs, 3))
    )  # x1 += k, no noise
    y = np.asarray(truth.measurement)
    assert (
        np.all(np.isnan(y[:, 1, 1]))
        and np.all(np.isfinite(y[:, [0, 2], 1]))
        and np.all(np.isfinite(y[:, :, 0]))
    )


def test_a_dead_sensor_mid_run_is_an_alarm_not_ill_health(engine):
    """Every sensor reads NaN at step 40 (``available`` False: a filter without
    missing-data handling): the monitor alarms at step 40 with the first channel's label,
    the record stays healthy, and the summary scores it: a detection in the faulty run
    (its onset 30 is before; an earlier alarm may have come first) and a false alarm in
    the fault-free one (a dead sensor is a fault, whatever the simulator's label)."""
    model, kf, detector, _ = engine
    us = jnp.full((T, 1), 0.01)
    sim = jaxfdi.linear_simulator(model, available=lambda k, x: jnp.full((5,), k != 40))
    labels = 10 + jnp.arange(5)
    records = []
    for onset in (ONSET, jaxfdi._simulation.faults.NEVER):
        result = jaxfdi.monitor(
            sim,
            kf,
            detector,
            jnp.zeros(7),
            kf.init(jnp.zeros(7), model.Q),
            us,
            jax.random.key(0),
            onset,
            keep_history=True,
            channel_labels=labels,
        )
        assert int(result.record.first_unhealthy) == -1
        assert bool(result.history.alarm[40]) and float(result.history.statistic[40]) == np.inf
        assert int(result.history.label[40]) == 10
        records.append(result.record)
    faulty, fault_free = (
        jaxfdi.summarize_detection(jax.tree_util.tree_map(lambda a: a[None], r), T) for r in records
    )
    assert faulty.unhealthy_runs == fault_free.unhealthy_runs == 0
    assert faulty.detection_rate == 1.0 and fault_free.false_alarm_rate == 1.0


def test_loop_input_errors():
    model = engine_model()
    sim = jaxfdi.linear_simulator(model)
    fdi = jaxfdi.FDI(lambda: None, lambda s, k, y, u: (s, None))
    with pytest.raises(ValueError, match="u0"):
        loop.run_loop(
            sim,
            fdi,
            loop.state_feedback(jnp.zeros((1, 7))),
            jnp.zeros(7),
            None,
            jax.random.key(0),
            5,
        )
    with pytest.raises(ValueError, match="steps"):
        loop.run_loop(sim, fdi, loop.feedforward(), jnp.zeros(7), None, jax.random.key(0))
    with pytest.raises(ValueError, match="exogenous"):
        loop.run_loop(
            sim,
            fdi,
            loop.feedforward(),
            jnp.zeros(7),
            None,
            jax.random.key(0),
            5,
            exogenous=jnp.zeros((4, 1)),
        )


def test_episode_scorer_over_a_flight_with_three_fault_episodes(engine):
    """Three episodes in one run (a group of two sensors, an actuator bias, a sensor
    ramp), scored inside the scan; against windows and first alarms found in plain
    Python from the stored alarm sequence."""
    model, kf, detector, _ = engine
    steps, grace = 150, 3
    group = jaxfdi._simulation.faults.fault_group(
        "bias", "sensor", [1, 3], 20, [25.0, 4.0], end=45, label=9
    )
    flight = jaxfdi._simulation.faults.concat_faults(
        group,
        jaxfdi.fault("bias", "actuator", 0, 70, 2e-3, end=95),
        jaxfdi.fault("ramp", "sensor", 2, 110, 0.0, slope=0.5),
    )
    onsets, ends, labels = jaxfdi._simulation.faults.episodes(flight, 1)
    us = jnp.full((steps, 1), 0.01)
    result = loop.run_loop(
        jaxfdi.linear_simulator(model, flight),
        filter_detector(kf, detector),
        loop.feedforward(),
        jnp.zeros(7),
        (kf.init(jnp.zeros(7), model.Q), detector.init()),
        jax.random.key(7),
        exogenous=us,
        scorer=loop.episode_scorer(
            (onsets, ends, labels), lambda out: out[1], lambda out: out[0].healthy, grace
        ),
        keep_history=True,
    )
    alarms = np.asarray(result.history.output[1].alarm)
    mode = np.asarray(result.history.sensed.mode)
    record = result.score
    real = [(int(o), int(e), int(l)) for o, e, l in zip(onsets, ends, labels) if o < steps]
    assert [r[2] for r in real] == [9, 1, 4]
    assert (
        set(mode[20:45]) == {9}
        and set(mode[70:95]) == {1}
        and set(mode[110:]) == {4}
        and mode[50] == 0
    )
    starts = sorted(o for o, _, _ in real)
    inside_any = np.zeros(steps, bool)
    for e, (o, end, _) in enumerate(real):
        later = [s for s in starts if s > o]
        close = min(end + grace, later[0] if later else 2**30)
        window = np.arange(steps)[(np.arange(steps) >= o) & (np.arange(steps) < close)]
        inside_any[window] = True
        hits = window[alarms[window]]
        index = [int(x) for x in np.asarray(onsets)].index(o)
        assert int(record.detection_step[index]) == (int(hits[0]) if hits.size else -1)
        assert hits.size, "each episode is large enough to be detected"
    assert int(record.false_alarms) == int(np.sum(alarms & ~inside_any))
    assert int(record.first_unhealthy) == -1


def test_peak_scorer_is_the_running_maximum_of_negative_values_too():
    """``peak_scorer`` against NumPy's masked maximum on values below zero (a log-likelihood, a margin); a
    channel never active keeps ``-inf``."""
    rng = np.random.default_rng(3)
    values = -np.abs(rng.normal(size=(20, 3))) - 1.0
    active = np.zeros((20, 3), bool)
    active[5:12, 0], active[::3, 1] = True, True  # channel 2: never active
    scorer = loop.peak_scorer(lambda out: out, lambda k: jnp.asarray(active)[k])
    score = scorer.init(lambda: jnp.zeros(3))
    for k in range(20):
        score = scorer.update(score, k, jnp.asarray(values[k]))
    want = np.where(active, values, -np.inf).max(axis=0)
    np.testing.assert_array_equal(np.asarray(score), want)
    assert want[0] < 0 and want[2] == -np.inf


def test_health_scorer_without_a_healthy_field_names_the_argument():
    scorer = loop.health_scorer()
    with pytest.raises(TypeError, match="healthy: the loop's output has no 'healthy' field"):
        scorer.init(lambda: jnp.zeros(3))
    explicit = loop.health_scorer(lambda out: jnp.all(jnp.isfinite(out)))
    score = explicit.init(lambda: jnp.zeros(3))
    score = explicit.update(score, 0, jnp.array([1.0, jnp.nan, 0.0]))
    assert not bool(score)
