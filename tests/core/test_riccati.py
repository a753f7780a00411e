"""DARE by doubling against scipy.linalg.solve_discrete_are; the steady-state KF against
jaxfdi's time-varying KF run from the steady-state prior."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import jaxfdi
from jaxfdi import steady_state_kalman
from jaxfdi._numerics.riccati import solve_discrete_are, solve_discrete_are_info
from jaxfdi.models import engine_model

RTOL = 1e-9


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(np.asarray(b)))


def _random_problems():
    """Fixed-seed stabilisable problems: unstable filter-shaped (A = Phi^T, B = C^T),
    a general one, and an LQR-shaped one (Q = C^T C of rank 2, p = 2 inputs)."""
    rng = np.random.default_rng(3)
    problems = {}
    Phi = rng.normal(size=(4, 4))
    Phi *= 1.2 / np.max(np.abs(np.linalg.eigvals(Phi)))  # unstable: the gain must stabilise it
    C = rng.normal(size=(2, 4))
    M = rng.normal(size=(4, 4))
    problems["filter"] = (Phi.T, C.T, M @ M.T + 0.1 * np.eye(4), np.diag([0.5, 2.0]))
    A = rng.normal(size=(5, 5)) / 2
    B = rng.normal(size=(5, 3))
    N = rng.normal(size=(3, 3))
    problems["general"] = (A, B, np.eye(5), N @ N.T + np.eye(3))
    A = np.eye(6) + 0.1 * rng.normal(size=(6, 6))  # a discretised, marginally unstable plant
    B = 0.1 * rng.normal(size=(6, 2))
    Cq = rng.normal(size=(2, 6))
    problems["lqr"] = (A, B, Cq.T @ Cq, np.diag([1.0, 0.1]))
    return problems


PROBLEMS = _random_problems()


@pytest.fixture(scope="module")
def engine():
    model = engine_model()
    return model, steady_state_kalman(model)


@pytest.fixture(scope="module")
def solve_jit():
    return jax.jit(solve_discrete_are_info)


def riccati_residual(A, B, Q, R, X):
    gain = np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)
    return A.T @ X @ A - A.T @ X @ B @ gain + Q - X


def test_engine_filter_riccati_equals_scipy(engine):
    model, steady = engine
    Phi, C, Q, R = (np.asarray(a) for a in (model.Phi, model.C, model.Q, model.R))
    reference = scipy.linalg.solve_discrete_are(Phi.T, C.T, Q, R)
    assert bool(steady.converged)
    assert _rel(steady.predicted_cov, reference) < RTOL
    S = C @ reference @ C.T + R
    assert _rel(steady.innovation_cov, S) < RTOL
    assert _rel(steady.gain, reference @ C.T @ np.linalg.inv(S)) < RTOL
    X = np.asarray(steady.predicted_cov)
    assert np.max(np.abs(riccati_residual(Phi.T, C.T, Q, R, X))) < 1e-11 * np.max(np.abs(X))


@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_random_problems_equal_scipy(name, solve_jit):
    A, B, Q, R = PROBLEMS[name]
    result = solve_jit(A, B, Q, R)
    reference = scipy.linalg.solve_discrete_are(A, B, Q, R)
    assert bool(result.converged) and int(result.iterations) < 64
    assert _rel(result.solution, reference) < RTOL
    X = np.asarray(result.solution)
    assert np.max(np.abs(riccati_residual(A, B, Q, R, X))) < 1e-11 * np.max(np.abs(X))
    np.testing.assert_allclose(X, X.T, atol=1e-12 * np.max(np.abs(X)))
    # stabilising: the closed loop A - B (R + B^T X B)^-1 B^T X A has spectral radius < 1
    closed = A - B @ np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)
    assert np.max(np.abs(np.linalg.eigvals(closed))) < 1.0


def test_kalman_from_steady_state_prior_stays_there(engine):
    model, steady = engine
    T = 40  # the covariance recursion does not look at the data: any ys will do
    ys = np.random.default_rng(0).normal(size=(T, 5)) * np.sqrt(np.diag(np.asarray(model.R)))
    us = np.full((T, 1), 0.01)
    kf = jaxfdi.filters.kalman_filter(model)
    _, info = jaxfdi.filters.run_filter(kf, kf.init(jnp.zeros(7), steady.predicted_cov), ys, us)
    P = np.asarray(steady.predicted_cov)
    assert max(_rel(Pk, P) for Pk in np.asarray(info.predicted_cov)) < RTOL
    assert max(_rel(Sk, steady.innovation_cov) for Sk in np.asarray(info.innovation_cov)) < RTOL


def test_vmap_and_float32(solve_jit):
    A, B, Q, R = PROBLEMS["general"]
    scales = jnp.array([0.5, 1.0, 2.0])
    batch = jax.vmap(lambda s: solve_discrete_are(A, B, s * Q, R))(scales)
    for s, X in zip(np.asarray(scales), np.asarray(batch)):
        assert _rel(X, scipy.linalg.solve_discrete_are(A, B, s * Q, R)) < RTOL
    args32 = [np.asarray(a, np.float32) for a in (A, B, Q, R)]
    result = solve_discrete_are_info(*args32)
    assert result.solution.dtype == jnp.float32 and bool(result.converged)
    assert np.all(np.isfinite(np.asarray(result.solution)))
    assert _rel(result.solution, scipy.linalg.solve_discrete_are(A, B, Q, R)) < 1e-4


@pytest.mark.parametrize(
    "args, name",
    [
        ((np.ones((3, 2)), np.ones((3, 1)), np.eye(3), np.eye(1)), "A"),
        ((np.eye(3), np.ones((2, 1)), np.eye(3), np.eye(1)), "B"),
        ((np.eye(3), np.ones((3, 1)), np.eye(2), np.eye(1)), "Q"),
        ((np.eye(3), np.ones((3, 2)), np.eye(3), np.eye(1)), "R"),
    ],
)
def test_bad_shapes_name_the_argument(args, name):
    with pytest.raises(ValueError, match=rf"^{name}:"):
        solve_discrete_are(*args)
    with pytest.raises(ValueError, match="max_iter"):
        solve_discrete_are(np.eye(2), np.eye(2), np.eye(2), np.eye(2), max_iter=0)
