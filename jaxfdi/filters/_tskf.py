"""Two-stage Kalman filter (TSKF) for a random-walk fault bias, optimal or robust to an unknown input (Keller &
Darouach 1997; Hsieh & Chen 1999; Keller, Darouach & Caramelle 1998; Lee & Lyou, Section III).

Plant, ``b`` the fault bias (``p`` components), ``d`` an unknown input::

    x[k+1] = Phi x[k] + Gamma u[k] + Fa[k] b[k] + E d[k] + w[k],   w ~ N(0, Q)
    b[k+1] = b[k] + wb[k],                                          wb ~ N(0, Qb)
    y[k]   = C x[k] + D u[k] + Fs[k] b[k] + v[k],                   v ~ N(0, R)

The augmented prior of ``[x; b]`` is factored as ``x = x_bar + V b`` (``x_bar`` independent of ``b``): a
bias-free filter ``(x_bar, P_bar)``, a bias filter ``(b, Pb)`` and the coupling ``V``; exactly the augmented-state
KF (the module's test) at the cost of an n-state and a p-state filter. One step, ``H_b = C V + Fs``:

* bias-free update: ``r_bar = y - C x_bar - D u``, ``S_bar = C P_bar C^T + R``, gain ``K_bar`` (Kalman; with an
  unknown input the unbiased minimum-variance gain of Kitanidis 1987, ``(I - K_bar C) E = 0``),
  ``x_bar += K_bar r_bar``, Joseph ``P_bar``, ``V -= K_bar H_b``;
* bias update in whitened coordinates ``e = N^T L^-1 (r_bar - H_b b)`` (``S_bar = L L^T``; ``N`` an orthonormal
  basis of the complement of ``L^-1 C E``, identity without unknown input): ``G = N^T L^-1 H_b``,
  ``S_b = G Pb G^T + I``, ``b += Pb G^T S_b^-1 e``;
* predict (optimal coupling of Hsieh & Chen): ``U = Phi V + Fa``, ``Pb' = Pb + Qb``, ``V' = U Pb Pb'^-1``,
  ``x_bar' = Phi x_bar + Gamma u + (U - V') b``, ``P_bar' = Phi P_bar Phi^T + Q + U Pb U^T - V' Pb' V'^T``.

The unknown input has infinite (diffuse) variance: that limit of the augmented KF is Kitanidis's filter, which
factors as above, the bias filter seeing only the part of ``y`` that ``C E d`` cannot reach. Test statistic
``lambda = e^T S_b^-1 e ~ chi2(m - q)`` under the filter's fault hypothesis; it equals ``r^T W^+ r`` for the paper's
residual ``r = y - C x[k|k] - D u - Fs b[k|k]`` (eqs. 13, 15), ``W = T S T^T`` its exact covariance (eq. 17 is
misprinted; ``T``: augmented innovation -> ``r``), and without unknown input the augmented filter's NIS.
Time-varying directions (``FaultDirection``): effectiveness loss ``Gamma (I - diag(xi)) u`` has
``Fa[k] = -Gamma diag(u[k])`` (``input_scaled``), sensor scaling ``(I + diag(xi)) C x`` has ``Fs[k] = diag(C x_hat)``
(``output_scaled``) at the prior mean ``x[k|k-1]`` (the paper's ``x[k|k]`` does not exist yet).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.filters._base import Filter, check_gaussian, check_step_inputs, report_dead
from jaxfdi.filters._driver import run_filter
from jaxfdi.filters._unknown_input import (
    check_decoupling,
    diffuse_log_likelihood,
    unbiased_minimum_variance_gain,
)
from jaxfdi.models import LinearGaussianModel, validate_linear_model


class FaultDirection(NamedTuple):
    """How a bias ``b`` (p,) enters: ``Fa[k] = state + Gamma (input_scaled * u[k][:, None])`` (n, p),
    ``Fs[k] = output + (C x_hat + D u)[:, None] * output_scaled`` (m, p). A pytree: banks vmap over stacked ones.

    Attributes:
      state: (n, p) constant actuator distribution
      input_scaled: (nu, p) Fa gains proportional to u (effectiveness: -e_i)
      output: (m, p) constant sensor distribution
      output_scaled: (m, p) Fs gains proportional to the predicted output (scaling: e_j)
    """

    state: Array
    input_scaled: Array
    output: Array
    output_scaled: Array


def actuator_direction(
    model: LinearGaussianModel, component: int, kind: str = "effectiveness"
) -> FaultDirection:
    """One actuator's fault direction: ``"effectiveness"`` (``Fa = -Gamma[:, i] u_i``, bias = lost fraction) or
    ``"additive"`` (``Fa = -Gamma[:, i]``, bias = amount subtracted from ``u_i``).

    Returns:
      ``FaultDirection`` of one bias (p = 1) in ``Phi``'s dtype: ``input_scaled = -e_i`` (nu, 1) for
      ``"effectiveness"``, ``state = -Gamma[:, i]`` (n, 1) for ``"additive"``; the other fields zero.
    """
    n, nu, m = validate_linear_model(model)
    checks.check_choice("kind", kind, ["effectiveness", "additive"])
    component = checks.check_int("component", component, 0, nu - 1, "an input index")
    e = jnp.zeros((nu, 1), model.Phi.dtype).at[component, 0].set(-1.0)
    zeros_m = jnp.zeros((m, 1), model.Phi.dtype)
    if kind == "effectiveness":
        return FaultDirection(jnp.zeros((n, 1), model.Phi.dtype), e, zeros_m, zeros_m)
    if kind == "additive":
        return FaultDirection(jnp.asarray(model.Gamma) @ e, jnp.zeros_like(e), zeros_m, zeros_m)
    raise ValueError(f"kind: expected 'effectiveness' or 'additive', got {kind!r}")


def sensor_direction(
    model: LinearGaussianModel, component: int, kind: str = "scaling"
) -> FaultDirection:
    """One sensor's fault direction: ``"scaling"`` (``Fs = e_j (C x_hat + D u)_j``, bias = relative gain error) or
    ``"additive"`` (``Fs = e_j``, bias added to ``y_j``).

    Returns:
      ``FaultDirection`` of one bias (p = 1) in ``Phi``'s dtype: ``output_scaled = e_j`` (m, 1) for ``"scaling"``,
      ``output = e_j`` (m, 1) for ``"additive"``; the other fields zero.
    """
    n, nu, m = validate_linear_model(model)
    checks.check_choice("kind", kind, ["scaling", "additive"])
    component = checks.check_int("component", component, 0, m - 1, "an output index")
    e = jnp.zeros((m, 1), model.Phi.dtype).at[component, 0].set(1.0)
    zeros = (jnp.zeros((n, 1), model.Phi.dtype), jnp.zeros((nu, 1), model.Phi.dtype))
    if kind == "scaling":
        return FaultDirection(*zeros, jnp.zeros_like(e), e)
    if kind == "additive":
        return FaultDirection(*zeros, e, jnp.zeros_like(e))
    raise ValueError(f"kind: expected 'scaling' or 'additive', got {kind!r}")


def stack_directions(directions: list[FaultDirection]) -> FaultDirection:
    """Stack directions with the same bias size along a leading bank axis.

    Returns:
      ``FaultDirection`` whose leaves have a leading axis of ``len(directions)``: (B, n, p), (B, nu, p), (B, m, p),
      (B, m, p).
    """
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *directions)


def actuator_matrix(direction: FaultDirection, model: LinearGaussianModel, u: Array) -> Array:
    """``Fa[k]`` (n, p) for the input ``u[k]``."""
    return direction.state + _linalg.matmul(model.Gamma, direction.input_scaled * u[:, None])


def sensor_matrix(
    direction: FaultDirection, model: LinearGaussianModel, x_hat: Array, u: Array
) -> Array:
    """``Fs[k]`` (m, p) at the state estimate ``x_hat``.

    Returns:
      (m, p) sensor fault matrix ``output + (C x_hat + D u)[:, None] * output_scaled`` for the (n,) ``x_hat`` and the
      (nu,) ``u[k]``.
    """
    y_hat = _linalg.matmul(model.C, x_hat) + _linalg.matmul(model.D, u)
    return direction.output + y_hat[:, None] * direction.output_scaled


class TSKFState(NamedTuple):
    """Prior of step k in two-stage form: ``x = x_bar + coupling b``.

    Attributes:
      bias_free_mean: (n,) x_bar[k|k-1]
      bias_free_cov: (n, n) P_bar[k|k-1]
      bias_mean: (p,) b[k|k-1]
      bias_cov: (p, p) Pb[k|k-1]
      coupling: (n, p) V[k|k-1]
    """

    bias_free_mean: Array
    bias_free_cov: Array
    bias_mean: Array
    bias_cov: Array
    coupling: Array


class TSKFInfo(NamedTuple):
    """Per-step outputs of the two-stage filter.

    Attributes:
      filtered_mean: (n,) x[k|k] = x_bar + V b
      filtered_cov: (n, n) P[k|k] = P_bar + V Pb V^T
      bias_mean: (p,) b[k|k], the fault estimate
      bias_cov: (p, p) Pb[k|k]
      residual: (m,) r = y - C x[k|k] - D u - Fs b[k|k] (eqs. 13, 15); NaN where y is dead
      residual_cov: (m, m) W, its exact covariance (rank m - q)
      statistic: () lambda = r^T W^+ r ~ chi2(m - q) under the filter's hypothesis; +inf
          with a dead (non-finite) component of y, which the update did not use
      log_likelihood: () log-density of the decoupled innovation
      healthy: () bool: S_bar, S_b, P[k|k] positive definite, all finite
    """

    filtered_mean: Array
    filtered_cov: Array
    bias_mean: Array
    bias_cov: Array
    residual: Array
    residual_cov: Array
    statistic: Array
    log_likelihood: Array
    healthy: Array


def tskf_statistic_dof(model: LinearGaussianModel, unknown_input: Array | None = None) -> int:
    """Degrees of freedom ``m - q`` of the chi-square TSKF statistic ``lambda`` (``TSKFInfo.statistic``), ``m``
    outputs, ``q = rank(E)`` decoupled unknown inputs (0 without ``unknown_input``); e.g.
    ``chi2_threshold(tskf_statistic_dof(model, E), pfa)``. Checks decoupling as ``two_stage_kalman_filter`` does."""
    _, _, m = validate_linear_model(model)
    return m - (0 if unknown_input is None else check_decoupling(model, unknown_input))


def two_stage_kalman_filter(
    model: LinearGaussianModel,
    direction: FaultDirection,
    bias_walk: Array,
    unknown_input: Array | None = None,
) -> Filter:
    """Two-stage Kalman filter for the bias along ``direction``; robust to ``E d`` if given.

    Args:
      model: the nominal ``LinearGaussianModel`` (``Q``, ``R`` of ``w``, ``v``).
      direction: a ``FaultDirection`` (a bias of size p).
      bias_walk: (p, p) covariance ``Qb`` of the bias random walk.
      unknown_input: (n, q) distribution ``E`` of an unknown input to decouple, ``rank(C E) = rank(E) = q <= m``
        (Lee & Lyou, eq. 5; checked at build time); ``None``: the optimal TSKF.

    Returns:
      ``Filter(init, step)``: ``init(mean, cov, bias_mean=None, bias_cov=None)`` (prior of the first step, ``x``
      and ``b`` independent; bias default 0 with zero covariance: fault-free at the start, ``bias_walk`` opens
      it); ``step(state, y, u) -> (state, TSKFInfo)``; run with ``run_filter``. ``TSKFInfo.statistic`` ~ chi2 with
      ``m - q`` dof under the filter's hypothesis (``m`` outputs, ``q = rank(E)``; 0 without ``unknown_input``).
    """
    n, nu, m = validate_linear_model(model)
    checks.check_shape("direction.state", direction.state, (n, None), "n states x p biases")
    p = checks.shape_of(direction.state)[1]
    checks.check_shape(
        "direction.input_scaled", direction.input_scaled, (nu, p), "nu inputs x p biases"
    )
    checks.check_shape("direction.output", direction.output, (m, p), "m outputs x p biases")
    checks.check_shape(
        "direction.output_scaled", direction.output_scaled, (m, p), "m outputs x p biases"
    )
    checks.check_covariance("bias_walk", bias_walk, p)
    q = 0 if unknown_input is None else check_decoupling(model, unknown_input)
    dof = m - q
    mm = _linalg.matmul

    def init(
        mean: Array, cov: Array, bias_mean: Array | None = None, bias_cov: Array | None = None
    ) -> TSKFState:
        mean, cov = check_gaussian(mean, cov, n)
        dtype = mean.dtype
        bias_mean = jnp.zeros((p,), dtype) if bias_mean is None else bias_mean
        bias_cov = jnp.zeros((p, p), dtype) if bias_cov is None else bias_cov
        bias_mean, bias_cov = check_gaussian(bias_mean, bias_cov, p, ("bias_mean", "bias_cov"))
        return TSKFState(
            mean,
            cov,
            jnp.asarray(bias_mean, dtype),
            jnp.asarray(bias_cov, dtype),
            jnp.zeros((n, p), dtype),
        )

    def step(state: TSKFState, y: Array, u: Array):
        check_step_inputs(y, u, m, nu)
        x_bar, P_bar, b, Pb, V = state
        prior_mean = x_bar + mm(V, b)
        Fs = sensor_matrix(direction, model, prior_mean, u)
        H_b = mm(model.C, V) + Fs  # (m, p)
        # a dead (non-finite) component takes its prediction: a zero innovation (filters._base)
        dead = ~jnp.isfinite(y)
        y = jnp.where(dead, mm(model.C, prior_mean) + mm(model.D, u) + mm(Fs, b), y)

        # bias-free filter
        r_bar = y - mm(model.C, x_bar) - mm(model.D, u)
        cross_cov = mm(P_bar, model.C.T)
        S_bar = _linalg.symmetrize(mm(model.C, cross_cov) + model.R)
        chol_S = _linalg.cholesky(S_bar)
        K_bar, basis = unbiased_minimum_variance_gain(cross_cov, chol_S, model.C, unknown_input)
        x_bar_post = x_bar + mm(K_bar, r_bar)
        P_bar_post = _linalg.joseph_cov(P_bar, K_bar, model.C, model.R)
        V_post = V - mm(K_bar, H_b)

        # bias filter on the decoupled, whitened innovation
        G = mm(basis.T, _linalg.solve_lower(chol_S, H_b))  # (m - q, p)
        e = mm(basis.T, _linalg.whiten(chol_S, r_bar - mm(H_b, b)))  # (m - q,)
        S_b = _linalg.symmetrize(mm(mm(G, Pb), G.T) + jnp.eye(dof, dtype=Pb.dtype))
        chol_Sb = _linalg.cholesky(S_b)
        K_b = _linalg.gain_from_cross_cov(mm(Pb, G.T), chol_Sb)  # (p, m - q)
        b_post = b + mm(K_b, e)
        Pb_post = _linalg.joseph_cov(Pb, K_b, G, jnp.eye(dof, dtype=Pb.dtype))
        statistic = jnp.sum(_linalg.whiten(chol_Sb, e) ** 2)
        S_aug = _linalg.symmetrize(S_bar + mm(mm(H_b, Pb), H_b.T))  # augmented S, without d
        log_lik = diffuse_log_likelihood(
            statistic, _linalg.cholesky(S_aug), model.C, unknown_input, dof
        )

        mean_post = x_bar_post + mm(V_post, b_post)
        cov_post = _linalg.symmetrize(P_bar_post + mm(mm(V_post, Pb_post), V_post.T))
        residual = y - mm(model.C, mean_post) - mm(model.D, u) - mm(Fs, b_post)

        # W = T S T^T, T the (linear) map from the augmented innovation to the residual
        def residual_of(innovation):
            db = mm(K_b, mm(basis.T, _linalg.whiten(chol_S, innovation)))
            dx = mm(K_bar, innovation) + mm(V_post, db)
            return innovation - mm(model.C, dx) - mm(Fs, db)

        T = jax.vmap(residual_of, in_axes=1, out_axes=1)(jnp.eye(m, dtype=y.dtype))
        residual_cov = _linalg.symmetrize(mm(mm(T, S_aug), T.T))

        # predict
        Fa = actuator_matrix(direction, model, u)
        U = mm(model.Phi, V_post) + Fa
        Pb_next = _linalg.symmetrize(Pb_post + bias_walk)
        V_next = _linalg.psd_solve(Pb_next, mm(U, Pb_post).T).T
        x_bar_next = mm(model.Phi, x_bar_post) + mm(model.Gamma, u) + mm(U - V_next, b_post)
        P_bar_next = _linalg.symmetrize(
            mm(mm(model.Phi, P_bar_post), model.Phi.T)
            + model.Q
            + mm(mm(U, Pb_post), U.T)
            - mm(mm(V_next, Pb_next), V_next.T)
        )
        healthy = (
            _linalg.cholesky_is_finite(chol_S)
            & _linalg.cholesky_is_finite(chol_Sb)
            & _linalg.cholesky_is_finite(_linalg.cholesky(cov_post))
            & jnp.all(jnp.isfinite(x_bar_next))
            & jnp.all(jnp.isfinite(b_post))
            & jnp.isfinite(statistic)
            & jnp.isfinite(log_lik)
        )
        residual, statistic = report_dead(residual, statistic, dead)
        info = TSKFInfo(
            mean_post,
            cov_post,
            b_post,
            Pb_post,
            residual,
            residual_cov,
            statistic,
            log_lik,
            healthy,
        )
        return TSKFState(x_bar_next, P_bar_next, b_post, Pb_next, V_next), info

    return Filter(init, step)


def run_tskf_bank(
    model: LinearGaussianModel,
    directions: FaultDirection,
    bias_walk: Array,
    init_mean: Array,
    init_cov: Array,
    init_bias_cov: Array,
    ys: Array,
    us: Array,
    unknown_input: Array | None = None,
) -> TSKFInfo:
    """Run a bank of TSKFs (Lee & Lyou's ``l + r`` actuator and sensor filters) on the same data: one filter vmapped
    over the stacked ``directions``.

    Args:
      model, bias_walk, unknown_input: as in ``two_stage_kalman_filter`` (shared).
      directions: ``FaultDirection`` with leaves (F, ...) (``stack_directions``).
      init_mean (n,), init_cov (n, n): prior of ``x[0]``; init_bias_cov (p, p): prior of ``b[0]`` (mean 0).
      ys: (T, m) measurements; us: (T, nu) inputs.

    Returns:
      ``TSKFInfo`` with leading axes (F, T).
    """
    leaves = jax.tree_util.tree_leaves(directions)
    if (
        any(np.ndim(leaf) != 3 for leaf in leaves)
        or len({np.shape(leaf)[0] for leaf in leaves}) != 1
    ):
        raise ValueError(
            "directions: expected a stack of FaultDirection (leaves of shape (F, *, p)); use stack_directions"
        )
    p = np.shape(directions.state)[-1]

    def one(direction):
        filt = two_stage_kalman_filter(model, direction, bias_walk, unknown_input)
        init = filt.init(
            init_mean, init_cov, jnp.zeros((p,), jnp.asarray(init_mean).dtype), init_bias_cov
        )
        return run_filter(filt, init, ys, us)[1]

    return jax.vmap(one)(directions)
