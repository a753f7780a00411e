"""Windowed GLRT: signatures against the Kalman filter's response to a noise-free fault,
the statistic against a brute-force double loop, its chi2(1) law and the unbiased
magnitude estimate by Monte Carlo, and the online detector on a faulty engine run."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

import jaxfdi
from jaxfdi import steady_state_kalman
from jaxfdi.detection import (
    detector_setup,
    fault_directions,
    fault_signatures,
    glr_sequence,
    glrt_detector,
    glrt_threshold,
)
from jaxfdi.detection._glrt import glr_by_onset, glr_statistic
from jaxfdi.models import engine_model

WINDOW = 10
NUM_INPUTS = 1
# (target, component, magnitude) for each direction, in the simulator's label order 1..6;
# seed 003 sizes: actuator 5 % of the 0.01 kg/s command, sensors 0.5 % of the operating point.
DIRECTIONS = [
    ("actuator", 0, 0.0005),
    ("sensor", 0, 135.0),
    ("sensor", 1, 16.99),
    ("sensor", 2, 2.21),
    ("sensor", 3, 8.285),
    ("sensor", 4, 5.125),
]


@pytest.fixture(scope="module")
def engine():
    model = engine_model()
    steady = steady_state_kalman(model)
    signatures = fault_signatures(model, steady.gain, fault_directions(model), WINDOW)
    return model, steady, signatures


def _fault(index, onset, magnitude=None):
    target, component, size = DIRECTIONS[index]
    return jaxfdi.fault("bias", target, component, onset, size if magnitude is None else magnitude)


def test_signature_shapes_and_order(engine):
    model, _, signatures = engine
    assert signatures.shape == (WINDOW, 5, 6)
    directions = fault_directions(model)
    np.testing.assert_array_equal(directions.state[:, 0], model.Gamma[:, 0])
    np.testing.assert_array_equal(directions.output[:, 1:], np.eye(5))
    # the simulator feeds the commanded input through D: an actuator fault is invisible at its onset
    np.testing.assert_array_equal(signatures[0, :, 0], 0.0)
    np.testing.assert_allclose(signatures[1, :, 0], model.C @ model.Gamma[:, 0], rtol=1e-12)


def _noise_free_measurements(model, fault_index, onset, T, u=0.01):
    """Plain NumPy plant, seed 003 eq. (4) without noise: x[k+1] = Phi x + Gamma (u + f_u),
    y[k] = C x + D u + f_y, a unit step fault from ``onset`` (None: fault-free)."""
    Phi, Gamma, C, D = (np.asarray(a) for a in (model.Phi, model.Gamma, model.C, model.D))
    x, ys = np.zeros(Phi.shape[0]), []
    for k in range(T):
        active = fault_index is not None and k >= onset
        f_u = 1.0 if active and fault_index == 0 else 0.0
        f_y = np.eye(C.shape[0])[fault_index - 1] if active and fault_index > 0 else 0.0
        ys.append(C @ x + D[:, 0] * u + f_y)
        x = Phi @ x + Gamma[:, 0] * (u + f_u)
    return np.array(ys)


def test_signatures_equal_noise_free_filter_response(engine):
    """Unit fault on a noise-free plant: the KF's innovations (faulty minus fault-free) equal
    G[k - onset] for every direction, lag and several onsets, and are 0 before the onset."""
    model, steady, signatures = engine
    onsets, T = (0, 3, 11), 11 + WINDOW
    cases = [(i, onset) for onset in onsets for i in range(6)] + [(None, 0)]
    ys = np.stack([_noise_free_measurements(model, i, onset, T) for i, onset in cases])
    kf = jaxfdi.filters.kalman_filter(model)
    _, info = jaxfdi.filters.run_filter(
        kf, kf.init(jnp.zeros(7), steady.predicted_cov), ys, np.full((T, 1), 0.01)
    )
    innov = np.asarray(info.innovation)
    G = np.asarray(signatures)
    for (i, onset), response in zip(cases, innov[:-1] - innov[-1]):
        scale = np.max(np.abs(G[:, :, i]))
        np.testing.assert_array_equal(response[:onset], 0.0)
        np.testing.assert_allclose(
            response[onset : onset + WINDOW], G[:, :, i], rtol=0, atol=1e-10 * scale
        )


def _brute_force(eps, G, S, num_valid):
    """Plain double loop over (direction, onset) with S^-1 (no whitening)."""
    N, m, d = G.shape
    S_inv = np.linalg.inv(S)
    stat, offset, mag = np.full(d, -np.inf), np.zeros(d, int), np.zeros(d)
    for i in range(d):
        for o in range(num_valid):
            theta = N - 1 - o
            dd = sum(G[j - theta, :, i] @ S_inv @ eps[j] for j in range(theta, N))
            RR = sum(G[j - theta, :, i] @ S_inv @ G[j - theta, :, i] for j in range(theta, N))
            if dd**2 / RR > stat[i]:
                stat[i], offset[i], mag[i] = dd**2 / RR, o, dd / RR
    return stat, offset, mag


@pytest.mark.parametrize("num_valid", [7, 4])
def test_glr_statistic_equals_brute_force(num_valid):
    rng = np.random.default_rng(5)
    N, m, d = 7, 3, 4
    G = rng.normal(size=(N, m, d))
    M = rng.normal(size=(m, m))
    S = M @ M.T + np.eye(m)
    eps = rng.normal(size=(N, m)) * 2.0
    result = glr_statistic(eps, G, S, num_valid=num_valid)
    stat, offset, mag = _brute_force(eps, G, S, num_valid)
    np.testing.assert_allclose(result.statistic, stat, rtol=1e-10)
    np.testing.assert_array_equal(result.onset_offset, offset)
    np.testing.assert_allclose(result.magnitude, mag, rtol=1e-10)


RUNS, ONSET, OFFSET = 200, 200, 5  # OFFSET: the magnitude is read OFFSET steps after the onset
T_SIM = ONSET + OFFSET + 10


@pytest.fixture(scope="module")
def monte_carlo(engine):
    """Innovations (7, RUNS, T_SIM, m) of the fault-blind KF (started at the steady-state
    prior, x0 ~ N(0, P): so eps ~ N(0, S) white exactly), fault-free then with each seed-003
    fault from step ONSET; the 7 groups share their noise (same keys and x0). One compiled
    call: jit(vmap) over 7 * RUNS runs of simulate + kalman_filter."""
    model, steady, _ = engine
    us = jnp.full((T_SIM, 1), 0.01)

    def one(fault, key, x0):
        _, truth, _ = jaxfdi.simulate(jaxfdi.linear_simulator(model, fault), x0, us, key)
        kf = jaxfdi.filters.kalman_filter(model)
        _, info = jaxfdi.filters.run_filter(
            kf, kf.init(jnp.zeros(7), steady.predicted_cov), truth.measurement, us
        )
        return info.innovation

    rng = np.random.default_rng(11)
    x0s = rng.standard_normal((RUNS, 7)) @ np.linalg.cholesky(np.asarray(steady.predicted_cov)).T
    keys = jax.random.split(jax.random.key(11), RUNS)
    groups = jaxfdi.stack_faults([jaxfdi.no_fault()] + [_fault(i, ONSET) for i in range(6)])
    faults = jax.tree.map(lambda leaf: jnp.repeat(leaf, RUNS), groups)  # group-major, 7 * RUNS
    innovations = jax.jit(jax.vmap(one))(faults, jnp.tile(keys, 7), np.tile(x0s, (7, 1)))
    return np.asarray(innovations).reshape(7, RUNS, T_SIM, 5)


def test_simulator_timing_matches_signatures(engine, monte_carlo):
    """Same noise, with and without a seed-003 fault from step ONSET in ``jaxfdi.simulate``:
    the innovations differ by exactly magnitude * G[k - ONSET] (0 before the onset)."""
    _, _, signatures = engine
    G = np.asarray(signatures)
    for i in range(6):
        difference = monte_carlo[1 + i, :, : ONSET + WINDOW] - monte_carlo[0, :, : ONSET + WINDOW]
        magnitude = DIRECTIONS[i][2]
        expected = np.concatenate([np.zeros((ONSET, 5)), magnitude * G[:, :, i]])
        np.testing.assert_allclose(
            difference,
            np.broadcast_to(expected, difference.shape),
            rtol=0,
            atol=1e-9 * magnitude * np.max(np.abs(G[:, :, i])),
        )


@jax.jit
def _by_onset(windows, signatures, S):
    """GLR by onset offset for a batch of (WINDOW, m) windows: (batch, WINDOW, d)."""
    return jax.vmap(lambda e: glr_by_onset(e, signatures, S))(windows)


def test_fixed_onset_glr_is_chi2_1_without_fault(engine, monte_carlo):
    """Disjoint windows of the fault-free runs: l_i(theta) at a fixed onset is chi2(1)."""
    _, steady, signatures = engine
    count = T_SIM // WINDOW
    windows = monte_carlo[0, :, : count * WINDOW].reshape(RUNS * count, WINDOW, 5)
    statistic = np.asarray(_by_onset(windows, signatures, steady.innovation_cov).statistic)[
        :, OFFSET
    ]
    assert statistic.shape == (RUNS * count, 6)
    for i in range(6):
        assert scipy.stats.kstest(statistic[:, i], scipy.stats.chi2(1).cdf).pvalue > 0.01, i


def test_magnitude_at_true_onset_is_unbiased(engine, monte_carlo):
    """nu_hat at the true onset, OFFSET steps after it: mean within 3 standard errors of the
    true size, variance the Cramer-Rao bound 1 / R(theta)."""
    _, steady, signatures = engine
    end = ONSET + OFFSET + 1
    windows = monte_carlo[1:, :, end - WINDOW : end].reshape(6 * RUNS, WINDOW, 5)
    magnitude = np.asarray(_by_onset(windows, signatures, steady.innovation_cov).magnitude)
    chol_inv = np.linalg.inv(np.linalg.cholesky(np.asarray(steady.innovation_cov)))
    for i in range(6):
        estimate = magnitude.reshape(6, RUNS, WINDOW, 6)[i, :, OFFSET, i]
        true = DIRECTIONS[i][2]
        standard_error = estimate.std(ddof=1) / np.sqrt(RUNS)
        assert abs(estimate.mean() - true) < 3 * standard_error, i
        information = np.sum((np.asarray(signatures)[: OFFSET + 1, :, i] @ chol_inv.T) ** 2)
        assert abs(estimate.var(ddof=1) * information - 1.0) < 3 * np.sqrt(2 / (RUNS - 1)), i


@pytest.fixture(scope="module")
def detect(engine):
    """jit(vmap over runs) of the online detector over (runs, T, m) innovations."""
    model, steady, _ = engine
    threshold = glrt_threshold(1e-4, 6, WINDOW, "bonferroni")
    det = glrt_detector(model, steady.gain, steady.innovation_cov, WINDOW, threshold)
    return jax.jit(jax.vmap(lambda e: jax.lax.scan(det.step, det.init(), e)[1]))


def test_detector_matches_glr_statistic(engine, monte_carlo, detect):
    """The online detector (shifted window, count of steps) equals glr_statistic on the
    window of data seen, onsets restricted to the data during the first N - 1 steps; so
    does every direction's statistic from ``glr_sequence``."""
    _, steady, signatures = engine
    innovations = monte_carlo[5, 0]
    decisions = jax.tree.map(
        lambda a: np.asarray(a)[0], detect(monte_carlo[5, :3])
    )  # the shape compiled below
    padded = np.concatenate([np.zeros((WINDOW - 1, 5)), innovations])
    windows = np.stack([padded[k : k + WINDOW] for k in range(T_SIM)])
    num_valid = np.minimum(np.arange(T_SIM) + 1, WINDOW)
    ref = jax.jit(jax.vmap(glr_statistic, in_axes=(0, None, None, 0)))(
        windows, signatures, steady.innovation_cov, num_valid
    )
    best = np.argmax(np.asarray(ref.statistic), axis=1)
    pick = lambda a: np.take_along_axis(np.asarray(a), best[:, None], 1)[:, 0]
    np.testing.assert_allclose(decisions.statistic, pick(ref.statistic), rtol=1e-10)
    np.testing.assert_array_equal(decisions.label, 1 + best)
    np.testing.assert_allclose(decisions.estimate, pick(ref.magnitude), rtol=1e-10)
    # every direction's statistic per step (the engine study's GLR figure): the same batch reference
    model, _, _ = engine
    setup = detector_setup(
        model, steady.gain, steady.innovation_cov, WINDOW, 200.0, "max", False, -1
    )
    every = glr_sequence(setup, jnp.asarray(innovations))
    np.testing.assert_allclose(every.statistic, ref.statistic, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(every.onset_offset, ref.onset_offset)


@pytest.mark.parametrize("index", [4, 0])
def test_detector_alarms_after_onset_with_right_label(monte_carlo, detect, index):
    """P4 bias 8.285 and actuator 0.0005 kg/s from step 200, N = 10, simulated engine runs.

    The threshold is derived (Bonferroni, 1e-4 per step): with the paper's l_T = 200 a P4
    bias of 8.285 has a full-window noncentrality of only ~84 and is not detected.
    """
    decisions = detect(monte_carlo[1 + index, :3])
    for alarm, label in zip(np.asarray(decisions.alarm), np.asarray(decisions.label)):
        assert not alarm[:ONSET].any()
        detection = ONSET + int(np.argmax(alarm[ONSET:]))
        assert alarm[detection] and detection < ONSET + WINDOW
        assert label[detection] == 1 + index


def test_paper_threshold_values():
    np.testing.assert_allclose(
        glrt_threshold(0.005, 6, 10), scipy.stats.chi2.isf(0.005, 60), rtol=1e-10
    )
    np.testing.assert_allclose(
        glrt_threshold(0.005, 6, 10, "bonferroni"), scipy.stats.chi2.isf(0.005 / 60, 1), rtol=1e-10
    )


def test_paper_isolation_logic():
    """Eq. (24): actuator only when the actuator and T4 GLRs both exceed the threshold."""
    from jaxfdi.detection._glrt import _paper_isolation

    cases = [
        ([20, 1, 1, 1, 1, 20], 0),
        ([20, 1, 1, 1, 15, 5], 4),
        ([5, 1, 12, 1, 1, 3], 2),
        ([20, 1, 1, 1, 1, 5], 0),
        ([3, 1, 1, 1, 1, 5], 5),
    ]
    statistic = jnp.asarray([c[0] for c in cases], float)
    fallback = jnp.argmax(statistic, axis=1)
    got = jax.vmap(lambda l, f: _paper_isolation(l, 10.0, NUM_INPUTS, 5, f))(statistic, fallback)
    np.testing.assert_array_equal(got, [c[1] for c in cases])


def test_float32_stays_float32(engine):
    model, steady, _ = engine
    cast = lambda tree: jax.tree.map(lambda a: jnp.asarray(a, jnp.float32), tree)
    det = glrt_detector(
        cast(model),
        cast(steady.gain),
        cast(steady.innovation_cov),
        WINDOW,
        200.0,
        isolation="paper",
    )
    innovations = np.random.default_rng(4).normal(size=(15, 5)).astype(np.float32) * 3
    state, decisions = jax.jit(lambda e: jax.lax.scan(det.step, det.init(), e))(
        jnp.asarray(innovations)
    )
    assert state.window.dtype == jnp.float32
    for value in (decisions.statistic, decisions.estimate):
        assert value.dtype == jnp.float32 and np.all(np.isfinite(np.asarray(value)))


def test_bad_input_names_the_argument(engine):
    model, steady, signatures = engine
    K, S = steady.gain, steady.innovation_cov
    det = glrt_detector(model, K, S, WINDOW, 200.0)
    with pytest.raises(ValueError, match="^innovation:"):
        det.step(det.init(), jnp.zeros(4))
    for window, error in (
        (0, ValueError),
        (-3, ValueError),
        (2.5, TypeError),
    ):  # a float is not a count
        with pytest.raises(error, match="^window:"):
            glrt_detector(model, K, S, window, 200.0)
    for threshold in (0.0, -1.0, np.inf):
        with pytest.raises(ValueError, match="^threshold:"):
            glrt_detector(model, K, S, WINDOW, threshold)
    with pytest.raises(ValueError, match="^gain:"):
        glrt_detector(model, K.T, S, WINDOW, 200.0)
    with pytest.raises(ValueError, match="^innovation_cov:"):
        glrt_detector(model, K, S[:4, :4], WINDOW, 200.0)
    with pytest.raises(ValueError, match="^isolation:"):
        glrt_detector(model, K, S, WINDOW, 200.0, isolation="vote")
    with pytest.raises(ValueError, match="^innovations:"):
        glr_statistic(np.zeros((WINDOW, 4)), signatures, S)
