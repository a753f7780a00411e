"""Shared small test problems (fixed shapes, so compiled functions are reused)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import jaxfdi
from jaxfdi.models import engine_model, linear_observation, linear_transition
from jaxfdi.models._rigid_body import (
    rigid_body_observation,
    rigid_body_params,
    rigid_body_transition,
)


def engine_data(T: int = 120, seed: int = 0):
    """Engine model with a simulated fault-free sequence: (model, ys, us, m0, P0)."""
    model = engine_model()
    us = jnp.full((T, 1), 0.01)
    _, truth, _ = jaxfdi.simulate(
        jaxfdi.linear_simulator(model), jnp.zeros(7), us, jax.random.key(seed)
    )
    return (
        model,
        np.asarray(truth.measurement),
        np.asarray(us),
        np.zeros(7),
        10.0 * np.asarray(model.Q),
    )


def rigid_body_data(T: int = 150, seed: int = 1, dtype=jnp.float64):
    """3-state rigid-body rates with torques; returns (params, Q, R, ys, us, m0, P0)."""
    params = rigid_body_params(dtype=dtype)
    k = np.arange(T)
    us = np.stack([2000 * np.sin(0.05 * k), 5000 * np.cos(0.03 * k), 3000 * np.ones(T)], 1)
    Q = np.eye(3) * 1e-6
    R = np.eye(3) * 1e-4
    sim = jaxfdi.simulator(rigid_body_transition, rigid_body_observation, Q, R, params)
    _, truth, _ = jaxfdi.simulate(
        sim, jnp.array([0.5, -0.3, 0.4], dtype), jnp.asarray(us, dtype), jax.random.key(seed)
    )
    return params, Q, R, np.asarray(truth.measurement), us, np.zeros(3), 0.1 * np.eye(3)


def linear_as_nonlinear(model):
    """The (f, h, Q, R, params) of a linear model, for EKF/UKF-equals-KF tests."""
    return linear_transition, linear_observation, model.Q, model.R, model


def engine_false_alarm_study(
    num_runs: int, T: int, window: int, pfa: float, seed: int = 0, chunk_size: int = 8192
):
    """Fault-free engine runs through ``monitor`` with the true ``x0 ~ N(0, P0)`` drawn per
    run, so every innovation of the (correct) KF is exactly ``N(0, S_k)`` and the windowed
    NIS at any step with a full window is exactly ``chi2(window * m)``.

    Returns the per-run ``DetectionRecord`` and the windowed statistic at the last step.
    """
    model = engine_model()
    P0 = 10.0 * np.asarray(model.Q)
    threshold = jaxfdi.detection.chi2_threshold(window * 5, pfa)
    us = jnp.full((T, 1), 0.01)
    key_x0, key_mc = jax.random.split(jax.random.key(seed))
    x0s = jax.random.multivariate_normal(key_x0, jnp.zeros(7), jnp.asarray(P0), (num_runs,))

    def run_one(key, x0):
        kf = jaxfdi.filters.kalman_filter(model)
        result = jaxfdi.monitor(
            jaxfdi.linear_simulator(model),
            kf,
            jaxfdi.detection.chi2_detector(threshold, window),
            x0,
            kf.init(jnp.zeros(7), jnp.asarray(P0)),
            us,
            key,
            jaxfdi._simulation.faults.NEVER,
            keep_history=True,
        )
        return result.record, result.history.statistic[-1]

    return jaxfdi.monte_carlo(run_one, key_mc, num_runs, x0s, chunk_size=chunk_size)
