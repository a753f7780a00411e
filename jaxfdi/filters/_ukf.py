"""Unscented Kalman filter: scaled UT (Julier 2002; Wan & van der Merwe 2000), additive noise, Cholesky sigma points.

Sigma points ``X0 = m``, ``X(+/-)i = m +/- sqrt(L + lambda) col_i(chol P)``, ``lambda = alpha^2 (L + kappa) - L``,
weights ``Wm0 = lambda / (L + lambda)``, ``Wc0 = Wm0 + 1 - alpha^2 + beta``, ``Wi = 1 / (2 (L + lambda))``. Update
``K = Pxy S^-1``, ``P+ = P - K S K^T`` (Park et al. 2004, eq. 29 corrected), in a Joseph-like form (below).

Centred form (the float32 fix): with small ``alpha`` the centre weights are huge and negative (``alpha = 1e-3``:
``Wc0 ~ -1e6``) and the textbook sums ``sum_i Wc_i (Y_i - ybar)(Y_i - ybar)^T`` cancel catastrophically in float32
(indefinite covariance, NaN). With ``d_i = Y_i - Y_0``, ``delta = sum_{i>0} W_i d_i`` the same moments are exactly
(using ``sum_i Wm_i = 1``, ``Wc_i = Wm_i`` for ``i > 0``)

    mean = Y_0 + delta,
    cov  = sum_{i>0} W_i d_i d_i^T + (beta - alpha^2) delta delta^T,
    Pxy  = sum_{i>0} W_i dx_i dy_i^T + (beta - alpha^2) delta_x delta_y^T,

with moderate positive weights: PSD by construction for ``beta >= alpha^2``. The +/- offsets are rounded
symmetrically (``s = (m + s) - m``) so a map's linear part cancels exactly in ``delta``.

Joseph-like update (PSD by construction): ``P - K S K^T`` subtracts nearly equal matrices when the measurement is
much more precise than the prior (variance 1e-24, or ``P0 = 1e12 I``), and round-off ``eps ||P||`` exceeds the true
posterior variance. The statistical linearisation ``H = Pxy^T P^-1`` (Lefebvre, Bruyninckx & De Schutter 2002) and
residuals ``e_i = d_i - H dx_i`` split ``Pyy = H P H^T + Lambda`` exactly, with PSD
``Lambda = sum_{i>0} W_i e_i e_i^T + (beta - alpha^2) delta delta^T``, so that exactly
``P+ = P - K S K^T = (I - K H) P (I - K H)^T + K (R + Lambda) K^T``, the EKF's Joseph form (Bucy & Joseph 1968)
with noise ``R + Lambda``, formed as ``F F^T + G G^T + (beta - alpha^2) (K delta)(K delta)^T + K R K^T``
(``F = (I - K H) chol P``, ``G = K [sqrt(W_i) e_i]``): for ``beta >= alpha^2`` a sum of Gram matrices, indefinite by
at most ``eps`` of its own size. For a linear ``h``, ``Lambda = 0``: the EKF's/KF's Joseph update.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import (
    Filter,
    FilterInfo,
    GaussianState,
    ModelFunction,
    check_step_inputs,
    dead_components,
    gaussian_filter,
    mask_innovation_cov,
    observed_mask,
    report_dead,
    used_innovation,
)


class SigmaPoints(NamedTuple):
    """Sigma points in centred form: the centre and the 2L offsets from it.

    Attributes:
      centre: (n,)
      offsets: (2n, n): +s_1..+s_n, -s_1..-s_n
    """

    centre: Array
    offsets: Array


def unscented_weights(
    n: int, alpha: float, beta: float, kappa: float
) -> tuple[float, float, float]:
    """``(Wi, Wm0, Wc0)`` of the scaled unscented transform for state size ``n``; ``n + lambda = alpha^2 (n + kappa)``
    is formed directly (as ``n + lambda`` it cancels, ``alpha = 1e-3``: ``3 + (3e-6 - 3)``, losing ~1e-10)."""
    spread = alpha**2 * (n + kappa)  # n + lambda
    w = 1.0 / (2.0 * spread)
    wm0 = 1.0 - n / spread  # lambda / (n + lambda)
    return w, wm0, wm0 + 1.0 - alpha**2 + beta


def sigma_points(mean: Array, cov: Array, scale: float) -> tuple[SigmaPoints, Array]:
    """Centred sigma points ``m +/- scale * col_i(chol P)``; also returns ``chol P``."""
    chol = _linalg.cholesky(cov)
    plus = mean[None, :] + scale * chol.T  # rows = m + s_i
    s = plus - mean[None, :]  # symmetric rounding
    return SigmaPoints(mean, jnp.concatenate([s, -s], axis=0)), chol


def _centred_differences_direct(
    points: SigmaPoints, g: Callable[[Array], Array]
) -> tuple[Array, Array]:
    """``(g(c), d_i = g(c + s_i) - g(c))`` by evaluating ``g`` at every sigma point."""
    y0 = g(points.centre)
    ys = jax.vmap(g)(points.centre[None, :] + points.offsets)
    return y0, ys - y0[None, :]


def _centred_differences_taylor(
    points: SigmaPoints, g: Callable[[Array], Array]
) -> tuple[Array, Array]:
    """``d(+/-i) = +/- J s_i + (1/2) s_i^T H s_i`` by nested forward-mode AD: the second-order Taylor expansion of
    ``g(c +/- s_i) - g(c)``, no subtraction of nearly equal numbers, so full relative precision in float32.
    Truncation error O(|s|^3) per point, O(alpha^2) relative in the moments: exact scaled UT as ``alpha -> 0``.
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
    """Propagate sigma points through ``g``: mean, cov, cross-cov (centred form); ``cross_w = beta - alpha^2``
    weights the ``delta delta^T`` term, ``taylor`` selects the AD differences (``_centred_differences_taylor``).
    """
    y0, dy = _propagate(points, g, taylor)
    return _moments(points, y0, dy, w, cross_w)


