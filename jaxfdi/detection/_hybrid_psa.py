"""Hybrid FDI: parity space plus analytic redundancy from a filter restarted on demand (Park, Kim, Park & Roh
2004, Sec. 2.2), as an ``FDI`` stage of the loop (``jaxfdi._simulation.stages``).

At every step ``k`` (``observe``, before the controller):

1. **Detection** (PSA): ``p = V m``, ``FD = p^T p``, alarm when ``FD > T_D``.
2. **Isolation** (PSA): suspects = groups with ``FI_g > T_I`` (``parity``); one suspect is isolated, two or more
   (parity near a singular direction) go to 3.
3. **Analytic redundancy**: the filter restarts ``L = restart_lag`` steps before ``k`` ("2-3 steps before the
   detection, so that the estimate is not yet corrupted") from the all-channel least-squares estimate, covariance
   ``sigma^2 (H^T H)^-1``, and runs to ``k`` on the channels of groups PSA judged healthy (suspects' channels NaN),
   giving the suspects' ``r_g = m_g - H_g x_hat[k|k]`` (eq. 30);
4. the suspect with the larger ``||r_g||`` is isolated. The decision is made once, at the first alarm with at
   least one suspect, and latched.
5. **Verification** (beyond the paper; RAIM FDE exclusion, Parkinson & Axelrad 1988): from the next step,
   ``FD_-g = ||D_g (m - H x_-g)||^2`` (``x_-g`` least squares without group ``g``, ``D_g`` keeps the other channels)
   vs ``T_V = sigma^2 chi2_isf(m - d - n, P_V)``; on alarm the exclusion moves to the group whose removal leaves the
   smallest ``FD_-h``. A fault growing from zero (stuck, drift) is often decided near a singular direction, where
   the UKF restarted from a corrupted state cannot tell the suspects apart; the faulty channels left in view show it
   by their own redundancy (1 dof for three 2-DOF sensors).

The controller's view is the least-squares state of the channels left (``exclusion_estimators``; all before a
decision). ``follow`` picks the decision obeyed (``"verified"``, ``"hybrid"``, ``"psa"``: largest ``FI``,
``"none"``: never exclude), an array in the state (one compiled flight for every mode); every decision is reported.

The replay (``filters.replay_filter`` over a ``RingBuffer`` of the last ``L`` steps' channels, filter inputs
and least-squares estimates) is bounded and inside the scan: the hybrid vmaps over Monte Carlo flights. Under
``vmap`` ``lax.cond`` computes both branches; with ``batch_axis`` (the ``vmap`` axis name, e.g. in
``monte_carlo(..., batched=True)``) the replay runs only at steps where some flight needs it (``psum``): same
numbers, filter cost paid a few steps per batch.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.stages import FDI
from jaxfdi.detection._chi2 import Decision, chi2_threshold
from jaxfdi.detection._parity import ParitySpace, parity_tests
from jaxfdi.filters import replay_filter, ring_buffer

#: ``follow`` names and their codes
FOLLOW = {"none": 0, "psa": 1, "hybrid": 2, "verified": 3}


class HybridPSAConfig(NamedTuple):
    """Arrays of the hybrid FDI (a pytree: pass it into ``jit``).

    Attributes:
      space: the parity space of the sensor groups
      detection_threshold: () T_D on FD = p^T p
      isolation_threshold: () T_I on FI
      estimators: (G + 1, n, m) least-squares state: [0] all channels, [g + 1] without group g
      restart_cov: (n, n) sigma^2 (H^T H)^-1, the restart state's covariance
      channel_group: (m,) int: the group of each channel (-1: none)
      verification_threshold: () T_V on FD_-g (inf: no verification)
    """

    space: ParitySpace
    detection_threshold: Array
    isolation_threshold: Array
    estimators: Array
    restart_cov: Array
    channel_group: Array
    verification_threshold: Array


class HistoryEntry(NamedTuple):
    """One step kept for the replay.

    Attributes:
      channels: (m,) the measured channels of that step
      inputs: (nu,) the filter's input of that step
      estimate: (n,) least-squares state from every channel (a restart point)
    """

    channels: Array
    inputs: Array
    estimate: Array


class StepValues(NamedTuple):
    """What ``observe`` found at the current step (reported by ``step``).

    Attributes:
      statistic: () FD
      alarm: () bool FD > T_D
      isolation_functions: (G,) FI of each group
      suspects: (G,) bool FI > T_I
      analytic_residuals: (G,) ||r_g|| if the filter ran at this step, else NaN
      filter_ran: () bool: the filter was replayed at this step
    """

    statistic: Array
    alarm: Array
    isolation_functions: Array
    suspects: Array
    analytic_residuals: Array
    filter_ran: Array


class HybridDecision(NamedTuple):
    """The latched decision of a run (its FDI summary).

    Attributes:
      detection_step: () int first step with FD > T_D (-1: none)
      decision_step: () int step of the isolation decision (-1: none)
      psa: () int PSA alone: isolated group + 1 (0: none)
      hybrid: () int hybrid: isolated group + 1 (0: none)
      suspects: (G,) bool at the decision
      isolation_functions: (G,) FI at the decision
      analytic_residuals: (G,) ||r_g|| at the decision (NaN: the filter was not needed)
      filter_used: () bool: two or more suspects, the filter decided
      filter_healthy: () bool: the replayed filter stayed healthy
      verified: () int: the exclusion after verification (group + 1; 0: none)
      revisions: () int: how often verification moved it
    """

    detection_step: Array
    decision_step: Array
    psa: Array
    hybrid: Array
    suspects: Array
    isolation_functions: Array
    analytic_residuals: Array
    filter_used: Array
    filter_healthy: Array
    verified: Array
    revisions: Array


class HybridPSAState(NamedTuple):
    """The FDI's state in the scan carry (``hybrid_psa_init``).

    Attributes:
      history: filters.history.RingBuffer of HistoryEntry, the last L steps
      current: what ``observe`` found at the current step
      decision: the latched decision of the run
      follow: () int, FOLLOW code
    """

    history: Any
    current: StepValues
    decision: HybridDecision
    follow: Array


class HybridPSAOutput(NamedTuple):
    """One step's output (``fdi.step``).

    Attributes:
      values: what ``observe`` found at this step (FD, its alarm, FI, suspects, ``||r_g||``)
      detection: FD alarm of this step (label -1)
      psa: latched: isolated by PSA alone (label group + 1)
      hybrid: latched: isolated by the hybrid (label group + 1)
      verified: the hybrid's exclusion after verification (label group + 1)
      excluded: () int group + 1 whose channels the view leaves out (0: none)
      healthy: () bool: FD is a number and the replayed filter stayed healthy
    """

    values: StepValues
    detection: Decision
    psa: Decision
    hybrid: Decision
    verified: Decision
    excluded: Array
    healthy: Array


def exclusion_estimators(space: ParitySpace) -> Array:
    """(G + 1, n, m) ``(H^T H)^-1 H^T``: all channels ([0]), without group ``g`` ([g + 1], its columns zero)."""
    H = space.H
    m = H.shape[0]
    G = space.groups.shape[0]
    keep = jnp.ones((G + 1, m), H.dtype).at[jnp.arange(1, G + 1)[:, None], space.groups].set(0.0)
    Hk = keep[:, :, None] * H[None]
    return jnp.linalg.solve(jnp.swapaxes(Hk, 1, 2) @ Hk, jnp.swapaxes(Hk, 1, 2))


def hybrid_psa_config(
    space: ParitySpace, sigma, detection_threshold, isolation_threshold, verification_pfa=None
) -> HybridPSAConfig:
    """The arrays of the hybrid FDI for ``space``, channel noise ``sigma`` and thresholds ``T_D``, ``T_I``
    (``parity.detection_threshold``, ``parity.isolation_threshold``); ``verification_pfa``: per-step false-alarm
    probability ``P_V`` of the verification (module doc, step 5; ``None`` or no redundancy left without a group:
    never revised).

    Returns:
      ``HybridPSAConfig`` in ``space.H``'s dtype (channel groups int32; ``T_V = inf`` without verification).
    """
    checks.check_positive("sigma", sigma, "the channels' noise standard deviation")
    checks.check_scalar(
        "detection_threshold", detection_threshold, 0.0, low_open=True, meaning="T_D > 0"
    )
    checks.check_scalar(
        "isolation_threshold", isolation_threshold, 0.0, 1.0, meaning="T_I in [0, 1]"
    )
    H = space.H
    dtype = H.dtype
    m = H.shape[0]
    G, d = space.groups.shape
    channel_group = (
        jnp.full((m,), -1, jnp.int32)
        .at[space.groups.ravel()]
        .set(jnp.repeat(jnp.arange(G, dtype=jnp.int32), d))
    )
    restart_cov = jnp.square(jnp.asarray(sigma, dtype)) * jnp.linalg.inv(H.T @ H)
    dof = m - d - H.shape[1]  # the redundancy left without one group
    if verification_pfa is None or dof < 1:
        verification = jnp.asarray(jnp.inf, dtype)
    else:
        checks.check_probability("verification_pfa", verification_pfa)
        verification = jnp.square(jnp.asarray(sigma, dtype)) * chi2_threshold(
            dof, jnp.asarray(verification_pfa, dtype)
        )
    return HybridPSAConfig(
        space,
        jnp.asarray(detection_threshold, dtype),
        jnp.asarray(isolation_threshold, dtype),
        exclusion_estimators(space),
        0.5 * (restart_cov + restart_cov.T),
        channel_group,
        verification,
    )


def subset_statistics(config: HybridPSAConfig, channels: Array) -> Array:
    """(G,) ``FD_-g``: squared least-squares residual of the channels left without group ``g`` (module doc, step
    5); ``+inf`` when a channel left is not finite."""
    H = config.space.H
    G = config.space.groups.shape[0]
    finite = jnp.isfinite(channels)
    m0 = jnp.where(finite, channels, 0.0)
    residual = m0[None, :] - (config.estimators[1:].astype(m0.dtype) @ m0) @ H.T.astype(
        m0.dtype
    )  # (G, m)
    keep = config.channel_group[None, :] != jnp.arange(G)[:, None]
    residual = jnp.where(keep, jnp.where(finite[None, :], residual, jnp.inf), 0.0)
    return jnp.sum(jnp.square(residual), axis=-1)


def hybrid_psa_init(
    config: HybridPSAConfig,
    input_example: Array,
    restart_lag: int = 3,
    follow: str | Array = "hybrid",
) -> HybridPSAState:
    """The initial state of ``hybrid_psa_fdi``: an empty history of ``restart_lag`` steps (the filter restarts that
    many steps before the decision; Park et al. 2004: 2-3), no decision.

    Args:
      config: ``hybrid_psa_config(...)``.
      input_example: shaped like the filter input (nu,).
      restart_lag: steps kept for the replay, >= 1.
      follow: the decision whose exclusion the controller's view obeys (module doc): "verified", "hybrid", "psa"
        (largest ``FI``) or "none" (never exclude); or its ``FOLLOW`` code as an array (one compiled flight for every
        mode).

    Returns:
      ``HybridPSAState``: the state ``hybrid_psa_fdi``'s ``observe`` and ``step`` carry.
    """
    restart_lag = checks.check_int("restart_lag", restart_lag, 1, meaning="a number of steps >= 1")
    if isinstance(follow, str):
        checks.check_choice("follow", follow, list(FOLLOW))
        follow = FOLLOW[follow]
    else:
        checks.check_int_array(
            "follow", follow, 0, 3, "a FOLLOW code (0 none, 1 psa, 2 hybrid, 3 verified)"
        )
    dtype = config.space.H.dtype
    m, n = config.space.H.shape
    G = config.space.groups.shape[0]
    example = HistoryEntry(
        jnp.zeros((m,), dtype), jnp.zeros(jnp.shape(input_example), dtype), jnp.zeros((n,), dtype)
    )
    nan_g = jnp.full((G,), jnp.nan, dtype)
    false_g = jnp.zeros((G,), bool)
    minus_one = jnp.asarray(-1, jnp.int32)
    zero = jnp.asarray(0, jnp.int32)
    current = StepValues(
        jnp.zeros((), dtype),
        jnp.zeros((), bool),
        jnp.zeros((G,), dtype),
        false_g,
        nan_g,
        jnp.zeros((), bool),
    )
    decision = HybridDecision(
        minus_one,
        minus_one,
        zero,
        zero,
        false_g,
        nan_g,
        nan_g,
        jnp.zeros((), bool),
        jnp.ones((), bool),
        zero,
        zero,
    )
    return HybridPSAState(
        ring_buffer(restart_lag, example), current, decision, jnp.asarray(follow, jnp.int32)
    )


def analytic_residuals(
    filt,
    config: HybridPSAConfig,
    entries: HistoryEntry,
    valid: Array,
    channels: Array,
    trusted: Array,
) -> tuple[Array, Array, Array, Array]:
    """Restart ``filt`` at the oldest stored step, run it to now on the ``trusted`` channels (Park et al., eq. 30).

    Args:
      filt: a Gaussian ``Filter`` (state x (n,), measurement all m channels, NaN = not used).
      config: ``hybrid_psa_config(...)``.
      entries, valid: the history, oldest first, (L, ...), and which entries are stored (``RingBuffer.ordered``);
        restart point ``entries[0]``, its least-squares estimate with covariance ``config.restart_cov``.
      channels: (m,) the current step's channels.
      trusted: (m,) bool, the channels the filter may use.

    Returns:
      ``(norms (G,), residual (m,), mean (n,), healthy ())``: ``||r_g||`` per group, ``r = m - H x_hat[k|k]``, the
      filtered state and whether every step stayed healthy.
    """
    # the restart point is its own step's prior with nothing measured (all NaN: update keeps it), so one scan
    # does every prediction
    restart = filt.init(entries.estimate[0], config.restart_cov)
    masked = jnp.where(
        trusted[None, :] & (jnp.arange(valid.shape[0]) > 0)[:, None], entries.channels, jnp.nan
    )
    state, infos = replay_filter(filt, restart, masked, entries.inputs, valid)
    post = filt.update(state, jnp.where(trusted, channels, jnp.nan), entries.inputs[-1])
    residual = channels - config.space.H @ post.filtered_mean
    norms = jnp.linalg.norm(residual[config.space.groups], axis=-1)
    healthy = post.healthy & jnp.all(infos.healthy | ~valid) & jnp.all(jnp.isfinite(norms))
    return norms, residual, post.filtered_mean, healthy


def hybrid_psa_fdi(
    config: HybridPSAConfig,
    analytic_filter,
    channels: Callable[[Array], Array],
    filter_input: Callable[[Array, Array], Array],
    view: Callable[[Array, Array], Any],
    batch_axis: str | None = None,
):
    """The hybrid FDI (module doc) as an ``FDI(init, step, observe)``.

    Args:
      config: ``hybrid_psa_config(...)``.
      analytic_filter: the analytic redundancy's Gaussian ``Filter`` (``init``, ``update``, ``predict``; state ``x``
        (n,), measuring every channel ``H x`` (m,), ``missing_measurements=True``; e.g. a UKF on the F-16's moment
        equations).
      channels: ``y -> m`` (m,), the redundant channels in the plant's measurement.
      filter_input: ``(y, u) -> v`` (nu,), the filter's input of a step (``u``: the control sent at that step).
      view: ``(y, x_selected) -> view``, what the controller reads, from the least-squares state of the channels
        the decision left.
      batch_axis: name of the ``vmap`` axis of a batch of runs, or ``None`` (module doc).

    Returns:
      ``FDI(init, step, observe)`` on a ``HybridPSAState``: ``init(input_example, restart_lag=3, follow="hybrid")``
      the state before the first step (``input_example`` shaped like the filter input (nu,), ``restart_lag`` steps of
      history, ``follow`` the decision the view obeys: "verified", "hybrid", "psa" or "none", module doc);
      ``observe(state, k, y) -> (state, view)`` runs the tests,
      latches the decision and gives ``view(y, x_selected)``; ``step(state, k, y, u) -> (state,
      HybridPSAOutput)`` reports the step's statistics and ``Decision``s and stores the step for the replay.
    """
    for name, fn in (("channels", channels), ("filter_input", filter_input), ("view", view)):
        checks.check_callable(name, fn)
    if not all(callable(getattr(analytic_filter, f, None)) for f in ("init", "update", "predict")):
        raise TypeError(
            f"analytic_filter: expected a Gaussian Filter with init, update and predict (e.g. "
            f"unscented_kalman_filter(...)), got {checks.received(analytic_filter)}"
        )
    space = config.space
    G = space.groups.shape[0]

    def observe(state: HybridPSAState, k, y):
        m = channels(y)
        statistic, fi = parity_tests(
            space, m
        )  # a dead channel: FD = +inf, its group the one suspect
        alarm = statistic > config.detection_threshold
        suspects = fi > config.isolation_threshold
        count = jnp.sum(suspects)
        d = state.decision
        decide = (d.decision_step < 0) & alarm & (count >= 1)
        need = decide & (count >= 2)
        run = need if batch_axis is None else jax.lax.psum(need.astype(jnp.int32), batch_axis) > 0
        trusted = (config.channel_group < 0) | ~suspects[jnp.clip(config.channel_group, 0, G - 1)]
        entries, valid = state.history.ordered()
        nan_g = jnp.full((G,), jnp.nan, m.dtype)

        def replay(_):
            norms, _, _, healthy = analytic_residuals(
                analytic_filter, config, entries, valid, m, trusted
            )
            return norms, healthy

        norms, healthy = jax.lax.cond(run, replay, lambda _: (nan_g, jnp.ones((), bool)), None)
        norms = jnp.where(need, norms, nan_g)
        healthy = jnp.where(need, healthy, True)
        psa = jnp.argmax(jnp.where(suspects, fi, -jnp.inf)).astype(jnp.int32) + 1
        by_residual = (
            jnp.argmax(jnp.where(suspects, jnp.nan_to_num(norms, nan=-jnp.inf), -jnp.inf)).astype(
                jnp.int32
            )
            + 1
        )
        hybrid = jnp.where(need & healthy, by_residual, psa)
        pick = lambda new, old: jnp.where(decide, new, old)
        # verification of the exclusion made at an earlier step (step 5)
        subset = subset_statistics(config, m)
        revise = (d.decision_step >= 0) & (
            subset[jnp.clip(d.verified - 1, 0, G - 1)] > config.verification_threshold
        )
        moved = jnp.where(revise, jnp.argmin(subset).astype(jnp.int32) + 1, d.verified)
        decision = HybridDecision(
            jnp.where((d.detection_step < 0) & alarm, jnp.asarray(k, jnp.int32), d.detection_step),
            pick(jnp.asarray(k, jnp.int32), d.decision_step),
            pick(psa, d.psa),
            pick(hybrid, d.hybrid),
            pick(suspects, d.suspects),
            pick(fi, d.isolation_functions),
            pick(norms, d.analytic_residuals),
            pick(need, d.filter_used),
            pick(healthy, d.filter_healthy),
            pick(hybrid, moved),
            d.revisions + (moved != d.verified).astype(jnp.int32),
        )
        excluded = _excluded(decision, state.follow)
        # a dead channel's column of its exclusion estimator is 0, and 0 * NaN must not reach the view
        x_selected = config.estimators[excluded].astype(m.dtype) @ jnp.where(
            jnp.isfinite(m), m, 0.0
        )
        current = StepValues(statistic, alarm, fi, suspects, norms, need)
        return state._replace(current=current, decision=decision), view(y, x_selected)

    def step(state: HybridPSAState, k, y, u):
        m = channels(y)
        entry = HistoryEntry(m, filter_input(y, u), config.estimators[0].astype(m.dtype) @ m)
        c, d = state.current, state.decision
        decided = d.decision_step >= 0
        nan = jnp.full((), jnp.nan, m.dtype)
        output = HybridPSAOutput(
            c,
            Decision(c.statistic, c.alarm, jnp.asarray(-1, jnp.int32), nan),
            Decision(c.statistic, decided, d.psa, nan),
            Decision(c.statistic, decided, d.hybrid, nan),
            Decision(c.statistic, decided, d.verified, nan),
            _excluded(d, state.follow),
            ~jnp.isnan(c.statistic) & d.filter_healthy,
        )
        return state._replace(history=state.history.push(entry)), output

    return FDI(partial(hybrid_psa_init, config), step, observe)


def _excluded(decision: HybridDecision, follow: Array) -> Array:
    """The group + 1 the view leaves out under ``follow`` (0: none)."""
    return jnp.select(
        [follow == FOLLOW["verified"], follow == FOLLOW["hybrid"], follow == FOLLOW["psa"]],
        [decision.verified, decision.hybrid, decision.psa],
        0,
    ).astype(jnp.int32)


__all__ = [
    "FOLLOW",
    "HybridPSAConfig",
    "HistoryEntry",
    "StepValues",
    "HybridDecision",
    "HybridPSAState",
    "HybridPSAOutput",
    "exclusion_estimators",
    "hybrid_psa_config",
    "subset_statistics",
    "hybrid_psa_init",
    "analytic_residuals",
    "hybrid_psa_fdi",
]
