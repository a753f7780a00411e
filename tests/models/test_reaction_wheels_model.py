"""Reaction-wheel spacecraft (seed 004) against independent references.

* the AD system matrix ``A = d body_rate_field / dw`` against the closed form
  ``-I^-1 ([w]x I - [I w + h_w]x)`` written here in NumPy (any geometry, full inertia,
  stop-hypothesis masks);
* the truth ``spacecraft_step``: inertial angular momentum conserved without external
  torque (across a wheel stop, and with wheel torques, which are internal); the rest
  state with wheel torques has the closed form ``w(t) = -t I^-1 H^T tau``;
* the EKF / UKF on the rate model against filterpy's ExtendedKalmanFilter /
  UnscentedKalmanFilter on the same data;
* the dual filter's ``F`` against filterpy's EKF + a NumPy prediction loop + NumPy
  determinants of the closed-form Jacobian; ``det A = 0`` at zero total momentum;
* ``allocate_wheel_torques`` against ``numpy.linalg.pinv``; ``slew_reference`` against
  finite differences; the credit isolator against a brute-force loop; bad input.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

import jaxfdi
from jaxfdi import no_fault
from jaxfdi.control import slew, slew_reference
from jaxfdi.control._attitude import allocate_wheel_torques
from jaxfdi.detection import dual_filter, hypothesis_credits
from jaxfdi.detection._credits import credit_isolator
from jaxfdi.detection._dual_filter import system_matrix_det
from jaxfdi.models import (
    body_rate_field,
    delivered_torque,
    kitsat3_params,
    spacecraft_step,
    stop_hypotheses,
    stop_transfer,
    wheel_rate_transition,
)
from jaxfdi.models._reaction_wheels import pyramid_axes, rate_jacobian, total_momentum
from jaxfdi.scenarios.reaction_wheels import estimation_filter, wheel_fault

jax.config.update("jax_enable_x64", True)

RPM = 2.0 * math.pi / 60.0
Q_SIGMA, GYRO_SIGMA = 1e-4, 3e-4  # the scenario's estimator process noise and gyro noise


def rel_err(actual, expected):
    expected = np.asarray(expected)
    return float(np.max(np.abs(np.asarray(actual) - expected)) / np.max(np.abs(expected)))


# --- independent NumPy closed forms --------------------------------------------------


def np_skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def np_wheel_momentum(speeds, inertia_w, axes, mask):
    """``h_w = I_w sum_i mask_i Omega_i a_i`` with the axes normalised here."""
    axes = np.asarray(axes, float)
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    return inertia_w * (np.asarray(mask) * np.asarray(speeds)) @ axes


def np_rate_jacobian(w, speeds, inertia, inertia_w, axes, mask):
    """``A = -I^-1 ([w]x I - [I w + h_w]x)`` (d/dw of ``-I^-1 w x (I w + h_w)``)."""
    inertia = np.asarray(inertia, float)
    momentum = inertia @ w + np_wheel_momentum(speeds, inertia_w, axes, mask)
    return -np.linalg.solve(inertia, np_skew(w) @ inertia - np_skew(momentum))


def random_inertia(rng):
    """A full (non-diagonal) symmetric positive definite inertia, ~ KITSAT-3's size."""
    B = rng.normal(size=(3, 3))
    return np.diag([3.1, 3.0, 4.0]) + 0.3 * (B + B.T) / 2


# --- shared fixtures -----------------------------------------------------------------


@pytest.fixture(scope="module")
def params():
    return kitsat3_params(dt=0.1)


@pytest.fixture(scope="module")
def jac_field():
    """``jax.jacfwd(body_rate_field)`` jitted once (params is a pytree argument)."""
    return jax.jit(jax.jacfwd(body_rate_field))


@pytest.fixture(scope="module")
def transition(params):
    f = jax.jit(lambda x, u: wheel_rate_transition(x, u, params))
    F = jax.jit(jax.jacfwd(lambda x, u: wheel_rate_transition(x, u, params)))
    return (lambda x, u: np.asarray(f(x, u))), (lambda x, u: np.asarray(F(x, u)))


