"""Seed 000's hybrid FDI on the closed-loop F-16 (detection.hybrid_psa, models.f16.rates,
scenarios.f16_fdi).

References: the full F-16 dynamics (the moment part), filterpy's UKF on the same moment
equations, a UKF started fresh from the buffered state (``run_filter``), NumPy least
squares, binomial intervals of the false-alarm and isolation counts. One compiled
closed-loop program (144 flights of 3.2 s, vmapped with the replay condition over the
batch) serves the closed-loop tests; the other tests replay a recorded sequence.

Notebook 06 runs last: its study starts from the same trimmed flight
(``flight_setup(gust_sigma=3.0)``, the study's default gusts) as the ``env`` fixture, whose
programs are then in the run's shared XLA cache (see conftest).
"""

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest
import scipy.stats
from _frames import assert_table_is_the_json
from _notebooks import images, run_clean, tables
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from jaxfdi import Target
from jaxfdi._simulation import loop, stages
from jaxfdi._simulation.faults import active_label, apply_faults
from jaxfdi.detection import _hybrid_psa as hp
from jaxfdi.filters import run_filter
from jaxfdi.models.f16 import (
    RATE_OFFSET,
    f16_dynamics,
    rate_model,
    rate_model_input,
    rate_transition,
)
from jaxfdi.models.f16._plant import MEASURED_STATES
from jaxfdi.models.f16._rates import rate_derivative
from jaxfdi.scenarios import f16_fdi as sf
from jaxfdi.scenarios.f16_flight import dispersions, flight_setup, nominal_dispersion

ONSET = 300  # the paper's 3 s
STEPS = 320  # closed-loop flights of 3.2 s
PAPER, NEAR, FREE, DEAD = 16, 64, 64, 12
BATCH = "flights"


@pytest.fixture(scope="module")
def env():
    setup, _ = flight_setup(gust_sigma=3.0)
    fdi, calibration = sf.fdi_setup(setup, samples=50_000)
    return setup, fdi, calibration


def _fly(setup, fdi, keys, disp, cases, follows):
    def one(k, d, c, f):
        out = sf.run_fdi_flight(setup, fdi, k, d, c, f, batch_axis=BATCH)
        return out.fdi.decision, out.healthy

    return jax.vmap(one, axis_name=BATCH)(keys, disp, cases, follows)


FLY = jax.jit(_fly)


def _cases(dtype):
    """The paper's case (16 noise draws), 64 faults within 5 deg of a singular direction
    (random sensor, FNR 10) and 64 fault-free flights."""
    rng = np.random.default_rng(0)
    cases = [sf.fault_case(dtype=dtype)] * PAPER
    near = [
        (int(rng.integers(3)), 45.0 + 90.0 * int(rng.integers(4)) + rng.uniform(-5.0, 5.0))
        for _ in range(NEAR)
    ]
    cases += [sf.fault_case("bias", s, 10.0, a, dtype=dtype) for s, a in near]
    cases += [sf.fault_case("none", dtype=dtype)] * FREE
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *cases)


@pytest.fixture(scope="module")
def flights(env):
    setup, fdi, _ = env
    short = setup._replace(reference=jax.tree_util.tree_map(lambda a: a[:STEPS], setup.reference))
    n = PAPER + NEAR + FREE
    keys = jax.random.split(jax.random.key(24), n)
    disp = dispersions(jax.random.key(25), setup, n)
    disp = jax.tree_util.tree_map(lambda a, b: a.at[:1].set(b), disp, nominal_dispersion(setup))
    cases = _cases(setup.x0.dtype)
    # then DEAD flights with a dead rate sensor (4 per sensor), on draws of their own
    dead = sf.fault_case("dead", np.arange(DEAD) % 3, 0.0, 0.0, dtype=setup.x0.dtype)
    keys = jnp.concatenate([keys, jax.random.split(jax.random.key(26), DEAD)])
    disp = jax.tree_util.tree_map(
        lambda a, b: jnp.concatenate([a, b]), disp, dispersions(jax.random.key(27), setup, DEAD)
    )
    cases = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), cases, dead)
    n += DEAD
    follows = jnp.full((n,), hp.FOLLOW["hybrid"], jnp.int32)
    decision, healthy = jax.tree_util.tree_map(
        np.asarray, FLY(short, fdi, keys, disp, cases, follows)
    )
    # the same flights with T_D at P_fa = 1e-3 per step (a statistical check of the FD law in closed loop)
    loose = fdi._replace(
        hybrid=fdi.hybrid._replace(
            detection_threshold=float(setup.sensors.rate_sigma) ** 2 * scipy.stats.chi2.isf(1e-3, 3)
        )
    )
    loose_decision, _ = jax.tree_util.tree_map(
        np.asarray, FLY(short, loose, keys, disp, cases, follows)
    )
    return decision, healthy, loose_decision, np.asarray(cases.sensor)


