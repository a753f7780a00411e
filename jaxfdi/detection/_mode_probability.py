"""Decision on mode probabilities of a multiple-model filter (Han et al. 2022, eq. 13).

A fault is declared when the most probable fault mode reaches ``mu_T``:
``max_{j != normal} mu_j(k) >= mu_T``; that mode is the isolated one. With mode labels
ordered as the simulator's (0 normal, then actuators, then sensors), the isolated mode
index is the fault label, so the monitor's record gives detection and isolation at once.

``confirm_steps = c > 1`` (not in the paper) declares only when the same fault mode has
been the most probable one at or above ``mu_T`` for ``c`` consecutive steps: an
actuator fault of the engine first shows in P4 alone, so for a step or two a P4-bias
mode explains it as well, and a first-crossing decision isolates it as P4 in ~10 % of
runs; ``c`` steps of confirmation let the slower T4 and RPM responses decide.
``confirm_steps`` may also be one length per mode, ``c_j``: mode j alarms once it has led
for ``c_j`` steps, so a mode that no other hypothesis mimics (the engine's P2 bias) can be
declared sooner than the actuator/P4 pair that needs the extra steps.
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import _checks
from jaxfdi.detection._chi2 import Decision, Detector


def confirmation_init() -> tuple[Array, Array]:
    """``(candidate label, steps it has led above the threshold)`` before any step."""
    return jnp.asarray(-1, jnp.int32), jnp.zeros((), jnp.int32)


def confirm(state: tuple[Array, Array], label: Array, above: Array, confirm_steps):
    """k-step confirmation of an isolating decision: alarm once the same ``label`` has led
    above its threshold for ``confirm_steps`` consecutive steps (an int, or one per label:
    ``confirm_steps[label]``); returns ``(state, alarm)``."""
    candidate, held = state
    held = jnp.where(above, jnp.where(label == candidate, held + 1, 1), 0)
    required = confirm_steps if np.ndim(confirm_steps) == 0 else jnp.asarray(confirm_steps)[label]
    return (jnp.where(above, label, -1), held), held >= required


def check_confirm_steps(confirm_steps) -> None:
    """``TypeError`` unless ``confirm_steps`` holds integers, ``ValueError`` unless it is
    one integer >= 1 or a 1-D sequence of them."""
    if isinstance(confirm_steps, (list, tuple)):
        confirm_steps = np.asarray(confirm_steps)
    _checks.check_int_array("confirm_steps", confirm_steps, 1, meaning="an integer >= 1, or one per mode (M,)")
    if np.ndim(confirm_steps) > 1 or np.size(confirm_steps) == 0:
        raise ValueError(f"confirm_steps: expected an integer >= 1, or one per mode (M,), got {confirm_steps}")


def mode_probability_detector(threshold, normal_mode: int = 0, confirm_steps=1) -> Detector:
    """Online detector on mode probabilities ``mu`` (M,).

    ``step(state, mu)`` or ``step(state, (mu, estimates))`` ``-> (state, Decision)``, with
    ``estimates`` (M,) a per-mode fault estimate (e.g. the bias each mode estimates); the
    decision's label is the top fault mode and its ``estimate`` that mode's (NaN without
    ``estimates``).

    Args:
      threshold: ``mu_T`` in (0, 1] (Han et al. 2022 use 0.5), or (M,) one per mode: the top
        fault mode j alarms when ``mu_j >= threshold[j]`` (the normal mode's entry is
        not used).
      normal_mode: index of the fault-free mode.
      confirm_steps: consecutive steps the same mode must stay the top fault mode at or
        above ``mu_T`` before an alarm (1: the paper's memoryless rule), or (M,) one per
        mode (the normal mode's entry is not used). A traced (M,) integer array is
        accepted (its values are then checked by whoever made it), so that detectors with
        different lengths can share one compiled program.

    Returns:
      ``Detector(init, step)``: ``init()`` gives the confirmation state ``(candidate label
      -1, steps held 0)``; ``step(state, mu)`` or ``step(state, (mu, estimates))`` returns
      ``(state, Decision)`` with statistic the top fault mode's probability and label its
      index.
    """
    _checks.check_real("threshold", threshold, "a probability mu_T in (0, 1], or one per mode (M,)")
    value = _checks.concrete(threshold)
    if value is not None and not (value.ndim <= 1 and np.all((0.0 < value) & (value <= 1.0))):
        raise ValueError(f"threshold: expected a probability mu_T in (0, 1], or one per mode (M,), got {threshold}")
    _checks.check_int("normal_mode", normal_mode, 0, meaning="the index of the fault-free mode")
    check_confirm_steps(confirm_steps)
    if _checks.concrete(confirm_steps) is None:  # traced: data of the compiled program
        steps = jnp.asarray(confirm_steps, jnp.int32)
    else:
        steps = int(confirm_steps) if np.ndim(confirm_steps) == 0 else np.asarray(confirm_steps, np.int32)

    def step(state, inputs):
        mode_prob, estimates = inputs if isinstance(inputs, tuple) else (inputs, None)
        mode_prob = jnp.asarray(mode_prob)
        if mode_prob.ndim != 1:
            raise ValueError(f"mode_prob: expected shape (M,), got {tuple(mode_prob.shape)}")
        if not -mode_prob.shape[0] <= normal_mode < mode_prob.shape[0]:
            raise ValueError(f"normal_mode: expected a mode index in [0, {mode_prob.shape[0]}), got {normal_mode}")
        fault_prob = mode_prob.at[normal_mode].set(-jnp.inf)
        label = jnp.argmax(fault_prob).astype(jnp.int32)
        statistic = fault_prob[label]
        level = jnp.asarray(threshold)
        if level.ndim == 1:
            _checks.check_shape("threshold", level, mode_prob.shape, "one mu_T per mode, or a scalar")
            level = level[label]
        if np.ndim(steps) == 1:
            _checks.check_shape("confirm_steps", steps, mode_prob.shape, "one confirmation length per mode, or an int")
        state, alarm = confirm(state, label, statistic >= level, steps)
        estimate = jnp.full((), jnp.nan, mode_prob.dtype) if estimates is None else jnp.asarray(estimates)[label]
        return state, Decision(statistic, alarm, label, estimate)

    return Detector(confirmation_init, step)
