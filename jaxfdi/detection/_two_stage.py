"""Two-stage fault isolation with a dual filter and multi-hypothesis filter banks (Choi & Park 2009, Fig. 10).

Stage 1 detects on the nominal model: the dual filter's fault detection parameter ``F`` (``dual_filter``, fault
when ``F > F_T``) and the windowed NIS of a nominal filter (``chi2_detector``). Stage 2 isolates with two banks over
the fault hypotheses ``p_x`` (model parameters, e.g. wheel ``x`` stopped):

- credit bank: one dual filter per hypothesis, credits ``C_x`` from the ``F_x`` (``credit_isolator``, eq. 10);
- likelihood bank: the static multiple-model filter over the nominal model and the hypotheses, mode probabilities
  from innovation likelihoods (``mode_probability_detector``).

Until the engaging alarm (``engage_on``: the NIS test or ``F``) both banks are slaved to the nominal filter,
restarting each step from its posterior ``N(m, P + S_e)`` (``engage_cov = S_e`` widens the prior, the nominal filter
lagging a fault), isolators idle; from the step after the alarm they run and decide on their own. With
``restart_prediction`` each hypothesis's prediction filter starts at the engaging step from its own estimation
filter's posterior ``f(m_x, u; p_x)``, not the nominal prediction (which keeps the nominal lag for good).

A non-finite measurement component is a dead sensor: every filter takes its prediction there and reports it; all
four decisions alarm then with the channel's label (``chi2.flag_dead`` on their own filters' dead report).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.detection._chi2 import Decision, chi2_detector, flag_dead
from jaxfdi.detection._credits import credit_isolator
from jaxfdi.detection._dual_filter import DualFilterState, dual_filter
from jaxfdi.detection._mode_probability import mode_probability_detector
from jaxfdi.filters import Filter, GaussianState, multiple_model

__all__ = ["TwoStageOutput", "two_stage_isolation"]


class TwoStageOutput(NamedTuple):
    """What the two stages give at one step.

    Attributes:
      decisions: (F, NIS, credit, likelihood) ``Decision``s
      peaks: (2,) F and the windowed NIS
      healthy: () bool: every filter healthy
      hypothesis_parameter: (M,) F_x of the credit bank
      mode_prob: (M + 1,) likelihood bank, nominal mode first
      engaged: () bool: the banks ran on their own at this step
    """

    decisions: tuple
    peaks: Array
    healthy: Array
    hypothesis_parameter: Array
    mode_prob: Array
    engaged: Array


def two_stage_isolation(
    nominal: Filter,
    bank_filter: Callable[[Any], Filter],
    transition: Callable,
    field: Callable,
    params: Any,
    hypotheses: Any,
    modes: Any,
    *,
    detection_threshold,
    nis_threshold,
    nis_window: int,
    credit_threshold,
    mode_threshold,
    mm_floor,
    engage_cov,
    confirm_steps: int = 1,
    engage_on: str = "nis",
    restart_prediction: bool = True,
    channel_labels=None,
) -> Filter:
    """The two stages (module doc) on ``x[k+1] = transition(x, u, p)``, ``x' = field(x, u, p)``, as a ``Filter``
    (``run_filter`` drives it; decisions in ``output.decisions``).

    ``nominal``: the dual filter's estimation filter on ``params``; ``bank_filter(p)``: the filter of the NIS test
    (on ``params``) and of the banks (each hypothesis); ``hypotheses`` (M, ...), ``modes`` (M + 1, ..., nominal
    first): stacked parameter pytrees. Credit-isolator labels: hypothesis index + 1 (``confirm_steps`` for both
    isolators); ``engage_cov`` (n, n) is added to the banks' restart covariance. ``channel_labels`` (m,) int: each
    channel's fault label, what a dead channel isolates to (``chi2.flag_dead``); ``None``: label -1.

    Returns:
      ``Filter(init, step)`` (no ``update``/``predict``): ``init(mean (n,), cov (n, n), u0) -> state``, a dict of the
      dual filter, NIS filter and test, both banks (slaved to the prior), engaged flag and isolators' states;
      ``step(state, y (m,), u) -> (state, TwoStageOutput)`` with the four ``Decision``s (F, NIS, credit,
      likelihood), peaks (2,), health, the credit bank's ``F_x`` (M,) and mode probabilities (M + 1,).
    """
    if engage_on not in ("nis", "fdp"):
        raise ValueError(f"engage_on: expected 'nis' or 'fdp', got {engage_on!r}")
    checks.check_scalar(
        "detection_threshold",
        detection_threshold,
        0.0,
        meaning="a threshold >= 0 on F = |det A_PF - det A_EKF| (a negative one alarms at every step)",
    )
    detector = dual_filter(nominal, transition, field, params)
    nis_filter = bank_filter(params)
    nis_test = chi2_detector(nis_threshold, nis_window, jnp.asarray(nis_threshold).dtype)

    def bank_dual(p):
        return dual_filter(bank_filter(p), transition, field, p)

    mm = multiple_model(bank_filter, modes, mm_floor)
    credits = credit_isolator(
        credit_threshold, relative=True, label_offset=1, confirm_steps=confirm_steps
    )
    mode_decision = mode_probability_detector(mode_threshold, confirm_steps=confirm_steps)
    num_modes = jax.tree_util.tree_leaves(modes)[0].shape[0]

    def slaved(post: GaussianState, u: Array):
        """The banks' next states, started from the nominal posterior ``post``."""
        start = GaussianState(post.mean, post.cov + engage_cov)
        bank_prior = jax.vmap(lambda p: bank_filter(p).predict(start, u))(hypotheses)
        mode_prior = jax.vmap(lambda p: bank_filter(p).predict(start, u))(modes)
        uniform = jnp.full((num_modes,), 1.0 / num_modes, post.mean.dtype)
        return DualFilterState(bank_prior, bank_prior.mean), mm.init(
            mode_prior.mean, mode_prior.cov, uniform
        )

    def init(mean: Array, cov: Array, u0: Array):
        bank0, mm0 = slaved(GaussianState(mean, cov), u0)
        return dict(
            dual=detector.init(mean, cov),
            nis_filter=nis_filter.init(mean, cov),
            nis=nis_test.init(),
            bank=bank0,
            mm=mm0,
            engaged=jnp.zeros((), bool),
            credit=credits.init(),
            mode=mode_decision.init(),
        )

    def step(c, y: Array, u: Array):
        dtype = y.dtype
        no_label, nan = jnp.asarray(-1, jnp.int32), jnp.full((), jnp.nan, dtype)
        # stage 1: the dual filter's F, and the windowed NIS of a nominal filter
        dual, dual_info = detector.step(c["dual"], y, u)
        fdp = dual_info.detection_parameter
        fdp_alarm = fdp > detection_threshold
        nis_filter_state, nis_info = nis_filter.step(c["nis_filter"], y, u)
        nis_state, nis_decision = nis_test.step(c["nis"], nis_info.nis)

        # stage 2: the banks, slaved to the nominal filter until the engaging alarm
        bank, bank_info = jax.vmap(lambda p, s: bank_dual(p).step(s, y, u))(hypotheses, c["bank"])
        mm_state, mm_info = mm.step(c["mm"], y, u)
        engaged_before = c["engaged"]
        engaged = engaged_before | (nis_decision.alarm if engage_on == "nis" else fdp_alarm)
        post = dual_info.estimator.posterior
        reset_bank, reset_mm = slaved(post, u)
        keep = lambda new, old: jax.tree_util.tree_map(
            lambda a, b: jnp.where(engaged, a, b), new, old
        )
        if (
            restart_prediction
        ):  # a bank slaved until now starts its prediction from its own posterior
            restart = jax.vmap(lambda p, m: transition(m, u, p))(
                hypotheses, bank_info.estimator.filtered_mean
            )
            bank = bank._replace(prediction=jnp.where(engaged_before, bank.prediction, restart))
        bank, mm_state = keep(bank, reset_bank), keep(mm_state, reset_mm)
        credit_state, credit_out = credits.step(c["credit"], bank_info.detection_parameter)
        mode_state, mode_out = mode_decision.step(c["mode"], mm_info.mode_prob)
        idle = lambda new, fresh: jax.tree_util.tree_map(
            lambda a, b: jnp.where(engaged_before, a, b), new, fresh
        )
        credit_state, mode_state = (
            idle(credit_state, credits.init()),
            idle(mode_state, mode_decision.init()),
        )
        labels = jnp.full(y.shape, -1, jnp.int32) if channel_labels is None else channel_labels
        dead = jnp.isnan  # the filters' dead report: NaN innovation on a dead component
        decisions = (
            flag_dead(
                Decision(fdp, fdp_alarm, no_label, nan),
                dead(dual_info.estimator.innovation),
                labels,
            ),
            flag_dead(nis_decision._replace(estimate=nan), dead(nis_info.innovation), labels),
            flag_dead(
                Decision(
                    credit_out.statistic, engaged_before & credit_out.alarm, credit_out.label, nan
                ),
                jnp.any(dead(bank_info.estimator.innovation), axis=0),
                labels,
            ),
            flag_dead(
                Decision(mode_out.statistic, engaged_before & mode_out.alarm, mode_out.label, nan),
                mm_info.dead,
                labels,
            ),
        )
        healthy = (
            dual_info.healthy & nis_info.healthy & jnp.all(bank_info.healthy) & mm_info.healthy
        )
        new = dict(
            dual=dual,
            nis_filter=nis_filter_state,
            nis=nis_state,
            bank=bank,
            mm=mm_state,
            engaged=engaged,
            credit=credit_state,
            mode=mode_state,
        )
        return new, TwoStageOutput(
            decisions,
            jnp.stack([fdp, nis_decision.statistic]),
            healthy,
            bank_info.detection_parameter,
            mm_info.mode_prob,
            engaged_before,
        )

    return Filter(init, step)
