"""Square-root unscented Kalman filter for float32 at scale: ``ukf.py``'s UKF (scaled UT, centred form) with a lower
triangular covariance factor ``L``, every update orthogonal (van der Merwe & Wan 2001; ``sqrt_kalman.py``'s arrays).

Sigma points ``m +/- s_i``, ``s_i = scale * col_i(L)``, centred images ``dY_{+/-i} = g(m +/- s_i) - g(m)``. The
statistical linearisation ``H = Pxy^T P^-1`` (Lefebvre et al. 2002) needs no solve here (``L^-1 s_i = scale e_i``):

    H L = (dY_+ - dY_-) / (2 scale),     e_i = dY_{+/-i} - H (+/- s_i) = (dY_+i + dY_-i) / 2,

predicted-measurement covariance ``H P H^T + Lambda``, ``Lambda = 2 W sum_i e_i e_i^T + (beta - alpha^2) delta
delta^T`` (``ukf.py``; ``W`` the sigma-point weight, ``delta = W sum dY``). The update conditions ``N(m, L L^T)`` on
``y = H x + e + v``, ``Cov(e + v) = Lambda + R``, by the square-root KF pre-array::

    [[L_noise, H L], [0, L]]  --QR-->  [[L_S, 0], [Kbar, L+]],
    L_noise = tria([sqrt(2 W) e_1..e_n, sqrt(beta - alpha^2) delta, L_R]),

``m+ = m + Kbar L_S^-1 r``: no gain ``Pxy S^-1`` (its solve with an ill-conditioned ``S`` breaks float32 filters).
Exactly, ``L+ L+^T`` is ``ukf.py``'s Joseph-like posterior and ``L_S L_S^T`` its ``S``. Time update
``L' = tria([sqrt(W) dX_1..dX_2n, sqrt(beta - alpha^2) delta_x, L_Q])``: non-negative weights (``beta >= alpha^2``),
no Cholesky downdate by van der Merwe & Wan's negative centre weight.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.filters._base import Filter, ModelFunction, check_step_inputs, used_innovation
from jaxfdi.filters._sqrt_kalman import (
    SqrtGaussianState,
    check_sqrt_state,
    factor,
    sqrt_info,
    sqrt_init,
    sqrt_update_linearised,
    tria,
)
from jaxfdi.filters._ukf import SigmaPoints, _propagate, scaled_transform


def factor_sigma_points(mean: Array, chol: Array, scale: float, taylor: bool) -> SigmaPoints:
    """Centred sigma points ``m +/- s_i``, ``s_i = scale * col_i(L)``. Direct differences: offsets rounded
    symmetrically, ``s = (m + s) - m``, as ``ukf.sigma_points``. Taylor differences never form ``m + s``: offsets stay
    exact, which matters in float32 (a well-measured direction's offset, 1e-7 of ``m``, is below ``m + s``'s
    rounding)."""
    s = scale * chol.T
    if not taylor:
        s = (mean[None, :] + s) - mean[None, :]
    return SigmaPoints(mean, jnp.concatenate([s, -s], axis=0))


def sqrt_unscented_kalman_filter(
    f: ModelFunction,
    h: ModelFunction,
    Q: Array,
    R: Array,
    params: Any = None,
    alpha: float = 1e-3,
    beta: float = 2.0,
    kappa: float = 0.0,
    sigma_differences: str = "auto",
) -> Filter:
    """Square-root UKF for ``x[k+1] = f(x, u, params) + w``, ``y = h(x, u, params) + v``.

    Arguments and ``FilterInfo`` as ``unscented_kalman_filter`` (equal in float64 to round-off); needs
    ``beta >= alpha^2`` (non-negative weights, module doc).

    Returns:
      ``Filter(init, step)`` (no ``update``/``predict``): ``init(mean (n,), cov (n, n)) -> SqrtGaussianState``;
      ``step(state, y (m,), u) -> (SqrtGaussianState, FilterInfo)``, info covariances as Gram matrices of factors.
    """
    n, m, alpha, beta, w, scale, use_taylor = scaled_transform(
        f, h, Q, R, alpha, beta, kappa, sigma_differences
    )
    if beta < alpha**2:
        raise ValueError(
            f"beta: the square-root form needs beta >= alpha^2 = {alpha**2:g} (non-negative weights), "
            f"got {beta}"
        )
    root_w, root_cross = w**0.5, (beta - alpha**2) ** 0.5
    chol_Q, chol_R = factor(jnp.asarray(Q)), factor(jnp.asarray(R))

    init = sqrt_init(n)

    def step(state: SqrtGaussianState, y: Array, u: Array):
        check_sqrt_state(state, n)
        check_step_inputs(y, u, m, None)
        dtype = state.mean.dtype
        taylor = use_taylor(state.mean)
        # measurement update, in the sigma-point basis (module doc)
        points = factor_sigma_points(state.mean, state.chol, scale, taylor)
        y0, dy = _propagate(points, lambda x: h(x, u, params), taylor)
        checks.check_shape("h(x, u, params)", y0, (m,), "one predicted measurement")
        plus, minus = dy[:n], dy[n:]
        linearised = (plus - minus).T / (2.0 * scale)  # H L, (m, n)
        residuals = 0.5 * (plus + minus)  # e_i, (n, m)
        delta_y = w * jnp.sum(dy, axis=0)
        innovation = used_innovation(y, y0 + delta_y)
        chol_noise = tria(
            jnp.concatenate(
                [
                    (2.0 * w) ** 0.5 * residuals.T,
                    root_cross * delta_y[:, None],
                    chol_R.astype(dtype),
                ],
                axis=1,
            )
        )
        mean, chol, innovation, chol_S, whitened = sqrt_update_linearised(
            state.mean, state.chol, innovation, linearised, chol_noise
        )
        # time update
        points = factor_sigma_points(mean, chol, scale, taylor)
        x0, dx = _propagate(points, lambda x: f(x, u, params), taylor)
        checks.check_shape("f(x, u, params)", x0, (n,), "the next state")
        delta_x = w * jnp.sum(dx, axis=0)
        next_mean = x0 + delta_x
        next_chol = tria(
            jnp.concatenate(
                [root_w * dx.T, root_cross * delta_x[:, None], chol_Q.astype(dtype)], axis=1
            )
        )
        return SqrtGaussianState(next_mean, next_chol), sqrt_info(
            state, mean, chol, innovation, chol_S, whitened, next_mean, ~jnp.isfinite(y)
        )

    return Filter(init, step)
