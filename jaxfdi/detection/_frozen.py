"""Frozen (stuck-at) channel test: a sensor whose output stops changing while its noise says it must.

A healthy channel ``y_i = s_i + e_i`` with white Gaussian noise of standard deviation >= ``sigma`` has, over ``L``
samples, ``sum_i (y_i - ybar)^2 / sigma^2 ~`` non-central ``chi2(L - 1, lambda)``,
``lambda = sum_i (s_i - sbar)^2 / sigma^2`` for any signal ``s`` (conditionally, if random and independent of the
noise). The law is stochastically increasing in ``lambda`` and the noise variance, so

    P(statistic < chi2.ppf(pfa, L - 1)) <= pfa,

with equality for a constant signal and noise exactly ``sigma``: the lower-tail test bounds the false-alarm
probability per window whatever the plant does. A frozen channel (``FaultKind.STUCK``) has statistic 0 once the
window holds only frozen samples, ``L - 1`` steps after the onset (the onset sample is live). ``sigma`` must not
exceed the true noise (a quantising sensor with step above its noise repeats values by itself: use the step's
``1/sqrt(12)``, or a longer window).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.detection._chi2 import Decision, Detector, chi2_threshold, flag_dead


class FrozenState(NamedTuple):
    """The stuck-at test's carry: a ring buffer of the last ``L`` samples.

    Attributes:
      buffer: (L, m) last L samples, ring buffer
      index: () next slot
      count: () samples seen (saturates at L)
    """

    buffer: Array
    index: Array
    count: Array


def frozen_threshold(window: int, pfa, dtype=None) -> Array:
    """``chi2.ppf(pfa, L - 1)``, the lower-tail threshold of ``frozen_statistic``.

    Returns:
      () threshold in ``dtype`` (default float): a window's statistic below it is an alarm.
    """
    window = checks.check_int("window", window, minimum=2, meaning="a window of L >= 2 samples")
    checks.check_probability("pfa", pfa)
    dtype = dtype or jnp.result_type(float)
    value, eps = checks.concrete(pfa), np.finfo(dtype).eps
    if value is not None and np.any(np.asarray(value) < eps):
        raise ValueError(
            f"pfa: expected a probability >= {eps:.4g} (np.finfo({np.dtype(dtype).name}).eps: the lower-tail "
            f"quantile is the upper tail at 1 - pfa, which must differ from 1), got {checks.received(value)}"
        )
    return chi2_threshold(jnp.asarray(window - 1, dtype), 1.0 - jnp.asarray(pfa, dtype))


def frozen_statistic(samples: Array, sigma: Array) -> Array:
    """``sum_i (y_i - ybar)^2 / sigma^2`` over axis 0 of ``samples`` (L, ...): per channel."""
    samples = jnp.asarray(samples)
    deviation = samples - jnp.mean(samples, axis=0)
    return jnp.sum(deviation**2, axis=0) / jnp.square(sigma)


def frozen_channel_detector(
    sigma, window: int, pfa, channel_labels: Array | None = None
) -> Detector:
    """Online stuck-at test on raw measurements ``y`` (m,).

    Statistic ``min_j frozen_statistic_j`` over the last ``window`` samples; alarm once ``window`` samples are in and
    it is below ``frozen_threshold(window, pfa)`` (lower tail: small means frozen); label ``channel_labels[j]`` of
    the most frozen channel (-1 without labels); estimate its held value. A non-finite sample is a dead channel
    (``chi2.flag_dead``), untested (statistic ``+inf``) while in the window: recovery ``window`` steps later.

    Args:
      sigma: (m,) a lower bound of each channel's noise standard deviation.
      window: L >= 2 samples.
      pfa: false-alarm probability per window and channel (an upper bound, module doc).
      channel_labels: (m,) int, the fault label of each channel.

    Returns:
      ``Detector(init, step)``: ``init()`` gives an empty ``FrozenState`` (zero (L, m) buffer in ``sigma``'s float
      dtype); ``step(state, y (m,)) -> (state, Decision)``.
    """
    checks.check_real("sigma", sigma, "noise standard deviations")
    checks.check_shape("sigma", sigma, (None,), "one noise standard deviation per channel (m,)")
    checks.check_finite("sigma", sigma, "noise standard deviations")
    value = checks.concrete(sigma)
    if value is not None and not np.all(value > 0):
        raise ValueError(
            f"sigma: expected positive noise standard deviations, got {checks.received(value)}"
        )
    m = checks.shape_of(sigma)[0]
    window = checks.check_int("window", window, minimum=2, meaning="a window of L >= 2 samples")
    if channel_labels is not None:
        checks.check_shape(
            "channel_labels", channel_labels, (m,), "one fault label per channel, as sigma"
        )
    dtype = checks.float_dtype(sigma)
    threshold = frozen_threshold(window, pfa, dtype)
    sigma = jnp.asarray(sigma, dtype)

    def init() -> FrozenState:
        zero = jnp.zeros((), jnp.int32)
        return FrozenState(jnp.zeros((window, m), dtype), zero, zero)

    def step(state: FrozenState, y: Array):
        checks.check_shape("y", y, (m,), "one measurement of the m channels")
        y = jnp.asarray(y, dtype)
        buffer = state.buffer.at[state.index].set(y)
        count = jnp.minimum(state.count + 1, window)
        dead_in_window = jnp.any(~jnp.isfinite(buffer), axis=0)
        per_channel = jnp.where(
            dead_in_window,
            jnp.inf,
            frozen_statistic(jnp.where(jnp.isfinite(buffer), buffer, 0.0), sigma),
        )
        channel = jnp.argmin(per_channel)
        statistic = per_channel[channel]
        label = jnp.asarray(
            -1 if channel_labels is None else jnp.asarray(channel_labels)[channel], jnp.int32
        )
        decision = Decision(
            statistic,
            (count == window) & (statistic < threshold),
            label,
            buffer[state.index, channel],
        )
        decision = flag_dead(
            decision, ~jnp.isfinite(y), None if channel_labels is None else channel_labels
        )
        return FrozenState(buffer, (state.index + 1) % window, count), decision

    return Detector(init, step)
