"""Extended Kalman filter (Jazwinski 1970): the KF on Jacobians of ``f`` and ``h`` by ``jax.jacfwd``.

``H = dh/dx (m, u)``, ``r = y - h(m, u)``, Joseph update as ``kalman``; ``F = df/dx (m+, u)``, ``m' = f(m+, u)``,
``P' = F P+ F^T + Q``. Jacobians are never hand-typed (printed ones carry typos).
"""

from __future__ import annotations

from typing import Any

import jax
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import (
    Filter,
    GaussianState,
    ModelFunction,
    check_step_inputs,
    gaussian_filter,
)
from jaxfdi.filters._kalman import joseph_update


def extended_kalman_filter(
    f: ModelFunction,
    h: ModelFunction,
    Q: Array,
    R: Array,
    params: Any = None,
    missing_measurements: bool = False,
) -> Filter:
    """EKF for ``x[k+1] = f(x, u, params) + w``, ``y = h(x, u, params) + v``.

    Args:
      f, h: pure functions of ``(x (n,), u (nu,), params)``.
      Q: (n, n) process-noise covariance; R: (m, m) measurement-noise covariance.
      params: any pytree passed to ``f`` and ``h`` (tunable, vmappable).
      missing_measurements: treat NaN components of ``y`` as not measured (static).

    Returns:
      ``Filter(init, step, update, predict)``: ``init(mean (n,), cov (n, n)) -> GaussianState``;
      ``step(state, y (m,), u) -> (GaussianState, FilterInfo)``: Joseph update with ``h``'s Jacobian at the prior
      mean, then prediction with ``f``'s Jacobian at the posterior mean.
    """
    checks.check_callable("f", f, "a function f(x, u, params) -> next state")
    checks.check_callable("h", h, "a function h(x, u, params) -> measurement")
    n = checks.check_covariance("Q", Q)
    m = checks.check_covariance("R", R)

    def update(state: GaussianState, y: Array, u: Array):
        check_step_inputs(y, u, m, None)
        y_pred = h(state.mean, u, params)
        checks.check_shape("h(x, u, params)", y_pred, (m,), "one predicted measurement")
        H = jax.jacfwd(h)(state.mean, u, params)
        return joseph_update(state.mean, state.cov, y, y_pred, H, R, missing_measurements)

    def predict(post: GaussianState, u: Array) -> GaussianState:
        next_mean = f(post.mean, u, params)
        checks.check_shape("f(x, u, params)", next_mean, (n,), "the next state")
        F = jax.jacfwd(f)(post.mean, u, params)
        return GaussianState(next_mean, _linalg.symmetrize(F @ post.cov @ F.T + Q))

    return gaussian_filter(n, update, predict)
