"""Linear Kalman filter against filterpy's KalmanFilter (Joseph form, same model)."""

import jax
import numpy as np
import pytest
from _problems import engine_data
from filterpy.kalman import KalmanFilter

import jaxfdi

RTOL = 1e-9


def filterpy_reference(model, ys, us, m0, P0, missing=()):
    """filterpy loop in jaxfdi's convention: update with y[k], then predict with u[k].

    filterpy has no feed-through, so ``D u[k]`` is subtracted from the data. A non-finite
    component of ``y[k]`` is replaced by its prediction ``(C x[k|k-1])_j`` (jaxfdi's rule
    for a dead channel without ``missing_measurements``).
    """
    n, nu, m = model.dims
    kf = KalmanFilter(dim_x=n, dim_z=m, dim_u=nu)
    kf.F, kf.B, kf.H = (np.asarray(a) for a in (model.Phi, model.Gamma, model.C))
    kf.Q, kf.R = np.asarray(model.Q), np.asarray(model.R)
    kf.x, kf.P = m0.reshape(n, 1).copy(), P0.copy()
    D = np.asarray(model.D)
    out = {
        "filtered_mean": [],
        "filtered_cov": [],
        "predicted_mean": [],
        "predicted_cov": [],
        "log_likelihood": [],
        "innovation": [],
    }
    for k in range(len(ys)):
        out["predicted_mean"].append(kf.x.ravel().copy())
        out["predicted_cov"].append(kf.P.copy())
        if k in missing:
            kf.update(None)
            out["log_likelihood"].append(0.0)
            out["innovation"].append(np.zeros(m))
        else:
            z = ys[k] - D @ us[k]
            dead = ~np.isfinite(z)
            z[dead] = (kf.H @ kf.x).ravel()[dead]
            kf.update(z.reshape(m, 1))
            out["log_likelihood"].append(kf.log_likelihood)
            out["innovation"].append(kf.y.ravel().copy())
        out["filtered_mean"].append(kf.x.ravel().copy())
        out["filtered_cov"].append(kf.P.copy())
        kf.predict(u=us[k].reshape(nu, 1))
    return {k: np.array(v) for k, v in out.items()}


@pytest.fixture(scope="module")
def engine():
    return engine_data()


def _runner(missing_measurements, unroll_factorizations=True):
    def run(model, m0, P0, ys, us):
        kf = jaxfdi.filters.kalman_filter(
            model,
            missing_measurements=missing_measurements,
            unroll_factorizations=unroll_factorizations,
        )
        return jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys, us)

    return jax.jit(run)


@pytest.fixture(scope="module")
def run_kf():
    return _runner(False)


@pytest.fixture(scope="module")
def run_kf_missing():
    return _runner(True)


def assert_rel(actual, expected, rtol, name):
    scale = np.max(np.abs(expected))
    err = np.max(np.abs(np.asarray(actual) - expected)) / scale
    assert err < rtol, f"{name}: relative error {err:.2e} > {rtol:.0e}"


@pytest.mark.parametrize("unroll", [True, False], ids=["unrolled", "lapack"])
def test_kf_equals_filterpy(engine, run_kf, unroll):
    """Both small-matrix paths (element-wise factorisations, LAPACK) against filterpy."""
    model, ys, us, m0, P0 = engine
    _, info = (run_kf if unroll else _runner(False, False))(model, m0, P0, ys, us)
    ref = filterpy_reference(model, ys, us, m0, P0)
    for name in ref:
        assert_rel(getattr(info, name), ref[name], RTOL, name)
    assert bool(np.all(info.healthy))
    assert np.all(np.asarray(info.num_observed) == 5)


def test_update_and_predict_halves_equal_filterpy(engine):
    """``update`` (its ``posterior``) then ``predict``, one step at a time as multiple-model
    filters and closed loops call them, against filterpy's update and predict."""
    model, ys, us, m0, P0 = engine
    kf = jaxfdi.filters.kalman_filter(model)
    ref = filterpy_reference(model, ys[:10], us[:10], m0, P0)
    state = kf.init(m0, P0)
    for k in range(10):
        post = kf.update(state, ys[k], us[k])
        assert_rel(post.posterior.mean, ref["filtered_mean"][k], RTOL, "filtered_mean")
        assert_rel(post.posterior.cov, ref["filtered_cov"][k], RTOL, "filtered_cov")
        state = kf.predict(post.posterior, us[k])
        if k + 1 < 10:
            assert_rel(state.mean, ref["predicted_mean"][k + 1], RTOL, "predicted_mean")
            assert_rel(state.cov, ref["predicted_cov"][k + 1], RTOL, "predicted_cov")


def test_missing_measurements_equal_filterpy_predict_only(engine, run_kf_missing):
    model, ys, us, m0, P0 = engine
    missing = {3, 4, 50}
    ys_missing = ys.copy()
    ys_missing[list(missing)] = np.nan
    _, info = run_kf_missing(model, m0, P0, ys_missing, us)
    ref = filterpy_reference(model, ys, us, m0, P0, missing)
    for name in ("filtered_mean", "filtered_cov", "log_likelihood"):
        assert_rel(getattr(info, name), ref[name], RTOL, name)
    assert np.all(np.asarray(info.num_observed)[list(missing)] == 0)


