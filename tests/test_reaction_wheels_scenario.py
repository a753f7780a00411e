"""Seed 004 scenario at reduced size: wheel fault semantics against hand-written
formulas, and the issue's claims on a closed-loop Monte Carlo batch.

One batch of 160 runs (the study's one closed-loop program, ``wheel_spec``, with the
batch's faults as its cases): 80 fault-free calibration runs, 40 fault-free test runs,
and a stop of each wheel (spinning near its 2000 rpm bias speed) in 10 runs each, onsets
uniform in 15-25 s. The banks engage on the NIS test, so the isolators do
not depend on ``F_T``; ``F_T`` is calibrated on the calibration runs and checked on the
test runs. Rates are checked with one-sided binomial bounds at the stated sizes.
"""
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxfdi.faults import FaultKind, no_fault
from jaxfdi.models.reaction_wheels import delivered_torque, kitsat3_params, stop_hypotheses, stop_transfer, wheel_momentum
from jaxfdi.metrics import binomial_lower_bound
from jaxfdi.scenarios import reaction_wheels as rw
from jaxfdi.study import run_study

CALIBRATION, FREE, PER_WHEEL = 80, 40, 10


@pytest.fixture(scope="module")
def batch():
    design = rw.wheel_design()
    cases = [("none", -1)] + [("stop", w) for w in range(4)]
    free = rw.case_faults([("none", -1)], CALIBRATION + FREE, jax.random.key(11))
    stops = rw.case_faults(cases[1:], PER_WHEEL, jax.random.key(12))
    faults = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), free, stops)
    spec = rw.wheel_spec(design, cases)._replace(cases=faults, case_names=tuple(map(str, range(160))))
    return design, run_study(spec, runs=1, seed=5).outputs["closed loop"]


def test_delivered_torque_follows_each_fault_kind():
    command = jnp.array([1e-3, -2e-3, 3e-3, 4e-3])
    expected_after = {  # wheel 2 from the onset (k = 10), by hand
        "stop": [1e-3, -2e-3, 0.0, 4e-3],
        "stuck": [1e-3, -2e-3, 0.0, 4e-3],
        "bias": [1e-3, -2e-3, 3e-3 + 5e-4, 4e-3],
        "gain": [1e-3, -2e-3, 3e-3 * (1 - 0.4), 4e-3],
    }
    magnitude = {"stop": 0.0, "stuck": 0.0, "bias": 5e-4, "gain": 0.4}
    for kind, after in expected_after.items():
        f = rw.wheel_fault(kind, 2, 10, magnitude[kind])
        np.testing.assert_allclose(delivered_torque(f, 9, command), command, atol=0)
        np.testing.assert_allclose(delivered_torque(f, 10, command), after, rtol=1e-15)
        np.testing.assert_allclose(delivered_torque(f, 500, command), after, rtol=1e-15)
    assert int(rw.wheel_fault("stop", 0, 1).kind) == FaultKind.STOP
    with pytest.raises(ValueError, match="kind"):
        rw.wheel_fault("explode", 0, 1)


def test_only_a_stop_moves_the_wheel_momentum_to_the_body():
    params = kitsat3_params()
    state = jnp.concatenate([jnp.array([1.0, 0, 0, 0]), jnp.array([0.01, -0.02, 0.005]),
                             jnp.array([200.0, -180.0, 220.0, -210.0])])
    for kind in ("stuck", "bias", "gain"):
        f = rw.wheel_fault(kind, 1, 7, 0.1)
        np.testing.assert_array_equal(stop_transfer(state, f, 7, params), state)
    f = rw.wheel_fault("stop", 1, 7)
    np.testing.assert_array_equal(stop_transfer(state, f, 6, params), state)
    moved = stop_transfer(state, f, 7, params)
    assert moved[7 + 1] == 0.0
    # the body's rate change is exactly the wheel's momentum I_w Omega a_1 through I^-1
    dw_expected = np.linalg.solve(np.asarray(params.inertia), 0.000239 * -180.0 * np.asarray(params.wheel_axes[1]))
    np.testing.assert_allclose(moved[4:7] - state[4:7], dw_expected, rtol=1e-12)


