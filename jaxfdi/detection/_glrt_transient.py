"""The windowed GLRT for a Kalman filter started at any prior: time-varying signatures (Willsky & Jones 1976,
sec. 3, with the filter's own gains).

``glrt``'s GLR needs constant ``K`` and ``S`` (steady state, ``P[k|k-1] = P_ss``). ``kalman_filter(model)`` started
at another prior ``P[0]`` has gains ``K_k`` and covariances ``S_k`` varying until ``P`` converges (data-independent
``P_{k+1} = Phi (I - K_k C) P_k (I - K_k C)^T Phi^T + Phi K_k R K_k^T Phi^T + Q``). A unit step in direction ``i``
(``g``, ``h``: ``fault_directions``) from ``theta`` then adds at ``k >= theta`` a signature depending on onset and
lag (``glrt``'s recursion with ``K_k``)::

    G[k, theta] = C E[k] + h,   E[theta] = 0,
    E[k+1] = Phi (I - K_k C) E[k] + g - Phi K_k h

Whitening by each step's ``S_k = L_k L_k^T``: ``w_j = L_j^-1 eps_j``, ``Gw[j, theta] = L_j^-1 G[j, theta]``. Over the
last ``N`` steps, for every onset ``theta = k - o``::

    d_i(theta) = sum_j Gw_i[j, theta]^T w_j,   R_i(theta) = sum_j ||Gw_i[j, theta]||^2,
    nu_hat = d / R,   l_i(theta) = d^2 / R   (chi2(1) under no fault)

With ``P[0] = P_ss``, ``transient_glrt_detector`` equals ``glrt_detector``.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi._simulation.faults import sensor_labels
from jaxfdi.detection._chi2 import Detector, flag_dead
from jaxfdi.detection._glrt import (
    DetectorSetup,
    FaultDirections,
    _check_decision_args,
    _check_directions,
    _check_window,
    _maximise,
    decide,
    fault_directions,
    glr_from_correlation,
    whiten_finite,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model


class TransientGLRTState(NamedTuple):
    """``transient_glrt_detector``'s state (the fields of the other form are empty).

    Attributes:
      cov: (n, n) the filter's predicted covariance P[k+1|k] (data-independent)
      errors: (N, n, d) E of onset k - o, advanced to step k + 1 (o: offsets of step k)
      window: (N, m) whitened innovations L_j^-1 eps_j, oldest first; (0, m) in the recursive form
      signatures: (N, N, m, d) T[o, p], onset k - o at window position p; (0, 0, m, d) recursive
      correlation: (N, d) d_i(k - o)
      information: (N, d) R_i(k - o)
      count: () int32, steps seen (saturates at N)
      onset_offset: () int32, onset offset of the last decision's isolated direction
    """

    cov: Array
    errors: Array
    window: Array
    signatures: Array
    correlation: Array
    information: Array
    count: Array
    onset_offset: Array


def time_varying_signatures(
    model: LinearGaussianModel,
    prior_cov: Array,
    directions: FaultDirections,
    onset: int,
    length: int,
) -> Array:
    """(length, m, d) innovation signatures ``G[theta + l, theta]`` of a unit step from ``theta = onset`` for
    ``kalman_filter(model)`` started at ``prior_cov`` (module docstring's recursion); ``onset`` may be traced (vmap
    over onsets)."""
    n, _, m = validate_linear_model(model)
    checks.check_covariance("prior_cov", prior_cov, n)
    checks.check_shape("onset", onset, (), "one step index theta")
    checks.check_int_array("onset", onset, minimum=0, meaning="a step index theta >= 0")
    length = checks.check_int("length", length, minimum=1, meaning="a positive number of lags")
    _check_directions(directions, n, m)
    dtype = jnp.result_type(model.Phi, prior_cov)
    g, h = jnp.asarray(directions.state, dtype), jnp.asarray(directions.output, dtype)
    arrays = (jnp.asarray(a, dtype) for a in (model.Phi, model.C, model.Q, model.R, prior_cov))
    return _time_varying_signatures(*arrays, g, h, jnp.asarray(onset, jnp.int32), length)


@partial(jax.jit, static_argnums=8)
def _time_varying_signatures(Phi, C, Q, R, P, g, h, onset, length: int) -> Array:
    """``onset`` may be traced (one compilation per ``length``): ``P[theta]`` by a loop."""
    P = jax.lax.fori_loop(0, onset, lambda _, P: _riccati_step(Phi, C, Q, R, P)[2], P)

    def lag(carry, _):
        P, E = carry
        gain, _, P_next = _riccati_step(Phi, C, Q, R, P)
        return (P_next, Phi @ (E - gain @ (C @ E)) + g - Phi @ (gain @ h)), C @ E + h

    return jax.lax.scan(lag, (P, jnp.zeros_like(g)), None, length=length)[1]


def _riccati_step(Phi, C, Q, R, P):
    """The KF's gain ``K = P C^T S^-1``, whitener ``L^-1`` (``S = L L^T``) and next predicted covariance (Joseph
    update, then ``Phi P+ Phi^T + Q``)."""
    S = _linalg.symmetrize(C @ P @ C.T + R)
    chol = jnp.linalg.cholesky(S)
    gain = jsl.cho_solve((chol, True), C @ P).T
    whitener = jsl.solve_triangular(chol, jnp.eye(S.shape[0], dtype=S.dtype), lower=True)
    I_KC = jnp.eye(P.shape[0], dtype=P.dtype) - gain @ C
    P_next = _linalg.symmetrize(Phi @ (I_KC @ P @ I_KC.T + gain @ R @ gain.T) @ Phi.T + Q)
    return gain, whitener, P_next


def transient_glrt_detector(
    model: LinearGaussianModel,
    prior_cov: Array,
    window: int,
    threshold,
    isolation: str = "max",
    actuator_feedthrough: bool = False,
    overlap_sensor: int = -1,
    recursive: bool = False,
) -> Detector:
    """The windowed GLRT of ``glrt_detector`` for a ``kalman_filter(model)`` started at any ``prior_cov``
    (``kf.init(mean, prior_cov)``): time-varying ``G[k, theta]`` (``time_varying_signatures``), ``S_k`` whitening.

    The state carries ``P_k`` (data-independent), each window onset's error signature ``E``, and either the window
    of whitened innovations with the onset-by-position table ``T[o, p]`` (O(N^2 m d) a step) or, ``recursive=True``,
    the running sums ``d``, ``R`` (O(N m d); same decisions to round-off); plus one Riccati step per step. With
    ``prior_cov = P_ss`` it equals ``glrt_detector``. Other arguments and step inputs as ``glrt_detector``.

    Returns:
      ``Detector(init, step)``: ``init()`` gives a ``TransientGLRTState`` with ``P_0 = prior_cov``, empty window and
      sums; ``step(state, innovation (m,)) -> (state, Decision)`` as ``glrt_detector``'s.
    """
    n, nu, m = validate_linear_model(model)
    window = _check_window(window)
    checks.check_covariance("prior_cov", prior_cov, n)
    checks.check_flag("recursive", recursive)
    _check_decision_args(threshold, isolation, overlap_sensor, m)
    setup = DetectorSetup(None, None, threshold, isolation, nu, nu + int(overlap_sensor) % m)
    dtype = jnp.result_type(model.Phi, prior_cov)
    Phi, C, Q, R, P0 = (
        jnp.asarray(a, dtype) for a in (model.Phi, model.C, model.Q, model.R, prior_cov)
    )
    g, h = (jnp.asarray(a, dtype) for a in fault_directions(model, actuator_feedthrough))
    d = g.shape[1]
    N = window

    def init() -> TransientGLRTState:
        zero = jnp.zeros((), jnp.int32)
        size = 0 if recursive else N
        return TransientGLRTState(
            P0,
            jnp.zeros((N, n, d), dtype),
            jnp.zeros((size, m), dtype),
            jnp.zeros((size, size, m, d), dtype),
            jnp.zeros((N, d), dtype),
            jnp.zeros((N, d), dtype),
            zero,
            zero,
        )

    def step(state: TransientGLRTState, innovation: Array):
        checks.check_shape(
            "innovation", innovation, (m,), "one step's innovation of the fault-blind filter"
        )
        gain, whitener, P_next = _riccati_step(Phi, C, Q, R, state.cov)
        errors = jnp.concatenate(
            [jnp.zeros((1, n, d), dtype), state.errors[:-1]], axis=0
        )  # E[k] of onset k - o
        white_signatures = jnp.einsum(
            "ab,obd->oad", whitener, jnp.einsum("ab,obd->oad", C, errors) + h
        )
        innovation = jnp.asarray(innovation, dtype)
        white = whiten_finite(whitener, innovation)
        count = jnp.minimum(state.count + 1, N)
        if recursive:
            older = lambda a: jnp.concatenate([jnp.zeros((1, d), dtype), a[:-1]], axis=0)
            correlation = older(state.correlation) + jnp.einsum(
                "omd,m->od", white_signatures, white
            )
            information = older(state.information) + jnp.sum(white_signatures**2, axis=1)
            buffer, table = state.window, state.signatures
        else:
            buffer = jnp.concatenate([state.window[1:], white[None]], axis=0)
            table = jnp.zeros_like(state.signatures).at[1:, :-1].set(state.signatures[:-1, 1:])
            table = table.at[:, -1].set(white_signatures)
            correlation = jnp.einsum("opmi,pm->oi", table, buffer)
            information = jnp.sum(table**2, axis=(1, 2))
        result = _maximise(glr_from_correlation(correlation, information, count))
        decision, onset_offset = decide(setup, result)
        closed = Phi @ (jnp.eye(n, dtype=dtype) - gain @ C)
        errors_next = jnp.einsum("ab,obd->oad", closed, errors) + (g - Phi @ (gain @ h))
        decision = flag_dead(decision, ~jnp.isfinite(innovation), sensor_labels(nu, m))
        return TransientGLRTState(
            P_next, errors_next, buffer, table, correlation, information, count, onset_offset
        ), decision

    return Detector(init, step)
