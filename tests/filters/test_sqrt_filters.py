"""Square-root KF and UKF: equal to the standard filters in float64, finite and accurate in
float32 on an ill-conditioned measurement (Dyer & McReynolds' example of two nearly equal
sensors) where the standard forms lose positive definiteness and return NaN."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _linear_gaussian_cases import engine_filtered
from _problems import rigid_body_data

from jaxfdi.filters import (
    kalman_filter,
    run_filter,
    sqrt_kalman_filter,
    sqrt_unscented_kalman_filter,
    unscented_kalman_filter,
)
from jaxfdi.filters._sqrt_kalman import SqrtGaussianState
from jaxfdi.models import LinearGaussianModel, linear_observation, linear_transition
from jaxfdi.models._rigid_body import rigid_body_observation, rigid_body_transition

FIELDS = (
    "predicted_mean",
    "predicted_cov",
    "filtered_mean",
    "filtered_cov",
    "innovation",
    "innovation_cov",
    "log_likelihood",
    "nis",
)


def _rel(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def test_sqrt_kf_equals_kf_on_the_engine():
    """Every FilterInfo field within 1e-10 of kalman_filter's (relative to its largest value)."""
    model, ys, us, m0, P0, (final, info) = engine_filtered()
    skf = sqrt_kalman_filter(model)
    got_final, got = run_filter(skf, skf.init(m0, P0), ys, us)
    for name in FIELDS:
        assert _rel(getattr(got, name), getattr(info, name)) < 1e-10, name
    np.testing.assert_array_equal(got.healthy, info.healthy)
    assert _rel(got_final.chol @ got_final.chol.T, final.cov) < 1e-10


@pytest.mark.parametrize("alpha,differences", [(1e-3, "taylor"), (0.5, "direct")])
def test_sqrt_ukf_equals_ukf_on_the_rigid_body(alpha, differences):
    """Rigid-body rates (nonlinear): every field within 1e-10. (With alpha = 1e-3 and
    direct differences both forms carry the UT's own ~1e-10 round-off, differently.)"""
    params, Q, R, ys, us, m0, P0 = rigid_body_data(T=60)
    args = (rigid_body_transition, rigid_body_observation, Q, R, params, alpha)
    ukf = unscented_kalman_filter(*args, sigma_differences=differences)
    sukf = sqrt_unscented_kalman_filter(*args, sigma_differences=differences)
    _, ref = run_filter(ukf, ukf.init(m0, P0), ys, us)
    _, got = run_filter(sukf, sukf.init(m0, P0), ys, us)
    for name in FIELDS:
        assert _rel(getattr(got, name), getattr(ref, name)) < 1e-10, name
    assert bool(got.healthy.all())


def _near_collinear_sensors(delta, dtype):
    """x in R^3 constant, y = [1 1 1; 1 1 1 + delta] x + v, v ~ N(0, delta^2 I), P0 = I:
    in float32, 1 + delta^2 rounds to 1 for delta = 1e-4 and C P C^T + R is singular."""
    C = np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0 + delta]])
    model = LinearGaussianModel(
        *(
            jnp.asarray(a, dtype)
            for a in (
                np.eye(3),
                np.zeros((3, 1)),
                C,
                np.zeros((2, 1)),
                np.zeros((3, 3)),
                delta**2 * np.eye(2),
            )
        )
    )
    rng = np.random.default_rng(0)
    x = rng.normal(size=3)
    ys = np.stack([C @ x + delta * rng.normal(size=2) for _ in range(6)])
    return model, jnp.asarray(ys, dtype), jnp.zeros((6, 1), dtype)


@pytest.mark.parametrize(
    "delta", [1e-4]
)  # 3e-4 fails the standard forms too; one case keeps CI cheap
def test_float32_stiff_case_sqrt_stays_finite(delta):
    """Standard KF and UKF in float32: NaN, unhealthy. Square-root forms: healthy, finite,
    positive semi-definite, and within 1e-2 of the float64 KF (the float32 answer's own
    accuracy: the third state is known to ~delta / (delta * 1) of its prior scale)."""
    model32, ys32, us32 = _near_collinear_sensors(delta, jnp.float32)
    model64, ys64, us64 = _near_collinear_sensors(delta, jnp.float64)
    kf64 = kalman_filter(model64)
    _, truth = run_filter(kf64, kf64.init(jnp.zeros(3), jnp.eye(3)), ys64, us64)
    assert bool(truth.healthy.all())
    prior = (jnp.zeros(3, jnp.float32), jnp.eye(3, dtype=jnp.float32))
    standard = {
        "kf": kalman_filter(model32),
        "ukf": unscented_kalman_filter(
            linear_transition, linear_observation, model32.Q, model32.R, model32
        ),
    }
    square_root = {
        "kf": sqrt_kalman_filter(model32),
        "ukf": sqrt_unscented_kalman_filter(
            linear_transition, linear_observation, model32.Q, model32.R, model32
        ),
    }
    for name in ("kf", "ukf"):
        _, bad = run_filter(standard[name], standard[name].init(*prior), ys32, us32)
        assert not bool(bad.healthy.all()) and not np.all(np.isfinite(bad.filtered_mean)), name
        _, good = run_filter(square_root[name], square_root[name].init(*prior), ys32, us32)
        assert good.filtered_mean.dtype == jnp.float32 and good.filtered_cov.dtype == jnp.float32
        assert bool(good.healthy.all()) and np.all(np.isfinite(good.filtered_cov)), name
        assert np.min(np.linalg.eigvalsh(np.asarray(good.filtered_cov, np.float64))) > -1e-6, name
        np.testing.assert_allclose(good.filtered_mean, truth.filtered_mean, atol=1e-2, err_msg=name)
        np.testing.assert_allclose(good.filtered_cov, truth.filtered_cov, atol=1e-2, err_msg=name)


def test_jit_vmap_gradient_and_bad_input():
    """vmap over runs equals the loop; the driver traces once; the log-likelihood's
    gradient in R equals the standard KF's (QR is differentiable); bad arguments named."""
    model, ys, us, m0, P0, _ = engine_filtered()
    ys = ys[:40]
    us = us[:40]
    skf = sqrt_kalman_filter(model)
    batch = np.stack([ys, ys * 1.01])
    runs = jax.jit(jax.vmap(lambda y: run_filter(skf, skf.init(m0, P0), y, us)[1].filtered_mean))(
        batch
    )
    np.testing.assert_allclose(
        runs[1], run_filter(skf, skf.init(m0, P0), batch[1], us)[1].filtered_mean, rtol=1e-12
    )

    def total(make, scale):
        filt = make(model._replace(R=model.R * scale))
        return jnp.sum(run_filter(filt, filt.init(m0, P0), ys, us)[1].log_likelihood)

    traced = chex.assert_max_traces(lambda s: total(sqrt_kalman_filter, s), n=1)
    grad_sqrt = jax.jit(jax.grad(traced))(1.3)
    grad_kf = jax.grad(lambda s: total(lambda p: kalman_filter(p, unroll_factorizations=False), s))(
        1.3
    )
    np.testing.assert_allclose(grad_sqrt, grad_kf, rtol=1e-8)
    with pytest.raises(ValueError, match="beta"):
        sqrt_unscented_kalman_filter(
            linear_transition, linear_observation, model.Q, model.R, model, alpha=0.5, beta=0.1
        )
    with pytest.raises(TypeError, match="state"):
        skf.step((m0, P0), ys[0], us[0])
    with pytest.raises(ValueError, match="y"):
        skf.step(SqrtGaussianState(m0, P0), ys[0, :3], us[0])