def test_paper_case_isolates_sensor_1(flights):
    """Bias of FNR 10 on both axes of sensor 1 at 3 s (the type-2 singular direction):
    detected at the onset in all 16 noise draws; in the nominal flight (draw 0) PSA flags
    sensors 1 and 3 and the UKF's residual isolates sensor 1 (the paper's Figs. 5-8).
    Over the draws: whenever PSA leaves two suspects the hybrid isolates sensor 1, with
    ``||r_1|| > 4 ||r_3||``; a draw where the noise pushes FI_1 below T_I leaves sensor 3
    the only suspect and PSA's one-suspect decision stands (the paper's step 2). That
    happens with probability P_MI = 0.01 per draw (T_I's calibration; the planes' Gram is
    I/2 in every direction), so the draws missing sensor 1 must stay within the 99.9 %
    binomial bound of Binomial(16, 0.01) (2)."""
    decision, healthy, _, _ = flights
    paper = slice(0, PAPER)
    assert np.all(healthy[paper])
    assert np.all(decision.detection_step[paper] == ONSET)
    assert np.all(decision.decision_step[paper] == ONSET)
    assert decision.suspects[0].tolist() == [True, False, True]
    assert bool(decision.filter_used[0]) and int(decision.hybrid[0]) == 1
    suspects = decision.suspects[paper]
    assert not np.any(
        suspects[:, 1]
    )  # sensor 2 never a suspect: the parity lies on the FP1/FP3 line
    used = decision.filter_used[paper]
    assert np.all(used == (suspects[:, 0] & suspects[:, 2]))
    assert np.all(decision.hybrid[paper][used] == 1)
    r = decision.analytic_residuals[paper][used]
    assert np.all(r[:, 0] > 4 * r[:, 2])  # ||r_1|| ~ 0.14 rad/s, ||r_3|| ~ noise
    missed = int(np.sum(decision.hybrid[paper] != 1))
    assert missed == int(np.sum(~suspects[:, 0]))
    assert missed <= scipy.stats.binom.ppf(0.999, PAPER, sf.MISSED_ISOLATION), missed


def test_hybrid_beats_psa_alone_near_singular_directions(flights):
    """64 faults within 5 deg of Table 1's singular directions (random sensor, FNR 10):
    PSA alone (the suspect with the largest FI) is about a coin flip, the hybrid isolates
    nearly all. Claim: the hybrid's rate exceeds PSA alone's by at least 0.25 and their
    99 % Clopper-Pearson intervals do not overlap."""
    decision, healthy, _, sensor = flights
    near = slice(PAPER, PAPER + NEAR)
    assert np.all(healthy[near]) and np.all(decision.decision_step[near] >= ONSET)
    psa = int(np.sum(decision.psa[near] == sensor[near] + 1))
    hybrid = int(np.sum(decision.hybrid[near] == sensor[near] + 1))

    def interval(k):
        return scipy.stats.binomtest(k, NEAR).proportion_ci(0.99)

    assert hybrid / NEAR >= 0.9 and (hybrid - psa) / NEAR >= 0.25, (psa, hybrid)
    assert interval(hybrid).low > interval(psa).high, (psa, hybrid)


