"""Issue 27 items 4 and 8: the paper's credit isolator per wheel, in the momentum-biased
default (all wheels +2000 rpm), and why it misses wheels.

One compiled closed-loop batch (the scenario's plant, ``wheel_fdi`` and controller in
``run_loop``): 4 noise-free stops at 20 s (plant noises off, the filters unchanged) and
``RUNS`` noisy stops per wheel with onsets uniform in 15-25 s.

* Statistics: per wheel, rates with one-sided 95 % Clopper-Pearson bounds computed here
  from ``scipy.stats.beta`` (the independent reference for the scenario's
  ``binomial_lower_bound``).
* Explanation: the credit bank re-implemented in NumPy (closed-form ``A``,
  finite-difference Jacobians, Joseph updates) on the noise-free runs' recorded gyro
  readings and commands; its ``F_x`` must equal the scenario's, and its rate
  discrepancies ``dw_x = w_PF - w_EKF`` and gradients ``g_x = grad det A_x`` give the
  reasons checked below.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from jaxfdi import binomial_lower_bound, detection_scorer, run_loop
from jaxfdi.control import wheel_attitude_controller, wheel_plant
from jaxfdi.models import WheelCommand, filter_input
from jaxfdi.scenarios import reaction_wheels as rw

RUNS, STEPS, ONSET = 20, 300, 200
LAGS = (3, 40)  # steps after the alarm: the decision (CONFIRM_STEPS) and 4 s
OPPOSITE = (2, 3, 0, 1)


def clopper_pearson_lower(k, n, confidence=0.95):
    return 0.0 if k == 0 else float(stats.beta.ppf(1 - confidence, k, n - k + 1))


@pytest.fixture(scope="module")
def batch():
    design = rw.wheel_design()
    params = design.params

    def run(f, key, noise):
        fdi = rw.wheel_fdi(design, gyro_health=False)  # noise-free gyros would look frozen to it
        plant = wheel_plant(
            params,
            f,
            noise * design.gyro_sigma,
            noise * design.disturbance_sigma,
            noise * design.wheel_noise_sigma,
        )
        controller = wheel_attitude_controller(
            params, design.gains, design.profile, design.initial_speeds
        )
        x0 = jnp.concatenate([jnp.array([1.0, 0, 0, 0]), jnp.zeros(3), design.initial_speeds])
        result = run_loop(
            plant,
            fdi,
            controller,
            x0,
            fdi.init(),
            key,
            STEPS,
            u0=WheelCommand(design.initial_speeds, jnp.zeros(4)),
            scorer=detection_scorer(f.onset, lambda out: out.decisions[2], single=True),
            keep_history=True,
        )
        h = result.history
        return dict(
            credit=result.score,
            y=h.sensed.measurement.rate,
            engaged=h.output.engaged,
            u=jax.vmap(lambda c: filter_input(c, params))(h.control),
            F=h.output.hypothesis_parameter,
            healthy=jnp.all(h.output.healthy),
        )

    quiet = [rw.wheel_fault("stop", w, ONSET) for w in range(4)]
    noisy = rw.case_faults([("stop", w) for w in range(4)], RUNS, jax.random.key(12))
    faults = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *quiet)
    faults = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), faults, noisy)
    keys = jax.random.split(jax.random.key(5), 4 + 4 * RUNS)
    noise = jnp.concatenate([jnp.zeros(4), jnp.ones(4 * RUNS)])
    out = jax.tree_util.tree_map(np.asarray, jax.jit(jax.vmap(run))(faults, keys, noise))
    return design, out


# --- the NumPy reference of the credit bank -------------------------------------------

I_B = np.diag([3.118, 3.050, 4.055])
I_W = 0.000239
_S = np.sqrt(0.5)
AXES = np.array(
    [
        [_S * _S, _S * _S, _S],
        [-_S * _S, _S * _S, _S],
        [-_S * _S, -_S * _S, _S],
        [_S * _S, -_S * _S, _S],
    ]
)
MASKS = 1.0 - np.eye(4)


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def transition(w, u, mask, dt=0.1):
    """RK4 over one step of ``I w' = -w x (I w + h) - h'``, wheel speeds ramping."""

    def field(x, t):
        h = I_W * (mask * (u[:4] + t * u[4:])) @ AXES
        return np.linalg.solve(I_B, -np.cross(x, I_B @ x + h) - I_W * (mask * u[4:]) @ AXES)

    k1 = field(w, 0)
    k2 = field(w + dt / 2 * k1, dt / 2)
    k3 = field(w + dt / 2 * k2, dt / 2)
    k4 = field(w + dt * k3, dt)
    return w + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def jacobian(fun, w, eps=1e-7):
    return np.stack([(fun(w + eps * e) - fun(w - eps * e)) / (2 * eps) for e in np.eye(3)], axis=-1)


def det_a(w, u, mask):
    """``det A``, ``A = -I^-1 ([w]x I - [I w + h]x)`` in closed form."""
    h = I_W * (mask * u[:4]) @ AXES
    return np.linalg.det(-np.linalg.solve(I_B, skew(w) @ I_B - skew(I_B @ w + h)))


def numpy_bank(y, u, engaged, u0, design, restart, until):
    """F (T, 4), w_PF and w_EKF (T, 4, 3) of the credit bank, up to step ``until``."""
    R = float(design.gyro_sigma) ** 2 * np.eye(3)
    widen = float(design.engage_sigma) ** 2 * np.eye(3)
    q_bank, q_nominal = float(design.bank_q), float(design.estimator_q)

    def update(m, P, yk):
        K = P @ np.linalg.inv(P + R)
        return m + K @ (yk - m), (np.eye(3) - K) @ P @ (np.eye(3) - K).T + K @ R @ K.T

    def predict(m, P, uk, mask, q):
        F = jacobian(lambda x: transition(x, uk, mask), m)
        return transition(m, uk, mask), F @ P @ F.T + q**2 * np.eye(3)

    def slaved(m, P, uk):
        return [
            (mp, Pp, mp) for mp, Pp in (predict(m, P + widen, uk, mask, q_bank) for mask in MASKS)
        ]

    first = int(
        np.argmax(engaged)
    )  # engaged: the bank ran on its own at this step (the alarm one step before)
    nm, nP = np.zeros(3), float(design.initial_sigma) ** 2 * np.eye(3)
    bank = slaved(nm, nP, u0)
    F, pred, filt = (np.full((until, 4) + s, np.nan) for s in ((), (3,), (3,)))
    for k in range(until):
        nmf, nPf = update(nm, nP, y[k])
        nm, nP = predict(nmf, nPf, u[k], np.ones(4), q_nominal)
        if (
            k < first - 1
        ):  # until the alarm the bank is re-slaved every step: only its last start matters
            bank = slaved(nmf, nPf, u[k]) if k == first - 2 else bank
            continue
        new = []
        for x, (m, P, p) in enumerate(bank):
            mf, Pf = update(m, P, y[k])
            F[k, x] = abs(det_a(p, u[k], MASKS[x]) - det_a(mf, u[k], MASKS[x]))
            pred[k, x], filt[k, x] = p, mf
            start = mf if restart and not engaged[k] else p
            new.append(
                (*predict(mf, Pf, u[k], MASKS[x], q_bank), transition(start, u[k], MASKS[x]))
            )
        bank = new if engaged[k + 1] else slaved(nmf, nPf, u[k])
    return F, pred, filt


@pytest.fixture(scope="module")
def explained(batch):
    """Per noise-free stop and start rule: alarm step, F, |dw| and cos(g, dw) at LAGS."""
    design, out = batch
    u0 = np.concatenate([np.asarray(design.initial_speeds), np.zeros(4)])
    result = {}
    for w in range(4):
        alarm = int(np.argmax(out["engaged"][w])) - 1
        for restart in (True, False):
            F, pred, filt = numpy_bank(
                out["y"][w],
                out["u"][w],
                out["engaged"][w],
                u0,
                design,
                restart,
                alarm + LAGS[-1] + 1,
            )
            rows = []
            for lag in LAGS:
                k = alarm + lag
                dw = pred[k] - filt[k]
                g = np.array(
                    [
                        jacobian(
                            lambda x: np.atleast_1d(det_a(x, out["u"][w][k], MASKS[i])), filt[k, i]
                        )[0]
                        for i in range(4)
                    ]
                )
                cos = np.sum(g * dw, 1) / np.linalg.norm(g, axis=1) / np.linalg.norm(dw, axis=1)
                rows.append(dict(F=F[k], dw=np.linalg.norm(dw, axis=1), cos=cos))
            result[w, restart] = dict(alarm=alarm, F=F, rows=rows)
    return result


def test_numpy_bank_reproduces_the_scenarios_credit_bank(batch, explained):
    """The scenario's F_x (default start) equals the NumPy bank's from the alarm on, to
    1e-6 relative (measured ~1e-8: finite-difference vs AD Jacobians)."""
    _, out = batch
    assert out["healthy"].all()
    for w in range(4):
        e = explained[w, True]
        k = slice(e["alarm"], e["alarm"] + LAGS[-1] + 1)
        np.testing.assert_allclose(e["F"][k], out["F"][w][k], rtol=1e-6)


def test_former_start_ranks_the_hypotheses_by_geometry_not_by_the_fault(explained):
    """The fixed bug: a prediction started from the nominal filter's predicted mean (which
    lags the stop's ~0.017 rad/s rate jump) gives every hypothesis nearly the same
    discrepancy |dw_x| (the lag, within 10 %), so F_x = |g_x . dw_x| ranks the hypotheses
    by geometry: hypothesis 3 has the smallest F 0.3 s after the alarm of a stop of wheel
    1 or 2, whichever wheel stopped. With each prediction started from its own EKF's
    posterior, the stopped wheel's |dw| is the smallest for every wheel, by 2x at 0.3 s
    and 10x at 4 s, and its F the smallest (noise-free)."""
    for w in range(4):
        former = explained[w, False]["rows"][0]
        assert np.ptp(former["dw"]) < 0.1 * np.min(former["dw"]), former["dw"]
        for lag, factor in zip(range(2), (1.8, 10.0)):
            now = explained[w, True]["rows"][lag]
            others = np.delete(now["dw"], w)
            assert np.min(others) > factor * now["dw"][w], (w, lag, now["dw"])
            assert np.argmin(now["F"]) == w, (w, lag, now["F"])
    assert [int(np.argmin(explained[w, False]["rows"][0]["F"])) for w in (0, 1)] == [2, 2]


def test_opposite_wheels_look_alike_to_det_a(explained):
    """What the fix cannot remove (the paper's scalar statistic): for a stop of wheel 1 the
    wrong hypothesis 3 (the opposite wheel of the pyramid) drifts more than twice as far
    as the right one 0.3 s after the alarm, but nearly orthogonally to grad det A_3
    (|cos| < 0.3), so its F is within 20 % of the right one's: measurement noise decides
    between wheels 1 and 3."""
    row = explained[0, True]["rows"][0]
    assert row["dw"][2] > 2.0 * row["dw"][0]
    assert abs(row["cos"][2]) < 0.3
    assert row["F"][2] < 1.2 * row["F"][0]


def test_credit_isolator_rates_per_wheel(batch):
    """Monte Carlo, RUNS stops per wheel (one-sided 95 % Clopper-Pearson bounds from
    scipy.stats.beta). The isolator decides CONFIRM_STEPS after the banks engage, when the
    F_x still differ by little more than the noise: a run of 100 stops per wheel
    (2026-11) measured it naming wheels 1-4 in 27, 54, 56 and 73 % of stops, while the
    largest credit 4 s after the engagement is the right one in 66, 98, 97 and 99 %.
    Claims: for wheels 2-4 the isolator's rate is above 10 % (passes from 5 of 20: P(X < 5)
    < 0.3 % at the measured rates) and the 4 s ranking's above 70 % (from 18 of 20: at a
    true 97 %, P(X < 18) = 2 %). Wheel 1 is not claimed: see the two tests above."""
    design, out = batch
    noisy = slice(4, None)
    rec = jax.tree_util.tree_map(lambda leaf: leaf[noisy], out["credit"])
    wheel = np.repeat(np.arange(4), RUNS)
    right = (rec.detection_step >= 0) & (rec.isolated == wheel + 1)
    assert np.all(rec.false_alarms == 0) and out["healthy"].all()
    alarm = np.argmax(out["engaged"][noisy], axis=1) - 1
    at = alarm + LAGS[-1]
    assert np.all(at < STEPS), at
    top_late = np.argmin(out["F"][noisy][np.arange(4 * RUNS), at], axis=1) == wheel
    bounds = {
        name: [clopper_pearson_lower(int(hit[wheel == w].sum()), RUNS) for w in range(4)]
        for name, hit in (("isolated", right), ("top_at_4s", top_late))
    }
    for w in (1, 2, 3):
        assert bounds["isolated"][w] > 0.10, bounds
        assert bounds["top_at_4s"][w] > 0.70, bounds
    k = int(right[wheel == 1].sum())
    assert binomial_lower_bound(k, RUNS) == pytest.approx(clopper_pearson_lower(k, RUNS), rel=1e-12)
    assert stats.binom.sf(4, RUNS, 0.54) > 0.997 and stats.binom.cdf(17, RUNS, 0.97) < 0.03