@pytest.fixture(scope="module")
def gyro_data(params):
    """80 steps of gyro data; time-varying commands u = [Omega (4), Omega' (4)] with
    Omega[k+1] = Omega[k] + dt Omega'[k]; the plant follows the nominal model with
    process noise, and wheel 0 stops (the stop hypothesis' model) from step 40 so
    that the dual filter's F has something to see."""
    rng = np.random.default_rng(4)
    T, dt = 80, float(params.dt)
    stopped = stop_hypotheses(params)
    stopped0 = jax.tree_util.tree_map(lambda leaf: leaf[0], stopped)
    f_nominal = jax.jit(lambda x, u: wheel_rate_transition(x, u, params))
    f_stopped = jax.jit(lambda x, u: wheel_rate_transition(x, u, stopped0))
    k = np.arange(T)
    acc = np.stack([30.0 * np.sin(0.15 * k + p) for p in (0.0, 1.0, 2.0, 3.0)], 1)  # rad/s^2
    speeds = np.empty((T, 4))
    speeds[0] = np.array([2000.0, 1500.0, -1000.0, 500.0]) * RPM
    for i in range(T - 1):
        speeds[i + 1] = speeds[i] + dt * acc[i]
    us = np.concatenate([speeds, acc], 1)
    w = np.array([0.02, -0.015, 0.01])
    ws, ys = [], []
    for i in range(T):
        ws.append(w)
        ys.append(w + GYRO_SIGMA * rng.normal(size=3))
        f = f_stopped if i >= 40 else f_nominal
        w = np.asarray(f(w, us[i])) + 2e-6 * rng.normal(size=3)
    m0 = np.array([0.02, -0.015, 0.01])  # the true start: x_PF follows the plant until the stop
    P0 = (1e-3) ** 2 * np.eye(3)
    return np.array(ys), us, m0, P0


