"""Eigenstructure assignment of a reconfigured state-feedback gain for a faulty actuator
(Lee & Lyou, eqs. 23-29; Zhang & Jiang 1999, 2000).

Sign: ``u = -K x`` as ``lqr_gain`` (closed loop ``A_bar - B K``); the paper's ``u = K x`` gains are the negatives.

Find ``K_f`` so ``A_bar - B_f K_f`` keeps the nominal ``lambda_i`` (eq. 23) with eigenvectors nearest the nominal
``v_i``: ``v_i^f`` lies in the span of ``E_i = (lambda_i I - A_bar)^-1 B_f`` (eq. 24); nearest (eq. 25, ``W_i = I``):
``v_i^f = E_i alpha_i``, ``alpha_i = E_i^+ v_i`` (eq. 26). The span is the null space of ``[lambda_i I - A_bar, -B_f]``
by SVD (the paper's "SVD-based" assignment), defined also where ``lambda_i`` is an eigenvalue of ``A_bar`` (the
integrators' 1). ``K_f v_i^f = -alpha_i``: ``K_f = -[alpha_1 ... alpha_N] (V^f)^-1``, minus eq. 29
``B_f^+ (V^f Lambda - A_bar V^f) (V^f)^-1`` when ``B_f`` has full column rank (eq. 28's SVDs are the pseudo-inverses).
Conjugate eigenvalues give conjugate columns: ``K_f`` is real up to round-off (imaginary part reported).

A dead actuator (zero column of ``B_f``): minimum-norm ``alpha_i`` has 0 on it, so its row of ``K_f`` is 0 and the
others assign what ``(A_bar, B_f)`` can move. If not (VTOL tracking ``v_h`` and ``theta``: one actuator cannot hold two
integrators, a mode at 1 becomes uncontrollable), ``V^f`` is singular, ``K_f`` is the least-squares solution of
``K_f V^f = -[alpha_i]``, and ``assignment_residual`` shows which eigenvalues were kept. (The paper's design, tracking
``v_h`` and ``q``, has that mode at 1 already, so either actuator alone keeps every eigenvalue.)
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks

#: relative singular-value cut-off for null spaces and pseudo-inverses.
NULL_RTOL = 1e-10


class EigenstructureResult(NamedTuple):
    """Eigenstructure assignment's gain with its diagnostics (eigenvectors, imaginary part, conditioning, residual).

    Attributes:
      gain: (p, N) real K_f: u = -K_f x, closed loop A_bar - B_f K_f
      eigenvectors: (N, N) complex V^f, columns v_i^f (eq. 26)
      gain_imaginary: () max |Im K_f| before taking the real part
      eigenvector_matrix_cond: () condition number of V^f (huge: not every eigenvalue is assignable)
      assignment_residual: (N,) |(A_bar - B_f K_f) v_i^f - lambda_i v_i^f| / |v_i^f|: ~0 where assigned
    """

    gain: Array
    eigenvectors: Array
    gain_imaginary: Array
    eigenvector_matrix_cond: Array
    assignment_residual: Array


def effectiveness_input(B: Array, loss: Array) -> Array:
    """``B_f = B (I - diag(loss))``: each input's effectiveness loss (0 healthy, 1 dead)."""
    return jnp.asarray(B) * (1.0 - jnp.asarray(loss))[None, :]