def _propagate(
    points: SigmaPoints, g: Callable[[Array], Array], taylor: bool
) -> tuple[Array, Array]:
    """``(g(c), d_i = g(c + s_i) - g(c))`` by direct evaluation or by the Taylor form."""
    differences = _centred_differences_taylor if taylor else _centred_differences_direct
    return differences(points, g)


def _moments(
    points: SigmaPoints, y0: Array, dy: Array, w: float, cross_w: float
) -> tuple[Array, Array, Array]:
    dx = points.offsets
    delta_y = w * jnp.sum(dy, axis=0)
    delta_x = w * jnp.sum(dx, axis=0)
    mean = y0 + delta_y
    cov = w * dy.T @ dy + cross_w * jnp.outer(delta_y, delta_y)
    cross = w * dx.T @ dy + cross_w * jnp.outer(delta_x, delta_y)
    return mean, _linalg.symmetrize(cov), cross


def joseph_like_cov(
    chol: Array,
    points: SigmaPoints,
    dy: Array,
    cross_cov: Array,
    gain: Array,
    R: Array,
    w: float,
    cross_w: float,
) -> Array:
    """``P - K S K^T`` as ``(I - K H) P (I - K H)^T + K (R + Lambda) K^T`` (module doc).

    Args:
      chol: (n, n) lower Cholesky factor of the prior ``P`` (the sigma points' factor).
      points: the sigma points (offsets ``dx_i``, (2n, n)).
      dy: (2n, m) measurement differences ``d_i``.
      cross_cov: (n, m) ``Pxy`` (columns of missing measurements zeroed).
      gain: (n, m) ``K = Pxy S^-1``.
      R: (m, m) measurement-noise covariance.
      w, cross_w: ``W_i`` and ``beta - alpha^2``.
    """
    mm = _linalg.matmul
    whitened_cross = _linalg.solve_lower(chol, cross_cov)  # B = L^-1 Pxy, so H L = B^T
    linearisation_t = _linalg.solve_lower_transposed(chol, whitened_cross)  # H^T = P^-1 Pxy, (n, m)
    residuals = dy - mm(points.offsets, linearisation_t)  # e_i = d_i - H dx_i, (2n, m)
    contraction = chol - mm(gain, whitened_cross.T)  # (I - K H) L = L - K B^T
    spread = mm(jnp.sqrt(w) * residuals, gain.T)  # rows sqrt(W_i) K e_i
    centre = mm(gain, w * jnp.sum(dy, axis=0))  # K delta
    cov = (
        mm(contraction, contraction.T)
        + mm(spread.T, spread)
        + cross_w * jnp.outer(centre, centre)
        + mm(mm(gain, R), gain.T)
    )
    return _linalg.symmetrize(cov)


def scaled_transform(f, h, Q, R, alpha, beta, kappa, sigma_differences: str):
    """Check a UKF's arguments at build time; return ``(n, m, alpha, beta, w, scale, use_taylor)``: sizes, static
    scaled-UT parameters as floats, weights (``unscented_weights``), ``sqrt(alpha^2 (n + kappa))`` and whether a
    mean of a given dtype takes Taylor-form differences (``sigma_differences``)."""
    checks.check_callable("f", f, "a transition function f(x, u, params)")
    checks.check_callable("h", h, "a measurement function h(x, u, params)")
    n = checks.check_covariance("Q", Q)
    m = checks.check_covariance("R", R)
    for name, value in (("alpha", alpha), ("beta", beta), ("kappa", kappa)):
        checks.check_real(name, value, "a real scalar (static)")
        if checks.concrete(value) is None:
            raise TypeError(
                f"{name}: expected a Python float (a static scaled-UT parameter), "
                f"got {checks.received(value)}"
            )
    checks.check_positive("alpha", alpha, "a positive scalar")
    checks.check_scalar("beta", beta, meaning="a real scalar")
    checks.check_scalar("kappa", kappa, meaning="a real scalar")
    alpha, beta, kappa = float(alpha), float(beta), float(kappa)
    if alpha**2 * (n + kappa) <= 0:
        raise ValueError(
            f"kappa: expected alpha^2 (n + kappa) > 0 for n = {n}, got kappa = {kappa}"
        )
    if sigma_differences not in ("auto", "direct", "taylor"):
        raise ValueError(
            f"sigma_differences: expected 'auto', 'direct' or 'taylor', got {sigma_differences!r}"
        )
    w, _, _ = unscented_weights(n, alpha, beta, kappa)

    def use_taylor(mean: Array) -> bool:
        if sigma_differences != "auto":
            return sigma_differences == "taylor"
        return bool(jnp.finfo(mean.dtype).eps > 1e-10 and alpha <= 1e-2)

    return n, m, alpha, beta, w, (alpha**2 * (n + kappa)) ** 0.5, use_taylor