def test_stop_hypotheses_switch_off_one_wheel_each():
    params = kitsat3_params()
    speeds = jnp.array([100.0, 200.0, 300.0, 400.0])
    bank = stop_hypotheses(params, include_nominal=True)
    for mode in range(5):
        p = jax.tree_util.tree_map(lambda leaf: leaf[mode], bank)
        kept = [i for i in range(4) if i != mode - 1]
        expected = 0.000239 * np.asarray(speeds)[kept] @ np.asarray(params.wheel_axes)[kept]
        np.testing.assert_allclose(wheel_momentum(speeds, p), expected, rtol=1e-14, atol=1e-15)


def test_fault_free_f_stays_under_the_calibrated_threshold(batch):
    """The issue: F stays under its threshold in >= 99 % of fault-free runs. ``F_T`` is
    FDP_MARGIN x the largest F of the 80 calibration runs; on 40 other runs, 2 or more
    exceedances would reject 'exceedance rate <= 1 %' at the 6 % level (binomial)."""
    _, out = batch
    threshold = rw.FDP_MARGIN * out.max_fault_free_fdp[:CALIBRATION].max()
    exceed = int(np.sum(out.max_fault_free_fdp[CALIBRATION:CALIBRATION + FREE] > threshold))
    assert stats.binom.sf(1, FREE, 0.01) < 0.07
    assert exceed <= 1, exceed
    # the NIS test's design rate (chi2, Pfa 1e-5 a step) gives a 0.6 % per-run false-alarm rate
    nis_false = int(np.sum(out.nis.false_alarms[:CALIBRATION + FREE] > 0))
    assert nis_false <= 3, nis_false  # P(X >= 4 | n = 120, p = 0.006) = 0.5 %
    assert out.healthy.all()


def test_each_wheel_stop_is_detected_at_once_and_isolated_within_two_seconds(batch):
    """The issue: for a stop of each wheel, the better isolator names the right wheel in
    >= 95 % of runs within 2 s. With 10 runs a wheel, 2 misses would reject a 95 % rate
    at the 8.6 % level, so at most 1 is allowed; the credit isolator's rates are computed
    alongside (it is not the better one: it confuses opposite wheels of the pyramid, 2 with
    4 and 1 with 3)."""
    design, out = batch
    dt = float(design.params.dt)
    stops = slice(CALIBRATION + FREE, None)
    onset = out.nis.onset[stops]
    wheel = np.repeat(np.arange(4), PER_WHEEL)
    detected = out.nis.detection_step[stops]
    assert np.all(detected >= 0) and np.all((detected - onset) * dt <= 0.5)
    rates = {}
    for name in ("likelihood", "credit"):
        rec = jax.tree_util.tree_map(lambda leaf: leaf[stops], getattr(out, name))
        in_time = (rec.detection_step >= 0) & (rec.isolated == wheel + 1) & ((rec.detection_step - onset) * dt <= 2.0)
        rates[name] = [float(in_time[wheel == w].mean()) for w in range(4)]
        assert np.all(rec.false_alarms == 0)  # no isolation before the onset
    assert stats.binom.cdf(8, PER_WHEEL, 0.95) < 0.09
    assert min(rates["likelihood"]) >= 0.9, rates


def test_run_wheels_rejects_unknown_options():
    design = rw.wheel_design()
    with pytest.raises(ValueError, match="engage_on"):
        rw.run_wheels(design, jax.random.key(0), no_fault(), steps=3, engage_on="never")
    with pytest.raises(ValueError, match="estimator"):
        rw.run_wheels(design, jax.random.key(0), no_fault(), steps=3, estimator="pf")


