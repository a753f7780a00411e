"""LQR-PI against SciPy's DARE and the textbook gain (u = -K x, SciPy/MATLAB's sign), and
eigenstructure assignment: the faulty closed loop
keeps the nominal eigenvalues (1e-8), the eigenvectors are the eq. 26 projections, the
gain is real, and a dead actuator gets a zero row."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg as sl

from jaxfdi.control import (
    assign_eigenstructure,
    integral_augmentation,
    lqr_gain,
    lqr_pi,
    nominal_eigenstructure,
)
from jaxfdi.control._eigenstructure import effectiveness_input
from jaxfdi.models import _vtol as vtol

H_PAPER = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0]])  # v_h and q (seed 001, eq. 35)
H_ANGLE = np.array([[1.0, 0, 0, 0], [0, 0, 0, 1]])  # v_h and theta: stabilisable
Q_PI, R_PI = np.diag([1.0, 1, 1, 1, 10, 10]), np.eye(2)


@pytest.fixture(scope="module")
def model():
    return vtol.vtol_model()


def _scipy_gain(A, B, Q, R):
    """SciPy's DARE and the textbook gain ``K = (R + B^T X B)^-1 B^T X A``, ``u = -K x``."""
    A, B = np.asarray(A), np.asarray(B)
    X = sl.solve_discrete_are(A, B, Q, R)
    return np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A), X


def test_lqr_gain_equals_scipy(model):
    K, X, converged = lqr_gain(model.Phi, model.Gamma, np.eye(4), np.eye(2))
    K_ref, X_ref = _scipy_gain(model.Phi, model.Gamma, np.eye(4), np.eye(2))
    assert bool(converged)
    np.testing.assert_allclose(X, X_ref, rtol=1e-9)
    np.testing.assert_allclose(K, K_ref, rtol=1e-9, atol=1e-12)


def test_lqr_gain_sign_is_u_minus_K_x(model):
    """``u = -K x`` stabilises the open-loop unstable VTOL and attains the cost
    ``x0^T X x0`` (summed over a long simulated horizon); ``u = +K x`` diverges."""
    A, B = np.asarray(model.Phi), np.asarray(model.Gamma)
    assert np.max(np.abs(np.linalg.eigvals(A))) > 1.0
    K, X, _ = (np.asarray(a) for a in lqr_gain(A, B, np.eye(4), np.eye(2)))
    assert np.max(np.abs(np.linalg.eigvals(A - B @ K))) < 1.0
    assert np.max(np.abs(np.linalg.eigvals(A + B @ K))) > 1.0
    x0 = np.array([1.0, -0.5, 0.2, 0.3])
    x, cost = x0, 0.0
    for _ in range(2000):
        u = -K @ x
        cost += x @ x + u @ u
        x = A @ x + B @ u
    np.testing.assert_allclose(cost, x0 @ X @ x0, rtol=1e-9)


def test_lqr_pi_equals_scipy_on_the_augmented_system(model):
    design = lqr_pi(model.Phi, model.Gamma, H_ANGLE, Q_PI, R_PI, vtol.TS)
    K_ref, _ = _scipy_gain(design.A_bar, design.B_bar, Q_PI, R_PI)
    np.testing.assert_allclose(design.gain, K_ref, rtol=1e-9, atol=1e-11)
    assert float(design.spectral_radius) < 1.0
    closed = np.asarray(design.A_bar) - np.asarray(design.B_bar) @ K_ref  # u = -K [x; z]
    np.testing.assert_allclose(
        float(design.spectral_radius), np.max(np.abs(np.linalg.eigvals(closed))), rtol=1e-9
    )
    # eq. 21 blocks
    np.testing.assert_allclose(design.A_bar[4:, :4], -vtol.TS * H_ANGLE)
    np.testing.assert_allclose(design.G[4:], vtol.TS * np.eye(2))