def test_a_dead_rate_sensor_is_detected_isolated_and_excluded_at_its_onset(flights):
    """Both axes of a rate sensor NaN from 3 s (4 flights per sensor): the parity test
    alarms at the onset (``FD = +inf``) with that sensor the one suspect, PSA and the
    hybrid isolate it at once, and every flight stays healthy: the controller flies on the
    estimate without the dead sensor and never receives a non-finite rate (one NaN rate
    would make the plant's state, and so the flight, non-finite)."""
    decision, healthy, _, sensor = flights
    dead = slice(PAPER + NEAR + FREE, None)
    assert np.all(healthy[dead])
    assert np.all(decision.detection_step[dead] == ONSET) and np.all(
        decision.decision_step[dead] == ONSET
    )
    assert np.array_equal(decision.suspects[dead], np.eye(3, dtype=bool)[sensor[dead]])
    assert np.all(decision.psa[dead] == sensor[dead] + 1) and np.all(
        decision.hybrid[dead] == sensor[dead] + 1
    )
    assert not np.any(decision.filter_used[dead])


def test_fault_free_flights_false_alarms_within_binomial_bounds(flights):
    """64 fault-free closed-loop flights of 320 steps: at P_fa = 1e-6 per step the
    flights with an FD alarm are within the 99.9 % binomial bound (expected 0.02); at
    1e-3 per step, the count (expected 17.5) lies in its 99.9 % binomial interval, so FD
    follows its chi-square law in the closed loop."""
    decision, healthy, loose, _ = flights
    free = slice(PAPER + NEAR, PAPER + NEAR + FREE)
    assert np.all(healthy[free])
    for pfa, record in ((sf.PFA, decision), (1e-3, loose)):
        per_flight = 1.0 - (1.0 - pfa) ** STEPS
        alarms = int(np.sum(record.detection_step[free] >= 0))
        low, high = scipy.stats.binom.interval(0.999, FREE, per_flight)
        assert low <= alarms <= high, (pfa, alarms, low, high)


@pytest.fixture(scope="module")
def recorded(env):
    """A recorded sequence: the flight's reference trajectory sensed with noise, a
    sensor-1 bias of FNR 10 in the type-2 direction from step 150, its controls."""
    setup, fdi, _ = env
    steps, onset = 200, 150
    ref = setup.reference
    x = np.asarray(ref.state[:steps])
    H = np.asarray(setup.sensors.rate_axes)
    rng = np.random.default_rng(7)
    ys = np.concatenate([x[:, list(MEASURED_STATES)], x[:, 6:9] @ H.T], axis=1)
    ys[:, RATE_OFFSET:] += 0.01 * rng.standard_normal((steps, 6))
    ys[onset:, RATE_OFFSET : RATE_OFFSET + 2] += 0.1
    return jnp.asarray(ys), jnp.asarray(ref.control[:steps]), onset


def _replayed(fdi, ys, us, batch_axis=None):
    """The hybrid FDI stage driven by ``run_loop`` over the recorded ``ys`` with the
    recorded controls (a plant that plays them back, a feed-forward controller)."""
    player = stages.Plant(
        lambda x0: None, lambda s, k, u, key: (s, ys[k]), lambda s, k, u, key: (s, None)
    )
    result = loop.run_loop(
        player,
        sf.f16_hybrid_fdi(fdi, batch_axis),
        loop.feedforward(),
        jnp.zeros(1),
        sf.fdi_state0(fdi),
        jax.random.key(0),
        exogenous=us,
        keep_history=True,
    )
    return result.final[1].decision, result.history.output


