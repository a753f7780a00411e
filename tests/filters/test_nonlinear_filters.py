"""EKF and UKF: equal to the KF on a linear model; the UKF equal to filterpy's
UnscentedKalmanFilter + MerweScaledSigmaPoints on the nonlinear rigid-body model; the
EKF equal to filterpy's ExtendedKalmanFilter with finite-difference Jacobians; and the
UKF stays finite and accurate in float32 with alpha = 1e-3."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _problems import engine_data, linear_as_nonlinear, rigid_body_data
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

import jaxfdi
from jaxfdi.models._rigid_body import rigid_body_observation, rigid_body_transition

FIELDS = (
    "filtered_mean",
    "filtered_cov",
    "predicted_mean",
    "predicted_cov",
    "innovation",
    "log_likelihood",
)


def rel_err(actual, expected):
    expected = np.asarray(expected)
    return np.max(np.abs(np.asarray(actual) - expected)) / np.max(np.abs(expected))


@pytest.fixture(scope="module")
def engine():
    return engine_data(T=60)


@pytest.fixture(scope="module")
def rigid():
    return rigid_body_data()


@pytest.fixture(scope="module")
def kf_info(engine):
    model, ys, us, m0, P0 = engine
    kf = jaxfdi.filters.kalman_filter(model)
    return jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys, us)[1]


def test_ekf_on_linear_model_equals_kf(engine, kf_info):
    model, ys, us, m0, P0 = engine
    ekf = jaxfdi.filters.extended_kalman_filter(*linear_as_nonlinear(model))
    _, info = jaxfdi.filters.run_filter(ekf, ekf.init(m0, P0), ys, us)
    for name in FIELDS:
        assert rel_err(getattr(info, name), getattr(kf_info, name)) < 1e-10, name


@pytest.mark.parametrize("alpha,tol", [(1.0, 1e-9), (1e-3, 1e-6)])
def test_ukf_on_linear_model_equals_kf(engine, kf_info, alpha, tol):
    """The UT is exact for linear maps; alpha = 1e-3 costs digits to the 1e6 weights
    even in float64 on this stiff, badly scaled model (states span 1e-1..1e4)."""
    model, ys, us, m0, P0 = engine
    ukf = jaxfdi.filters.unscented_kalman_filter(*linear_as_nonlinear(model), alpha=alpha)
    _, info = jaxfdi.filters.run_filter(ukf, ukf.init(m0, P0), ys, us)
    for name in FIELDS:
        assert rel_err(getattr(info, name), getattr(kf_info, name)) < tol, name


def filterpy_ukf(params, Q, R, ys, us, m0, P0, alpha, beta, kappa):
    points = MerweScaledSigmaPoints(3, alpha, beta, kappa)
    ukf = UnscentedKalmanFilter(3, 3, float(params.dt), hx=lambda x: x, fx=None, points=points)
    ukf.x, ukf.P, ukf.Q, ukf.R = m0.copy(), P0.copy(), Q, R
    f = jax.jit(lambda x, u: rigid_body_transition(x, u, params))
    out = {"filtered_mean": [], "filtered_cov": [], "log_likelihood": []}
    for k in range(len(ys)):
        ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)  # jaxfdi's step starts from N(x, P)
        ukf.update(ys[k])
        out["filtered_mean"].append(ukf.x.copy())
        out["filtered_cov"].append(ukf.P.copy())
        out["log_likelihood"].append(ukf.log_likelihood)
        ukf.predict(fx=lambda x, dt, u: np.asarray(f(x, u)), u=us[k])
    return {k: np.array(v) for k, v in out.items()}


@pytest.mark.parametrize("alpha,tol", [(0.5, 1e-8), (0.1, 1e-8), (1e-3, 1e-7)])
def test_ukf_equals_filterpy(rigid, alpha, tol):
    """To 1e-8 for moderate alpha. At alpha = 1e-3 filterpy's own textbook sums lose
    ~1e6 * eps in float64 (weights -1e6), so the reference itself is good to ~1e-8
    only: we check 1e-7 there."""
    params, Q, R, ys, us, m0, P0 = rigid
    ukf = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params, alpha, 2.0, 0.0
    )
    _, info = jaxfdi.filters.run_filter(ukf, ukf.init(m0, P0), ys, us)
    ref = filterpy_ukf(params, Q, R, ys, us, m0, P0, alpha, 2.0, 0.0)
    for name, value in ref.items():
        assert rel_err(getattr(info, name), value) < tol, name


def test_ekf_equals_filterpy_with_numerical_jacobians(rigid):
    params, Q, R, ys, us, m0, P0 = rigid
    f = jax.jit(lambda x, u: rigid_body_transition(x, u, params))

    def fd_jacobian(x, u, eps=1e-6):
        return np.stack(
            [
                (np.asarray(f(x + eps * e, u)) - np.asarray(f(x - eps * e, u))) / (2 * eps)
                for e in np.eye(3)
            ],
            1,
        )

    ref = ExtendedKalmanFilter(3, 3)
    ref.x, ref.P, ref.Q, ref.R = m0.reshape(3, 1).copy(), P0.copy(), Q, R
    means, covs = [], []
    for k in range(len(ys)):
        ref.update(ys[k].reshape(3, 1), HJacobian=lambda x: np.eye(3), Hx=lambda x: x)
        means.append(ref.x.ravel().copy())
        covs.append(ref.P.copy())
        ref.F = fd_jacobian(ref.x.ravel(), us[k])
        ref.x = np.asarray(f(ref.x.ravel(), us[k])).reshape(3, 1)
        ref.P = ref.F @ ref.P @ ref.F.T + ref.Q
    ekf = jaxfdi.filters.extended_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params
    )
    _, info = jaxfdi.filters.run_filter(ekf, ekf.init(m0, P0), ys, us)
    assert rel_err(info.filtered_mean, np.array(means)) < 1e-7
    assert (
        rel_err(info.filtered_cov, np.array(covs)) < 1e-6
    )  # central differences: O(eps^2) + round-off


def test_ukf_float32_alpha_1e3_stays_finite_and_matches_float64(rigid):
    """Acceptance test of the centred/Taylor form: float32, alpha = 1e-3 (Wc0 ~ -1e6)."""
    params, Q, R, ys, us, m0, P0 = rigid
    ukf64 = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params
    )
    _, ref = jaxfdi.filters.run_filter(ukf64, ukf64.init(m0, P0), ys, us)

    f32 = lambda a: jnp.asarray(a, jnp.float32)
    params32 = jax.tree_util.tree_map(f32, params)
    ukf32 = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, f32(Q), f32(R), params32
    )
    _, info = jaxfdi.filters.run_filter(ukf32, ukf32.init(f32(m0), f32(P0)), f32(ys), f32(us))
    assert info.filtered_mean.dtype == jnp.float32
    assert info.filtered_cov.dtype == jnp.float32
    assert bool(jnp.all(jnp.isfinite(info.filtered_mean))) and bool(
        jnp.all(jnp.isfinite(info.filtered_cov))
    )
    assert bool(jnp.all(info.healthy))
    assert rel_err(info.filtered_mean, ref.filtered_mean) < 1e-3
    assert (
        rel_err(
            np.sqrt(np.diagonal(info.filtered_cov, axis1=1, axis2=2)),
            np.sqrt(np.diagonal(ref.filtered_cov, axis1=1, axis2=2)),
        )
        < 1e-2
    )


def test_textbook_differences_in_float32_are_what_the_taylor_form_fixes(rigid):
    """The same float32 run with direct sigma-point differences is far off (> 1e-3),
    which is why ``sigma_differences='auto'`` picks the Taylor form there."""
    params, Q, R, ys, us, m0, P0 = rigid
    ukf64 = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, rigid_body_observation, Q, R, params
    )
    _, ref = jaxfdi.filters.run_filter(ukf64, ukf64.init(m0, P0), ys, us)
    f32 = lambda a: jnp.asarray(a, jnp.float32)
    ukf = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition,
        rigid_body_observation,
        f32(Q),
        f32(R),
        jax.tree_util.tree_map(f32, params),
        sigma_differences="direct",
    )
    _, info = jaxfdi.filters.run_filter(ukf, ukf.init(f32(m0), f32(P0)), f32(ys), f32(us))
    finite = bool(jnp.all(jnp.isfinite(info.filtered_mean)))
    assert (not finite) or rel_err(info.filtered_mean, ref.filtered_mean) > 1e-3
