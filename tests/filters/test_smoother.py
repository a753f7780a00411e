"""RTS smoother, sequential and parallel in time: equal to each other on the engine, and
equal to dense Gaussian conditioning of the whole sequence on a small case (T = 13)."""

import jax.numpy as jnp
import numpy as np
import pytest
from _linear_gaussian_cases import condition, engine_filtered, joint_gaussian, small_model

from jaxfdi.filters import GaussianState, kalman_filter, rts_smoother, run_filter


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(np.asarray(b)))


def test_parallel_equals_sequential_on_the_engine():
    model, *_, (_, info) = engine_filtered()
    sequential, parallel = rts_smoother(model, info), rts_smoother(model, info, parallel=True)
    assert _rel(parallel.mean, sequential.mean) < 1e-9 and _rel(parallel.cov, sequential.cov) < 1e-9
    assert _rel(parallel.gain, sequential.gain) < 1e-9
    # the last step is the filtered one; smoothing shrinks the variances
    np.testing.assert_array_equal(sequential.mean[-1], info.filtered_mean[-1])
    assert np.all(
        np.diagonal(sequential.cov, axis1=1, axis2=2)
        <= np.diagonal(info.filtered_cov, axis1=1, axis2=2) * (1 + 1e-12)
    )


@pytest.mark.parametrize("parallel", [False, True])
def test_smoother_equals_dense_conditioning(parallel):
    """N(x_k | y_0..y_{T-1}) of the joint Gaussian by one dense solve, from the
    sequential and from the parallel filter's outputs."""
    model, T = small_model(), 13
    rng = np.random.default_rng(6)
    us, ys = rng.normal(size=(T, 1)), rng.normal(size=(T, 2)) * 2.0
    m0, P0 = np.array([0.3, -0.1, 0.2]), np.diag([0.5, 0.4, 0.3])
    mean, cov, _ = condition(joint_gaussian(model, m0, P0, us, T), ys)
    kf = kalman_filter(model)
    infos = (
        run_filter(kf, kf.init(m0, P0), ys, us)[1],
        run_filter(
            kalman_filter(model, missing_measurements=True),
            GaussianState(jnp.asarray(m0), jnp.asarray(P0)),
            ys,
            us,
            parallel=True,
        )[1],
    )
    for info in infos:
        result = rts_smoother(model, info, parallel=parallel)
        np.testing.assert_allclose(result.mean, mean.reshape(T, 3), rtol=1e-9, atol=1e-12)
        blocks = np.stack([cov[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] for k in range(T)])
        np.testing.assert_allclose(result.cov, blocks, rtol=1e-9, atol=1e-12)


def test_bad_input():
    model, T = small_model(), 13
    _, info = run_filter(
        kalman_filter(model, missing_measurements=True),
        GaussianState(jnp.zeros(3), jnp.eye(3)),
        np.zeros((T, 2)),
        np.zeros((T, 1)),
        parallel=True,
    )
    with pytest.raises(TypeError, match="info"):
        rts_smoother(model, (info.filtered_mean, info.filtered_cov))
    with pytest.raises(ValueError, match="info.filtered_cov"):
        rts_smoother(model, info._replace(filtered_cov=info.filtered_cov[:, :2]), parallel=True)
    with pytest.raises(TypeError, match="^parallel: expected True or False"):
        rts_smoother(model, info, parallel=1)
