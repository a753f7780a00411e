"""Discrete LQR and proportional-integral state feedback (Lee & Lyou, eqs. 21-22).

Integral action: ``z[k+1] = z[k] + Ts e``, ``e = r - H x``; the augmented ``x_a = [x; z]``::

    x_a[k+1] = A_bar x_a[k] + B_bar u[k] + G r[k],
    A_bar = [[A, 0], [-Ts H, I]],  B_bar = [B; 0],  G = [0; Ts I]

is stabilised by ``u = -K x_a = -[K_p K_I] x_a``, ``K = (R + B^T X B)^-1 B^T X A``, ``X`` the stabilising
DARE solution (``jaxfdi._numerics.riccati``, structure-preserving doubling, verified by residual and closed-loop
spectral radius). Sign: ``u = -K x``, closed loop ``A - B K`` (SciPy ``place_poles``, MATLAB and
python-control ``dlqr``); Lee and Lyou's ``u = K x`` has the negative ``K``.

A stabilising gain needs no transmission zero of ``(A, B, H)`` at ``z = 1``. The paper's VTOL choice
(track ``v_h`` and ``q = d theta / dt``) has one (the derivative's zero at ``s = 0``), so one closed-loop
eigenvalue stays at exactly 1 (SciPy's ``solve_discrete_are`` refuses it): a constant pitch-rate command
ramps the pitch angle, with no divergence elsewhere (``lqr_pi``'s ``allow_marginal``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics.riccati import DareSolution, require_stabilising, solve_discrete_are_info

#: why an LQR design has no stabilising solution
_NOT_STABILISABLE = (
    "(A, B) is not stabilisable or (Q, A) has an unobservable mode on the unit circle"
)
_PI_NOT_STABILISABLE = (
    "(A_bar, B_bar) is not stabilisable ((A, B) is not, or (A, B, H) has a zero at z = 1) or "
    "(Q, A_bar) has an unobservable mode on the unit circle"
)


class PIDesign(NamedTuple):
    """A proportional-integral LQR design on the integrator-augmented system.

    Attributes:
      A_bar: (n + g, n + g) state matrix of the integrator-augmented system
      B_bar: (n + g, p) input matrix of the integrator-augmented system
      G: (n + g, g) command input of the integrator
      gain: (p, n + g) K = [K_p K_I]; the control is u = -K [x; z] (closed loop A_bar - B_bar K)
      riccati: (n + g, n + g) X, the DARE solution
      converged: () bool: a verified stabilising Riccati solution (False for a marginal design)
      spectral_radius: () max |eig(A_bar - B_bar K)|: >= 1 means no stabilising gain exists
    """

    A_bar: Array
    B_bar: Array
    G: Array
    gain: Array
    riccati: Array
    converged: Array
    spectral_radius: Array


def lqr_gain(
    A: Array, B: Array, Q: Array, R: Array, allow_marginal: bool = False
) -> tuple[Array, Array, Array]:
    """Discrete LQR: ``(K, X, converged)`` with ``u = -K x`` (SciPy/MATLAB sign).

    ``K = (R + B^T X B)^-1 B^T X A`` minimises ``sum x^T Q x + u^T R u`` for ``x[k+1] = A x + B u``, ``X``
    the stabilising solution of ``X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q`` (Lewis, Vrabie &
    Syrmos 2012, sec. 2.4). Differentiable in ``A, B, Q, R``, forward and reverse (implicit DARE).

    Args:
      A: (n, n) discrete state matrix.
      B: (n, p) input matrix.
      Q: (n, n) state weight (positive semi-definite).
      R: (p, p) input weight (positive definite).
      allow_marginal: accept a closed-loop eigenvalue on the unit circle (an uncontrollable mode at
        ``|z| = 1``; ``converged`` then False).

    Returns:
      ``K`` (p, n), ``X`` (n, n), ``converged`` (a verified stabilising solution).

    Raises:
      ValueError: with concrete arguments, no stabilising solution (``(A, B)`` not stabilisable or
        ``(Q, A)`` unobservable on the unit circle); under ``jit``/``vmap``: check ``converged``.
    """
    solution, K = _lqr(A, B, Q, R)
    require_stabilising(solution, (A, B, Q, R), "A, B, Q, R", _NOT_STABILISABLE, allow_marginal)
    return K, solution.solution, solution.converged


def _lqr(A: Array, B: Array, Q: Array, R: Array) -> tuple[DareSolution, Array]:
    solution = solve_discrete_are_info(A, B, Q, R)
    X = solution.solution
    A, B, R = (jnp.asarray(a, X.dtype) for a in (A, B, R))
    return solution, jnp.linalg.solve(R + B.T @ X @ B, B.T @ X @ A)


def integral_augmentation(A: Array, B: Array, H: Array, Ts: float) -> tuple[Array, Array, Array]:
    """``(A_bar, B_bar, G)`` of eq. 21 for tracking ``r = H x`` with integral action.

    Returns:
      ``(A_bar, B_bar, G)`` in ``A``'s dtype (module doc): (n + g, n + g), (n + g, p), (n + g, g), ``g`` the
      rows of ``H``.
    """
    n = checks.check_square("A", A, None, "discrete state matrix")
    checks.check_shape("B", B, (n, None), "n states x p inputs")
    checks.check_shape("H", H, (None, n), "g tracked outputs x n states")
    g = checks.shape_of(H)[0]
    checks.check_positive("Ts", Ts, "a positive sample time")
    A, B, H = (jnp.asarray(a) for a in (A, B, H))
    eye = jnp.eye(g, dtype=A.dtype)
    A_bar = jnp.block([[A, jnp.zeros((n, g), A.dtype)], [-Ts * H, eye]])
    B_bar = jnp.concatenate([B, jnp.zeros((g, B.shape[1]), A.dtype)])
    G = jnp.concatenate([jnp.zeros((n, g), A.dtype), Ts * eye])
    return A_bar, B_bar, G


def lqr_pi(
    A: Array, B: Array, H: Array, Q: Array, R: Array, Ts: float, allow_marginal: bool = True
) -> PIDesign:
    """LQR-PI design of eqs. 21-22: ``Q`` (n + g, n + g), ``R`` (p, p).

    Control ``u = -design.gain @ [x; z]`` (the paper's eq. 22 ``u = K [x; z]`` uses ``-design.gain``).
    ``allow_marginal`` (default True, for the paper's design): an uncontrollable closed-loop eigenvalue on the unit
    circle (plant zero at ``z = 1``) returns ``converged = False``, ``spectral_radius = 1``; no closed loop of spectral
    radius <= 1 raises ``ValueError`` (concrete arguments; under ``jit`` check ``converged`` and ``spectral_radius``).

    Returns:
      ``PIDesign``: ``A_bar``, ``B_bar``, ``G``, gain ``K = [K_p K_I]`` (p, n + g), Riccati ``X``,
      ``converged``, ``spectral_radius``.
    """
    A_bar, B_bar, G = integral_augmentation(A, B, H, Ts)
    checks.check_covariance("Q", Q, A_bar.shape[0])
    checks.check_covariance("R", R, B_bar.shape[1], definite=True)
    solution, K = _lqr(A_bar, B_bar, Q, R)
    require_stabilising(
        solution, (A, B, H, Q, R, Ts), "A, B, H, Q, R", _PI_NOT_STABILISABLE, allow_marginal
    )
    return PIDesign(
        A_bar, B_bar, G, K, solution.solution, solution.converged, solution.spectral_radius
    )
