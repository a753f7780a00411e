"""Faults as data: a ``Fault`` pytree and the pure function that applies it.

A fault acts on one component of the actuator signal ``u`` or of the sensor signal
``y`` while ``onset <= k < end`` (steps). Every leaf is an array, so batches of faults
(different kinds, components, onsets, magnitudes) vmap like any other data, and each
Monte Carlo run carries its own label.

Kinds (``s`` is the nominal component, ``k`` the step):

============  ==================================  =====================================
kind          faulty component                    parameters
============  ==================================  =====================================
NONE          ``s``                               (a fault-free run)
BIAS          ``s + magnitude``                   step/bias
RAMP          ``s + magnitude + slope (k - onset)``  drift, ``slope`` per step
IMPULSE       ``s + magnitude`` at ``k == onset`` only  a single-sample spike
SCALE         ``(1 + magnitude) s``               multiplicative (sensor scaling)
EFFECTIVENESS ``(1 - magnitude) s``               actuator effectiveness loss, 0..1
STUCK         ``s(onset)``                        stuck at the value at onset
STOP          ``0``                               the component stops (no output)
============  ==================================  =====================================

A plant model may give a kind more physics than the signal change: the reaction-wheel
scenario reads STOP as "the wheel's speed goes to 0 and its momentum to the body" and
STUCK as "the wheel's speed freezes" (``scenarios.reaction_wheels.wheel_fault``).
"""
from __future__ import annotations

import enum
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

#: an ``end`` far beyond any simulation: the fault never clears.
NEVER = 2**30


class FaultKind(enum.IntEnum):
    NONE = 0
    BIAS = 1
    RAMP = 2
    IMPULSE = 3
    SCALE = 4
    EFFECTIVENESS = 5
    STUCK = 6
    STOP = 7


class Target(enum.IntEnum):
    ACTUATOR = 0
    SENSOR = 1


class Fault(NamedTuple):
    """One fault (scalar leaves) or a batch of faults (leaves with leading axes)."""

    kind: Array       # int, a FaultKind
    target: Array     # int, a Target
    component: Array  # int, index into u (actuator) or y (sensor)
    onset: Array      # int, first faulty step
    magnitude: Array  # float
    slope: Array      # float, per step (RAMP)
    end: Array        # int, first step after the fault (NEVER = permanent)


def fault(kind, target, component, onset, magnitude=0.0, slope=0.0, end=NEVER) -> Fault:
    """Build a ``Fault``; ``kind`` and ``target`` take the enums or their names."""
    if isinstance(kind, str):
        kind = FaultKind[kind.upper()]
    if isinstance(target, str):
        target = Target[target.upper()]
    for name, value in (("kind", kind), ("target", target)):
        enum_type = FaultKind if name == "kind" else Target
        if not isinstance(value, jax.Array) and int(value) not in {e.value for e in enum_type}:
            raise ValueError(f"{name}: expected one of {[e.name for e in enum_type]}, got {value}")
    return Fault(
        kind=jnp.asarray(kind, jnp.int32),
        target=jnp.asarray(target, jnp.int32),
        component=jnp.asarray(component, jnp.int32),
        onset=jnp.asarray(onset, jnp.int32),
        magnitude=jnp.asarray(magnitude, dtype=jnp.result_type(float)),
        slope=jnp.asarray(slope, dtype=jnp.result_type(float)),
        end=jnp.asarray(end, jnp.int32),
    )


def no_fault() -> Fault:
    """The fault-free label (never active)."""
    return fault(FaultKind.NONE, Target.SENSOR, 0, NEVER)


def stack_faults(faults: list[Fault]) -> Fault:
    """Stack faults along a new leading axis (a batch for vmap, or simultaneous faults)."""
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *faults)


def is_active(f: Fault, k: Array) -> Array:
    """Whether fault ``f`` (scalar leaves) acts at step ``k``."""
    live = (f.kind != FaultKind.NONE) & (k >= f.onset) & (k < f.end)
    return jnp.where(f.kind == FaultKind.IMPULSE, live & (k == f.onset), live)


def fault_label(f: Fault, num_inputs: int) -> Array:
    """Integer mode label: 0 no fault, ``1 + i`` actuator i, ``1 + num_inputs + j`` sensor j.

    For the engine (one input) this is the seed-003 order: normal, actuator, RPM, P2, T2,
    P4, T4.
    """
    label = jnp.where(f.target == Target.ACTUATOR, 1 + f.component, 1 + num_inputs + f.component)
    return jnp.where(f.kind == FaultKind.NONE, 0, label)


def apply_fault(f: Fault, k: Array, signal: Array, target: int, held: Array) -> tuple[Array, Array]:
    """Apply one fault (scalar leaves) to ``signal`` at step ``k``.

    Args:
      f: the fault.
      k: current step.
      signal: (d,) nominal actuator or sensor vector.
      target: which signal this is (``Target.ACTUATOR`` or ``Target.SENSOR``); a fault on
        the other target leaves it unchanged.
      held: () the value held by a STUCK fault (carried by the simulator).

    Returns:
      ``(faulty signal, new held value)``.
    """
    on_this = (f.target == target) & is_active(f, k)
    one_hot = jax.nn.one_hot(f.component, signal.shape[0], dtype=signal.dtype)
    s = signal[jnp.clip(f.component, 0, signal.shape[0] - 1)]
    held = jnp.where((k == f.onset) & (f.target == target), s, held)
    elapsed = (k - f.onset).astype(signal.dtype)
    faulty = jnp.select(
        [
            f.kind == FaultKind.BIAS,
            f.kind == FaultKind.RAMP,
            f.kind == FaultKind.IMPULSE,
            f.kind == FaultKind.SCALE,
            f.kind == FaultKind.EFFECTIVENESS,
            f.kind == FaultKind.STUCK,
            f.kind == FaultKind.STOP,
        ],
        [
            s + f.magnitude,
            s + f.magnitude + f.slope * elapsed,
            s + f.magnitude,
            (1 + f.magnitude) * s,
            (1 - f.magnitude) * s,
            held,
            jnp.zeros_like(s),
        ],
        s,
    ).astype(signal.dtype)
    return jnp.where(on_this, signal + one_hot * (faulty - s), signal), held


def apply_faults(faults: Fault, k: Array, signal: Array, target: int, held: Array) -> tuple[Array, Array]:
    """Apply a stack of faults (leaves with a leading axis F) in order; ``held`` is (F,)."""

    def body(sig, fault_and_held):
        one, h = fault_and_held
        return apply_fault(one, k, sig, target, h)

    return jax.lax.scan(body, signal, (faults, held))