def test_paper_pi_design_keeps_an_eigenvalue_at_one(model):
    """Tracking the pitch rate puts a plant zero at z = 1: no stabilising gain exists
    (SciPy refuses: SciPy < 1.17 raises, 1.17 returns a gain whose closed loop keeps an
    eigenvalue within 1e-6 of 1), and the design reports a closed-loop eigenvalue at 1."""
    rosenbrock = np.block(
        [[np.asarray(model.Phi) - np.eye(4), np.asarray(model.Gamma)], [H_PAPER, np.zeros((2, 2))]]
    )
    assert abs(np.linalg.det(rosenbrock)) < 1e-15
    A_bar, B_bar = (
        np.asarray(m) for m in integral_augmentation(model.Phi, model.Gamma, H_PAPER, vtol.TS)[:2]
    )
    try:
        K_ref, _ = _scipy_gain(A_bar, B_bar, Q_PI, R_PI)
    except (ValueError, np.linalg.LinAlgError):
        pass  # SciPy < 1.17: LinAlgError ("eigenvalues too close to the unit circle")
    else:
        assert np.min(np.abs(np.linalg.eigvals(A_bar - B_bar @ K_ref) - 1.0)) < 1e-6
    design = lqr_pi(model.Phi, model.Gamma, H_PAPER, Q_PI, R_PI, vtol.TS)
    assert abs(float(design.spectral_radius) - 1.0) < 1e-9


def test_the_papers_pitch_rate_command_has_no_steady_state(model):
    """Why the paper's loop cannot track ``r = [-50, -5]`` (issue 38): a PI loop that
    tracks ``r`` settles at an equilibrium ``(x, u)`` with ``x = Phi x + Gamma u`` and
    ``H x = r``. That linear system ``[[Phi - I, Gamma], [H, 0]] [x; u] = [0; r]`` has a
    solution only if ``w . [0; r] = 0`` for its left null vector ``w``; for ``H = (v_h, q)``
    that vector's command part is the q axis (theta integrates q: a constant pitch rate
    needs a ramping pitch angle), so every ``r_q != 0`` is out of reach and only
    ``r_q = 0`` can be held. Tracking theta instead reaches every command. Reference:
    SciPy's SVD and least squares on the same matrices."""
    Phi, Gamma = np.asarray(model.Phi), np.asarray(model.Gamma)
    for H, reachable in ((H_PAPER, False), (H_ANGLE, True)):
        M = np.block([[Phi - np.eye(4), Gamma], [H, np.zeros((2, 2))]])
        U, s, _ = sl.svd(M)
        for r in (np.array([-50.0, -5.0]), np.array([-50.0, 0.0])):
            rhs = np.r_[np.zeros(4), r]
            solution, *_ = sl.lstsq(M, rhs)
            residual = np.linalg.norm(M @ solution - rhs)
            if reachable or r[1] == 0.0:
                assert residual < 1e-9 * np.linalg.norm(r), (H, r, residual)
            else:
                # the residual is exactly the command's component along w
                w = U[:, -1]
                assert s[-1] < 1e-15 * s[0]
                assert abs(w[4]) < 1e-12 and abs(w[5]) > 0.09  # w's command part: q only
                np.testing.assert_allclose(residual, abs(w @ rhs), rtol=1e-6)
                assert residual > 0.45  # 5 * |w_q|: no equilibrium


LOSSES = {
    "none": [0.0, 0.0],
    "a1 0.5": [0.5, 0.0],
    "a2 0.5": [0.0, 0.5],
    "both": [0.2, 0.3],
    "a1 dead": [1.0, 0.0],
    "a2 dead": [0.0, 1.0],
}