def test_replayed_ukf_equals_a_fresh_ukf_from_the_buffered_state(env, recorded):
    """At the decision, the FDI's bounded replay (restart 3 steps back, inside the scan)
    gives the residuals of a UKF started fresh from the buffered least-squares state and
    run with ``run_filter`` on the healthy sensor's channels, to 1e-12; and a batch with
    the replay under a ``psum`` condition equals the same batch with both branches
    computed (vmap without an axis name)."""
    _, fdi, _ = env
    ys, us, onset = recorded
    decision, out = jax.jit(_replayed)(fdi, ys, us)
    step = int(decision.decision_step)
    assert step == onset and int(decision.hybrid) == 1 and bool(decision.filter_used)
    assert np.asarray(decision.suspects).tolist() == [True, False, True]
    trusted = jnp.repeat(~decision.suspects, 2)
    norms, _ = sf.analytic_residual_trace(
        fdi, ys, us, step - sf.RESTART_LAG, trusted, sf.RESTART_LAG
    )
    np.testing.assert_allclose(decision.analytic_residuals, norms[-1], rtol=1e-12, atol=1e-15)
    assert np.all(np.isnan(np.asarray(out.values.analytic_residuals)[np.arange(len(ys)) != step]))
    # a batch: per-run noise, with the psum condition and without
    noise = 0.01 * jax.random.normal(jax.random.key(1), (4,) + ys[:, RATE_OFFSET:].shape)
    batch = jnp.broadcast_to(ys, (4,) + ys.shape).at[:, :, RATE_OFFSET:].add(noise)
    named = jax.jit(jax.vmap(lambda y: _replayed(fdi, y, us, BATCH)[0], axis_name=BATCH))(batch)
    plain = jax.jit(jax.vmap(lambda y: _replayed(fdi, y, us)[0]))(batch)
    for a, b in zip(jax.tree_util.tree_leaves(named), jax.tree_util.tree_leaves(plain)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-13, atol=0)


