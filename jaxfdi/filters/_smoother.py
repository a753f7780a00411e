"""Rauch-Tung-Striebel smoother (Rauch, Tung & Striebel 1965), sequential and parallel in time (Särkkä &
García-Fernández 2021, sec. IV), from a Kalman filter's outputs.

For ``x_{k+1} = Phi x_k + Gamma u_k + w``: from filtered ``N(m_k, P_k)`` (``info.filtered_*``) and predicted
``N(m_{k+1}^-, P_{k+1}^-)`` (``info.predicted_*`` of step ``k + 1``), backwards from ``ms_{T-1} = m_{T-1}``:

    G_k = P_k Phi^T (P_{k+1}^-)^-1,
    ms_k = m_k + G_k (ms_{k+1} - m_{k+1}^-),   Ps_k = P_k + G_k (Ps_{k+1} - P_{k+1}^-) G_k^T.

Parallel form: element ``(E, g, L) = (G_k, m_k - G_k m_{k+1}^-, P_k - G_k P_{k+1}^- G_k^T)`` (last
``(0, m_{T-1}, P_{T-1})``) of ``p(x_k | x_{k+1}, y_0..y_k) = N(E x_{k+1} + g, L)``; combination
``(E_i E_j, E_i g_j + g_i, E_i L_j E_i^T + L_i)`` (``i`` before ``j``); reverse scan: ``N(ms_k, Ps_k) = N(g, L)``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import FilterInfo
from jaxfdi.filters._parallel import (  # batched transpose, symmetric part, matrix-vector
    _mT,
    _mv,
    _sym,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model


class SmootherResult(NamedTuple):
    """Smoothed moments ``N(x_k | y_0..y_{T-1})`` and the smoother gains.

    Attributes:
      mean: (T, n)
      cov: (T, n, n)
      gain: (T, n, n) G_k (zero at the last step)
    """

    mean: Array
    cov: Array
    gain: Array


class SmoothingElement(NamedTuple):
    E: Array  # (n, n)
    g: Array  # (n,)
    L: Array  # (n, n)


def smoother_gains(Phi: Array, filtered_cov: Array, next_predicted_cov: Array) -> Array:
    """``G_k = P_k Phi^T (P_{k+1}^-)^-1`` for stacks (T - 1, n, n), by a Cholesky solve of the symmetric
    ``P_{k+1}^-``: ``G^T = (P^-)^-1 Phi P_k``."""
    chol = _linalg.stack_cholesky(
        _sym(next_predicted_cov)
    )  # no LAPACK for small n: _linalg.solve_pivoted
    return _mT(_linalg.stack_cho_solve(chol, Phi @ filtered_cov))


def rts_smoother(
    model: LinearGaussianModel, info: FilterInfo, *, parallel: bool = False
) -> SmootherResult:
    """RTS smoother over a Kalman filter's ``info``: a backward ``lax.scan``, or with ``parallel=True`` the reverse
    associative scan (module doc, O(log T) depth; equal to round-off), as ``run_filter(..., parallel=True)``.

    Args:
      model: the ``LinearGaussianModel`` the filter ran with (``Phi`` is used).
      info: ``FilterInfo`` of ``run_filter(kalman_filter(model), ...)`` (also ``parallel=True``), leading axis T.
      parallel: the associative scan instead of the sequential one.

    Returns:
      ``SmootherResult``: smoothed means ``ms_k`` (T, n) and covariances ``Ps_k`` (T, n, n) of ``x_k`` given
      ``y_0..y_{T-1}``, and gains ``G_k`` (T, n, n), zero at the last step.
    """
    checks.check_flag("parallel", parallel)
    Phi, info = _check(model, info)
    smooth = _parallel if parallel else _sequential
    return smooth(
        Phi, info.filtered_mean, info.filtered_cov, info.predicted_mean, info.predicted_cov
    )


@jax.jit
def _sequential(Phi, mean, cov, predicted_mean, predicted_cov) -> SmootherResult:
    gains = smoother_gains(Phi, cov[:-1], predicted_cov[1:])

    def back(later, step):
        smoothed_mean, smoothed_cov = later
        m, P, m_next, P_next, G = step
        m_s = m + G @ (smoothed_mean - m_next)
        P_s = _sym(P + G @ (smoothed_cov - P_next) @ G.T)
        return (m_s, P_s), (m_s, P_s)

    _, (means, covs) = jax.lax.scan(
        back,
        (mean[-1], cov[-1]),
        (mean[:-1], cov[:-1], predicted_mean[1:], predicted_cov[1:], gains),
        reverse=True,
    )
    last_gain = jnp.zeros_like(cov[:1])
    return SmootherResult(
        jnp.concatenate([means, mean[-1:]]),
        jnp.concatenate([covs, cov[-1:]]),
        jnp.concatenate([gains, last_gain]),
    )


def combine_smoothing(later: SmoothingElement, earlier: SmoothingElement) -> SmoothingElement:
    """``earlier ⊗ later`` as ``associative_scan(..., reverse=True)`` calls it (later element first)."""
    return SmoothingElement(
        earlier.E @ later.E,
        _mv(earlier.E, later.g) + earlier.g,
        _sym(earlier.E @ later.L @ _mT(earlier.E) + earlier.L),
    )


@jax.jit
def _parallel(Phi, mean, cov, predicted_mean, predicted_cov) -> SmootherResult:
    gains = smoother_gains(Phi, cov[:-1], predicted_cov[1:])
    g = mean[:-1] - _mv(gains, predicted_mean[1:])
    L = _sym(cov[:-1] - gains @ predicted_cov[1:] @ _mT(gains))
    elements = SmoothingElement(
        jnp.concatenate([gains, jnp.zeros_like(cov[:1])]),
        jnp.concatenate([g, mean[-1:]]),
        jnp.concatenate([L, cov[-1:]]),
    )
    smoothed = jax.lax.associative_scan(combine_smoothing, elements, reverse=True)
    return SmootherResult(smoothed.g, smoothed.L, elements.E)


def _check(model: LinearGaussianModel, info: FilterInfo):
    n, _, _ = validate_linear_model(model)
    if not isinstance(info, FilterInfo):
        raise TypeError(
            f"info: expected the FilterInfo of run_filter(kalman_filter(model), ...), got "
            f"{checks.received(info)}"
        )
    checks.check_shape("info.filtered_mean", info.filtered_mean, (None, n), "T steps x n states")
    T = checks.shape_of(info.filtered_mean)[0]
    for name in ("filtered_cov", "predicted_cov"):
        checks.check_shape(f"info.{name}", getattr(info, name), (T, n, n), "T steps x n x n")
    checks.check_shape("info.predicted_mean", info.predicted_mean, (T, n), "T steps x n states")
    if T < 1:
        raise ValueError("info: expected at least one step")
    dtype = jnp.result_type(info.filtered_mean, model.Phi)
    return jnp.asarray(model.Phi, dtype), jax.tree.map(lambda a: jnp.asarray(a), info)
