"""The state chi-square test (SCST) with Da's two periodically reset propagators.

Da (1994): the filter's ``x_f`` against a *propagator* ``x_m`` (the model run without measurements from
a reset to ``x_f``). Fault-free ``beta = x_m - x_f`` is zero-mean, covariance ``B = P_m - P_f``, so

    l(k) = beta^T B^-1 beta ~ chi2(15)       (Yoo et al. 2010, eqs. 2-4; threshold 32.80 at 0.005)

Error-state form (Yoo et al. 2010, Fig. 3), with feedback (the filter jumps by ``dx[k|k]``, the
propagator does not; both drift alike between epochs):

    beta[k|k] = beta[k|k-1] + dx[k|k],     beta[k+1|k] = Phi_k beta[k|k],
    P_m[k+1] = Phi_k P_m[k] Phi_k^T + Q_k,  B(k) = P_m(k) - P_f[k|k].

A reset (``beta = 0``, ``P_m = P_f[k|k]``) makes ``B = 0`` singular, so two propagators are reset alternately every
``period`` epochs, half a period apart, and the older one is tested (never younger than ``period / 2``, except in the
first ``period / 2`` epochs). Resets ignore the decisions, so an alarm clears at most ``period`` epochs after its cause
(a propagator kept through an alarm would hold it for ever after a transient fault).

``B`` is checked: scaled to unit diagonal (``D^-1/2 B D^-1/2``), Cholesky-factored; *valid* only if every diagonal entry
is positive, the factor finite and ``(max pivot / min pivot)^2`` (a lower bound of the condition number)
<= ``max_condition``. An invalid epoch decides nothing (alarm False, statistic 0; ``valid``, ``condition`` say so).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.detection import Decision

#: largest accepted condition estimate of the scaled B (float64 solves keep ~6 digits of l); B nears it on
#: straight legs (nothing learnt on heading and z gyro bias since the reset: their rows nearly dependent)
DEFAULT_MAX_CONDITION = 1e10


class ScstState(NamedTuple):
    """The state chi-square test's carry: two staggered propagators.

    Attributes:
      difference: (2, n) beta[k|k-1] of propagators a and b
      cov: (2, n, n) P_m[k|k-1]
      age: (2,) int, epochs since each propagator's reset (-1: not started)
      epoch: () int, epochs seen
    """

    difference: Array
    cov: Array
    age: Array
    epoch: Array


class ScstOutput(NamedTuple):
    """One epoch of the state chi-square test.

    Attributes:
      decision: statistic l (0 when invalid), alarm, label -1, estimate NaN
      valid: () bool: B passed the checks
      condition: () float: condition estimate of the scaled B (inf when not PD)
      used: () int: the propagator tested (0 = a, 1 = b)
      age: () int: its age [epochs]
      reset: (2,) bool: propagators reset at this epoch
    """

    decision: Decision
    valid: Array
    condition: Array
    used: Array
    age: Array
    reset: Array


class StateChi2Test(NamedTuple):
    """``init(n) -> state``; ``step(state, correction, filtered_cov, transition,
    process_cov) -> (state, ScstOutput)``, once per epoch after the filter's update."""

    init: callable
    step: callable


def scst_statistic(
    difference: Array, cov_difference: Array, max_condition: float
) -> tuple[Array, Array, Array]:
    """``(l, valid, condition)`` of ``beta^T B^-1 beta`` with the checks of the module doc."""
    diagonal = jnp.diagonal(cov_difference)
    positive = jnp.all(diagonal > 0)
    scale = jnp.sqrt(jnp.where(diagonal > 0, diagonal, 1.0))
    scaled = cov_difference / (scale[:, None] * scale[None, :])
    chol = jnp.linalg.cholesky(_linalg.symmetrize(scaled))
    pivots = jnp.diagonal(chol)
    finite = jnp.all(jnp.isfinite(chol))
    condition = jnp.where(finite & positive, (jnp.max(pivots) / jnp.min(pivots)) ** 2, jnp.inf)
    whitened = jax.scipy.linalg.solve_triangular(
        jnp.where(finite, chol, jnp.eye(chol.shape[0], dtype=chol.dtype)),
        difference / scale,
        lower=True,
    )
    valid = finite & positive & (condition <= max_condition)
    return jnp.where(valid, jnp.sum(whitened**2), 0.0), valid, condition


