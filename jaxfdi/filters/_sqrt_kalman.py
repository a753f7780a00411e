"""Square-root (Cholesky-factor) Kalman filter: ``P = L L^T`` carried as the lower triangular ``L`` and updated by
orthogonal transformations of pre-arrays (Kaminski, Bryson & Schmidt 1971; array form of Morf & Kailath 1975), so
round-off never makes it indefinite (for float32 filters at scale).

Measurement update: QR of ``pre^T`` gives a lower triangular post-array with the same Gram matrix ``pre pre^T``::

    pre = [[L_R, C L],      post = [[L_S,   0 ],     L_S L_S^T = S = C P C^T + R,
           [0,   L  ]]              [Kbar,  L+]]     Kbar = P C^T L_S^-T,  L+ L+^T = P - Kbar Kbar^T,

so ``K = Kbar L_S^-1``, ``m+ = m + Kbar w``, ``w = L_S^-1 r``, ``log det S = 2 sum log diag L_S``. Time update: the
triangular factor of ``[Phi L+, L_Q]`` (``tria``). ``S``, ``P[k|k]``, ``P[k+1|k]`` are never formed from
differences; ``FilterInfo`` covariances are Gram matrices of the factors (PSD by construction).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import (
    Filter,
    FilterInfo,
    check_gaussian,
    check_step_inputs,
    report_dead,
    used_innovation,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model


class SqrtGaussianState(NamedTuple):
    """Gaussian prior ``N(mean, chol chol^T)`` of the next step, by its factor.

    Attributes:
      mean: (n,)
      chol: (n, n) lower triangular, non-negative diagonal
    """

    mean: Array
    chol: Array


def tria(a: Array) -> Array:
    """Lower triangular ``L``, ``L L^T = a a^T``, non-negative diagonal, for ``a`` (n, k), ``k >= n``: ``R^T`` of
    the QR of ``a^T`` (only ``R`` formed), columns signed for a non-negative diagonal."""
    lower = jnp.linalg.qr(a.T, mode="r").T
    sign = jnp.where(jnp.diagonal(lower) < 0, -1.0, 1.0).astype(a.dtype)
    return lower * sign[None, :]


def factor(cov: Array) -> Array:
    """Lower triangular square root of a PSD ``cov``: ``tria(psd_sqrt(cov))`` (no Cholesky: zero variance allowed)."""
    return tria(_linalg.psd_sqrt(cov))


def sqrt_update(mean: Array, chol: Array, y: Array, y_pred: Array, H: Array, chol_R: Array):
    """Condition ``N(mean, chol chol^T)`` on ``y = H x + v``, ``v ~ N(0, chol_R chol_R^T)`` by one QR (module doc).
    Returns ``(mean+, chol+, innovation, chol_S, whitened innovation)``."""
    return sqrt_update_linearised(mean, chol, used_innovation(y, y_pred), H @ chol, chol_R)


def sqrt_update_linearised(
    mean: Array, chol: Array, innovation: Array, H_chol: Array, chol_noise: Array
):
    """Array-form update from ``H L`` (m, n), the innovation and the noise factor (m, k):
    ``[[L_noise, H L], [0, L]]`` -> ``[[L_S, 0], [Kbar, L+]]``."""
    n, m, k = mean.shape[0], innovation.shape[0], chol_noise.shape[1]
    pre = jnp.block([[chol_noise, H_chol], [jnp.zeros((n, k), mean.dtype), chol]])
    post = tria(pre)
    chol_S, gain_bar, chol_post = post[:m, :m], post[m:, :m], post[m:, m:]
    whitened = _linalg.solve_lower(chol_S, innovation)
    return mean + gain_bar @ whitened, chol_post, innovation, chol_S, whitened


def sqrt_init(n: int):
    """``init(mean, cov) -> SqrtGaussianState``: validates the prior against ``n``, stores ``cov``'s Cholesky factor."""

    def init(mean: Array, cov: Array) -> SqrtGaussianState:
        mean, cov = check_gaussian(mean, cov, n)
        return SqrtGaussianState(mean, factor(cov))

    return init


