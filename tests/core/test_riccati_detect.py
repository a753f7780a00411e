"""Riccati solvers that know when there is no answer, and their derivatives (issue 22).

Detection: a DARE without a stabilising solution — an unstable mode that ``B`` cannot
reach, or (the filter form) an unstable plant seen by ``C = 0`` — gives
``converged = False`` with the closed-loop spectral radius of the uncontrollable mode,
stops at the first overflow instead of running 64 doubling steps, and makes
``solve_discrete_are``, ``steady_state_kalman`` and ``lqr_gain`` raise a ``ValueError``
naming their arguments (concrete inputs); under ``jit``/``vmap`` the flag comes back
instead. The reference for the radius is the uncontrollable eigenvalue itself, which no
gain can move; SciPy refuses these problems too. The solvable problems of
``test_riccati.py`` keep their solutions, with a residual at round-off and SciPy's
closed-loop spectral radius.

Derivatives: the DARE solution, the LQR gain and the steady-state Kalman gain,
differentiated implicitly (a Stein equation in the closed loop), against central
differences of SciPy's ``solve_discrete_are`` (an independent solver), and forward mode
against reverse mode, along random directions (symmetric ones for Q and R).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from test_riccati import PROBLEMS

import jaxfdi
from jaxfdi import steady_state_kalman
from jaxfdi._numerics.riccati import solve_discrete_are, solve_discrete_are_info
from jaxfdi.control import integral_augmentation, lqr_gain, lqr_pi
from jaxfdi.models import _vtol as vtol

#: an unstable mode (1.5) that the input cannot reach
NOT_STABILISABLE = (np.diag([1.5, 0.5]), np.array([[0.0], [1.0]]), np.eye(2), np.eye(1))
#: an unstable plant (eigenvalue 1.1) measured by nothing: (C, Phi) not detectable
BLIND = jaxfdi.models.linear_gaussian_model(
    np.array([[1.1, 0.1], [0.0, 0.9]]), np.zeros((1, 2)), np.eye(2), np.eye(1)
)


def test_non_stabilisable_is_detected():
    result = solve_discrete_are_info(*NOT_STABILISABLE)
    assert not bool(result.converged)
    assert int(result.iterations) < 20  # stopped at the overflow, not after 64 steps
    np.testing.assert_allclose(result.spectral_radius, 1.5, rtol=1e-9)  # the mode B cannot move
    assert float(result.residual) > 1e-3
    with pytest.raises(ValueError, match=r"^A, B, Q, R: no stabilising solution.*not stabilisable"):
        solve_discrete_are(*NOT_STABILISABLE)
    with pytest.raises(
        ValueError, match=r"^A, B, Q, R: no stabilising solution.*spectral radius 1\.5"
    ):
        lqr_gain(*NOT_STABILISABLE)
    with pytest.raises((ValueError, np.linalg.LinAlgError)):  # SciPy has no answer either
        scipy.linalg.solve_discrete_are(*NOT_STABILISABLE)


def test_undetectable_filter_is_detected():
    Phi, C, Q, R = (np.asarray(a) for a in (BLIND.Phi, BLIND.C, BLIND.Q, BLIND.R))
    result = solve_discrete_are_info(Phi.T, C.T, Q, R)
    assert not bool(result.converged) and int(result.iterations) < 20
    np.testing.assert_allclose(result.spectral_radius, 1.1, rtol=1e-9)
    with pytest.raises(
        ValueError,
        match=r"^model\.Phi, model\.C, model\.Q: no stabilising solution.*not detectable",
    ):
        steady_state_kalman(BLIND)
    # under jit the flag comes back instead of an error
    steady = jax.jit(steady_state_kalman)(BLIND)
    assert not bool(steady.converged)
    np.testing.assert_allclose(steady.spectral_radius, 1.1, rtol=1e-9)


def test_vmap_flags_each_problem():
    """One stabilisable and one non-stabilisable problem in a batch: a flag each, no error."""
    A, B, Q, R = NOT_STABILISABLE
    reachable = np.array([[1.0], [1.0]])
    batch = jax.vmap(solve_discrete_are_info)(
        np.stack([A, A]), np.stack([reachable, B]), np.stack([Q, Q]), np.stack([R, R])
    )
    np.testing.assert_array_equal(batch.converged, [True, False])
    np.testing.assert_allclose(
        batch.solution[0], scipy.linalg.solve_discrete_are(A, reachable, Q, R), rtol=1e-9
    )
    np.testing.assert_allclose(batch.spectral_radius[1], 1.5, rtol=1e-9)


def test_a_solvable_problem_keeps_its_solution_and_reports_it():
    """(All of test_riccati.py's problems keep SciPy's solution there.)"""
    A, B, Q, R = PROBLEMS["general"]
    result = solve_discrete_are_info(A, B, Q, R)
    X = scipy.linalg.solve_discrete_are(A, B, Q, R)
    K = np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)
    assert bool(result.converged)
    assert float(result.residual) < 1e-13
    np.testing.assert_allclose(result.solution, X, rtol=1e-9, atol=1e-12 * np.max(np.abs(X)))
    np.testing.assert_allclose(
        result.spectral_radius, np.max(np.abs(np.linalg.eigvals(A - B @ K))), rtol=1e-9
    )
    np.testing.assert_allclose(
        solve_discrete_are(A, B, Q, R), X, rtol=1e-9, atol=1e-12 * np.max(np.abs(X))
    )


def test_steady_state_reports_its_residual_and_error_dynamics():
    """``BLIND`` with its unstable state measured: detectable, so the filter exists."""
    model = BLIND._replace(C=np.array([[1.0, 0.0]]))
    steady = steady_state_kalman(model)
    Phi, C, Q, R = (np.asarray(a) for a in (model.Phi, model.C, model.Q, model.R))
    P = scipy.linalg.solve_discrete_are(Phi.T, C.T, Q, R)
    assert bool(steady.converged) and float(steady.residual) < 1e-13
    np.testing.assert_allclose(steady.predicted_cov, P, rtol=1e-10)
    error_dynamics = Phi @ (np.eye(2) - np.asarray(steady.gain) @ C)
    np.testing.assert_allclose(
        steady.spectral_radius, np.max(np.abs(np.linalg.eigvals(error_dynamics))), rtol=1e-9
    )
    assert float(steady.spectral_radius) < 1.0


def test_paper_pi_design_is_marginal_not_refused():
    """The (v_h, q) design of seed 001 keeps an uncontrollable closed-loop eigenvalue at
    z = 1 (test_control.py): ``lqr_pi`` returns it flagged (``converged = False``,
    ``spectral_radius = 1``); ``lqr_gain`` on the same augmented system refuses it unless
    ``allow_marginal``."""
    model = vtol.vtol_model()
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0]])
    Q, R = np.diag([1.0, 1, 1, 1, 10, 10]), np.eye(2)
    design = lqr_pi(model.Phi, model.Gamma, H, Q, R, vtol.TS)
    assert not bool(design.converged)
    assert abs(float(design.spectral_radius) - 1.0) < 1e-9
    A_bar, B_bar, _ = integral_augmentation(model.Phi, model.Gamma, H, vtol.TS)
    with pytest.raises(ValueError, match="no stabilising solution"):
        lqr_gain(A_bar, B_bar, Q, R)
    K, _, converged = lqr_gain(A_bar, B_bar, Q, R, allow_marginal=True)
    np.testing.assert_allclose(K, design.gain, rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="no stabilising solution"):
        lqr_pi(model.Phi, model.Gamma, H, Q, R, vtol.TS, allow_marginal=False)


# --- derivatives ---------------------------------------------------------------------


def _directions(rng, A, B, Q, R):
    def sym(n):
        a = rng.normal(size=(n, n))
        return 0.5 * (a + a.T)

    return (
        0.1 * rng.normal(size=A.shape) * np.max(np.abs(A)),
        0.1 * rng.normal(size=B.shape) * np.max(np.abs(B)),
        0.1 * sym(Q.shape[0]) * np.max(np.abs(Q)),
        0.1 * sym(R.shape[0]) * np.min(np.diag(R)),
    )


def _central(f, args, direction, step=1e-5):
    plus = f(*(a + step * d for a, d in zip(args, direction)))
    minus = f(*(a - step * d for a, d in zip(args, direction)))
    return (plus - minus) / (2 * step)


def _scipy_kalman_gain(Phi, C, Q, R):
    P = scipy.linalg.solve_discrete_are(Phi.T, C.T, Q, R)
    return P @ C.T @ np.linalg.inv(C @ P @ C.T + R)


def _kalman_gain(Phi, C, Q, R):
    model = jaxfdi.models.LinearGaussianModel(
        Phi, jnp.zeros((Phi.shape[0], 1)), C, jnp.zeros((C.shape[0], 1)), Q, R
    )
    return steady_state_kalman(model).gain


def _scipy_lqr(A, B, Q, R):
    X = scipy.linalg.solve_discrete_are(A, B, Q, R)
    return np.concatenate([X, np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)])


def _lqr(A, B, Q, R):
    K, X, _ = lqr_gain(A, B, Q, R)
    return jnp.concatenate([X, K])


CASES = {  # (ours, SciPy's, arguments): X stacked over K for the LQR; the Kalman gain
    "lqr X and K": (_lqr, _scipy_lqr, PROBLEMS["lqr"]),
    "kalman gain": (
        _kalman_gain,
        _scipy_kalman_gain,
        (PROBLEMS["filter"][0].T, PROBLEMS["filter"][1].T) + PROBLEMS["filter"][2:],
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_derivatives_equal_central_differences_of_scipy(name):
    ours, reference, args = CASES[name]
    args = tuple(np.asarray(a, np.float64) for a in args)
    rng = np.random.default_rng(7)
    direction = _directions(rng, *args)
    value, forward = jax.jvp(
        ours, tuple(jnp.asarray(a) for a in args), tuple(jnp.asarray(d) for d in direction)
    )
    np.testing.assert_allclose(
        value, reference(*args), rtol=1e-8, atol=1e-11 * np.max(np.abs(value))
    )
    central = _central(reference, args, direction)
    scale = np.max(np.abs(central))
    np.testing.assert_allclose(forward, central, rtol=0, atol=1e-6 * scale)
    # reverse mode: <W, J d> from the vjp equals the same product from the jvp
    weights = rng.normal(size=np.shape(value))
    _, pullback = jax.vjp(ours, *(jnp.asarray(a) for a in args))
    cotangents = pullback(jnp.asarray(weights))
    reverse = sum(np.sum(np.asarray(c) * d) for c, d in zip(cotangents, direction))
    np.testing.assert_allclose(
        reverse,
        np.sum(weights * np.asarray(forward)),
        rtol=1e-10,
        atol=1e-12 * np.sum(np.abs(weights * np.asarray(forward))),
    )


def test_gradient_under_jit_and_vmap():
    """``grad`` of an LQR cost through ``jit`` and ``vmap`` over weights, against central
    differences of SciPy (no error raised on traced inputs)."""
    A, B, Q, R = PROBLEMS["lqr"]
    x0 = np.linspace(1.0, -1.0, A.shape[0])

    def cost(scale):
        return x0 @ solve_discrete_are(A, B, scale * Q, R) @ x0

    grads = jax.jit(jax.vmap(jax.grad(cost)))(jnp.array([0.5, 2.0]))
    for s, g in zip((0.5, 2.0), np.asarray(grads)):
        step = 1e-6
        central = (
            x0 @ scipy.linalg.solve_discrete_are(A, B, (s + step) * Q, R) @ x0
            - x0 @ scipy.linalg.solve_discrete_are(A, B, (s - step) * Q, R) @ x0
        ) / (2 * step)
        np.testing.assert_allclose(g, central, rtol=1e-7)
