"""Engine mode models: structure against hand-built matrices, and the bias modes'
estimate of a fault's size against the injected value."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfdi import FaultKind, Target, fault, linear_simulator, simulate
from jaxfdi.filters import kalman_filter, run_filter
from jaxfdi.models import bias_mode_initial_state, bias_modes, engine_model, noise_inflation_modes


@pytest.fixture(scope="module")
def engine():
    return engine_model()


def test_noise_inflation_modes_structure(engine):
    modes = noise_inflation_modes(engine, jnp.array([10.0, 20.0, 30.0, 40.0, 50.0]), 0.008)
    assert modes.Q.shape == (7, 7, 7) and modes.R.shape == (7, 5, 5)
    g = np.asarray(engine.Gamma[:, 0])
    np.testing.assert_allclose(
        modes.Q[1], np.asarray(engine.Q) + 0.008**2 * np.outer(g, g), rtol=1e-14
    )
    for j in range(5):
        R = np.array(engine.R)
        R[j, j] *= 10.0 * (j + 1)
        np.testing.assert_allclose(modes.R[2 + j], R, rtol=1e-14)
        np.testing.assert_allclose(modes.Q[2 + j], engine.Q, rtol=1e-14)
    np.testing.assert_allclose(modes.R[:2], np.broadcast_to(engine.R, (2, 5, 5)), rtol=1e-14)
    np.testing.assert_allclose(modes.Phi, np.broadcast_to(engine.Phi, (7, 7, 7)), rtol=1e-14)
    with pytest.raises(ValueError, match=r"sensor_inflation: expected shape \(5,\)"):
        noise_inflation_modes(engine, jnp.ones(3), 0.008)


def test_bias_modes_structure(engine):
    walk, prior = np.arange(1.0, 7.0) * 1e-3, np.arange(1.0, 7.0)
    modes = bias_modes(engine, walk, prior)
    assert modes.Phi.shape == (7, 13, 13) and modes.C.shape == (7, 5, 13)
    normal, actuator, p4 = (jax.tree.map(lambda a, j=j: np.asarray(a[j]), modes) for j in (0, 1, 5))
    np.testing.assert_allclose(normal.Phi[:7, 7:], 0.0)
    np.testing.assert_allclose(normal.Q[7:, 7:], np.diag(prior))  # every bias reset to its prior
    np.testing.assert_allclose(actuator.Phi[:7, 7], engine.Gamma[:, 0], rtol=1e-14)
    np.testing.assert_allclose(actuator.C[:, 7], engine.D[:, 0], rtol=1e-14)
    assert actuator.Phi[7, 7] == 1.0 and actuator.Q[7, 7] == walk[0]
    np.testing.assert_allclose(
        p4.C[:, 7:], np.eye(5, 6, k=1) * (np.arange(6) == 4)
    )  # sensor P4 = output 3
    assert p4.Phi[11, 11] == 1.0 and p4.Q[11, 11] == walk[4]


@pytest.mark.parametrize("label", [1, 5])  # actuator, P4 sensor
def test_matching_bias_mode_estimates_the_fault_size(engine, label):
    """A KF on the matching bias mode, run on data with a bias present from the start
    (the bias prior is the one a mode gets on entry), estimates its size within 3
    posterior sigmas, and those sigmas are small."""
    onset, T = 0, 400
    if label == 1:
        f, size = fault(FaultKind.BIAS, Target.ACTUATOR, 0, onset, 5e-4), 5e-4
    else:
        f, size = fault(FaultKind.BIAS, Target.SENSOR, label - 2, onset, 8.285), 8.285
    us = jnp.full((T, 1), 0.01)
    _, truth, _ = simulate(linear_simulator(engine, f), jnp.zeros(7), us, jax.random.PRNGKey(4))
    prior = np.array([1e-6, 1e4, 400.0, 4.0, 100.0, 36.0])
    modes = bias_modes(engine, 1e-12, prior)
    kf = kalman_filter(jax.tree.map(lambda a: a[label], modes))
    m0, P0 = bias_mode_initial_state(engine, jnp.zeros(7), engine.Q, prior)
    _, info = run_filter(kf, kf.init(m0, P0), truth.measurement, us)
    estimate = info.filtered_mean[-1, 7 + label - 1]
    sigma = jnp.sqrt(info.filtered_cov[-1, 7 + label - 1, 7 + label - 1])
    assert abs(estimate - size) < 3 * sigma and sigma < 0.1 * size