def sqrt_kalman_filter(model: LinearGaussianModel) -> Filter:
    """Square-root linear Kalman filter for a ``LinearGaussianModel`` (module doc).

    Outputs of ``kalman_filter`` (equal in exact arithmetic, in float64 to round-off); ``Q``, ``R`` factored once.

    Returns:
      ``Filter(init, step)`` (no ``update``/``predict``): ``init(mean (n,), cov (n, n)) -> SqrtGaussianState``
      (mean and lower-triangular factor of ``P[0|-1]``; PSD prior allowed); ``step(state, y (m,), u (nu,)) ->
      (SqrtGaussianState, FilterInfo)``, info covariances as Gram matrices of the factors.
    """
    n, nu, m = validate_linear_model(model)
    chol_Q, chol_R = factor(model.Q), factor(model.R)

    init = sqrt_init(n)

    def step(state: SqrtGaussianState, y: Array, u: Array):
        check_sqrt_state(state, n)
        check_step_inputs(y, u, m, nu)
        mm = _linalg.matmul
        y_pred = mm(model.C, state.mean) + mm(model.D, u)
        mean, chol, innovation, chol_S, whitened = sqrt_update(
            state.mean, state.chol, y, y_pred, model.C, chol_R.astype(state.chol.dtype)
        )
        next_mean = mm(model.Phi, mean) + mm(model.Gamma, u)
        next_chol = tria(jnp.concatenate([mm(model.Phi, chol), chol_Q.astype(chol.dtype)], axis=1))
        return SqrtGaussianState(next_mean, next_chol), sqrt_info(
            state, mean, chol, innovation, chol_S, whitened, next_mean, ~jnp.isfinite(y)
        )

    return Filter(init, step)


def sqrt_info(
    prior: SqrtGaussianState,
    mean: Array,
    chol: Array,
    innovation: Array,
    chol_S: Array,
    whitened: Array,
    next_mean: Array,
    dead: Array,
) -> FilterInfo:
    """The step's ``FilterInfo`` from the factors (covariances as Gram matrices); healthy when the factors of ``S``
    and ``P[k|k]`` have non-zero finite diagonals and every output is finite; ``dead`` (m,) as ``report_dead``."""
    m = innovation.shape[0]
    nis = jnp.sum(whitened**2)
    diag_S = jnp.diagonal(chol_S)
    log_likelihood = -0.5 * (nis + 2.0 * jnp.sum(jnp.log(diag_S)) + m * math.log(2.0 * math.pi))
    diag_P = jnp.abs(jnp.diagonal(chol))
    healthy = (
        jnp.all(jnp.isfinite(chol_S))
        & jnp.all(diag_S > 0)
        & jnp.all(jnp.isfinite(chol))
        & jnp.all(diag_P > 0)
        & jnp.all(jnp.isfinite(mean))
        & jnp.all(jnp.isfinite(next_mean))
        & jnp.isfinite(nis)
        & jnp.isfinite(log_likelihood)
    )
    gram = lambda L: L @ L.T
    innovation, nis = report_dead(innovation, nis, dead)
    return FilterInfo(
        prior.mean,
        gram(prior.chol),
        mean,
        gram(chol),
        innovation,
        gram(chol_S),
        log_likelihood,
        nis,
        jnp.sum(~dead).astype(jnp.int32),
        healthy,
    )


def check_sqrt_state(state, n: int) -> None:
    """``state`` is a ``SqrtGaussianState`` of size ``n`` (trace-time)."""
    if not isinstance(state, SqrtGaussianState):
        raise TypeError(
            f"state: expected a SqrtGaussianState(mean, chol) from the filter's init, got "
            f"{checks.received(state)}"
        )
    checks.check_shape("state.chol", state.chol, (n, n), "lower triangular factor")