def test_ukf_on_the_moment_equations_equals_filterpy(env, recorded):
    """The analytic redundancy's UKF (moment equations 34-36 with the coefficient errors,
    only sensor 2's channels measured, the rest NaN) against filterpy's
    UnscentedKalmanFilter + MerweScaledSigmaPoints on the same transition with sensor 2's
    two channels: filtered means and covariances to 1e-8."""
    _, fdi, _ = env
    ys, us, _ = recorded
    inputs = jax.vmap(rate_model_input)(ys, us)
    channels = np.asarray(ys[:, RATE_OFFSET:])
    H = np.asarray(fdi.rates.rate_axes)
    trusted = np.array([False, False, True, True, False, False])
    ukf = sf.f16_rate_ukf(fdi)
    m0 = np.linalg.lstsq(H, channels[0], rcond=None)[0]
    P0 = np.asarray(fdi.hybrid.restart_cov)
    T = 40
    _, info = jax.jit(
        lambda: run_filter(
            ukf,
            ukf.init(jnp.asarray(m0), jnp.asarray(P0)),
            jnp.where(trusted, channels[:T], jnp.nan),
            inputs[:T],
        )
    )()
    f = jax.jit(lambda x, v: rate_transition(x, v, fdi.rates))
    points = MerweScaledSigmaPoints(3, sf.UKF_ALPHA, sf.UKF_BETA, sf.UKF_KAPPA)
    ref = UnscentedKalmanFilter(3, 2, 0.01, hx=lambda x: H[trusted] @ x, fx=None, points=points)
    ref.x, ref.P = m0.copy(), P0.copy()
    ref.Q, ref.R = np.asarray(fdi.process_cov), np.asarray(fdi.noise_cov)[np.ix_(trusted, trusted)]
    means, covs = [], []
    for k in range(T):
        ref.sigmas_f = points.sigma_points(ref.x, ref.P)  # jaxfdi's step starts from N(x, P)
        ref.update(channels[k, trusted])
        means.append(ref.x.copy())
        covs.append(ref.P.copy())
        ref.predict(fx=lambda x, dt, v: np.asarray(f(x, v)), v=np.asarray(inputs[k]))
    np.testing.assert_allclose(info.filtered_mean, np.array(means), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(info.filtered_cov, np.array(covs), rtol=1e-8, atol=1e-14)


def test_rate_model_is_the_moment_part_of_the_dynamics(env):
    """``rate_derivative`` with no coefficient error equals ``f16_dynamics``' P', Q', R'
    over 32 random states and controls; a 10 % error on Cm changes Q' only."""
    setup, fdi, _ = env
    params = setup.params
    rng = np.random.default_rng(3)
    lo = np.array([350, -0.05, -0.05, -0.5, -0.3, -1, -0.5, -0.3, -0.3, 0, 0, 0, 20])
    hi = np.array([800, 0.3, 0.05, 0.5, 0.3, 1, 0.5, 0.3, 0.3, 1, 1, 20000, 80])
    xs = jnp.asarray(lo + (hi - lo) * rng.random((32, 13)))
    us = jnp.asarray(np.column_stack([rng.random(32), rng.uniform(-10, 10, (32, 3))]))
    exact = rate_model(params, setup.sensors.rate_axes)
    ys = jnp.concatenate([xs[:, list(MEASURED_STATES)], jnp.zeros((32, 6))], axis=1)
    ours = jax.vmap(lambda x, y, u: rate_derivative(x[6:9], rate_model_input(y, u), exact))(
        xs, ys, us
    )
    full = jax.vmap(lambda x, u: f16_dynamics(x, u, params)[6:9])(xs, us)
    np.testing.assert_allclose(ours, full, rtol=1e-12, atol=1e-12)
    pitch = rate_model(params, setup.sensors.rate_axes, coefficient_error=(0.0, 0.1, 0.0))
    moved = jax.vmap(lambda x, y, u: rate_derivative(x[6:9], rate_model_input(y, u), pitch))(
        xs, ys, us
    )
    np.testing.assert_allclose(moved[:, [0, 2]], full[:, [0, 2]], rtol=1e-12, atol=1e-12)
    assert np.all(np.abs(moved[:, 1] - full[:, 1]) > 0)


def test_sensor_faults_act_on_both_axes_with_their_label_and_size(env):
    """``sensor_fault``: bias of FNR v in direction a adds ``v sigma sqrt(2) (cos a, sin a)``
    to the sensor's two channels only (RMS / sigma = v), labelled sensor + 1; drift, stuck
    and scale behave as ``faults`` defines them."""
    setup, _, _ = env
    sigma = setup.sensors.rate_sigma
    y = jnp.asarray(np.random.default_rng(2).standard_normal(14))
    for sensor in range(3):
        case = sf.fault_case("bias", sensor, 7.0, 30.0, onset_s=0.1)
        f = sf.sensor_fault(case, sigma)
        out, _ = apply_faults(f, 10, y, Target.SENSOR, jnp.zeros(2))
        delta = np.asarray(out - y)
        axes = [RATE_OFFSET + 2 * sensor, RATE_OFFSET + 2 * sensor + 1]
        np.testing.assert_allclose(
            delta[axes],
            7.0 * 0.01 * np.sqrt(2) * np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)]),
            rtol=1e-12,
        )
        assert np.sqrt(np.mean(delta[axes] ** 2)) / 0.01 == pytest.approx(7.0)
        assert np.count_nonzero(delta) == 2 and int(active_label(f, 10, 4)) == sensor + 1
        assert int(active_label(f, 9, 4)) == 0
    drift = sf.sensor_fault(sf.fault_case("drift", 1, 10.0, 0.0, onset_s=0.1), sigma)
    out, _ = apply_faults(drift, 110, y, Target.SENSOR, jnp.zeros(2))  # one second after the onset
    assert float(out[RATE_OFFSET + 2] - y[RATE_OFFSET + 2]) == pytest.approx(
        10.0 * 0.01 * np.sqrt(2), rel=1e-12
    )
    scale = sf.sensor_fault(sf.fault_case("scale", 2, 0.5, 90.0, onset_s=0.1), sigma)
    out, _ = apply_faults(scale, 10, y, Target.SENSOR, jnp.zeros(2))
    np.testing.assert_allclose(
        out[RATE_OFFSET + 4 :], y[RATE_OFFSET + 4 :] * np.array([1.0, 1.5]), rtol=1e-12, atol=1e-15
    )
    stuck = sf.sensor_fault(sf.fault_case("stuck", 0, 0.0, 0.0, onset_s=0.1), sigma)
    _, held = apply_faults(stuck, 10, y, Target.SENSOR, jnp.zeros(2))
    out, _ = apply_faults(stuck, 11, y + 1.0, Target.SENSOR, held)
    np.testing.assert_allclose(
        out[RATE_OFFSET : RATE_OFFSET + 2], y[RATE_OFFSET : RATE_OFFSET + 2], rtol=1e-15
    )


