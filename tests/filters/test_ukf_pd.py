"""The UKF's Joseph-like measurement update (issue 22): positive definite where the
textbook ``P - K S K^T`` is not, and equal to it where that one is sound.

The failing cases are the issue's: the 3-state rigid body (RK4 of Euler's rotation
equations, gyro measurements; ``tests/_problems.py``) with one measurement variance of
1e-24, or with ``P0 = 1e12 I``. There the textbook update from the very same sigma-point
moments is indefinite or far off (checked here with NumPy; the library's former update
was not positive definite from the first step on both), while the EKF on the same data
stays healthy: the reference behaviour the UKF must match. Where the textbook update is sound
(a nonlinear measurement, alpha 1e-3 and 1) the Joseph-like form equals it to 1e-10,
the textbook update being computed independently in NumPy (Cholesky sigma points, the
centred moments of the module doc, ``P - K S K^T``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _problems import rigid_body_data

import jaxfdi
from jaxfdi.models._rigid_body import rigid_body_observation, rigid_body_transition

T = 12
PARAMS, Q, R, YS, US, M0, P0 = rigid_body_data(T=T)
R_TINY = np.diag([1e-24, 1e-4, 1e-4])  # one measurement variance of 1e-24
P0_HUGE = 1e12 * np.eye(3)
FAILING = {"R variance 1e-24": (R_TINY, P0), "P0 = 1e12 I": (R, P0_HUGE)}


def nonlinear_gyros(w, tau, params):
    """A nonlinear measurement of the rates (so the linearisation error Lambda is not 0)."""
    return jnp.stack([w[0] + 0.5 * w[1] ** 2, jnp.sin(w[1]), w[2] * w[0]])


def textbook_update(mean, cov, y, h, noise_cov, alpha, beta=2.0, kappa=0.0):
    """One scaled-UT measurement update in NumPy, ``P+ = P - K S K^T`` (centred moments)."""
    n = mean.shape[0]
    spread = alpha**2 * (n + kappa)
    w = 1.0 / (2.0 * spread)
    s = (mean + np.sqrt(spread) * np.linalg.cholesky(cov).T) - mean
    dx = np.concatenate([s, -s])
    y0 = np.asarray(h(jnp.asarray(mean), None, None))
    dy = np.stack([np.asarray(h(jnp.asarray(mean + d), None, None)) for d in dx]) - y0
    delta = w * dy.sum(axis=0)
    Pyy = w * dy.T @ dy + (beta - alpha**2) * np.outer(delta, delta)
    Pxy = w * dx.T @ dy
    S = Pyy + noise_cov
    K = np.linalg.solve(S, Pxy.T).T
    return mean + K @ (y - y0 - delta), cov - K @ S @ K.T


def _run_batch(make):
    """``make(R)`` filters run on the rigid-body data from each failing case's prior: one
    compiled ``vmap`` over the cases."""
    Rs = jnp.asarray(np.stack([case[0] for case in FAILING.values()]))
    P0s = jnp.asarray(np.stack([case[1] for case in FAILING.values()]))

    def one(R_case, P0_case):
        filt = make(R_case)
        return jaxfdi.filters.run_filter(filt, filt.init(jnp.asarray(M0), P0_case), YS, US)[1]

    return jax.jit(jax.vmap(one))(Rs, P0s)


@pytest.fixture(scope="module")
def failing_runs():
    ukf = _run_batch(
        lambda R_case: jaxfdi.filters.unscented_kalman_filter(
            rigid_body_transition, rigid_body_observation, Q, R_case, PARAMS
        )
    )
    ekf = _run_batch(
        lambda R_case: jaxfdi.filters.extended_kalman_filter(
            rigid_body_transition, rigid_body_observation, Q, R_case, PARAMS
        )
    )
    return ukf, ekf


def test_the_failing_cases_defeat_the_textbook_update(failing_runs):
    """The cases are real. From the UKF's own priors, ``P - K S K^T`` (NumPy) is indefinite
    on the 1e-24 channel from the third step, where the Joseph-like form keeps its variance
    at 1e-24; with ``P0 = 1e12 I`` it cancels ``1e12 eps ~ 1e-4`` away and misses the exact
    first posterior ``(P0^-1 + R^-1)^-1`` (the measurement is linear) by a factor of 3,
    which the Joseph-like form matches to 1e-9."""
    ukf = jax.tree_util.tree_map(np.asarray, failing_runs[0])
    tiny, huge = 0, 1
    smallest = []
    for k in range(T):
        _, cov = textbook_update(
            ukf.predicted_mean[tiny, k],
            ukf.predicted_cov[tiny, k],
            YS[k],
            rigid_body_observation,
            R_TINY,
            1e-3,
        )
        smallest.append(np.linalg.eigvalsh(cov)[0])
    assert min(smallest) < 0, smallest
    np.testing.assert_allclose(ukf.filtered_cov[tiny, :, 0, 0], 1e-24, rtol=0.02)
    exact = np.linalg.inv(np.linalg.inv(P0_HUGE) + np.linalg.inv(R))
    _, textbook = textbook_update(M0, P0_HUGE, YS[0], rigid_body_observation, R, 1e-3)
    assert np.max(np.abs(textbook - exact)) > np.max(np.abs(exact))
    np.testing.assert_allclose(
        ukf.filtered_cov[huge, 0], exact, rtol=0, atol=1e-9 * np.max(np.abs(exact))
    )


@pytest.mark.parametrize("index, name", list(enumerate(FAILING)))
def test_ukf_stays_positive_definite_where_the_ekf_does(failing_runs, index, name):
    ukf, ekf = (jax.tree_util.tree_map(lambda a: np.asarray(a[index]), run) for run in failing_runs)
    assert ekf.healthy.all(), f"{name}: the EKF reference lost health"
    assert ukf.healthy.all(), f"{name}: UKF unhealthy at steps {np.flatnonzero(~ukf.healthy)}"
    for k in range(T):
        for cov in (ukf.filtered_cov[k], ukf.predicted_cov[k]):
            np.linalg.cholesky(cov)  # positive definite (raises otherwise)
            np.testing.assert_allclose(cov, cov.T, rtol=0, atol=1e-15 * np.max(np.abs(cov)))
    # the same estimates as the EKF: the model is mildly nonlinear over one step's spread
    spread = np.sqrt(np.diagonal(ekf.filtered_cov, axis1=1, axis2=2))
    assert np.all(np.abs(ukf.filtered_mean - ekf.filtered_mean) <= 1e-3 * spread + 1e-9), name
    if name == "R variance 1e-24":  # the exact channel pins the estimate to the measurement
        np.testing.assert_allclose(ukf.filtered_mean[:, 0], YS[:, 0], rtol=0, atol=1e-10)
        assert np.all(ukf.filtered_cov[:, 0, 0] < 1e-20)


@pytest.mark.parametrize(
    "h, alpha",
    [(nonlinear_gyros, 1e-3), (nonlinear_gyros, 1.0)],
    ids=["nonlinear alpha 1e-3", "nonlinear alpha 1"],
)
def test_equals_the_textbook_update_where_it_is_sound(h, alpha):
    rng = np.random.default_rng(0)
    ys = np.stack([np.asarray(h(jnp.asarray(y), None, None)) for y in YS]) + 1e-2 * rng.normal(
        size=YS.shape
    )
    filt = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, h, Q, R, PARAMS, alpha=alpha
    )
    _, info = jaxfdi.filters.run_filter(filt, filt.init(jnp.asarray(M0), jnp.asarray(P0)), ys, US)
    assert bool(np.all(info.healthy))
    for k in range(T):
        mean, cov = textbook_update(
            np.asarray(info.predicted_mean[k]),
            np.asarray(info.predicted_cov[k]),
            ys[k],
            h,
            R,
            alpha,
        )
        np.linalg.cholesky(cov)  # the textbook update is sound here
        scale = np.max(np.abs(cov))
        np.testing.assert_allclose(info.filtered_cov[k], cov, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(
            info.filtered_mean[k], mean, rtol=0, atol=1e-10 * np.max(np.abs(mean))
        )


def test_missing_component_is_skipped_by_the_joseph_like_update():
    """A NaN component neither updates the state nor the covariance: the update equals the
    textbook update on the observed components alone."""
    filt = jaxfdi.filters.unscented_kalman_filter(
        rigid_body_transition, nonlinear_gyros, Q, R, PARAMS, missing_measurements=True
    )
    y = np.asarray(nonlinear_gyros(jnp.asarray(YS[0]), None, None)) + 0.01
    y_missing = y.copy()
    y_missing[1] = np.nan
    post = jax.jit(filt.update)(
        filt.init(jnp.asarray(M0), jnp.asarray(P0)), jnp.asarray(y_missing), jnp.asarray(US[0])
    )
    kept = [0, 2]

    def observed(w, tau, params):
        return nonlinear_gyros(w, tau, params)[jnp.array(kept)]

    mean, cov = textbook_update(M0, P0, y[kept], observed, R[np.ix_(kept, kept)], 1e-3)
    np.testing.assert_allclose(post.filtered_cov, cov, rtol=0, atol=1e-10 * np.max(np.abs(cov)))
    np.testing.assert_allclose(post.filtered_mean, mean, rtol=0, atol=1e-10)
    assert int(post.num_observed) == 2