def test_complete_data_is_the_same_with_or_without_missing_support(engine, run_kf, run_kf_missing):
    model, ys, us, m0, P0 = engine
    _, info = run_kf(model, m0, P0, ys, us)
    _, info_missing = run_kf_missing(model, m0, P0, ys, us)
    for name in ("filtered_mean", "filtered_cov", "log_likelihood", "nis"):
        assert_rel(getattr(info, name), np.asarray(getattr(info_missing, name)), 1e-14, name)


def test_dead_channel_is_reported_and_never_reaches_the_state(engine, run_kf):
    """A dead sensor (NaN on channel 1 from step 10, +inf on channel 2 at step 20) is
    evidence, not poison: those steps report ``nis = +inf`` and a NaN innovation on the
    dead channel, the filter stays healthy, and its state equals filterpy's KF fed the
    prediction ``(C x[k|k-1])_j`` in place of each dead component (the default path's
    rule: a zero innovation, covariance updated as measured), to RTOL."""
    model, ys, us, m0, P0 = engine
    bad = ys.copy()
    bad[10:, 1] = np.nan
    bad[20, 2] = np.inf
    _, info = run_kf(model, m0, P0, bad, us)
    m = model.dims[2]
    ref = filterpy_reference(model, bad, us, m0, P0)
    assert_rel(info.filtered_mean, ref["filtered_mean"], RTOL, "filtered_mean")
    assert_rel(info.filtered_cov, ref["filtered_cov"], RTOL, "filtered_cov")
    nis, innovation = np.asarray(info.nis), np.asarray(info.innovation)
    assert np.all(np.isfinite(nis[:10])) and np.all(nis[10:] == np.inf)
    assert np.array_equal(np.isnan(innovation), ~np.isfinite(bad)) and not np.any(
        np.isinf(innovation)
    )
    assert np.asarray(info.healthy).all()
    assert (
        list(np.asarray(info.num_observed)[8:12]) == [m, m, m - 1, m - 1]
        and int(info.num_observed[20]) == m - 2
    )


def test_partially_missing_equals_filter_on_observed_rows(engine):
    """A NaN in one component equals the KF that only has the other rows of C, D, R."""
    model, ys, us, m0, P0 = engine
    k_missing, j_missing = 7, 2
    ys_nan = ys.copy()
    ys_nan[k_missing, j_missing] = np.nan
    kf = jaxfdi.filters.kalman_filter(model, missing_measurements=True)
    state = kf.init(m0, P0)
    keep = np.array([j for j in range(5) if j != j_missing])
    reduced = model._replace(C=model.C[keep], D=model.D[keep], R=model.R[np.ix_(keep, keep)])
    kf_reduced = jaxfdi.filters.kalman_filter(reduced)
    for k in range(k_missing + 1):
        if k < k_missing:
            state, info = kf.step(state, ys_nan[k], us[k])
        else:
            state_r, info_r = kf_reduced.step(state, ys[k][keep], us[k])
            state, info = kf.step(state, ys_nan[k], us[k])
    assert_rel(info.filtered_mean, np.asarray(info_r.filtered_mean), 1e-11, "mean")
    assert_rel(info.filtered_cov, np.asarray(info_r.filtered_cov), 1e-11, "cov")
    np.testing.assert_allclose(info.log_likelihood, info_r.log_likelihood, rtol=1e-11)
    assert int(info.num_observed) == 4


def test_log_likelihood_equals_exact_joint_gaussian():
    """Sum of step log-likelihoods = log N(y_1:T) of the stacked joint Gaussian (T = 4)."""
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(3)
    n, m, T = 2, 1, 4
    Phi = np.array([[0.9, 0.2], [-0.1, 0.8]])
    C = np.array([[1.0, 0.5]])
    Q = np.array([[0.2, 0.05], [0.05, 0.1]])
    R = np.array([[0.3]])
    model = jaxfdi.models.LinearGaussianModel(Phi, np.zeros((n, 0)), C, np.zeros((m, 0)), Q, R)
    m0, P0 = np.array([0.3, -0.2]), np.eye(n)
    ys = rng.normal(size=(T, m))
    kf = jaxfdi.filters.kalman_filter(model)
    _, info = jaxfdi.filters.run_filter(kf, kf.init(m0, P0), ys)
    # joint moments of x_0..x_{T-1}
    means, covs = [m0], [P0]
    for _ in range(T - 1):
        means.append(Phi @ means[-1])
        covs.append(Phi @ covs[-1] @ Phi.T + Q)
    cross = np.zeros((T * n, T * n))
    for i in range(T):
        for j in range(i, T):
            block = np.linalg.matrix_power(Phi, j - i) @ covs[i]
            cross[j * n : (j + 1) * n, i * n : (i + 1) * n] = block
            cross[i * n : (i + 1) * n, j * n : (j + 1) * n] = block.T
    H = np.kron(np.eye(T), C)
    joint_mean = H @ np.concatenate(means)
    joint_cov = H @ cross @ H.T + np.kron(np.eye(T), R)
    exact = multivariate_normal(joint_mean, joint_cov).logpdf(ys.ravel())
    np.testing.assert_allclose(float(np.sum(info.log_likelihood)), exact, rtol=1e-12)