def test_ukf_estimator_agrees_with_the_ekf_on_the_closed_loop():
    """The UKF option, checked against the EKF on the same closed-loop run (a stop of
    wheel 2 at step 200): over 0.1 s the rate model is nearly linear, so the two filters'
    F and mode probabilities agree closely (measured 4e-10 relative in F, 2e-8 in mu),
    and both banks reach the same decisions."""
    design = rw.wheel_design()
    f = rw.wheel_fault("stop", 1, 200)
    runs = {kind: jax.jit(lambda kind=kind: rw.run_wheels(design, jax.random.key(3), f, steps=260, estimator=kind,
                                                          history=True))()
            for kind in ("ekf", "ukf")}
    (out_e, hist_e), (out_u, hist_u) = runs["ekf"], runs["ukf"]
    F_e = np.asarray(hist_e.detection_parameter)
    assert np.max(np.abs(np.asarray(hist_u.detection_parameter) - F_e)) < 1e-6 * np.max(F_e)
    assert np.max(np.abs(np.asarray(hist_u.mode_prob) - np.asarray(hist_e.mode_prob))) < 1e-5
    for name in ("nis", "credit", "likelihood"):
        e, u = getattr(out_e, name), getattr(out_u, name)
        assert int(e.detection_step) == int(u.detection_step) and int(e.isolated) == int(u.isolated)
    assert int(out_u.likelihood.isolated) == 2 and bool(out_u.healthy)


def test_a_run_that_goes_nan_is_counted_unhealthy_in_the_table():
    """A torque bias of NaN on wheel 2 from step 20 makes the truth, the gyros and every
    filter NaN: the run is reported unhealthy (first_unhealthy = 21, the first NaN
    reading), left out of the row's rates, and the table says so; the finite run beside
    it is scored as usual. (Both through the study's closed-loop program, the batch's.)"""
    design = rw.wheel_design()
    faults = jax.tree_util.tree_map(lambda *x: jnp.stack(x), rw.wheel_fault("bias", 1, 20, 0.0)._replace(magnitude=jnp.asarray(jnp.nan)),
                                    rw.wheel_fault("bias", 1, 20, 2e-3))
    spec = rw.wheel_spec(design, [("bias", 1)])._replace(cases=faults, case_names=("bias NaN w2", "bias w2"))
    out = run_study(spec, runs=1, seed=0).outputs["closed loop"]
    assert list(out.healthy) == [False, True]
    assert out.nis.first_unhealthy[0] == 21 and out.nis.first_unhealthy[1] == -1
    row = rw.summarize_case(out, "bias", 1, 0.1)
    assert row["unhealthy_runs"] == 1 and row["runs"] == 2
    only_good = rw.summarize_case(jax.tree_util.tree_map(lambda leaf: leaf[1:], out), "bias", 1, 0.1)
    for method in rw.METHODS:
        np.testing.assert_equal(row[method], only_good[method])  # NaN == NaN here
    table = rw.WheelStudy({}, [row], out).table()
    assert "WARNING: 1 of 2 runs went numerically bad" in table and "bias w2 1" in table


def test_momentum_patterns_give_the_closed_form_net_wheel_momentum():
    """Issue 27: the default biases every wheel the same way, so the body carries
    ``h_w = I_w H^T Omega = 4 I_w Omega cos(beta) e_z`` (45/45 pyramid, beta = 45 deg);
    the ``zero`` pattern (+, -, +, -) has ``H^T Omega = 0``."""
    Omega = 2000.0 * rw.RPM
    net, zero = rw.wheel_design(), rw.wheel_design(momentum="zero")
    np.testing.assert_allclose(wheel_momentum(net.initial_speeds, net.params),
                               [0.0, 0.0, 4 * 0.000239 * Omega * np.cos(np.radians(45.0))], atol=1e-15)
    np.testing.assert_allclose(wheel_momentum(zero.initial_speeds, zero.params), np.zeros(3), atol=1e-15)
    np.testing.assert_allclose(np.abs(np.asarray(net.initial_speeds)), np.full(4, Omega), rtol=1e-15)
    with pytest.raises(ValueError, match="momentum"):
        rw.wheel_design(momentum="some")



def test_binomial_lower_bound_equals_scipys_clopper_pearson():
    for successes, trials in [(9, 10), (10, 10), (37, 50), (1, 3)]:
        want = stats.binomtest(successes, trials, alternative="greater").proportion_ci(0.95).low
        assert binomial_lower_bound(successes, trials) == pytest.approx(want, rel=1e-9)
    assert binomial_lower_bound(0, 10) == 0.0 and np.isnan(binomial_lower_bound(0, 0))