@pytest.mark.parametrize("H", [H_PAPER, H_ANGLE], ids=["paper (v_h, q)", "(v_h, theta)"])
@pytest.mark.parametrize("loss", list(LOSSES))
def test_eigenstructure_assignment_keeps_the_nominal_eigenvalues(model, H, loss):
    design = lqr_pi(model.Phi, model.Gamma, H, Q_PI, R_PI, vtol.TS)
    lam, V = nominal_eigenstructure(design.A_bar, design.B_bar, design.gain)
    B_f = effectiveness_input(design.B_bar, jnp.asarray(LOSSES[loss]))
    result = jax.jit(assign_eigenstructure)(design.A_bar, B_f, lam, V)
    closed = np.asarray(design.A_bar - B_f @ result.gain)  # u = -K_f x
    eig = np.linalg.eigvals(closed)
    dead = [j for j, value in enumerate(LOSSES[loss]) if value == 1.0]
    for j in dead:
        np.testing.assert_allclose(result.gain[j], 0.0, atol=1e-10)
    if dead and H is H_ANGLE:
        # one input cannot hold two integrators: (A_bar, B_f) loses rank at z = 1, V^f is
        # singular, and the result says so: an eigenvalue at 1, a flagged residual
        assert np.all(np.isfinite(np.asarray(result.gain)))
        assert float(result.eigenvector_matrix_cond) > 1e12
        assert np.min(np.abs(eig - 1.0)) < 1e-8
        assert float(jnp.max(result.assignment_residual)) > 1e-2
        return
    np.testing.assert_allclose(result.assignment_residual, 0.0, atol=1e-9)
    # every nominal eigenvalue is an eigenvalue of the faulty loop, with eigenvector v_i^f
    for i, lam_i in enumerate(lam):
        assert np.min(np.abs(eig - lam_i)) < 1e-8, f"{loss}: eigenvalue {lam_i} moved"
        v = np.asarray(result.eigenvectors[:, i])
        assert np.linalg.norm(closed @ v - lam_i * v) < 1e-8 * max(1.0, np.linalg.norm(v))
    assert float(result.gain_imaginary) < 1e-10
    if loss == "none":
        np.testing.assert_allclose(result.gain, design.gain, atol=1e-10)


@pytest.mark.parametrize("loss", ["a1 0.5", "a2 0.5", "both"])
def test_eigenvectors_are_the_eq26_projections(model, loss):
    """Where lambda_i is not an eigenvalue of A_bar, v_i^f = E_i (E_i^H E_i)^-1 E_i^H v_i
    with E_i = (lambda_i I - A_bar)^-1 B_f (NumPy, independent of the SVD route)."""
    design = lqr_pi(model.Phi, model.Gamma, H_ANGLE, Q_PI, R_PI, vtol.TS)
    lam, V = nominal_eigenstructure(design.A_bar, design.B_bar, design.gain)
    B_f = np.asarray(effectiveness_input(design.B_bar, jnp.asarray(LOSSES[loss])))
    result = assign_eigenstructure(design.A_bar, B_f, lam, V)
    A_bar = np.asarray(design.A_bar)
    for i, lam_i in enumerate(lam):
        E = np.linalg.solve(lam_i * np.eye(6) - A_bar, B_f)
        projected = E @ np.linalg.solve(E.conj().T @ E, E.conj().T @ V[:, i])
        np.testing.assert_allclose(np.asarray(result.eigenvectors[:, i]), projected, atol=1e-9)
    # the projection is the closest admissible vector: the residual is orthogonal to span(E_i)
    # (checked above by equality), and K_f agrees with the paper's eq. 29 (B_f full rank)
    Vf = np.asarray(result.eigenvectors)
    K29 = (
        -np.linalg.pinv(B_f) @ (Vf @ np.diag(lam) - A_bar @ Vf) @ np.linalg.inv(Vf)
    )  # the paper's u = K x, negated
    np.testing.assert_allclose(np.asarray(result.gain), K29.real, atol=1e-8)


def test_bad_shapes(model):
    design = lqr_pi(model.Phi, model.Gamma, H_ANGLE, Q_PI, R_PI, vtol.TS)
    lam, V = nominal_eigenstructure(design.A_bar, design.B_bar, design.gain)
    with pytest.raises(ValueError, match="B_faulty"):
        assign_eigenstructure(design.A_bar, np.zeros((5, 2)), lam, V)
    with pytest.raises(ValueError, match="H"):
        lqr_pi(model.Phi, model.Gamma, np.eye(3), Q_PI, R_PI, vtol.TS)
    with pytest.raises(ValueError, match="Q"):
        lqr_pi(model.Phi, model.Gamma, H_ANGLE, np.eye(4), R_PI, vtol.TS)
