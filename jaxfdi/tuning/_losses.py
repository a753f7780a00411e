"""Differentiable losses on labelled runs (simulator labels: ``Sensed.mode`` per step, fault onset per run).

* ``mode_cross_entropy``: mean over steps of ``-log mu_{true mode}(k)`` for IMM/MM mode probabilities (log-loss of
  a probabilistic classifier, Bishop 2006 eq. 4.108);
* ``soft_detection_loss``: alarm ``[s_k >= h]`` relaxed to ``a_k = sigmoid((s_k - h) / temperature)``, independent
  per-step alarm probabilities: ``P(no alarm before the onset) = prod_{k<onset} (1 - a_k)``,
  ``P(first alarm at k >= onset) = a_k prod_{onset<=j<k} (1 - a_j)``; loss
  ``w_fa P(false alarm) + w_miss P(missed) + w_delay E[delay] / horizon``, missed runs at the full horizon. With an
  isolation margin ``m_k`` (> 0 when the label at step k would be wrong, e.g. ``max_{j != true} mu_j - mu_true``)
  it adds ``w_iso P(misisolated)``, ``P(misisolated) = sum_{k >= onset} P(first alarm at k) sigmoid(m_k /
  temperature)``. As ``temperature -> 0``: the hard rates of ``metrics`` (tested);
* ``innovation_nll``: ``-(1/T) sum_k log N(r_k; 0, S_k)``, minimised over ``Q, R`` by the maximum-likelihood
  estimate (Mehra 1970; Shumway & Stoffer 1982).

All per run; average over a batch with ``jax.vmap`` and ``jnp.mean``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks


def mode_cross_entropy(log_mode_prob: Array, true_mode: Array, floor: float = 1e-12) -> Array:
    """``mean_k -log(mu_{true_mode[k]}(k) + floor)``.

    Args:
      log_mode_prob: (T, M) log mode probabilities (``IMMInfo.log_mode_prob``).
      true_mode: (T,) int true mode per step (``Sensed.mode``).
      floor: probability floor: an impossible mode costs ``-log(floor)`` (finite, finite gradient), not infinity.

    Returns:
      () mean over the T steps of ``-log(mu_true + floor)`` [nats], in ``(0, -log(floor)]``, differentiable.
    """
    checks.check_scalar(
        "floor", floor, 0.0, 1.0, low_open=True, meaning="a probability floor in (0, 1]"
    )
    checks.check_shape(
        "log_mode_prob", log_mode_prob, (None, None), "(T, M) log mode probabilities"
    )
    T = log_mode_prob.shape[0]
    checks.check_shape("true_mode", true_mode, (T,), "one int mode label per step")
    checks.check_int_array(
        "true_mode", true_mode, 0, checks.shape_of(log_mode_prob)[1] - 1, "mode labels"
    )
    picked = jnp.take_along_axis(
        log_mode_prob, jnp.asarray(true_mode)[:, None].astype(jnp.int32), axis=1
    )[:, 0]
    return -jnp.mean(jnp.logaddexp(picked, math.log(floor)))


def soft_alarm_log_prob(
    statistic: Array, threshold: Array, temperature: Array
) -> tuple[Array, Array]:
    """``(log a_k, log(1 - a_k))`` with ``a_k = sigmoid((s_k - h) / temperature)``."""
    z = (statistic - threshold) / temperature
    return jax.nn.log_sigmoid(z), jax.nn.log_sigmoid(-z)


def soft_detection_loss(
    statistic: Array,
    threshold: Array,
    onset: Array,
    temperature: Array = 1.0,
    false_alarm_weight: float = 1.0,
    miss_weight: float = 1.0,
    delay_weight: float = 1.0,
    wrong_label_margin: Array | None = None,
    isolation_weight: float = 1.0,
) -> tuple[Array, dict[str, Array]]:
    """Smoothed false-alarm / missed-detection / delay loss of one run (module doc).

    Args:
      statistic: (T,) test statistic ``s_k`` (alarm when ``s_k >= threshold``).
      threshold, temperature: () scalars (may be traced and tuned).
      onset: () int fault onset step (``faults.NEVER`` or >= T: fault-free run).
      wrong_label_margin: optional (T,) margin ``m_k``, > 0 where an alarm at step k would isolate the wrong fault.

    Returns:
      ``(loss, parts)``; ``parts`` has ``false_alarm``, ``missed`` (probabilities), ``delay`` (expected, steps;
      missed runs count ``T - onset``) and ``misisolated`` (probability) when a margin is given.
    """
    checks.check_positive("temperature", temperature, "a positive temperature")
    for name, weight in (
        ("false_alarm_weight", false_alarm_weight),
        ("miss_weight", miss_weight),
        ("delay_weight", delay_weight),
        ("isolation_weight", isolation_weight),
    ):
        checks.check_scalar(name, weight, 0.0, meaning="a loss weight >= 0")
    checks.check_shape("statistic", statistic, (None,), "(T,) test statistic")
    T = statistic.shape[0]
    value = checks.concrete(onset)
    if value is not None and np.any(value < 0):
        raise ValueError(
            f"onset: expected a fault onset step >= 0 (faults.NEVER: fault-free), got "
            f"{checks.received(value)}"
        )
    k = jnp.arange(T)
    onset = jnp.minimum(jnp.asarray(onset), T)
    log_a, log_not = soft_alarm_log_prob(statistic, threshold, temperature)
    before = k < onset
    log_quiet_before = jnp.sum(jnp.where(before, log_not, 0.0))
    false_alarm = -jnp.expm1(log_quiet_before)
    after_not = jnp.where(before, 0.0, log_not)
    log_quiet_until = jnp.cumsum(after_not) - after_not  # log prod_{onset <= j < k} (1 - a_j)
    first = jnp.where(
        before, 0.0, jnp.exp(log_a + log_quiet_until)
    )  # P(first alarm after onset at k)
    missed = jnp.exp(jnp.sum(after_not))
    faulty = onset < T
    horizon = jnp.maximum(T - onset, 1)
    delay = jnp.sum(first * (k - onset)) + missed * horizon
    loss = false_alarm_weight * false_alarm + jnp.where(
        faulty, miss_weight * missed + delay_weight * delay / horizon, 0.0
    )
    parts = {
        "false_alarm": false_alarm,
        "missed": jnp.where(faulty, missed, 0.0),
        "delay": jnp.where(faulty, delay, 0.0),
    }
    if wrong_label_margin is not None:
        checks.check_shape(
            "wrong_label_margin",
            wrong_label_margin,
            (T,),
            "(T,) margin, > 0 where the label is wrong",
        )
        misisolated = jnp.where(
            faulty, jnp.sum(first * jax.nn.sigmoid(wrong_label_margin / temperature)), 0.0
        )
        loss = loss + isolation_weight * misisolated
        parts["misisolated"] = misisolated
    return loss, parts


def innovation_nll(log_likelihood: Array) -> Array:
    """``-(1/T) sum_k log N(r_k; 0, S_k)`` from the (T,) per-step ``FilterInfo.log_likelihood``.

    Returns:
      () the mean negative log-likelihood per step [nats], ``-mean(log_likelihood)``.
    """
    checks.check_shape("log_likelihood", log_likelihood, (None,), "(T,) per-step log-likelihoods")
    return -jnp.mean(log_likelihood)