def nominal_eigenstructure(A_bar, B_bar, K_nominal) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (N,) and eigenvectors (N, N) of the nominal loop ``A_bar - B_bar K_n``
    (``u = -K_n x``; NumPy, concrete arrays: computed once per design, outside the hot loop).

    Returns:
      ``(eigenvalues (N,), eigenvectors (N, N))`` as NumPy complex arrays (``np.linalg.eig``: eigenvectors as
      unit-norm columns), ``assign_eigenstructure``'s targets.
    """
    closed = np.asarray(A_bar) - np.asarray(B_bar) @ np.asarray(K_nominal)
    return np.linalg.eig(closed)


def assign_eigenstructure(
    A_bar: Array, B_faulty: Array, eigenvalues: Array, eigenvectors: Array
) -> EigenstructureResult:
    """Reconfigured gain ``K_f`` (``u = -K_f x``): ``A_bar - B_f K_f`` keeps ``eigenvalues``, eigenvectors
    projected onto the admissible subspaces (eq. 26, ``W_i = I``). Traceable (``jit``/``vmap`` over
    ``B_faulty``: reconfigure from an online fault estimate).

    Args:
      A_bar: (N, N) open-loop (augmented) state matrix.
      B_faulty: (N, p) faulty input matrix ``B_f``.
      eigenvalues: (N,) complex nominal closed-loop eigenvalues (distinct).
      eigenvectors: (N, N) complex nominal eigenvectors (columns), e.g. ``nominal_eigenstructure``'s.

    Returns:
      ``EigenstructureResult``: real ``K_f`` (p, N), ``V^f`` (N, N), dropped max ``|Im K_f|``, ``cond(V^f)``,
      residual per eigenvalue (N,) (~0 where kept).
    """
    N = checks.check_square("A_bar", A_bar, None, "augmented state matrix")
    checks.check_shape("B_faulty", B_faulty, (N, None), "N states x p inputs")
    checks.check_shape("eigenvalues", eigenvalues, (N,), "nominal closed-loop eigenvalues")
    checks.check_shape("eigenvectors", eigenvectors, (N, N), "nominal eigenvectors as columns")
    A_bar = jnp.asarray(A_bar)
    ctype = jnp.result_type(A_bar.dtype, jnp.complex64)
    lam = jnp.asarray(eigenvalues, ctype)
    V = jnp.asarray(eigenvectors, ctype)
    B_f = jnp.asarray(B_faulty, ctype)
    eye = jnp.eye(N, dtype=ctype)
    p = B_f.shape[1]

    def column(lam_i, v_i):
        # admissible pairs (v, w) with (lambda I - A_bar) v = B_f w: the null space of
        # [lambda I - A_bar, -B_f], by SVD (defined also where lambda is an eigenvalue of
        # A_bar, e.g. the integrators' 1, where E_i = (lambda I - A_bar)^-1 B_f is not);
        # its dimension is p, more where the pair (A_bar, B_f) loses rank at lambda
        S = jnp.concatenate([lam_i * eye - A_bar.astype(ctype), -B_f], axis=1)
        _, sv, Vh = jnp.linalg.svd(S, full_matrices=True)
        in_null = jnp.concatenate([sv <= NULL_RTOL * sv[0], jnp.ones((p,), bool)])
        null = Vh.conj().T * in_null[None, :]  # (N + p, N + p), zero columns off the null space
        beta = jnp.linalg.pinv(null[:N], rtol=NULL_RTOL) @ v_i  # eq. 26 with W_i = I
        return null[:N] @ beta, null[N:] @ beta

    V_f, alphas = jax.vmap(column, in_axes=(0, 1), out_axes=(1, 1))(lam, V)
    # K_f V^f = -[alpha_i] (u = -K x); least squares (pseudo-inverse) where V^f is singular
    K_complex = -alphas @ jnp.linalg.pinv(V_f, rtol=NULL_RTOL)
    closed = A_bar.astype(ctype) - B_f @ K_complex.real.astype(ctype)
    residual = jnp.linalg.norm(closed @ V_f - V_f * lam[None, :], axis=0) / jnp.maximum(
        jnp.linalg.norm(V_f, axis=0), 1e-300
    )
    singular = jnp.linalg.svd(V_f, compute_uv=False)
    return EigenstructureResult(
        gain=K_complex.real,
        eigenvectors=V_f,
        gain_imaginary=jnp.max(jnp.abs(K_complex.imag)),
        eigenvector_matrix_cond=singular[0] / singular[-1],
        assignment_residual=residual,
    )


class GainSchedule(NamedTuple):
    """Reconfigured gains tabulated over one actuator's effectiveness loss at a time.

    Attributes:
      losses: (G,) grid of losses in [0, 1], increasing
      gains: (p, G, p, N): gains[i, g] = K_f (u = -K_f x) for input i with loss losses[g]
      max_residual: (p, G) largest assignment residual of each entry (~0 where every eigenvalue is kept)
    """

    losses: Array
    gains: Array
    max_residual: Array


def effectiveness_gain_schedule(
    A_bar: Array, B_bar: Array, eigenvalues: Array, eigenvectors: Array, num_losses: int = 201
) -> GainSchedule:
    """``assign_eigenstructure`` for each input's loss on a uniform grid over [0, 1], so a loop looks the
    gain up (``scheduled_gain``) instead of ``2 (N + 1)`` SVDs a step: exact at grid points, linear
    between (smooth in the loss away from 1).

    Returns:
      ``GainSchedule(losses (G,), gains (p, G, p, N), max_residual (p, G))``, ``G = num_losses`` points
      ``linspace(0, 1)`` in ``A_bar``'s dtype.
    """
    num_losses = checks.check_int(
        "num_losses", num_losses, 2, meaning="a number of grid points >= 2 over [0, 1]"
    )
    p = checks.shape_of(B_bar)[1]
    losses = jnp.linspace(0.0, 1.0, num_losses, dtype=jnp.asarray(A_bar).dtype)

    def one(i, loss):
        B_f = effectiveness_input(B_bar, loss * jax.nn.one_hot(i, p, dtype=losses.dtype))
        result = assign_eigenstructure(A_bar, B_f, eigenvalues, eigenvectors)
        return result.gain, jnp.max(result.assignment_residual)

    gains, residual = jax.jit(jax.vmap(jax.vmap(one, in_axes=(None, 0)), in_axes=(0, None)))(
        jnp.arange(p), losses
    )
    return GainSchedule(losses, gains, residual)


def scheduled_gain(schedule: GainSchedule, component: Array, loss: Array) -> Array:
    """``K_f`` (``u = -K_f x``) for input ``component`` with ``loss`` (clipped to [0, 1]), linear in
    ``schedule``. Traceable.

    Returns:
      (p, N) ``K_f`` between the two gains of ``schedule.gains[component]`` bracketing ``loss``.
    """
    losses = schedule.losses
    position = jnp.clip(loss, 0.0, 1.0) * (losses.shape[0] - 1)
    lower = jnp.clip(jnp.floor(position).astype(jnp.int32), 0, losses.shape[0] - 2)
    weight = position - lower
    table = schedule.gains[component]
    return (1.0 - weight) * table[lower] + weight * table[lower + 1]
