"""The 15-state loosely coupled EKF and the state chi-square test, piece by piece: the error
state's feedback is the exact inverse of its definition, the EKF's update equals an
independent NumPy Kalman update, the SCST statistic equals beta^T B^-1 beta solved by
NumPy, a singular or ill-conditioned B is reported (never used), Da's statistic is
chi-square(n) on a linear-Gaussian system (KS test over Monte Carlo runs of the library's
Kalman filter), and bad arguments are refused by name."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import jaxfdi
from jaxfdi import rotation
from jaxfdi.ins import GpsFix, NavState
from jaxfdi.ins import _error_state as error_state
from jaxfdi.ins import _imu as imu
from jaxfdi.ins import _loosely_coupled as loosely_coupled
from jaxfdi.ins import _plant as plant
from jaxfdi.ins import _scst as scst
from jaxfdi.ins import _trajectory as trajectory

PARK = (37.5684, 126.8851, 70.0)


def _nav():
    return NavState(
        jnp.asarray([math.radians(PARK[0]), math.radians(PARK[1]), 130.0]),
        jnp.asarray([11.0, -3.0, 0.4]),
        rotation.euler_to_quaternion(0.1, -0.05, 2.0),
    )


def test_feedback_is_the_exact_inverse_of_the_error():
    rng = np.random.default_rng(1)
    nav = _nav()
    for scale in (1e-6, 1.0):
        error = jnp.asarray(
            rng.normal(size=9) * np.array([3, 3, 3, 0.1, 0.1, 0.1, 0.01, 0.01, 0.05]) * scale
        )
        truth = error_state.correct(nav, error)
        # exact up to the round-off of a latitude difference, eps * (R + h) ~ 1e-9 m
        np.testing.assert_allclose(
            error_state.navigation_error(nav, truth), error, rtol=1e-9, atol=1e-8
        )


def test_update_equals_an_independent_kalman_update():
    """One epoch's update and feedback against the textbook equations in NumPy:
    ``K = P H^T (H P H^T + R)^-1``, ``dx = K z``, ``P+ = (I - K H) P``."""
    rng = np.random.default_rng(2)
    a = rng.normal(size=(15, 15))
    prior = a @ a.T * 1e-3 + np.diag(
        [4, 4, 9, 0.01, 0.01, 0.01, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4, 1e-4, 1e-11, 1e-11, 1e-11]
    )
    nav = _nav()
    offset = np.array([2.0, -1.5, 3.0])  # the fix: the INS moved by a known NED offset
    fix_nav = error_state.correct(
        nav, jnp.concatenate([jnp.asarray(offset), jnp.asarray([0.05, -0.02, 0.1]), jnp.zeros(3)])
    )
    R_p = np.diag([9.0, 6.0, 20.0]) + 1.0
    fix = GpsFix(
        fix_nav.position, fix_nav.velocity, jnp.asarray(R_p), 0.01 * jnp.eye(3), jnp.asarray(True)
    )
    filt = loosely_coupled.loosely_coupled_filter(imu.hg1900(), 0.01)
    state = filt.init(nav, jnp.asarray(prior))
    samples = jnp.tile(jnp.asarray([0.0, 0.0, -9.8, 0.0, 0.0, 0.0]), (100, 1))
    _, info = jax.jit(filt.step)(state, fix, samples)
    H = np.eye(6, 15)
    R = np.block([[R_p, np.zeros((3, 3))], [np.zeros((3, 3)), 0.01 * np.eye(3)]])
    z = np.asarray(error_state.navigation_error(nav, fix_nav))[:6]
    np.testing.assert_allclose(z, np.concatenate([offset, [0.05, -0.02, 0.1]]), rtol=1e-9)
    S = H @ prior @ H.T + R
    K = prior @ H.T @ np.linalg.inv(S)
    np.testing.assert_allclose(info.correction, K @ z, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(
        info.filtered_cov, (np.eye(15) - K @ H) @ prior, rtol=1e-7, atol=1e-18
    )
    assert float(info.nis) == pytest.approx(z @ np.linalg.solve(S, z), rel=1e-10)
    truth_after = error_state.correct(nav, K @ z)  # the feedback: INS minus the estimated error
    np.testing.assert_allclose(info.filtered_nav.position, truth_after.position, rtol=1e-14)
    assert bool(info.healthy) and bool(info.used)
    # a fix RAIM rejected leaves the prior alone
    _, coasted = jax.jit(filt.step)(state, fix._replace(valid=jnp.asarray(False)), samples)
    assert float(coasted.nis) == 0.0 and not np.any(np.asarray(coasted.correction))
    np.testing.assert_array_equal(coasted.filtered_cov, prior)


def test_scst_statistic_equals_numpy_and_reports_bad_B():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(15, 15))
    B = a @ a.T + np.diag(10.0 ** rng.uniform(-8, 2, 15))
    beta = rng.normal(size=15)
    statistic, valid, condition = scst.scst_statistic(jnp.asarray(beta), jnp.asarray(B), 1e8)
    assert bool(valid) and float(statistic) == pytest.approx(
        beta @ np.linalg.solve(B, beta), rel=1e-9
    )
    scaled = B / np.sqrt(np.outer(np.diag(B), np.diag(B)))
    assert (
        1.0 <= float(condition) <= np.linalg.cond(scaled) * (1 + 1e-9)
    )  # a lower bound of the condition
    # right after a reset B = 0: no decision, reported
    statistic, valid, condition = scst.scst_statistic(jnp.zeros(15), jnp.zeros((15, 15)), 1e8)
    assert not bool(valid) and float(statistic) == 0.0 and np.isinf(float(condition))
    # indefinite (a propagator that lost a direction): refused
    indefinite = B - np.eye(15) * np.linalg.eigvalsh(B)[1]
    statistic, valid, _ = scst.scst_statistic(jnp.asarray(beta), jnp.asarray(indefinite), 1e8)
    assert not bool(valid) and float(statistic) == 0.0
    # ill-conditioned: two directions nearly equal, condition ~1e12 > 1e8
    u = rng.normal(size=15)
    nearly = np.outer(u, u) + 1e-12 * np.eye(15)
    statistic, valid, condition = scst.scst_statistic(jnp.asarray(beta), jnp.asarray(nearly), 1e8)
    assert not bool(valid) and float(condition) > 1e8 and float(statistic) == 0.0


@pytest.fixture(scope="module")
def linear_scst_samples():
    """Da's SCST on a linear-Gaussian system (a 3-state double integrator with a bias, the
    position measured) run by the library's Kalman filter: 400 runs of 120 steps, the
    statistic of propagator ``a`` at its full age (period 20) every 20 steps."""
    dt = 1.0
    Phi = jnp.asarray([[1.0, dt, 0.5 * dt**2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = jnp.diag(jnp.asarray([1e-4, 1e-3, 1e-4]))
    model = jaxfdi.models.linear_gaussian_model(
        Phi, jnp.asarray([[1.0, 0.0, 0.0]]), Q, jnp.asarray([[0.25]])
    )
    kf = jaxfdi.filters.kalman_filter(model)
    test = scst.state_chi2_test(20, 1e9)
    steps = 120

    def one(key):
        key_x0, key_run = jax.random.split(key)
        x0 = jax.random.normal(key_x0, (3,))  # drawn from the filter's prior N(0, I)
        _, truth, _ = jaxfdi.simulate(
            jaxfdi.linear_simulator(model), x0, jnp.zeros((steps, 0)), key_run
        )
        _, info = jaxfdi.filters.run_filter(
            kf, kf.init(jnp.zeros(3), jnp.eye(3)), truth.measurement
        )

        def body(state, step):
            correction, cov = step
            return test.step(state, correction, cov, Phi, Q)

        _, out = jax.lax.scan(
            body, test.init(3), (info.filtered_mean - info.predicted_mean, info.filtered_cov)
        )
        return out.decision.statistic, out.valid, out.used, out.age

    statistic, valid, used, age = jax.jit(jax.vmap(one))(jax.random.split(jax.random.key(4), 400))
    pick = np.arange(20, steps, 20)
    assert np.all(np.asarray(age)[:, pick] == 20) and np.all(np.asarray(used)[:, pick] == 0)
    assert not np.any(np.asarray(valid)[:, 0])  # the first epoch: both propagators just reset
    return np.asarray(statistic)[:, pick][np.asarray(valid)[:, pick]]


def test_scst_is_chi_square_on_a_linear_gaussian_system(linear_scst_samples):
    """Fault-free, beta ~ N(0, P_m - P_f) (Da 1994): the statistics follow chi-square(3)
    (KS test over 2000 decisions at the propagator's full age)."""
    assert linear_scst_samples.size == 2000
    assert stats.kstest(linear_scst_samples, "chi2", args=(3,)).pvalue > 0.01
    assert np.mean(linear_scst_samples) == pytest.approx(3.0, abs=3 * math.sqrt(6 / 2000) * 1.5)


def test_bad_arguments_are_refused_by_name():
    with pytest.raises(ValueError, match="period"):
        scst.state_chi2_test(25, 32.8)
    with pytest.raises(ValueError, match="period"):
        scst.state_chi2_test(1, 32.8)
    filt = loosely_coupled.loosely_coupled_filter(imu.hg1900(), 0.01)
    state = filt.init(_nav(), jnp.eye(15))
    fix = GpsFix(_nav().position, _nav().velocity, jnp.eye(3), jnp.eye(3), jnp.asarray(True))
    with pytest.raises(ValueError, match="u: expected"):
        filt.step(state, fix, jnp.zeros((100, 3)))
    with pytest.raises(ValueError, match="cov"):
        filt.init(_nav(), -jnp.eye(15))
    flight = plant.flight_tables(trajectory.stationary(PARK, 3.0), 2)
    with pytest.raises(ValueError, match="imu_fault"):
        plant.gps_ins_plant(
            None,
            0.0,
            flight,
            jnp.ones((2, 5), bool),
            jnp.ones((2, 5)),
            imu.hg1900(),
            imu_fault=jaxfdi.fault("bias", "sensor", 7, 1, 1e-4),
        )
    with pytest.raises(ValueError, match="trajectory: expected"):
        plant.flight_tables(trajectory.stationary(PARK, 3.0), 5)


def test_hold_last_finite_against_a_loop():
    """A dead IMU sample is replaced by its channel's latest finite one (the previous
    epoch's ``last`` before the first): brute force over a random NaN/inf pattern."""
    rng = np.random.default_rng(4)
    samples = rng.normal(size=(40, 6))
    samples[rng.random((40, 6)) < 0.3] = np.nan
    samples[:5, 2] = np.inf  # dead from the epoch's start: ``last`` fills it
    samples[:, 4] = np.nan  # dead the whole epoch
    last = rng.normal(size=6)
    expected, held = samples.copy(), last.copy()
    for i in range(40):
        for j in range(6):
            if np.isfinite(samples[i, j]):
                held[j] = samples[i, j]
            expected[i, j] = held[j]
    filled, new_last = jax.jit(loosely_coupled.hold_last_finite)(
        jnp.asarray(samples), jnp.asarray(last)
    )
    np.testing.assert_array_equal(np.asarray(filled), expected)
    np.testing.assert_array_equal(np.asarray(new_last), expected[-1])


def test_a_dead_imu_channel_keeps_the_ins_finite():
    """One epoch with the roll gyro NaN from its 30th sample equals the epoch with those
    samples replaced by the 29th (the filter coasts on the last finite sample)."""
    filt = loosely_coupled.loosely_coupled_filter(imu.hg1900(), 0.01)
    state = filt.init(_nav(), jnp.eye(15) * 1e-2)
    fix = GpsFix(_nav().position, _nav().velocity, jnp.eye(3), jnp.eye(3), jnp.asarray(False))
    samples = (
        np.tile([0.1, -0.2, -9.8, 0.01, 0.0, 0.002], (100, 1))
        + np.random.default_rng(5).normal(size=(100, 6)) * 1e-3
    )
    dead = samples.copy()
    dead[30:, 3] = np.nan
    held = samples.copy()
    held[30:, 3] = samples[29, 3]
    step = jax.jit(filt.step)
    (next_dead, info_dead), (next_held, _) = (
        step(state, fix, jnp.asarray(dead)),
        step(state, fix, jnp.asarray(held)),
    )
    assert bool(info_dead.healthy)
    for a, b in zip(jax.tree_util.tree_leaves(next_dead), jax.tree_util.tree_leaves(next_held)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_a_stuck_imu_channel_holds_its_onset_sample_and_a_dead_one_is_nan():
    """The plant's IMU faults act per sample: STUCK on the roll gyro from epoch 1 holds
    epoch 1's first sample on every later sample; DEAD on the yaw gyro from epoch 2 is
    NaN on that channel alone."""
    from jaxfdi.data import data_path
    from jaxfdi.gnss import _orbits as orbits
    from jaxfdi.gnss import _rinex as rinex

    table = orbits.ephemeris_table(
        rinex.read_rinex_nav(data_path("gps_nav_rinex2_sugl0010.20n")), 2086
    )
    slots = table.prn.shape[0]
    model = imu.hg1900()
    flight = plant.flight_tables(trajectory.stationary(PARK, 4.0, rate=10.0), 3)
    faults = jaxfdi._simulation.faults.concat_faults(
        jaxfdi.fault("stuck", "sensor", 3, 1), jaxfdi.fault("dead", "sensor", 5, 2)
    )
    gps_ins = plant.gps_ins_plant(
        table,
        262_000.0,
        flight,
        jnp.zeros((3, slots), bool),
        jnp.ones((3, slots)),
        model,
        imu_fault=faults,
    )
    key = jax.random.PRNGKey(0)
    state = gps_ins.init((jnp.zeros(2), imu.draw_errors(key, model)))
    epochs = []
    for k in range(3):
        state, sensed = gps_ins.measure(
            state, jnp.asarray(k), jnp.zeros(0), jax.random.fold_in(key, k)
        )
        state, _ = gps_ins.advance(state, jnp.asarray(k), jnp.zeros(0), jax.random.fold_in(key, k))
        epochs.append(np.asarray(sensed.measurement.imu))
    first, second, third = epochs
    assert np.unique(first[:, 3]).size == 10  # live before the onset
    np.testing.assert_array_equal(
        second[:, 3], second[0, 3]
    )  # held from the onset epoch's first sample
    np.testing.assert_array_equal(third[:, 3], second[0, 3])
    assert (
        np.isnan(third[:, 5]).all()
        and np.isfinite(third[:, :5]).all()
        and np.isfinite(second).all()
    )