def test_fault_cases_from_arrays_are_the_cases_one_by_one():
    """``fault_case`` on arrays (one host transfer per field: how 10^5 flights are set up)
    gives, row by row, the kind's code, the sensor, the FNR, the angle in radians
    (``math.radians``) and the onset step (``round(onset_s / DT)``) of each flight; a
    scalar call gives the 0-d case; an unknown kind is refused."""
    rng = np.random.default_rng(5)
    kinds = np.array(["bias", "drift", "stuck", "scale", "none"])[rng.integers(0, 5, 200)]
    sensor, size = rng.integers(0, 3, 200), rng.uniform(0.0, 20.0, 200)
    angle, onset = rng.uniform(0.0, 360.0, 200), rng.uniform(0.0, 10.0, 200)
    cases = sf.fault_case(kinds, sensor, size, angle, onset, dtype=jnp.float64)
    codes = [int(sf.FaultKind.NONE if k == "none" else sf.KINDS[k]) for k in kinds]
    assert (
        np.asarray(cases.kind).tolist() == codes
        and np.asarray(cases.sensor).tolist() == sensor.tolist()
    )
    assert np.asarray(cases.size).tolist() == size.tolist()
    assert np.asarray(cases.angle).tolist() == [math.radians(a) for a in angle]
    assert np.asarray(cases.onset).tolist() == [int(round(t / sf.DT)) for t in onset]
    assert cases.kind.dtype == jnp.int32 and cases.angle.dtype == jnp.float64
    one = sf.fault_case("drift", 2, 4.0, 30.0, 1.5)
    assert (
        [np.shape(f) for f in one] == [()] * 5
        and int(one.onset) == 150
        and int(one.kind) == int(sf.KINDS["drift"])
    )
    with pytest.raises(ValueError, match=r"^kind: expected one of .*'melt'"):
        sf.fault_case(np.array(["bias", "melt"]), 0, 1.0, 0.0)


