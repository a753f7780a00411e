"""Unscented Kalman filter with the scaled unscented transform (Julier 2002;
Wan & van der Merwe 2000), additive noise, Cholesky sigma points.

Sigma points ``X0 = m``, ``X(+/-)i = m +/- sqrt(L + lambda) col_i(chol P)``,
``lambda = alpha^2 (L + kappa) - L``, weights ``Wm0 = lambda / (L + lambda)``,
``Wc0 = Wm0 + 1 - alpha^2 + beta``, ``Wi = 1 / (2 (L + lambda))``.
Measurement update ``P+ = P - K S K^T`` (seed 000, eq. 29 corrected).

Centred form (the float32 fix). With small ``alpha`` the centre weights are huge and
negative (``alpha = 1e-3`` gives ``Wc0 ~ -1e6``), and the textbook sums
``sum_i Wc_i (Y_i - ybar)(Y_i - ybar)^T`` cancel catastrophically in float32: the
"covariance" loses positive-definiteness and the filter returns NaN. Writing every
point relative to the centre, ``d_i = Y_i - Y_0`` and ``delta = sum_{i>0} W_i d_i``, the
same moments are, exactly in real arithmetic,

    mean = Y_0 + delta,
    cov  = sum_{i>0} W_i d_i d_i^T + (beta - alpha^2) delta delta^T,
    Pxy  = sum_{i>0} W_i dx_i dy_i^T + (beta - alpha^2) delta_x delta_y^T,

(using ``sum_i Wm_i = 1`` and ``Wc_i = Wm_i`` for ``i > 0``), which have only positive
weights of moderate size: positive semi-definite by construction for ``beta >= alpha^2``.
The +/- offsets are rounded symmetrically (``s = (m + s) - m``) so that the linear part
of a map cancels exactly in ``delta``.
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import _checks, _linalg
from jaxfdi.filters._base import (
    ConditionedGaussian,
    Filter,
    GaussianState,
    check_step_inputs,
    gaussian_filter,
    mask_innovation_cov,
    observed_mask,
)


class SigmaPoints(NamedTuple):
    """Sigma points in centred form: the centre and the 2L offsets from it."""

    centre: Array   # (n,)
    offsets: Array  # (2n, n): +s_1..+s_n, -s_1..-s_n


def unscented_weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[float, float, float]:
    """``(Wi, Wm0, Wc0)`` of the scaled unscented transform for state size ``n``."""
    lam = alpha**2 * (n + kappa) - n
    w = 1.0 / (2.0 * (n + lam))
    wm0 = lam / (n + lam)
    return w, wm0, wm0 + 1.0 - alpha**2 + beta


def sigma_points(mean: Array, cov: Array, scale: float) -> tuple[SigmaPoints, Array]:
    """Centred sigma points ``m +/- scale * col_i(chol P)``; also returns ``chol P``."""
    chol = _linalg.cholesky(cov)
    plus = mean[None, :] + scale * chol.T        # rows = m + s_i
    s = plus - mean[None, :]                      # symmetric rounding
    return SigmaPoints(mean, jnp.concatenate([s, -s], axis=0)), chol


def _centred_differences_direct(points: SigmaPoints, g: Callable[[Array], Array]) -> tuple[Array, Array]:
    """``(g(c), d_i = g(c + s_i) - g(c))`` by evaluating ``g`` at every sigma point."""
    y0 = g(points.centre)
    ys = jax.vmap(g)(points.centre[None, :] + points.offsets)
    return y0, ys - y0[None, :]


def _centred_differences_taylor(points: SigmaPoints, g: Callable[[Array], Array]) -> tuple[Array, Array]:
    """``d(+/-i) = +/- J s_i + (1/2) s_i^T H s_i`` by nested forward-mode AD.

    The second-order Taylor expansion of ``g(c +/- s_i) - g(c)``: no subtraction of
    nearly equal numbers, so it keeps full relative precision in float32. Its
    truncation error is O(|s|^3) per point and O(alpha^2) relative in the moments, so
    it converges to the exact scaled UT as ``alpha -> 0``.
    """
    c = points.centre
    n = c.shape[0]
    s = points.offsets[:n]

    def first_and_second(direction):
        def directional(x):
            return jax.jvp(g, (x,), (direction,))
        (y0, js), (_, hss) = jax.jvp(directional, (c,), (direction,))
        return y0, js, hss

    y0, js, hss = jax.vmap(first_and_second)(s)
    return y0[0], jnp.concatenate([js + 0.5 * hss, -js + 0.5 * hss], axis=0)


def unscented_moments(
    points: SigmaPoints, g: Callable[[Array], Array], w: float, cross_w: float, taylor: bool = False
):
    """Propagate sigma points through ``g``; return mean, cov, cross-cov (centred form).

    ``cross_w = beta - alpha^2`` weights the ``delta delta^T`` correction; ``taylor``
    selects the AD differences (see ``_centred_differences_taylor``).
    """
    differences = _centred_differences_taylor if taylor else _centred_differences_direct
    y0, dy = differences(points, g)
    dx = points.offsets
    delta_y = w * jnp.sum(dy, axis=0)
    delta_x = w * jnp.sum(dx, axis=0)
    mean = y0 + delta_y
    cov = w * dy.T @ dy + cross_w * jnp.outer(delta_y, delta_y)
    cross = w * dx.T @ dy + cross_w * jnp.outer(delta_x, delta_y)
    return mean, _linalg.symmetrize(cov), cross


def unscented_kalman_filter(
    f: Callable[[Array, Array, Any], Array],
    h: Callable[[Array, Array, Any], Array],
    Q: Array,
    R: Array,
    params: Any = None,
    alpha: float = 1e-3,
    beta: float = 2.0,
    kappa: float = 0.0,
    sigma_differences: str = "auto",
    missing_measurements: bool = False,
) -> Filter:
    """UKF for ``x[k+1] = f(x, u, params) + w``, ``y = h(x, u, params) + v``.

    Sigma points are redrawn from ``N(m, P)`` before each measurement update (so the
    additive ``Q`` is felt by the predicted measurement), as in filterpy >= 2.

    Args:
      f, h: pure functions of ``(x (n,), u (nu,), params)``.
      Q: (n, n), R: (m, m) additive noise covariances.
      params: pytree passed to ``f`` and ``h``.
      alpha, beta, kappa: scaled-UT parameters (static). ``beta >= alpha^2`` keeps the
        centred covariance positive semi-definite.
      sigma_differences: how ``g(c + s_i) - g(c)`` is formed. ``"direct"`` evaluates
        ``g`` at each sigma point (the textbook UT). ``"taylor"`` uses the second-order
        expansion by nested ``jax.jvp`` (exact as alpha -> 0, error O(alpha^2)), which
        stays accurate in float32 where direct differences of points only
        ``alpha * sigma`` apart lose most of their digits. ``"auto"`` (default) picks
        ``"taylor"`` for float32 and narrower states with ``alpha <= 1e-2``, else
        ``"direct"``.
      missing_measurements: treat NaN components of ``y`` as not measured (static).
    """
    n = _checks.check_covariance("Q", Q)
    m = _checks.check_covariance("R", R)
    if not (alpha > 0):
        raise ValueError(f"alpha: expected a positive scalar, got {alpha}")
    if n + alpha**2 * (n + kappa) - n <= 0:
        raise ValueError(f"kappa: expected alpha^2 (n + kappa) > 0 for n = {n}, got kappa = {kappa}")
    w, _, _ = unscented_weights(n, alpha, beta, kappa)
    scale = (alpha**2 * (n + kappa)) ** 0.5
    cross_w = beta - alpha**2
    if sigma_differences not in ("auto", "direct", "taylor"):
        raise ValueError(f"sigma_differences: expected 'auto', 'direct' or 'taylor', got {sigma_differences!r}")

    def use_taylor(mean: Array) -> bool:
        if sigma_differences != "auto":
            return sigma_differences == "taylor"
        return bool(jnp.finfo(mean.dtype).eps > 1e-10 and alpha <= 1e-2)

    def update(state: GaussianState, y: Array, u: Array) -> ConditionedGaussian:
        check_step_inputs(y, u, m, None)
        taylor = use_taylor(state.mean)
        points, _ = sigma_points(state.mean, state.cov, scale)
        y_pred, Pyy, Pxy = unscented_moments(points, lambda x: h(x, u, params), w, cross_w, taylor)
        _checks.check_shape("h(x, u, params)", y_pred, (m,), "one predicted measurement")
        S = _linalg.symmetrize(Pyy + R)
        if missing_measurements:
            mask, y_obs, num_observed = observed_mask(y)
            innovation = jnp.where(mask, y_obs - y_pred, 0.0)
            S = mask_innovation_cov(S, mask)
            Pxy = jnp.where(mask[None, :], Pxy, 0.0)
        else:
            innovation, num_observed = y - y_pred, jnp.asarray(m, jnp.int32)
        chol_S = _linalg.cholesky(S)
        gain = _linalg.gain_from_cross_cov(Pxy, chol_S)
        whitened = _linalg.whiten(chol_S, innovation)
        # P - K S K^T = P - (L^-1 Pxy^T)^T (L^-1 Pxy^T)
        half = _linalg.whiten(chol_S, Pxy.T)
        return ConditionedGaussian(
            mean=state.mean + gain @ innovation,
            cov=_linalg.symmetrize(state.cov - half.T @ half),
            innovation=innovation,
            innovation_cov=S,
            log_likelihood=_linalg.gaussian_log_likelihood(whitened, chol_S, num_observed),
            nis=jnp.sum(whitened**2),
            num_observed=num_observed,
            healthy=_linalg.cholesky_is_finite(chol_S),
        )

    def predict(post: GaussianState, u: Array) -> GaussianState:
        points, _ = sigma_points(post.mean, post.cov, scale)
        next_mean, next_cov, _ = unscented_moments(points, lambda x: f(x, u, params), w, cross_w, use_taylor(post.mean))
        _checks.check_shape("f(x, u, params)", next_mean, (n,), "the next state")
        return GaussianState(next_mean, _linalg.symmetrize(next_cov + Q))

    return gaussian_filter(n, update, predict)
