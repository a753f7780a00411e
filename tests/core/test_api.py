"""API a new user expects: starting a KF or an IMM from a posterior (filterpy's
predict-then-update loop, 1e-10), and a model without inputs end to end (no zero-width
matrices to write by hand), against filterpy."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

import jaxfdi
from jaxfdi.filters import (
    init_from_posterior,
    interacting_multiple_model,
    kalman_filter,
    run_filter,
)
from jaxfdi.models import LinearGaussianModel, linear_gaussian_model, noise_inflation_modes

T = 30
PHI = np.array([[0.9, 0.1, 0.0], [0.0, 0.8, 0.2], [0.1, 0.0, 0.7]])
GAMMA = np.array([[0.5], [0.0], [0.3]])
C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
Q, R = np.diag([0.05, 0.02, 0.03]), np.diag([0.1, 0.2])
X0, P0 = np.array([0.1, -0.2, 0.3]), np.diag([0.5, 0.4, 0.3])
TRANSITION = np.array([[0.90, 0.05, 0.05], [0.10, 0.88, 0.02], [0.05, 0.0, 0.95]])


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(7)
    us = rng.normal(size=(T, 1))
    ys = rng.normal(size=(T, 2)) + np.where(np.arange(T)[:, None] >= 12, [2.0, 0.0], 0.0)
    return ys, us, rng.normal(size=1)  # u[-1]: the input before y[0]


def _filterpy_kf(Gamma, x0=X0):
    kf = KalmanFilter(dim_x=3, dim_z=2, dim_u=Gamma.shape[1])
    kf.F, kf.H, kf.Q, kf.R, kf.x, kf.P = PHI, C, Q, R, x0.copy(), P0.copy()
    if Gamma.shape[1]:
        kf.B = Gamma
    return kf


def test_kalman_from_posterior_equals_filterpy_predict_then_update(data):
    ys, us, u_before = data
    ref = _filterpy_kf(GAMMA)
    means, covs, logliks = [], [], []
    for k in range(T):
        ref.predict(u=u_before if k == 0 else us[k - 1])
        ref.update(ys[k])
        means.append(ref.x.copy()), covs.append(ref.P.copy()), logliks.append(ref.log_likelihood)
    kf = kalman_filter(LinearGaussianModel(PHI, GAMMA, C, np.zeros((2, 1)), Q, R))
    _, info = run_filter(kf, init_from_posterior(kf, X0, P0, u_before), ys, us)
    np.testing.assert_allclose(info.filtered_mean, means, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(info.filtered_cov, covs, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(info.log_likelihood, logliks, rtol=1e-10)


@pytest.mark.parametrize("per_mode", [False, True], ids=["shared posterior", "per-mode posteriors"])
def test_imm_from_posterior_equals_filterpy_imm_estimator(data, per_mode):
    """filterpy's predict-first IMM loop (``IMMEstimator(filters, mu0, M)``; ``predict``
    mixes the filters' posteriors, then ``update``) from posterior mode probabilities."""
    ys, us, u_before = data
    plant = LinearGaussianModel(PHI, GAMMA, C, np.zeros((2, 1)), Q, R)
    modes = jax.tree.map(lambda a: a[:3], noise_inflation_modes(plant, 50.0, 0.8))
    mu0 = np.array([0.7, 0.2, 0.1])
    means = np.stack([X0, X0 + 0.3, X0 - 0.2]) if per_mode else np.stack([X0] * 3)
    covs = np.stack([(1 + j) * P0 for j in range(3)]) if per_mode else np.stack([P0] * 3)
    filters = []
    for j in range(3):
        kf = KalmanFilter(dim_x=3, dim_z=2, dim_u=1)
        kf.F, kf.B, kf.H = np.array(modes.Phi[j]), np.array(modes.Gamma[j]), np.array(modes.C[j])
        kf.Q, kf.R, kf.x, kf.P = (
            np.array(modes.Q[j]),
            np.array(modes.R[j]),
            means[j].copy(),
            covs[j].copy(),
        )
        filters.append(kf)
    ref = IMMEstimator(filters, mu0, TRANSITION)
    ref_mu, ref_x, ref_P = [], [], []
    for k in range(T):
        ref.predict(u_before if k == 0 else us[k - 1])
        ref.update(ys[k])
        ref_mu.append(ref.mu.copy()), ref_x.append(ref.x.copy()), ref_P.append(ref.P.copy())
    imm = interacting_multiple_model(kalman_filter, modes, TRANSITION)
    if per_mode:
        state0 = init_from_posterior(imm, means, covs, u_before, mode_prob=mu0)
    else:
        state0 = imm.init(
            X0, P0, mu0, posterior=True, u=u_before
        )  # the init option, shared moments
    _, info = run_filter(imm, state0, ys, us)
    np.testing.assert_allclose(info.mode_prob, ref_mu, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(info.mean, ref_x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(info.cov, ref_P, rtol=1e-10, atol=1e-12)


def test_init_from_posterior_bad_input():
    kf = kalman_filter(LinearGaussianModel(PHI, GAMMA, C, np.zeros((2, 1)), Q, R))
    with pytest.raises(ValueError, match="mode_prob"):
        init_from_posterior(kf, X0, P0, np.zeros(1), mode_prob=np.ones(1))
    with pytest.raises(ValueError, match="mean"):
        init_from_posterior(kf, X0[:2], P0, np.zeros(1))
    imm = interacting_multiple_model(
        kalman_filter, jax.tree.map(lambda a: a[None], kf_model()), np.ones((1, 1))
    )
    with pytest.raises(ValueError, match="filt"):
        init_from_posterior(imm, X0, P0, np.zeros(1))


def kf_model():
    return LinearGaussianModel(PHI, GAMMA, C, np.zeros((2, 1)), Q, R)


def test_model_without_inputs_end_to_end():
    """``linear_gaussian_model(Phi, C, Q, R)``: zero-width Gamma and D; the KF with
    ``us=None`` equals filterpy's KF without inputs; ``simulate`` runs it with (T, 0)
    inputs and its noise-free state follows ``Phi`` alone."""
    model = linear_gaussian_model(PHI, C, Q, R)
    assert model.dims == (3, 0, 2) and model.Gamma.shape == (3, 0) and model.D.shape == (2, 0)
    _, truth, _ = jaxfdi.simulate(
        jaxfdi.linear_simulator(model), jnp.asarray(X0), jnp.zeros((T, 0)), jax.random.key(1)
    )
    ys = np.asarray(truth.measurement)
    assert ys.shape == (T, 2) and np.all(np.isfinite(ys))
    kf = kalman_filter(model)
    _, info = run_filter(kf, kf.init(X0, P0), ys)  # us=None
    _, info_posterior = run_filter(kf, init_from_posterior(kf, X0, P0), ys)
    ref, ref_prior = _filterpy_kf(np.zeros((3, 0))), _filterpy_kf(np.zeros((3, 0)))
    means, prior_means = [], []
    for k in range(T):
        ref.update(ys[k])
        means.append(ref.x.copy())
        ref.predict()
        ref_prior.predict()
        ref_prior.update(ys[k])
        prior_means.append(ref_prior.x.copy())
    np.testing.assert_allclose(info.filtered_mean, means, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(info_posterior.filtered_mean, prior_means, rtol=1e-10, atol=1e-12)
    # noise-free: the simulator's state is Phi^k x0
    quiet = linear_gaussian_model(PHI, C, np.zeros((3, 3)), np.zeros((2, 2)))
    _, clean, _ = jaxfdi.simulate(
        jaxfdi.linear_simulator(quiet), jnp.asarray(X0), jnp.zeros((5, 0)), jax.random.key(0)
    )
    np.testing.assert_allclose(
        clean.state, [np.linalg.matrix_power(PHI, k) @ X0 for k in range(5)], rtol=1e-12
    )


def test_linear_gaussian_model_keeps_given_blocks_and_checks_shapes():
    model = linear_gaussian_model(PHI, C, Q, R, Gamma=GAMMA)
    np.testing.assert_array_equal(model.Gamma, GAMMA)
    assert model.D.shape == (2, 1) and not np.any(np.asarray(model.D))
    with pytest.raises(ValueError, match="Gamma"):
        linear_gaussian_model(PHI, C, Q, R, Gamma=np.ones((2, 1)))
    with pytest.raises(ValueError, match="D"):
        linear_gaussian_model(PHI, C, Q, R, Gamma=GAMMA, D=np.ones((2, 2)))
    with pytest.raises(ValueError, match="C"):
        linear_gaussian_model(PHI, C[:, :2], Q, R)