def unscented_kalman_filter(
    f: ModelFunction,
    h: ModelFunction,
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

    Sigma points are redrawn from ``N(m, P)`` before each update (the additive ``Q`` reaches the predicted
    measurement), as in filterpy >= 2.

    Args:
      f, h: pure functions of ``(x (n,), u (nu,), params)``.
      Q: (n, n), R: (m, m) additive noise covariances.
      params: pytree passed to ``f`` and ``h``.
      alpha, beta, kappa: scaled-UT parameters (static); ``beta >= alpha^2`` keeps the covariance PSD.
      sigma_differences: how ``g(c + s_i) - g(c)`` is formed: ``"direct"`` evaluates ``g`` at each sigma point
        (textbook UT); ``"taylor"``: second-order expansion by nested ``jax.jvp`` (error O(alpha^2)), accurate in
        float32 where direct differences of points ``alpha * sigma`` apart lose most digits; ``"auto"`` (default):
        ``"taylor"`` for float32 and narrower with ``alpha <= 1e-2``, else ``"direct"``.
      missing_measurements: treat NaN components of ``y`` as not measured (static).

    Returns:
      ``Filter(init, step, update, predict)``: ``init(mean (n,), cov (n, n)) -> GaussianState``;
      ``step(state, y (m,), u) -> (GaussianState, FilterInfo)``, unscented update then prediction through ``f``.
    """
    n, m, alpha, beta, w, scale, use_taylor = scaled_transform(
        f, h, Q, R, alpha, beta, kappa, sigma_differences
    )
    cross_w = beta - alpha**2

    def update(state: GaussianState, y: Array, u: Array) -> FilterInfo:
        check_step_inputs(y, u, m, None)
        taylor = use_taylor(state.mean)
        points, chol = sigma_points(state.mean, state.cov, scale)
        y0, dy = _propagate(points, lambda x: h(x, u, params), taylor)
        y_pred, Pyy, Pxy = _moments(points, y0, dy, w, cross_w)
        checks.check_shape("h(x, u, params)", y_pred, (m,), "one predicted measurement")
        S = _linalg.symmetrize(Pyy + R)
        if missing_measurements:
            mask, y_obs, num_observed = observed_mask(y)
            innovation = jnp.where(mask, y_obs - y_pred, 0.0)
            S = mask_innovation_cov(S, mask)
            Pxy = jnp.where(mask[None, :], Pxy, 0.0)
        else:
            innovation, num_observed = (
                used_innovation(y, y_pred),
                jnp.sum(jnp.isfinite(y)).astype(jnp.int32),
            )
        chol_S = _linalg.cholesky(S)
        gain = _linalg.gain_from_cross_cov(Pxy, chol_S)
        whitened = _linalg.whiten(chol_S, innovation)
        mean = state.mean + gain @ innovation
        reported, nis = report_dead(
            innovation, jnp.sum(whitened**2), dead_components(y, missing_measurements)
        )
        return FilterInfo(
            predicted_mean=state.mean,
            predicted_cov=state.cov,
            filtered_mean=mean,
            filtered_cov=joseph_like_cov(chol, points, dy, Pxy, gain, R, w, cross_w),
            innovation=reported,
            innovation_cov=S,
            log_likelihood=_linalg.gaussian_log_likelihood(
                whitened, chol_S, num_observed if missing_measurements else m
            ),
            nis=nis,
            num_observed=num_observed,
            healthy=(
                _linalg.cholesky_is_finite(chol_S)
                & _linalg.cholesky_is_finite(chol)
                & jnp.all(jnp.isfinite(mean))
            ),
        )

    def predict(post: GaussianState, u: Array) -> GaussianState:
        points, _ = sigma_points(post.mean, post.cov, scale)
        next_mean, next_cov, _ = unscented_moments(
            points, lambda x: f(x, u, params), w, cross_w, use_taylor(post.mean)
        )
        checks.check_shape("f(x, u, params)", next_mean, (n,), "the next state")
        return GaussianState(next_mean, _linalg.symmetrize(next_cov + Q))

    return gaussian_filter(n, update, predict)
