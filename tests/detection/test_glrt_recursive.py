"""The recursive (running-sum) GLRT against the windowed one and a NumPy double loop:
statistic, onset, magnitude, label and alarm at every step of faulty engine runs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfdi
from jaxfdi import steady_state_kalman
from jaxfdi.detection import fault_directions, fault_signatures, glrt_detector, glrt_threshold
from jaxfdi.models import engine_model

T, ONSET = 90, 40
SIZES = [0.0005, 135.0, 16.99, 2.21, 8.285, 5.125]  # seed 003: actuator, then sensors 1..5


@pytest.fixture(scope="module")
def engine():
    model = engine_model()
    return model, steady_state_kalman(model)


@pytest.fixture(scope="module")
def innovations(engine):
    """(3, T, 5) innovations of the fault-blind KF: a fault-free run, a P4 bias and an
    actuator bias from step ONSET, started at the steady-state prior."""
    model, steady = engine
    us = jnp.full((T, 1), 0.01)

    def one(fault, key):
        _, truth, _ = jaxfdi.simulate(jaxfdi.linear_simulator(model, fault), jnp.zeros(7), us, key)
        kf = jaxfdi.filters.kalman_filter(model)
        return jaxfdi.filters.run_filter(
            kf, kf.init(jnp.zeros(7), steady.predicted_cov), truth.measurement, us
        )[1].innovation

    faults = jaxfdi.stack_faults(
        [
            jaxfdi.no_fault(),
            jaxfdi.fault("bias", "sensor", 3, ONSET, SIZES[4]),
            jaxfdi.fault("bias", "actuator", 0, ONSET, SIZES[0]),
        ]
    )
    keys = jax.random.split(jax.random.key(3), 3)
    return np.asarray(jax.jit(jax.vmap(one))(faults, keys))


def _decisions(det, innovations):
    return jax.jit(jax.vmap(lambda e: jax.lax.scan(det.step, det.init(), e)))(innovations)


@pytest.mark.parametrize("window,isolation", [(10, "max"), (25, "paper")])
def test_recursive_equals_windowed(engine, innovations, window, isolation):
    """Every output of every step equal (1e-10 relative), both isolation rules."""
    model, steady = engine
    threshold = glrt_threshold(1e-4, 6, window, "bonferroni")
    args = (model, steady.gain, steady.innovation_cov, window, threshold, isolation)
    final_w, windowed = _decisions(glrt_detector(*args), innovations)
    final_r, recursive = _decisions(glrt_detector(*args, recursive=True), innovations)
    np.testing.assert_allclose(recursive.statistic, windowed.statistic, rtol=1e-10, atol=0)
    np.testing.assert_allclose(recursive.estimate, windowed.estimate, rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(recursive.label, windowed.label)
    np.testing.assert_array_equal(recursive.alarm, windowed.alarm)
    np.testing.assert_array_equal(final_r.onset_offset, final_w.onset_offset)
    np.testing.assert_array_equal(final_r.count, final_w.count)
    alarm = np.asarray(recursive.alarm)
    assert (
        not alarm[:, :ONSET].any() and alarm[1:, ONSET:].any(axis=1).all()
    )  # the faults are found


def test_recursive_equals_numpy_double_loop(engine, innovations):
    """d_i(theta) = sum_{j=theta..k} G_i[j - theta]^T S^-1 eps_j by a plain double loop
    over onsets and steps, the GLR d^2 / R maximised over onsets with data."""
    model, steady = engine
    window = 8
    G = np.asarray(fault_signatures(model, steady.gain, fault_directions(model), window))
    S_inv = np.linalg.inv(np.asarray(steady.innovation_cov))
    det = glrt_detector(model, steady.gain, steady.innovation_cov, window, 50.0, recursive=True)
    _, got = _decisions(det, innovations[1:2])
    eps = innovations[1]
    for k in (0, 3, ONSET + 2, ONSET + 9, T - 1):
        best = np.full(6, -np.inf)
        magnitude = np.zeros(6)
        for theta in range(max(0, k - window + 1), k + 1):
            d = sum(G[j - theta].T @ S_inv @ eps[j] for j in range(theta, k + 1))
            R = sum(np.diag(G[j - theta].T @ S_inv @ G[j - theta]) for j in range(theta, k + 1))
            glr = np.where(R > 0, d**2 / np.where(R > 0, R, 1.0), 0.0)
            better = glr > best
            best = np.where(better, glr, best)
            magnitude = np.where(
                better, np.where(R > 0, d / np.where(R > 0, R, 1.0), 0.0), magnitude
            )
        np.testing.assert_allclose(got.statistic[0, k], best.max(), rtol=1e-9)
        assert got.label[0, k] == 1 + np.argmax(best)
        np.testing.assert_allclose(got.estimate[0, k], magnitude[np.argmax(best)], rtol=1e-9)


def test_float32_and_bad_input(engine, innovations):
    model, steady = engine
    det = glrt_detector(
        model,
        jnp.asarray(steady.gain, jnp.float32),
        jnp.asarray(steady.innovation_cov, jnp.float32),
        10,
        50.0,
        recursive=True,
    )
    state, decision = jax.jit(det.step)(det.init(), jnp.asarray(innovations[1, 0], jnp.float32))
    assert state.correlation.dtype == jnp.float32 and decision.statistic.dtype == jnp.float32
    assert np.isfinite(decision.statistic)
    with pytest.raises(ValueError, match="window"):
        glrt_detector(model, steady.gain, steady.innovation_cov, 0, 50.0, recursive=True)
    with pytest.raises(ValueError, match="threshold"):
        glrt_detector(model, steady.gain, steady.innovation_cov, 10, -1.0, recursive=True)
    with pytest.raises(TypeError, match="^recursive: expected True or False"):
        glrt_detector(model, steady.gain, steady.innovation_cov, 10, 50.0, recursive="yes")
    with pytest.raises(
        TypeError, match="^recursive: expected True or False"
    ):  # the other two GLRTs' engine switch
        jaxfdi.detection.transient_glrt_detector(
            model, jnp.eye(model.Phi.shape[0]), 10, 50.0, recursive=1
        )
    with pytest.raises(TypeError, match="^recursive: expected True or False"):
        jaxfdi.detection.corrected_glrt(model, 10, 50.0, recursive=None)
    with pytest.raises(TypeError, match="^correct: expected True or False"):
        jaxfdi.detection.corrected_glrt(model, 10, 50.0, correct="no")
    with pytest.raises(ValueError, match="innovation"):
        det.step(det.init(), jnp.zeros(4))
