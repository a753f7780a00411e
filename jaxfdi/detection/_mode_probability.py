"""Decision on mode probabilities of a multiple-model filter (Han et al. 2022, eq. 13).

Fault when the most probable fault mode reaches ``mu_T``: ``max_{j != normal} mu_j(k) >= mu_T``; that mode is
isolated, its index (simulator order: 0 normal, actuators, sensors) being the fault label.

``confirm_steps = c > 1`` (not in the paper): declare only once the same fault mode has led at or above ``mu_T``
for ``c`` consecutive steps. An engine actuator fault first shows in P4 alone, so for a step or two a P4-bias mode
explains it as well and first-crossing isolates it as P4 in ~10 % of runs; ``c`` steps let the slower T4 and RPM
responses decide. Per-mode ``c_j``: a mode nothing mimics (engine P2 bias) is declared before the actuator/P4 pair.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.detection._chi2 import Decision, Detector


def confirmation_init() -> tuple[Array, Array]:
    """``(candidate label, steps it has led above the threshold)`` before any step."""
    return jnp.asarray(-1, jnp.int32), jnp.zeros((), jnp.int32)


def confirm(state: tuple[Array, Array], label: Array, above: Array, confirm_steps):
    """k-step confirmation of an isolating decision: alarm once the same ``label`` has led above its threshold for
    ``confirm_steps`` consecutive steps (an int, or per label ``confirm_steps[label]``); returns ``(state, alarm)``."""
    candidate, held = state
    held = jnp.where(above, jnp.where(label == candidate, held + 1, 1), 0)
    required = confirm_steps if np.ndim(confirm_steps) == 0 else jnp.asarray(confirm_steps)[label]
    return (jnp.where(above, label, -1), held), held >= required


def check_confirm_steps(confirm_steps) -> None:
    """``TypeError`` unless integers, ``ValueError`` unless one integer >= 1 or a 1-D sequence of them."""
    if isinstance(confirm_steps, (list, tuple)):
        confirm_steps = np.asarray(confirm_steps)
    checks.check_int_array(
        "confirm_steps", confirm_steps, 1, meaning="an integer >= 1, or one per mode (M,)"
    )
    if np.ndim(confirm_steps) > 1 or np.size(confirm_steps) == 0:
        raise ValueError(
            f"confirm_steps: expected an integer >= 1, or one per mode (M,), got {confirm_steps}"
        )


def mode_probability_detector(threshold, normal_mode: int = 0, confirm_steps=1) -> Detector:
    """Online detector on mode probabilities ``mu`` (M,).

    ``step(state, mu)`` or ``step(state, (mu, estimates)) -> (state, Decision)``, ``estimates`` (M,) a per-mode
    fault estimate (e.g. each mode's bias); label = top fault mode, ``estimate`` its estimate (NaN without).

    Args:
      threshold: ``mu_T`` in (0, 1] (Han et al. 2022: 0.5), or (M,) per mode: top fault mode j alarms when
        ``mu_j >= threshold[j]`` (normal mode's entry unused).
      normal_mode: index of the fault-free mode.
      confirm_steps: consecutive steps the same mode must stay top fault mode at or above ``mu_T`` (1: the paper's
        memoryless rule), or (M,) per mode (normal entry unused). A traced (M,) integer array is accepted (values
        checked by its maker), so detectors with different lengths share one compiled program.

    Returns:
      ``Detector(init, step)``: ``init()`` gives the confirmation state ``(candidate label -1, steps held 0)``;
      ``step`` returns ``(state, Decision)``, statistic the top fault mode's probability, label its index.
    """
    checks.check_real("threshold", threshold, "a probability mu_T in (0, 1], or one per mode (M,)")
    value = checks.concrete(threshold)
    if value is not None and not (value.ndim <= 1 and np.all((0.0 < value) & (value <= 1.0))):
        raise ValueError(
            f"threshold: expected a probability mu_T in (0, 1], or one per mode (M,), got {threshold}"
        )
    checks.check_int("normal_mode", normal_mode, 0, meaning="the index of the fault-free mode")
    check_confirm_steps(confirm_steps)
    if checks.concrete(confirm_steps) is None:  # traced: data of the compiled program
        steps = jnp.asarray(confirm_steps, jnp.int32)
    else:
        steps = (
            int(confirm_steps)
            if np.ndim(confirm_steps) == 0
            else np.asarray(confirm_steps, np.int32)
        )

    def step(state, inputs):
        mode_prob, estimates = inputs if isinstance(inputs, tuple) else (inputs, None)
        mode_prob = jnp.asarray(mode_prob)
        if mode_prob.ndim != 1:
            raise ValueError(f"mode_prob: expected shape (M,), got {tuple(mode_prob.shape)}")
        if not -mode_prob.shape[0] <= normal_mode < mode_prob.shape[0]:
            raise ValueError(
                f"normal_mode: expected a mode index in [0, {mode_prob.shape[0]}), got {normal_mode}"
            )
        fault_prob = mode_prob.at[normal_mode].set(-jnp.inf)
        label = jnp.argmax(fault_prob).astype(jnp.int32)
        statistic = fault_prob[label]
        level = jnp.asarray(threshold)
        if level.ndim == 1:
            checks.check_shape(
                "threshold", level, mode_prob.shape, "one mu_T per mode, or a scalar"
            )
            level = level[label]
        if np.ndim(steps) == 1:
            checks.check_shape(
                "confirm_steps",
                steps,
                mode_prob.shape,
                "one confirmation length per mode, or an int",
            )
        state, alarm = confirm(state, label, statistic >= level, steps)
        estimate = (
            jnp.full((), jnp.nan, mode_prob.dtype)
            if estimates is None
            else jnp.asarray(estimates)[label]
        )
        return state, Decision(statistic, alarm, label, estimate)

    return Detector(confirmation_init, step)
