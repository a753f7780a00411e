"""The associative-scan (parallel-in-time) Kalman filter against the sequential one on
the engine, and against dense Gaussian conditioning of the whole sequence on a small case."""
import jax.numpy as jnp
import numpy as np
import pytest

from _linear_gaussian_cases import condition, engine_filtered, joint_gaussian, small_model
from jaxfdi.filters import GaussianState, parallel_kalman_filter
from jaxfdi.models import LinearGaussianModel


def _rel(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


def test_parallel_equals_sequential_on_the_engine():
    """Every FilterInfo field and the final prediction within 1e-9 (relative to the
    field's largest value) of run_filter(kalman_filter), float64."""
    model, ys, us, m0, P0, (final, info) = engine_filtered()
    got_final, got = parallel_kalman_filter(model, GaussianState(m0, P0), ys, us)
    for name in ("predicted_mean", "predicted_cov", "filtered_mean", "filtered_cov", "innovation", "innovation_cov",
                 "log_likelihood", "nis"):
        assert _rel(getattr(got, name), getattr(info, name)) < 1e-9, name
    np.testing.assert_array_equal(got.num_observed, info.num_observed)
    np.testing.assert_array_equal(got.healthy, info.healthy)
    assert _rel(got_final.mean, final.mean) < 1e-9 and _rel(got_final.cov, final.cov) < 1e-9


def test_parallel_equals_dense_conditioning(T=13):
    """x[k|k] and P[k|k] = the joint Gaussian of (x_0..x_{T-1}, y_0..y_{T-1}) conditioned on
    y_0..y_k by a dense solve; the summed log-likelihood = log p(y_0..y_{T-1})."""
    model = small_model()
    rng = np.random.default_rng(4)
    us, ys = rng.normal(size=(T, 1)), rng.normal(size=(T, 2)) * 2.0
    m0, P0 = np.array([0.3, -0.1, 0.2]), np.diag([0.5, 0.4, 0.3])
    _, info = parallel_kalman_filter(model, GaussianState(jnp.asarray(m0), jnp.asarray(P0)), ys, us)
    joint = joint_gaussian(model, m0, P0, us, T)
    for k in range(T):
        mean, cov, log_density = condition(joint, ys, k + 1)
        np.testing.assert_allclose(info.filtered_mean[k], mean[3 * k:3 * k + 3], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(info.filtered_cov[k], cov[3 * k:3 * k + 3, 3 * k:3 * k + 3], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.sum(info.log_likelihood), log_density, rtol=1e-10)


def test_bad_input():
    model = small_model()
    ys, us = np.zeros((13, 2)), np.zeros((13, 1))
    prior = GaussianState(jnp.zeros(3), jnp.eye(3))
    with pytest.raises(ValueError, match="ys"):
        parallel_kalman_filter(model, prior, ys[:, :1], us)
    with pytest.raises(ValueError, match="us"):
        parallel_kalman_filter(model, prior, ys, us[:5])
    with pytest.raises(TypeError, match="init_state"):
        parallel_kalman_filter(model, (jnp.zeros(3), jnp.eye(3)), ys, us)
    with pytest.raises(ValueError, match="init_state.cov"):
        parallel_kalman_filter(model, GaussianState(jnp.zeros(3), -jnp.eye(3)), ys, us)