def test_exclusion_estimators_and_bad_input(env):
    """The selected rates after excluding a sensor are NumPy's least squares on the four
    channels left."""
    _, fdi, calibration = env
    H = np.asarray(fdi.hybrid.space.H)
    m = np.random.default_rng(0).standard_normal(6)
    est = np.asarray(fdi.hybrid.estimators)
    np.testing.assert_allclose(est[0] @ m, np.linalg.lstsq(H, m, rcond=None)[0], rtol=1e-12)
    for g in range(3):
        keep = [c for c in range(6) if c // 2 != g]
        np.testing.assert_allclose(
            est[g + 1] @ m, np.linalg.lstsq(H[keep], m[keep], rcond=None)[0], rtol=1e-12
        )
    assert float(calibration.missed_isolation) <= sf.MISSED_ISOLATION
    with pytest.raises(ValueError, match="follow"):
        hp.hybrid_psa_init(fdi.hybrid, jnp.zeros(8), follow="sometimes")
    with pytest.raises(ValueError, match="restart_lag"):
        hp.hybrid_psa_init(fdi.hybrid, jnp.zeros(8), restart_lag=0)
    with pytest.raises(ValueError, match="isolation_threshold"):
        hp.hybrid_psa_config(fdi.hybrid.space, 0.01, 1.0, 1.5)
    with pytest.raises(TypeError, match="analytic_filter"):
        hp.hybrid_psa_fdi(fdi.hybrid, None, lambda y: y, lambda y, u: u, lambda y, x: x)
    with pytest.raises(ValueError, match="coefficient_error"):
        rate_model(env[0].params, H, coefficient_error=(0.1, 0.1))


def test_verification_statistic_is_the_least_squares_residual_of_the_channels_left(env):
    """``FD_-g`` (hybrid_psa step 5) is NumPy's least-squares residual of the four channels
    left without sensor g, +inf when a channel left is not finite; ``T_V`` is
    ``sigma^2 chi2.isf(P_V, 6 - 2 - 3)`` (SciPy)."""
    setup, fdi, _ = env
    H = np.asarray(fdi.hybrid.space.H)
    m = np.random.default_rng(1).standard_normal(6)
    fd = np.asarray(hp.subset_statistics(fdi.hybrid, jnp.asarray(m)))
    for g in range(3):
        keep = [c for c in range(6) if c // 2 != g]
        x = np.linalg.lstsq(H[keep], m[keep], rcond=None)[0]
        np.testing.assert_allclose(fd[g], np.sum((m[keep] - H[keep] @ x) ** 2), rtol=1e-10)
    dead = np.asarray(hp.subset_statistics(fdi.hybrid, jnp.asarray(m).at[4].set(jnp.nan)))
    assert np.isfinite(dead[2]) and np.all(np.isinf(dead[:2]))
    np.testing.assert_allclose(dead[2], fd[2], rtol=1e-12)
    sigma = float(setup.sensors.rate_sigma)
    np.testing.assert_allclose(
        float(fdi.hybrid.verification_threshold),
        sigma**2 * scipy.stats.chi2.isf(sf.VERIFICATION_PFA, 1),
        rtol=1e-9,
    )
    assert np.isinf(
        float(hp.hybrid_psa_config(fdi.hybrid.space, 0.01, 1.0, 0.5).verification_threshold)
    )


KIND_RUNS = 40


@pytest.fixture(scope="module")
def kinds(tmp_path_factory):
    """Every fault kind at the paper's size, 40 full flights (15 s) each, flown without FDI,
    under the paper's hybrid rule and under the verified rule (the same draws), as the
    paper page's command runs it (``jaxfdi run f16-fault-kinds``, in this process): its JSON
    is ``fault_kind_study``'s rows, and their table as a DataFrame has the same numbers."""
    import json

    from jaxfdi import cli

    out = tmp_path_factory.mktemp("f16-fault-kinds")
    argv = ["run", "f16-fault-kinds", "--runs", str(KIND_RUNS), "--seed", "38", "--quiet"]
    assert cli.main([*argv, "--out", str(out)]) == 0
    data = json.loads((out / "f16-fault-kinds.json").read_text())
    assert data["config"]["runs"] == KIND_RUNS
    assert_table_is_the_json(sf.F16KindStudy(data["config"], data["rows"]).to_frame(), data["rows"])
    return {(r["kind"], r["follow"]): r for r in data["rows"]}


def test_with_verified_fdi_no_fault_kind_leaves_the_envelope_more_often_than_without(kinds):
    """Issue 38: for every fault kind, envelope exits under the verified FDI are not more
    frequent than without FDI (one-sided Fisher exact test, p > 0.01), and where FDI is
    needed (a drift: about half the flights leave without it) fewer, with non-overlapping
    99 % Clopper-Pearson intervals. The paper's rule (no verification) flies a stuck sensor
    out of the envelope (it excludes a healthy sensor), and the verified rule misisolates
    fewer stuck sensors than it, again with non-overlapping 99 % intervals."""
    for kind in sf.KIND_SIZES:
        none, verified = kinds[(kind, "none")], kinds[(kind, "verified")]
        assert verified["healthy"] == verified["flights"] == KIND_RUNS, kind
        table = [
            [verified["envelope_exits"], KIND_RUNS - verified["envelope_exits"]],
            [none["envelope_exits"], KIND_RUNS - none["envelope_exits"]],
        ]
        assert scipy.stats.fisher_exact(table, alternative="greater").pvalue > 0.01, (kind, table)
    drift_none, drift = kinds[("drift", "none")], kinds[("drift", "verified")]
    assert drift["envelope_exit_interval_99"][1] < drift_none["envelope_exit_interval_99"][0], (
        drift,
        drift_none,
    )
    stuck_hybrid, stuck = kinds[("stuck", "hybrid")], kinds[("stuck", "verified")]
    assert stuck_hybrid["envelope_exits"] > stuck["envelope_exits"]
    assert stuck["misisolated_interval_99"][1] < stuck_hybrid["misisolated_interval_99"][0], (
        stuck,
        stuck_hybrid,
    )
    assert kinds[("none", "verified")]["envelope_exits"] == 0


def test_a_flight_gone_bad_is_an_exit_and_never_a_decision():
    """``_full_flight_rows`` on four hand-made flights of one kind: the two that went
    numerically bad are exits whatever their tracking errors, and are neither right nor
    wrong decisions even when their FDI named the faulty sensor."""
    from types import SimpleNamespace

    from jaxfdi.scenarios.f16_flight import ERRORS

    setup, _ = flight_setup()
    onset = 300
    n = 4
    decision = SimpleNamespace(
        decision_step=np.full(n, onset + 10),
        detection_step=np.full(n, onset + 5),
        psa=np.array([1, 2, 1, 1]),
        hybrid=np.array([1, 2, 1, 1]),
        verified=np.array([1, 2, 1, 1]),
        revisions=np.zeros(n, int),
        filter_used=np.zeros(n, bool),
    )
    out = SimpleNamespace(
        tracking=SimpleNamespace(max_abs=np.zeros((n, len(ERRORS)))),
        healthy=np.array([True, True, False, False]),
        fdi=decision,
    )
    labels = [("bias", 10.0, "verified")] * n
    (row,) = sf._full_flight_rows(out, labels, np.zeros(n, int), onset, setup)
    assert row["envelope_exits"] == 2 and row["healthy"] == 2
    assert row["decided"] == 2 and row["isolated"] == 1 and row["misisolated"] == 1


def test_f16_hybrid_notebook(env, python3_kernel, monkeypatch, tmp_path):
    """Notebook 06 (seed 000: hybrid PSA + UKF on the closed-loop F-16) end to end in a fresh
    kernel, one run per case (the programs of ``jaxfdi run f16 --runs 1``: 24 directions
    per sensor plane, 400 optimiser steps; compilation dominates, so fewer would not be
    cheaper); its Table 1 check, printed paper comparison and figures checked. After
    ``env`` (the fixture), so that the trimmed flight's programs are in the run's XLA cache."""
    frame, rows = tmp_path / "frame.pkl", tmp_path / "rows.json"
    outputs, text = run_clean(
        "06_f16_hybrid_psa_ukf.ipynb",
        python3_kernel,
        monkeypatch,
        {"JAXFDI_NB_RUNS": "1", "JAXFDI_NB_OPT_STEPS": "400"},  # the CLI's 400 steps
        f"import json\nstudy.to_frame().to_pickle({str(frame)!r})\n"
        f"open({str(rows)!r}, 'w').write(json.dumps(study.rows))",
    )
    assert_table_is_the_json(
        pd.read_pickle(frame), json.loads(rows.read_text())
    )  # to_frame() is the rows
    assert "runs per case: 1, directions per sensor plane: 24, optimiser steps: 400" in text
    for kind in (1, 2, 3):
        assert f"type {kind}: sensors" in text
    assert "Headline case beside the paper's" in text
    assert "PSA suspects: ours [1, 3] | paper: [1, 3]" in text
    assert "isolated sensor: ours 1 | paper: 1" in text
    html = tables(outputs)  # the study as DataFrames, a table per section
    assert html.count("<table") == 9 and "<h4>table1</h4>" in html and "<h4>paper_case</h4>" in html
    assert len(images(outputs)) == 5, f"expected 5 figures, got {len(images(outputs))}"