def state_chi2_test(
    period: int, threshold, max_condition: float = DEFAULT_MAX_CONDITION
) -> StateChi2Test:
    """Da's SCST with two propagators reset every ``period`` epochs (module doc).

    Args:
      period: epochs between resets of one propagator (even, >= 2).
      threshold: alarm when ``l > threshold`` (``chi2_threshold(15, pfa)``: 32.80 at 0.005).
      max_condition: largest accepted condition estimate of the scaled ``B``.

    Returns:
      ``StateChi2Test(init, step)``: ``init(n, dtype=None) -> ScstState`` (not yet started);
      ``step(state, correction, filtered_cov, transition, process_cov) -> (state, ScstOutput)`` with (n,)
      ``dx[k|k]``, (n, n) ``P[k|k]``, ``Phi_k``, ``Q_k``; the state at ``k + 1``.
    """
    period = checks.check_int("period", period, 2, meaning="an even number of epochs >= 2")
    if period % 2:
        raise ValueError(
            f"period: expected an even number of epochs (the propagators are half a period apart), "
            f"got {period}"
        )
    checks.check_real("threshold", threshold, "a real threshold")
    checks.check_finite("threshold", threshold, "a detection threshold")
    checks.check_positive("max_condition", max_condition, "a positive condition-number limit")
    offsets = jnp.asarray([0, period // 2])

    def init(n: int, dtype=None) -> ScstState:
        dtype = dtype or jnp.result_type(float)
        return ScstState(
            jnp.zeros((2, n), dtype),
            jnp.zeros((2, n, n), dtype),
            jnp.full((2,), -1, jnp.int32),
            jnp.zeros((), jnp.int32),
        )

    def step(
        state: ScstState,
        correction: Array,
        filtered_cov: Array,
        transition: Array,
        process_cov: Array,
    ):
        n = checks.shape_of(state.difference)[-1]
        checks.check_shape("correction", correction, (n,), "the filter's correction dx[k|k]")
        for name, value in (
            ("filtered_cov", filtered_cov),
            ("transition", transition),
            ("process_cov", process_cov),
        ):
            checks.check_shape(name, value, (n, n), f"the filter's {n} x {n} matrix")
        started = state.age >= 0
        difference = jnp.where(started[:, None], state.difference + correction, 0.0)
        cov = jnp.where(started[:, None, None], state.cov, filtered_cov)
        age = jnp.maximum(state.age, 0)
        used = jnp.argmax(age).astype(jnp.int32)
        used_age = age[used]
        statistic, valid, condition = scst_statistic(
            difference[used], cov[used] - filtered_cov, max_condition
        )
        alarm = valid & (statistic > threshold)
        reset = (
            (state.epoch > 0)
            & (jnp.mod(state.epoch - offsets, period) == 0)
            & (state.epoch >= offsets)
        )
        difference = jnp.where(reset[:, None], 0.0, difference)
        cov = jnp.where(reset[:, None, None], filtered_cov, cov)
        age = jnp.where(reset, 0, age)
        propagated = jnp.einsum("ij,pj->pi", transition, difference)
        cov = jnp.einsum("ij,pjk,lk->pil", transition, cov, transition) + process_cov
        decision = Decision(
            statistic, alarm, jnp.asarray(-1, jnp.int32), jnp.full((), jnp.nan, statistic.dtype)
        )
        out = ScstOutput(decision, valid, condition, used, used_age, reset)
        return ScstState(propagated, _linalg.symmetrize(cov), age + 1, state.epoch + 1), out

    return StateChi2Test(init, step)
