"""Multi-hypothesis isolation by credits (Choi & Park 2009, Section III, eq. 10).

A bank of dual filters, one per fault hypothesis (reaction wheels: wheel ``x`` stopped), gives one ``F_x`` each;
the hypothesis matching the plant keeps ``F_x`` small while the others grow. Credit

    C_x = max(F_mean - F_x, 0),    F_mean = (1/M) sum_x F_x,

isolated to the largest credit once large enough. ``F`` scales with the operating point (rates, wheel momentum, fault
size), so a scale-free threshold on ``C_x / F_mean`` in ``[0, 1]`` (1: ``F_x = 0``) supplements the paper's one.

Limit: ``F_x ~ |g_x . (x_PF - x_EKF)|``, ``g_x = grad det A_x``, sees a
hypothesis's discrepancy only along ``g_x``; a wrong hypothesis drifting nearly orthogonally to it keeps ``F`` as
small as the right one's (reaction-wheel pyramid: wheel 1 stopped vs hypothesis 3, the opposite wheel) and noise
decides. A likelihood bank on the innovation vectors has no such blind direction.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.detection._chi2 import Decision, Detector, flag_dead
from jaxfdi.detection._mode_probability import confirm, confirmation_init


def hypothesis_credits(detection_parameters: Array) -> Array:
    """``C_x = max(F_mean - F_x, 0)`` for ``F`` (..., M) along the last axis (eq. 10).

    Returns:
      (..., M) credits ``C_x >= 0``, ``F``'s shape and units (0 for each hypothesis at or above the mean).
    """
    detection_parameters = jnp.asarray(detection_parameters)
    mean = jnp.mean(detection_parameters, axis=-1, keepdims=True)
    return jnp.maximum(mean - detection_parameters, 0.0)


def credit_isolator(
    threshold, relative: bool = True, label_offset: int = 0, confirm_steps: int = 1
) -> Detector:
    """Online isolator on the bank's ``F`` (M,): names ``argmax C_x`` once it is above ``threshold``.

    Args:
      threshold: on ``C_x / F_mean`` (``relative=True``, default; in ``(0, 1]`` to be meaningful, 1 means
        ``F_x = 0``) or on ``C_x`` (the paper's form).
      relative: which credit the threshold applies to.
      label_offset: added to the hypothesis index for the label (1 when hypothesis ``x`` is label ``1 + x``).
      confirm_steps: consecutive steps the same hypothesis must lead above the threshold.

    ``step(state, F) -> (state, Decision)``: statistic the leading (relative) credit, estimate ``F_mean``. A
    non-finite ``F_x`` is evidence: alarm, ``statistic = +inf``, label -1 (which hypothesis is unknown), ``flag_dead``.
    """
    checks.check_positive("threshold", threshold, "a positive scalar credit threshold")
    checks.check_int("confirm_steps", confirm_steps, 1, meaning="an integer number of steps >= 1")
    checks.check_int("label_offset", label_offset, meaning="an integer label offset")

    def step(state, detection_parameters: Array):
        detection_parameters = jnp.asarray(detection_parameters)
        if detection_parameters.ndim != 1:
            raise ValueError(
                f"detection_parameters: expected shape (M,), got {tuple(detection_parameters.shape)}"
            )
        credit = hypothesis_credits(detection_parameters)
        mean = jnp.mean(detection_parameters)
        if relative:
            credit = jnp.where(mean > 0, credit / jnp.where(mean > 0, mean, 1.0), 0.0)
        best = jnp.argmax(credit).astype(jnp.int32)
        statistic = credit[best]
        state, alarm = confirm(state, best, statistic >= threshold, confirm_steps)
        decision = Decision(statistic, alarm, best + label_offset, mean)
        return state, flag_dead(
            decision,
            ~jnp.isfinite(detection_parameters),
            jnp.full(detection_parameters.shape, -1, jnp.int32),
        )

    return Detector(confirmation_init, step)