def filterpy_ekf(transition, ys, us, m0, P0):
    """filterpy's EKF with the jaxfdi transition as its state prediction and the
    transition's Jacobian (jacfwd of the numpy-wrapped transition) as F; H = I."""
    f, F = transition

    class RateEKF(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = f(self.x, u)

    ekf = RateEKF(3, 3)
    ekf.x, ekf.P = m0.copy(), P0.copy()
    ekf.Q, ekf.R = Q_SIGMA**2 * np.eye(3), GYRO_SIGMA**2 * np.eye(3)
    out = {
        "filtered_mean": [],
        "filtered_cov": [],
        "predicted_mean": [],
        "predicted_cov": [],
        "log_likelihood": [],
    }
    for k in range(len(ys)):
        out["predicted_mean"].append(ekf.x.copy())
        out["predicted_cov"].append(ekf.P.copy())
        ekf.update(ys[k], HJacobian=lambda x: np.eye(3), Hx=lambda x: x)
        out["filtered_mean"].append(ekf.x.copy())
        out["filtered_cov"].append(ekf.P.copy())
        out["log_likelihood"].append(ekf.log_likelihood)
        ekf.F = F(ekf.x, us[k])
        ekf.predict(u=us[k])
    return {name: np.array(v) for name, v in out.items()}


def filterpy_ukf(transition, ys, us, m0, P0, dt):
    f, _ = transition
    points = MerweScaledSigmaPoints(3, alpha=0.5, beta=2.0, kappa=0.0)
    ukf = UnscentedKalmanFilter(3, 3, dt, hx=lambda x: x, fx=None, points=points)
    ukf.x, ukf.P = m0.copy(), P0.copy()
    ukf.Q, ukf.R = Q_SIGMA**2 * np.eye(3), GYRO_SIGMA**2 * np.eye(3)
    out = {"filtered_mean": [], "filtered_cov": [], "predicted_mean": [], "log_likelihood": []}
    for k in range(len(ys)):
        out["predicted_mean"].append(ukf.x.copy())
        ukf.sigmas_f = points.sigma_points(
            ukf.x, ukf.P
        )  # jaxfdi redraws the points before the update
        ukf.update(ys[k])
        out["filtered_mean"].append(ukf.x.copy())
        out["filtered_cov"].append(ukf.P.copy())
        out["log_likelihood"].append(ukf.log_likelihood)
        ukf.predict(fx=lambda x, dt, u: f(x, u), u=us[k])
    return {name: np.array(v) for name, v in out.items()}


@pytest.fixture(scope="module")
def ekf_reference(transition, gyro_data):
    ys, us, m0, P0 = gyro_data
    return filterpy_ekf(transition, ys, us, m0, P0)


# --- 1. the system matrix ------------------------------------------------------------

GEOMETRIES = {
    "pyramid_45_45": None,
    "orthogonal_3": np.eye(3),
    "random_5": np.random.default_rng(55).normal(size=(5, 3)),  # unnormalised rows
}


@pytest.mark.parametrize("geometry", list(GEOMETRIES))
@pytest.mark.parametrize("full_inertia", [False, True])
def test_autodiff_jacobian_equals_closed_form(jac_field, geometry, full_inertia):
    """``jacfwd(body_rate_field)`` = NumPy ``-I^-1([w]x I - [I w + h_w]x)`` to 1e-12
    (relative to max|A|), nominal and under every stop hypothesis (mask row i: wheel i
    contributes no momentum); ``rate_jacobian`` too. Measured max 1.1e-15."""
    rng = np.random.default_rng(2 * list(GEOMETRIES).index(geometry) + int(full_inertia))
    inertia = random_inertia(rng) if full_inertia else np.array([3.118, 3.050, 4.055])
    p = kitsat3_params(wheel_axes=GEOMETRIES[geometry], inertia=inertia)
    axes = pyramid_axes() if GEOMETRIES[geometry] is None else GEOMETRIES[geometry]
    I_full = inertia if full_inertia else np.diag(inertia)
    N = p.wheel_axes.shape[0]
    masks = np.asarray(stop_hypotheses(p).wheel_mask)
    np.testing.assert_array_equal(masks, 1.0 - np.eye(N))  # hypothesis i: wheel i off
    worst = 0.0
    for trial in range(4):
        w = rng.normal(scale=0.05, size=3)
        speeds = rng.uniform(-3000, 3000, size=N) * RPM
        u = np.concatenate([speeds, rng.normal(scale=20.0, size=N)])  # accelerations do not enter A
        for mask in [np.ones(N)] + list(masks):
            pm = p._replace(wheel_mask=jnp.asarray(mask))
            A = np.asarray(jac_field(jnp.asarray(w), jnp.asarray(u), pm))
            A_ref = np_rate_jacobian(w, speeds, I_full, float(p.wheel_inertia), axes, mask)
            err = rel_err(A, A_ref)
            worst = max(
                worst, err, rel_err(rate_jacobian(jnp.asarray(w), jnp.asarray(speeds), pm), A_ref)
            )
        # the stop hypotheses actually change A (the mask is not ignored)
        A_stop = np_rate_jacobian(w, speeds, I_full, float(p.wheel_inertia), axes, masks[0])
        A_nom = np_rate_jacobian(w, speeds, I_full, float(p.wheel_inertia), axes, np.ones(N))
        assert rel_err(A_stop, A_nom) > 1e-4
    print(f"jacobian {geometry} full={full_inertia}: max rel err {worst:.1e}")
    assert worst < 1e-12


# --- 2. the truth: angular momentum -------------------------------------------------


@pytest.fixture(scope="module")
def momentum_run(params):
    """600 steps of ``stop_transfer`` + ``spacecraft_step`` with the delivered torques of
    fault ``f`` and no external torque; returns the states (601, 7 + N) and the
    inertial momenta."""

    @jax.jit
    def run(x0, tau, f):
        def body(x, k):
            x = stop_transfer(x, f, k, params)
            nxt = spacecraft_step(x, delivered_torque(f, k, tau), jnp.zeros(3), params)
            return nxt, nxt

        _, xs = jax.lax.scan(body, x0, jnp.arange(600))
        xs = jnp.concatenate([x0[None], xs])
        return xs, jax.vmap(lambda x: total_momentum(x, params))(xs)

    return run


def initial_truth():
    q0 = np.array([0.9, 0.1, -0.3, 0.2])
    return np.concatenate(
        [q0 / np.linalg.norm(q0), [0.03, -0.02, 0.015], np.array([2000, -2000, 2000, -1500]) * RPM]
    )


def test_momentum_conserved_across_a_wheel_stop(params, momentum_run):
    """No wheel torque, no external torque, 60 s at 0.1 s, wheel 0 stops at 20 s:
    inertial momentum drifts < 1e-9 (relative) over the whole run. Measured 1.4e-14."""
    x0 = initial_truth()
    xs, L = momentum_run(jnp.asarray(x0), jnp.zeros(4), wheel_fault("stop", 0, 200))
    xs, L = np.asarray(xs), np.asarray(L)
    drift = np.max(np.linalg.norm(L - L[0], axis=1)) / np.linalg.norm(L[0])
    print(f"momentum drift across stop: {drift:.1e}")
    assert drift < 1e-9
    # the stop happened: wheel 0 at rest from step 200 on (the momentum went to the body)
    assert np.all(xs[:201, 7] != 0.0) and np.all(xs[201:, 7] == 0.0)
    np.testing.assert_array_equal(xs[201:, 8:], np.broadcast_to(xs[0, 8:], xs[201:, 8:].shape))
    # the body's rates jumped at the stop by ~ I^-1 I_w Omega_0 a_0 (0.05 N m s / ~3 kg m^2)
    assert np.linalg.norm(xs[201, 4:7] - xs[200, 4:7]) > 5e-3
    assert np.all(np.abs(np.linalg.norm(xs[:, :4], axis=1) - 1.0) < 1e-14)


def test_stop_transfer_keeps_body_momentum(params):
    """At the onset the wheel's speed goes to 0 and ``I w + h_w`` is unchanged (1e-14
    relative; measured <= 1.7e-16); any other step it is the identity (rates up to
    round-off)."""
    rng = np.random.default_rng(7)
    inertia = np.diag([3.118, 3.050, 4.055])
    for wheel in range(4):
        x = initial_truth()
        x[4:7] = rng.normal(scale=0.03, size=3)
        x[7:] = rng.uniform(-3000, 3000, size=4) * RPM
        f = wheel_fault("stop", wheel, 200)
        new = np.asarray(stop_transfer(jnp.asarray(x), f, jnp.asarray(200), params))
        body = lambda s: (
            inertia @ s[4:7] + np_wheel_momentum(s[7:], 0.000239, pyramid_axes(), np.ones(4))
        )
        err = np.linalg.norm(body(new) - body(x)) / np.linalg.norm(body(x))
        print(f"stop_transfer wheel {wheel}: body momentum rel change {err:.1e}")
        assert err < 1e-14
        assert new[7 + wheel] == 0.0
        np.testing.assert_array_equal(np.delete(new[7:], wheel), np.delete(x[7:], wheel))
        np.testing.assert_array_equal(new[:4], x[:4])
        assert np.linalg.norm(new[4:7] - x[4:7]) > 1e-3
        for k in (199, 201):  # not the onset: the state is left exactly as it is
            same = np.asarray(stop_transfer(jnp.asarray(x), f, jnp.asarray(k), params))
            np.testing.assert_array_equal(same, x)


def test_wheel_torque_is_internal(params, momentum_run):
    """Constant wheel torques, no external torque, 60 s: inertial momentum drifts
    < 1e-9 (measured 7.3e-14); the wheels spin up by t tau / I_w (1e-12; measured 3.9e-14)."""
    tau = np.array([1e-3, -2e-3, 5e-4, 1.5e-3])
    x0 = initial_truth()
    xs, L = momentum_run(jnp.asarray(x0), jnp.asarray(tau), no_fault())
    xs, L = np.asarray(xs), np.asarray(L)
    drift = np.max(np.linalg.norm(L - L[0], axis=1)) / np.linalg.norm(L[0])
    t = 0.1 * np.arange(601)[:, None]
    speed_err = rel_err(xs[:, 7:], x0[7:] + t * tau / 0.000239)
    print(f"momentum drift with wheel torque: {drift:.1e}, wheel speed rel err {speed_err:.1e}")
    assert drift < 1e-9
    assert speed_err < 1e-12
    assert np.linalg.norm(xs[-1, 4:7] - xs[0, 4:7]) > 1e-2  # the torques did move the body


def test_wheel_torque_from_rest_has_closed_form(params):
    """From rest (w = 0, Omega = 0) the body momentum ``I w + h_w`` stays 0, so
    ``w x (I w + h_w) = 0`` and ``w(t) = -t I^-1 I_w H^T (tau / I_w) = -t I^-1 H^T tau``
    exactly (RK4 is exact for a linear solution); 1e-12. Measured 1.4e-15."""
    tau = np.array([2e-3, -1e-3, 5e-4, 1e-3])
    x = jnp.asarray(np.concatenate([[1.0, 0, 0, 0], np.zeros(3), np.zeros(4)]))
    step = jax.jit(lambda x: spacecraft_step(x, jnp.asarray(tau), jnp.zeros(3), params))
    for _ in range(20):
        x = step(x)
    H = np.asarray(pyramid_axes())
    inertia = np.diag([3.118, 3.050, 4.055])
    w_ref = -2.0 * np.linalg.solve(inertia, H.T @ tau)
    err = rel_err(np.asarray(x[4:7]), w_ref)
    print(f"rest-to-spin closed form rel err {err:.1e}")
    assert err < 1e-12


# --- 3. EKF / UKF against filterpy -------------------------------------------------------


def test_ekf_equals_filterpy(params, gyro_data, ekf_reference):
    """``estimation_filter(kind='ekf')`` = filterpy's EKF (its predict overridden by the
    same transition, F = jacfwd of the numpy-wrapped transition, H = I) to 1e-8 of
    max|reference|, every field. Measured <= 3.4e-16."""
    ys, us, m0, P0 = gyro_data
    ekf = estimation_filter(params, jnp.asarray(Q_SIGMA), jnp.asarray(GYRO_SIGMA), "ekf")
    _, info = jaxfdi.filters.run_filter(ekf, ekf.init(jnp.asarray(m0), jnp.asarray(P0)), ys, us)
    for name, value in ekf_reference.items():
        err = rel_err(getattr(info, name), value)
        print(f"ekf {name}: {err:.1e}")
        assert err < 1e-8, name


def test_ukf_equals_filterpy(params, transition, gyro_data):
    """``estimation_filter(kind='ukf')`` (alpha 0.5, beta 2, kappa 0) = filterpy's
    UnscentedKalmanFilter + MerweScaledSigmaPoints to 1e-8 of max|reference|, means,
    covariances and log-likelihoods per step. Measured <= 1.6e-14."""
    ys, us, m0, P0 = gyro_data
    ukf = estimation_filter(params, jnp.asarray(Q_SIGMA), jnp.asarray(GYRO_SIGMA), "ukf")
    _, info = jaxfdi.filters.run_filter(ukf, ukf.init(jnp.asarray(m0), jnp.asarray(P0)), ys, us)
    ref = filterpy_ukf(transition, ys, us, m0, P0, float(params.dt))
    for name, value in ref.items():
        err = rel_err(getattr(info, name), value)
        print(f"ukf {name}: {err:.1e}")
        assert err < 1e-8, name


# --- 4. the dual filter's F -------------------------------------------------------------


def test_dual_filter_parameter_equals_numpy(params, transition, gyro_data, ekf_reference):
    """``F[k] = |det A(x_PF[k]) - det A(x_EKF[k|k])|`` against filterpy's EKF for
    ``x_EKF[k|k]``, a NumPy loop ``x_PF[k+1] = f(x_PF[k], u[k])`` from the same start
    and ``numpy.linalg.det`` of the NumPy closed-form A: 1e-8 of each series' max.
    Measured: dets 1.9e-15, F 5.0e-14 (F is a difference of close determinants)."""
    ys, us, m0, P0 = gyro_data
    f, _ = transition
    estimator = estimation_filter(params, jnp.asarray(Q_SIGMA), jnp.asarray(GYRO_SIGMA), "ekf")
    dual = dual_filter(estimator, wheel_rate_transition, body_rate_field, params)
    _, info = jaxfdi.filters.run_filter(dual, dual.init(jnp.asarray(m0), jnp.asarray(P0)), ys, us)

    inertia, axes = np.diag([3.118, 3.050, 4.055]), pyramid_axes()
    det = lambda x, u: np.linalg.det(
        np_rate_jacobian(x, u[:4], inertia, 0.000239, axes, np.ones(4))
    )
    x_pf, pf, det_pf, det_est = m0.copy(), [], [], []
    for k in range(len(ys)):
        pf.append(x_pf)
        det_pf.append(det(x_pf, us[k]))
        det_est.append(det(ekf_reference["filtered_mean"][k], us[k]))
        x_pf = f(x_pf, us[k])
    det_pf, det_est = np.array(det_pf), np.array(det_est)
    ref = {
        "prediction": np.array(pf),
        "det_prediction": det_pf,
        "det_estimation": det_est,
        "detection_parameter": np.abs(det_pf - det_est),
    }
    for name, value in ref.items():
        err = rel_err(getattr(info, name), value)
        print(f"dual filter {name}: {err:.1e}")
        assert err < 1e-8, name
    assert rel_err(info.estimator.filtered_mean, ekf_reference["filtered_mean"]) < 1e-8
    assert bool(np.all(np.asarray(info.healthy)))
    # the stop of wheel 0 at step 40 shows in F
    F = ref["detection_parameter"]
    print(f"F before the stop <= {np.max(F[:40]):.2e}, after up to {np.max(F[40:]):.2e}")
    assert np.max(F[40:]) > 3 * np.max(F[:40])


# --- 5. det A at zero total momentum --------------------------------------------------


def test_det_vanishes_at_zero_total_momentum(params, jac_field):
    """``I w + h_w = 0`` gives ``A = -I^-1 [w]x I``, singular: ``|det A| < 1e-14 *
    max|A|^3`` (measured 5.0e-17), while the same rates with a nonzero
    momentum give ``|det A|`` far above it."""
    rng = np.random.default_rng(11)
    H = np.asarray(params.wheel_axes)
    Iw, inertia = float(params.wheel_inertia), np.asarray(params.inertia)
    det = jax.jit(
        lambda w, u: system_matrix_det(body_rate_field, w, u, params)
    )  # what the dual filter uses
    worst = 0.0
    for _ in range(10):
        w = rng.normal(scale=0.05, size=3)
        speeds = np.linalg.lstsq(Iw * H.T, -inertia @ w, rcond=None)[0]  # h_w = -I w
        speeds += (
            np.array([1.0, -1.0, 1.0, -1.0]) * rng.uniform(-2000, 2000) * RPM
        )  # plus null-space speeds
        u = jnp.asarray(np.concatenate([speeds, np.zeros(4)]))
        A = np.asarray(jac_field(jnp.asarray(w), u, params))
        scale = np.max(np.abs(A)) ** 3
        d = float(det(jnp.asarray(w), u))
        worst = max(worst, abs(d) / scale)
        assert abs(d) < 1e-14 * scale
        spun = u.at[:4].add(jnp.asarray(np.array([1000.0, 500.0, 0.0, 0.0]) * RPM))
        d_spun = float(det(jnp.asarray(w), spun))
        A_spun = np.asarray(jac_field(jnp.asarray(w), spun, params))
        assert abs(d_spun) > 1e-6 * np.max(np.abs(A_spun)) ** 3
    print(f"|det A| / max|A|^3 at zero momentum: {worst:.1e}")


# --- 6. torque allocation ---------------------------------------------------------------


@pytest.mark.parametrize("axes", [None, np.random.default_rng(3).normal(size=(5, 3))])
def test_allocation_minimum_norm_and_saturation(axes):
    """Unsaturated: ``-H^T tau = T`` and ``tau = -pinv(H^T) T`` (numpy.linalg.pinv, the
    minimum-norm solution) to 1e-12, measured 3.3e-16; saturated: ``tau`` scaled as a
    whole (direction of ``-H^T tau`` kept, cosine 1 to 1e-12) with ``max|tau|`` = limit."""
    H = np.asarray(kitsat3_params(wheel_axes=axes).wheel_axes)  # normalised rows
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(5):
        T = rng.normal(scale=1e-3, size=3)
        tau = np.asarray(allocate_wheel_torques(jnp.asarray(T), jnp.asarray(H), jnp.asarray(1.0)))
        tau_ref = -np.linalg.pinv(H.T) @ T
        worst = max(worst, rel_err(-H.T @ tau, T), rel_err(tau, tau_ref))
        assert rel_err(-H.T @ tau, T) < 1e-12
        assert rel_err(tau, tau_ref) < 1e-12
        # saturated: same direction, scaled so the largest wheel torque is the limit
        limit = 0.3 * np.max(np.abs(tau_ref))
        sat = np.asarray(allocate_wheel_torques(jnp.asarray(T), jnp.asarray(H), jnp.asarray(limit)))
        assert abs(np.max(np.abs(sat)) - limit) < 1e-12 * limit
        assert rel_err(sat, tau_ref * limit / np.max(np.abs(tau_ref))) < 1e-12
        delivered = -H.T @ sat
        cosine = delivered @ T / (np.linalg.norm(delivered) * np.linalg.norm(T))
        assert abs(cosine - 1.0) < 1e-12
    print(f"allocation max rel err {worst:.1e}")


# --- 7. slew reference ---------------------------------------------------------------------


def test_slew_reference_derivatives():
    """``w_ref = theta' e`` and ``alpha_ref = theta'' e`` against central differences
    (h = 1e-3 s: truncation ~2e-9 relative) to 1e-7 of the peak; unit ``q_ref``; zero
    rate and acceleration at the ends and outside; ``theta(end) = angle``."""
    profile = slew(axis=(1.0, 2.0, -0.5), angle_deg=20.0, start=5.0, duration=40.0)
    ref = jax.jit(lambda t: slew_reference(t, profile))
    axis = np.asarray(profile.axis)

    def parts(t):
        q, w, a = (np.asarray(v) for v in ref(jnp.asarray(t)))
        theta = 2.0 * np.arctan2(np.linalg.norm(q[1:]), q[0])
        return q, theta, w, a

    h = 1e-3
    times = np.linspace(5.01, 44.99, 41)
    rate_err = acc_err = 0.0
    peak_rate = 2.0 * float(profile.angle) / 40.0
    peak_acc = 2.0 * math.pi * float(profile.angle) / 40.0**2
    for t in times:
        q, theta, w, a = parts(t)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-15
        np.testing.assert_allclose(q[1:] / np.linalg.norm(q[1:]), axis, atol=1e-14)
        assert (
            np.linalg.norm(np.cross(w, axis)) < 1e-15 and np.linalg.norm(np.cross(a, axis)) < 1e-15
        )
        fd_rate = (parts(t + h)[1] - parts(t - h)[1]) / (2 * h)
        fd_acc = (parts(t + h)[2] @ axis - parts(t - h)[2] @ axis) / (2 * h)
        rate_err = max(rate_err, abs(w @ axis - fd_rate) / peak_rate)
        acc_err = max(acc_err, abs(a @ axis - fd_acc) / peak_acc)
    print(f"slew: rate vs FD {rate_err:.1e}, acceleration vs FD {acc_err:.1e}")
    assert rate_err < 1e-7 and acc_err < 1e-7
    for t in (0.0, 5.0, 45.0, 60.0):
        q, theta, w, a = parts(t)
        assert np.max(np.abs(w)) < 1e-15 * peak_rate and np.max(np.abs(a)) < 1e-14 * peak_acc, t
        assert abs(np.linalg.norm(q) - 1.0) < 1e-15
    assert abs(parts(45.0)[1] - math.radians(20.0)) < 1e-14 and parts(0.0)[1] == 0.0
    np.testing.assert_allclose(parts(60.0)[0], parts(45.0)[0], atol=1e-15)


# --- 8. credits ---------------------------------------------------------------------------


def brute_force_isolator(Fs, threshold, relative, label_offset, confirm_steps):
    candidate, held = -1, 0
    out = []
    for F in Fs:
        M = len(F)
        mean = sum(F) / M
        credit = [max(mean - F[x], 0.0) for x in range(M)]
        if relative:
            credit = [c / mean if mean > 0 else 0.0 for c in credit]
        best = max(range(M), key=lambda x: (credit[x], -x))  # first maximum
        stat = credit[best]
        if stat >= threshold:
            held = held + 1 if best == candidate else 1
            candidate = best
        else:
            candidate, held = -1, 0
        out.append((stat, held >= confirm_steps, best + label_offset, mean))
    return out


def random_F_sequence(rng, T=60, M=4):
    """Random F with stretches where one hypothesis is much smaller (so credits lead),
    ties and an all-zero row (F_mean = 0)."""
    F = rng.uniform(0.0, 1.0, size=(T, M))
    leader = rng.integers(0, M, size=T // 5).repeat(5)
    low = rng.uniform(size=T) < 0.6
    F[np.arange(T)[low], leader[low]] *= 0.01
    F[7] = 0.0
    F[8] = 0.5
    return F


@pytest.mark.parametrize("relative,threshold", [(True, 0.5), (True, 0.7), (False, 0.3)])
@pytest.mark.parametrize("confirm_steps", [1, 3])
def test_credit_isolator_equals_brute_force(relative, threshold, confirm_steps):
    """Statistic (1e-12), alarm, label (index + offset) and F_mean per step equal a
    plain-Python loop of ``C_x = max(mean - F_x, 0)`` (relative: ``/ mean``, 0 when the
    mean is 0), first argmax, and the consecutive-steps confirmation."""
    rng = np.random.default_rng(confirm_steps * 10 + int(threshold * 10))
    Fs = random_F_sequence(rng)
    iso = credit_isolator(threshold, relative=relative, label_offset=1, confirm_steps=confirm_steps)
    step = jax.jit(iso.step)
    state = iso.init()
    ref = brute_force_isolator(Fs.tolist(), threshold, relative, 1, confirm_steps)
    alarms = 0
    for F, (stat, alarm, label, mean) in zip(Fs, ref):
        state, d = step(state, jnp.asarray(F))
        assert abs(float(d.statistic) - stat) <= 1e-12 * max(1.0, abs(stat))
        assert bool(d.alarm) == alarm and int(d.label) == label
        assert abs(float(d.estimate) - mean) <= 1e-15
        alarms += alarm
    assert 0 < alarms < len(Fs)  # the sequence exercises both outcomes


def test_hypothesis_credits_equals_brute_force():
    F = random_F_sequence(np.random.default_rng(1), T=20, M=5)
    C = np.asarray(hypothesis_credits(jnp.asarray(F)))
    ref = np.array([[max(sum(row) / len(row) - x, 0.0) for x in row] for row in F.tolist()])
    assert np.max(np.abs(C - ref)) < 1e-15
    assert np.all(C[7] == 0.0) and np.all(C[8] == 0.0)


def test_credit_isolator_bad_input():
    for bad in (0.0, -1.0, np.array([0.5, 0.5])):
        with pytest.raises(ValueError, match="threshold"):
            credit_isolator(bad)
    for bad in (0, 1.5, -2):
        with pytest.raises((ValueError, TypeError), match="confirm_steps"):
            credit_isolator(0.5, confirm_steps=bad)
    iso = credit_isolator(0.5)
    with pytest.raises(ValueError, match="detection_parameters"):
        iso.step(iso.init(), jnp.ones((2, 4)))


# --- 9. bad input ------------------------------------------------------------------------


def test_bad_input_names_the_argument(params):
    for bad in (np.ones((4, 2)), np.ones(3), np.ones((2, 4, 3))):
        with pytest.raises(ValueError, match=r"^wheel_axes: expected shape \(\*, 3\)"):
            kitsat3_params(wheel_axes=bad)
    with pytest.raises(ValueError, match=r"^inertia: expected .*\(3, 3\)"):
        kitsat3_params(inertia=np.ones((2, 2)))
    w = jnp.zeros(3)
    for size in (4, 7, 9):
        with pytest.raises(ValueError, match=r"^u: expected shape \(8,\)"):
            body_rate_field(w, jnp.zeros(size), params)
        with pytest.raises(ValueError, match=r"^u: expected shape \(8,\)"):
            wheel_rate_transition(w, jnp.zeros(size), params)


def test_dual_filter_rejects_a_model_of_another_size(params):
    ekf = estimation_filter(params, Q_SIGMA, GYRO_SIGMA)
    with pytest.raises(ValueError, match="estimator"):
        dual_filter(lambda x: x, wheel_rate_transition, body_rate_field, params)
    bad_field = lambda x, u, p: jnp.concatenate([body_rate_field(x, u, p), jnp.zeros(1)])
    filt = dual_filter(ekf, wheel_rate_transition, bad_field, params)
    state = filt.init(jnp.zeros(3), 1e-6 * jnp.eye(3))
    with pytest.raises(ValueError, match=r"^field\(x, u, params\): expected shape \(3,\)"):
        filt.step(state, jnp.zeros(3), jnp.zeros(8))
