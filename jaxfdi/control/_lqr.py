"""Discrete LQR and proportional-integral state feedback (Lee & Lyou, eqs. 21-22).

Integral action: the tracking error ``e = r - H x`` is integrated, ``z[k+1] = z[k] + Ts e``,
and the augmented system ``x_a = [x; z]``::

    x_a[k+1] = A_bar x_a[k] + B_bar u[k] + G r[k],
    A_bar = [[A, 0], [-Ts H, I]],  B_bar = [B; 0],  G = [0; Ts I]

is stabilised by ``u = -K x_a = -[K_p K_I] x_a``, ``K`` the discrete LQR gain
``K = (R + B^T X B)^-1 B^T X A`` with ``X`` the stabilising solution of the discrete
algebraic Riccati equation (``jaxfdi._riccati``, structure-preserving doubling).

Sign convention: ``u = -K x`` and the closed loop ``A - B K``, as SciPy
(``scipy.signal.place_poles``), MATLAB (``dlqr``) and python-control (``dlqr``). Lee and Lyou
write ``u = K x``; its ``K`` is the negative of ours.

A stabilising gain needs ``(A_bar, B_bar)`` stabilisable, i.e. no transmission zero of
``(A, B, H)`` at ``z = 1``. The paper's VTOL choice (track ``v_h`` and the pitch rate
``q = d theta / dt``) has one — the derivative puts a zero at ``s = 0`` — so one
closed-loop eigenvalue stays at exactly 1 (``spectral_radius``; SciPy's
``solve_discrete_are`` refuses this case): a constant pitch-rate command makes the
pitch angle ramp, which the loop follows without diverging elsewhere.

Existence. ``lqr_gain`` and ``lqr_pi`` raise ``ValueError`` (concrete arguments) when the
Riccati solver finds no stabilising solution (``jaxfdi._riccati``: verified by residual
and closed-loop spectral radius). ``lqr_pi`` accepts by default the marginal case above
(an uncontrollable closed-loop eigenvalue on the unit circle, which no gain can move)
and returns it with ``converged = False`` and ``spectral_radius = 1``; ``lqr_gain``
accepts it only with ``allow_marginal=True``. Under ``jit``/``vmap`` nothing is raised:
read ``converged`` and ``spectral_radius``.
"""
from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import _checks
from jaxfdi._riccati import DareSolution, require_stabilising, solve_discrete_are_info

#: why an LQR design has no stabilising solution
_NOT_STABILISABLE = "(A, B) is not stabilisable or (Q, A) has an unobservable mode on the unit circle"
_PI_NOT_STABILISABLE = ("(A_bar, B_bar) is not stabilisable ((A, B) is not, or (A, B, H) has a zero at z = 1) or "
                        "(Q, A_bar) has an unobservable mode on the unit circle")


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


def lqr_gain(A: Array, B: Array, Q: Array, R: Array, allow_marginal: bool = False) -> tuple[Array, Array, Array]:
    """Discrete LQR: ``(K, X, converged)`` with ``u = -K x`` (SciPy/MATLAB sign).

    ``K = (R + B^T X B)^-1 B^T X A`` minimises ``sum x^T Q x + u^T R u`` for
    ``x[k+1] = A x + B u``, ``X`` the stabilising solution of the DARE
    ``X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q``; the closed loop is ``A - B K``
    (e.g. Lewis, Vrabie & Syrmos 2012, sec. 2.4). Differentiable in ``A, B, Q, R`` in
    forward and reverse mode (implicit differentiation of the DARE, ``jaxfdi._riccati``).

    Args:
      A: (n, n) discrete state matrix.
      B: (n, p) input matrix.
      Q: (n, n) state weight (positive semi-definite).
      R: (p, p) input weight (positive definite).
      allow_marginal: accept a design whose closed loop keeps an eigenvalue on the unit
        circle (an uncontrollable mode at ``|z| = 1``; ``converged`` is then False).

    Returns:
      ``K`` (p, n), ``X`` (n, n) and the Riccati solver's ``converged`` flag (a verified
      stabilising solution).

    Raises:
      ValueError: with concrete arguments, when no stabilising solution exists
        (``(A, B)`` not stabilisable or ``(Q, A)`` with an unobservable mode on the unit
        circle); under ``jit``/``vmap`` nothing is raised: check ``converged``.
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
      ``(A_bar, B_bar, G)`` in ``A``'s dtype: ``A_bar = [[A, 0], [-Ts H, I]]`` (n + g, n + g),
      ``B_bar = [B; 0]`` (n + g, p) and ``G = [0; Ts I]`` (n + g, g), the reference's input
      to the integrator, with ``g`` the number of tracked outputs (rows of ``H``).
    """
    n = _checks.check_square("A", A, None, "discrete state matrix")
    _checks.check_shape("B", B, (n, None), "n states x p inputs")
    _checks.check_shape("H", H, (None, n), "g tracked outputs x n states")
    g = _checks.shape_of(H)[0]
    _checks.check_positive("Ts", Ts, "a positive sample time")
    A, B, H = (jnp.asarray(a) for a in (A, B, H))
    eye = jnp.eye(g, dtype=A.dtype)
    A_bar = jnp.block([[A, jnp.zeros((n, g), A.dtype)], [-Ts * H, eye]])
    B_bar = jnp.concatenate([B, jnp.zeros((g, B.shape[1]), A.dtype)])
    G = jnp.concatenate([jnp.zeros((n, g), A.dtype), Ts * eye])
    return A_bar, B_bar, G


def lqr_pi(A: Array, B: Array, H: Array, Q: Array, R: Array, Ts: float, allow_marginal: bool = True) -> PIDesign:
    """LQR-PI design of eqs. 21-22: ``Q`` (n + g, n + g), ``R`` (p, p).

    The control is ``u = -design.gain @ [x; z]`` (``u = -K x``, as ``lqr_gain``; the
    paper's eq. 22 ``u = K [x; z]`` uses ``-design.gain``).

    ``allow_marginal`` (default True, for the paper's design of the module doc): a design
    whose closed loop keeps an uncontrollable eigenvalue on the unit circle (a plant zero
    at ``z = 1``) is returned with ``converged = False`` and ``spectral_radius = 1``; a
    design with no closed loop of spectral radius <= 1 raises ``ValueError`` (concrete
    arguments; under ``jit`` check ``converged`` and ``spectral_radius``).

    Returns:
      ``PIDesign``: the augmented ``A_bar`` (n + g, n + g), ``B_bar`` (n + g, p), ``G``
      (n + g, g), the gain ``K = [K_p K_I]`` (p, n + g), the Riccati solution ``X``
      (n + g, n + g), the ``converged`` flag and the closed loop's ``spectral_radius``.
    """
    A_bar, B_bar, G = integral_augmentation(A, B, H, Ts)
    _checks.check_covariance("Q", Q, A_bar.shape[0])
    _checks.check_covariance("R", R, B_bar.shape[1], definite=True)
    solution, K = _lqr(A_bar, B_bar, Q, R)
    require_stabilising(solution, (A, B, H, Q, R, Ts), "A, B, H, Q, R", _PI_NOT_STABILISABLE, allow_marginal)
    return PIDesign(A_bar, B_bar, G, K, solution.solution, solution.converged, solution.spectral_radius)
