"""Faults as data: a ``Fault`` pytree and the pure function that applies it.

A fault acts on one component of the actuator signal ``u`` or sensor signal ``y`` while ``onset <= k < end``
(steps), as its ``FaultKind`` says. Every leaf is an array, so batches of faults (kinds, components, onsets,
magnitudes) vmap like data and each Monte Carlo run carries its own label.

A fault on a *group* of components (both axes of a 2-DOF rate sensor, one satellite's pseudorange) is a stack of
single-component faults sharing one explicit ``label`` (``fault_group``; ``label = -1``, the default: derived by
``fault_label`` from target and component). Faults with different ``onset``/``end`` in one stack
(``concat_faults``) are episodes of one run (``episodes``); a step's mode is the label of the stack's first active
fault (``active_label``).

A plant may give a kind more physics: the reaction-wheel scenario reads STOP as "speed to 0, momentum to the body"
and STUCK as "speed freezes" (``scenarios.reaction_wheels.wheel_fault``).
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks

#: an ``end`` far beyond any simulation: the fault never clears.
NEVER = 2**30


class FaultKind(enum.IntEnum):
    """How a fault acts on the nominal component ``s`` at step ``k``.

    Attributes:
      NONE: 0, no fault: the component is nominal (a fault-free run)
      BIAS: 1, ``s + magnitude`` (a step)
      RAMP: 2, ``s + magnitude + slope (k - onset)`` (a drift, ``slope`` per step)
      IMPULSE: 3, ``s + magnitude`` at ``k == onset`` only (a single-sample spike)
      SCALE: 4, ``(1 + magnitude) s`` (sensor scaling)
      EFFECTIVENESS: 5, ``(1 - magnitude) s``, an actuator effectiveness loss in [0, 1]
      STUCK: 6, ``s(onset)``: stuck at the value at onset
      STOP: 7, ``0``: the component stops (no output)
      DEAD: 8, ``NaN``: a dead or disconnected sensor (sensors only)
    """

    NONE = 0
    BIAS = 1
    RAMP = 2
    IMPULSE = 3
    SCALE = 4
    EFFECTIVENESS = 5
    STUCK = 6
    STOP = 7
    DEAD = 8


class Target(enum.IntEnum):
    """Where a fault acts: on an actuator (input) or a sensor (measurement) component.

    Attributes:
      ACTUATOR: 0, a component of the actuator (input) signal ``u``
      SENSOR: 1, a component of the sensor (measurement) signal ``y``
    """

    ACTUATOR = 0
    SENSOR = 1


class Fault(NamedTuple):
    """One fault (scalar leaves) or a batch of faults (leaves with leading axes).

    Attributes:
      kind: int, a FaultKind
      target: int, a Target
      component: int, index into u (actuator) or y (sensor)
      onset: int, first faulty step
      magnitude: float, the fault's size (its use per kind: FaultKind)
      slope: float, per step (RAMP)
      end: int, first step after the fault (NEVER = permanent)
      label: int, mode label; -1: derived from target and component (``fault_label``)
    """

    kind: Array
    target: Array
    component: Array
    onset: Array
    magnitude: Array
    slope: Array
    end: Array
    label: Array = -1


def _enum_value(name: str, value, enum_type):
    """``value`` (an enum, its name or its integer) as an integer of ``enum_type``."""
    expected = [e.name.lower() for e in enum_type]
    if isinstance(value, str):
        if value.upper() not in enum_type.__members__:
            raise ValueError(f"{name}: expected one of {expected}, got {value!r}")
        return enum_type[value.upper()]
    if isinstance(value, enum_type):
        return value
    checks.check_int_array(
        name, value, meaning=f"one of {expected} (a name, the enum or its integer)"
    )
    concrete = checks.concrete(value)
    if concrete is not None and not np.all(np.isin(concrete, [e.value for e in enum_type])):
        raise ValueError(
            f"{name}: expected one of {expected} (or their integers "
            f"{[e.value for e in enum_type]}), got {checks.received(concrete)}"
        )
    return value


def fault(kind, target, component, onset, magnitude=0.0, slope=0.0, end=NEVER, label=-1) -> Fault:
    """Build a ``Fault``; ``kind`` and ``target`` take the enums or their names; arguments may be arrays (a batch).

    Checked at trace time: integer ``component >= 0``, ``onset >= 0``, ``end > onset``, ``label >= -1``; finite
    real ``magnitude`` and ``slope``; EFFECTIVENESS ``magnitude`` in [0, 1] (above 1 reverses the input's sign).
    The simulator checks ``component`` against the signal size. ``label`` >= 0 sets the mode label explicitly
    (e.g. a sensor group's); -1 (default): ``fault_label``.

    Returns:
      ``Fault`` with int32 ``kind``, ``target``, ``component``, ``onset``, ``end``, ``label`` and float
      ``magnitude``, ``slope`` (default float dtype), each of its argument's shape (scalars for one fault).
    """
    kind = _enum_value("kind", kind, FaultKind)
    target = _enum_value("target", target, Target)
    checks.check_int_array("component", component, 0, meaning="a component index >= 0")
    checks.check_int_array("onset", onset, 0, meaning="a step index >= 0")
    checks.check_int_array("end", end, meaning="a step index after the onset")
    checks.check_int_array("label", label, -1, meaning="a mode label >= 0, or -1 (derived)")
    for name, value in (("magnitude", magnitude), ("slope", slope)):
        checks.check_real(name, value, "real numbers")
        checks.check_finite(name, value)
    onsets, ends = checks.concrete(onset), checks.concrete(end)
    if onsets is not None and ends is not None and np.any((ends <= onsets) & (onsets < NEVER)):
        raise ValueError(
            f"end: expected a step after the onset (end > onset), got end {checks.received(ends)} "
            f"for onset {checks.received(onsets)}"
        )
    kinds, sizes, targets = (
        checks.concrete(kind),
        checks.concrete(magnitude),
        checks.concrete(target),
    )
    if (
        kinds is not None
        and targets is not None
        and np.any((kinds == FaultKind.DEAD) & (targets == Target.ACTUATOR))
    ):
        raise ValueError(
            "kind: DEAD (a NaN output) is a sensor fault; an actuator that stops is STOP, got DEAD on "
            "an actuator"
        )
    if kinds is not None and sizes is not None:
        loss = np.broadcast_to(
            kinds == FaultKind.EFFECTIVENESS, np.broadcast_shapes(np.shape(kinds), np.shape(sizes))
        )
        if np.any(loss & ((sizes < 0) | (sizes > 1))):
            raise ValueError(
                f"magnitude: expected an effectiveness loss in [0, 1] (1 = no effect at all), got "
                f"{checks.received(sizes)}"
            )
    return Fault(
        kind=jnp.asarray(kind, jnp.int32),
        target=jnp.asarray(target, jnp.int32),
        component=jnp.asarray(component, jnp.int32),
        onset=jnp.asarray(onset, jnp.int32),
        magnitude=jnp.asarray(magnitude, dtype=jnp.result_type(float)),
        slope=jnp.asarray(slope, dtype=jnp.result_type(float)),
        end=jnp.asarray(end, jnp.int32),
        label=jnp.asarray(label, jnp.int32),
    )


def fault_group(
    kind, target, components, onset, magnitudes, slopes=0.0, end=NEVER, label=-1
) -> Fault:
    """One fault on a group of components, labelled as one: a stack (leading axis G).

    Entry ``g`` acts on ``components[g]`` with ``magnitudes[g]``, ``slopes[g]`` (scalars broadcast), sharing kind,
    target, onset, end and ``label``; a fault "in any direction of the sensor's plane" is
    ``magnitudes = size * direction``.

    Args:
      components: (G,) component indices, G >= 1.
      magnitudes, slopes: (G,) or scalar.
      label: the group's mode label (>= 0), shared by every entry; -1 keeps the derived per-component labels.

    Returns:
      ``Fault`` with leaves of a leading axis G (for ``concat_faults`` and the simulator).
    """
    if np.size(components) == 0:
        raise ValueError(
            f"components: expected shape (G,) with G >= 1, got {checks.received(components)}"
        )
    checks.check_int_array("components", components, 0, meaning="component indices >= 0")
    components = jnp.asarray(components, jnp.int32)
    if components.ndim != 1 or components.shape[0] < 1:
        raise ValueError(
            f"components: expected shape (G,) with G >= 1, got {tuple(components.shape)}"
        )
    values = checks.concrete(components)
    if values is not None and len(np.unique(values)) != values.size:  # faulted twice
        raise ValueError(
            f"components: expected each component of the group once, got {checks.received(values)}"
        )
    size = components.shape[0]
    for name, value in (("magnitudes", magnitudes), ("slopes", slopes)):
        shape = checks.shape_of(value)
        if len(shape) not in (0, 1) or (len(shape) == 1 and shape[0] != size):
            raise ValueError(
                f"{name}: expected a scalar or shape ({size},) like components, got {shape}"
            )
    entries = [
        fault(
            kind,
            target,
            components[g],
            onset,
            jnp.broadcast_to(jnp.asarray(magnitudes), (size,))[g],
            jnp.broadcast_to(jnp.asarray(slopes), (size,))[g],
            end,
            label,
        )
        for g in range(size)
    ]
    return stack_faults(entries)


def no_fault() -> Fault:
    """The fault-free label (never active).

    Returns:
      ``Fault`` with scalar leaves: kind NONE on sensor 0, ``onset = NEVER``; its ``fault_label`` is 0.
    """
    return fault(FaultKind.NONE, Target.SENSOR, 0, NEVER)


def stack_faults(faults: list[Fault]) -> Fault:
    """Stack faults along a new leading axis (a batch for vmap, or simultaneous faults).

    Returns:
      ``Fault`` whose leaves have a new leading axis of ``len(faults)`` (scalar leaves become (F,)).
    """
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *faults)


def concat_faults(*faults: Fault) -> Fault:
    """One stack (leading axis F) of single faults and stacks, in order: one run's faults (group, later episodes).

    Returns:
      ``Fault`` whose leaves are the arguments' stacks concatenated along axis 0.
    """
    if not faults:
        raise ValueError("faults: expected at least one Fault, got none")
    for i, f in enumerate(faults):
        if not isinstance(f, Fault):
            raise TypeError(
                f"faults: expected Fault arguments (fault, fault_group, ...), got {checks.received(f)} "
                f"at position {i}"
            )
    return jax.tree_util.tree_map(
        lambda *leaves: jnp.concatenate(leaves), *(as_stack(f) for f in faults)
    )


def is_active(f: Fault, k: Array) -> Array:
    """Whether fault ``f`` (scalar leaves) acts at step ``k``.

    Returns:
      () bool: ``onset <= k < end`` for a fault of a kind other than NONE; an IMPULSE only at ``k == onset``.
    """
    live = (f.kind != FaultKind.NONE) & (k >= f.onset) & (k < f.end)
    return jnp.where(f.kind == FaultKind.IMPULSE, live & (k == f.onset), live)


def sensor_labels(num_inputs: int, num_sensors: int) -> Array:
    """(num_sensors,) int: sensor ``j``'s ``fault_label`` ``1 + num_inputs + j``, what a dead ``j`` isolates to.

    Returns:
      (num_sensors,) int32 array ``[1 + num_inputs, ..., num_inputs + num_sensors]``.
    """
    return 1 + int(num_inputs) + jnp.arange(int(num_sensors), dtype=jnp.int32)


def fault_label(f: Fault, num_inputs: int) -> Array:
    """Integer mode label: 0 no fault, ``1 + i`` actuator i, ``1 + num_inputs + j`` sensor j; an explicit
    ``f.label`` (>= 0, e.g. a ``fault_group``'s) takes precedence. For the engine (one input) this is the mode order
    of Han et al. (2022): normal, actuator, RPM, P2, T2, P4, T4.

    Returns:
      int32 array of the leaves' shape (() for one fault): 0 for a NONE fault, else ``f.label`` if >= 0, else the
      label derived from target and component.
    """
    derived = jnp.where(f.target == Target.ACTUATOR, 1 + f.component, 1 + num_inputs + f.component)
    label = jnp.where(jnp.asarray(f.label) >= 0, f.label, derived)
    return jnp.where(f.kind == FaultKind.NONE, 0, label).astype(jnp.int32)


def active_label(faults: Fault, k: Array, num_inputs: int) -> Array:
    """() int: ``fault_label`` of the first fault of the stack (leaves (F,) or scalar) active at ``k``, else 0."""
    faults = as_stack(faults)
    active = jax.vmap(is_active, in_axes=(0, None))(faults, k)
    labels = jax.vmap(fault_label, in_axes=(0, None))(faults, num_inputs)
    return jnp.where(jnp.any(active), labels[jnp.argmax(active)], 0).astype(jnp.int32)


def episodes(faults: Fault, num_inputs: int) -> tuple[Array, Array, Array]:
    """The fault episodes of one run: ``(onsets, ends, labels)``, each (F,) int.

    Entry ``i``: fault ``i``'s onset, end (``onset + 1`` for an IMPULSE) and ``fault_label``. NONE faults and
    repeats of an earlier entry's (onset, end, label) (further components of a ``fault_group``) carry
    ``onset = end = NEVER``, label 0. Fixed shapes (jits, vmaps over runs); feeds ``metrics.episode_record_init``.

    Returns:
      ``(onsets, ends, labels)``: three (F,) int32 arrays (steps, steps, mode labels), F the stack's length (1 for
      a scalar fault).
    """
    faults = as_stack(faults)
    ends = jnp.where(
        faults.kind == FaultKind.IMPULSE, jnp.minimum(faults.end, faults.onset + 1), faults.end
    )
    labels = jax.vmap(fault_label, in_axes=(0, None))(faults, num_inputs)
    count = faults.kind.shape[0]
    same = (
        (faults.onset[:, None] == faults.onset[None, :])
        & (ends[:, None] == ends[None, :])
        & (labels[:, None] == labels[None, :])
        & (faults.kind != FaultKind.NONE)[None, :]
    )
    earlier = jnp.arange(count)[None, :] < jnp.arange(count)[:, None]
    valid = (faults.kind != FaultKind.NONE) & ~jnp.any(same & earlier, axis=1)
    never = jnp.asarray(NEVER, jnp.int32)
    return (
        jnp.where(valid, faults.onset, never).astype(jnp.int32),
        jnp.where(valid, ends, never).astype(jnp.int32),
        jnp.where(valid, labels, 0).astype(jnp.int32),
    )


def as_stack(f: Fault) -> Fault:
    """Leaves (F,): scalar faults become a stack of one; a stack's scalar leaf (hand-built, no ``label``) broadcast.

    Returns:
      ``Fault`` whose leaves all have the leading axis F (``f.kind``'s shape, (1,) for a scalar fault); leaves
      that already have axes are returned as they are.
    """
    shape = jnp.shape(f.kind) if jnp.ndim(f.kind) else (1,)
    return jax.tree_util.tree_map(
        lambda leaf: jnp.broadcast_to(jnp.asarray(leaf), shape) if jnp.ndim(leaf) == 0 else leaf, f
    )


def apply_fault(f: Fault, k: Array, signal: Array, target: int, held: Array) -> tuple[Array, Array]:
    """Apply one fault (scalar leaves) to ``signal`` at step ``k``.

    Args:
      f: the fault.
      k: current step.
      signal: (d,) nominal actuator or sensor vector.
      target: ``Target.ACTUATOR`` or ``Target.SENSOR``, which signal this is; a fault on the other leaves it as is.
      held: () the value held by a STUCK fault (carried by the simulator).

    Returns:
      ``(faulty signal, new held value)``.
    """
    on_this = (f.target == target) & is_active(f, k)
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
            f.kind == FaultKind.DEAD,
        ],
        [
            s + f.magnitude,
            s + f.magnitude + f.slope * elapsed,
            s + f.magnitude,
            (1 + f.magnitude) * s,
            (1 - f.magnitude) * s,
            held,
            jnp.zeros_like(s),
            jnp.full_like(s, jnp.nan),
        ],
        s,
    ).astype(signal.dtype)
    # the component takes the faulty value itself (a held value is held to the last bit)
    here = on_this & (jnp.arange(signal.shape[0]) == f.component)
    return jnp.where(here, faulty, signal).astype(signal.dtype), held


def apply_faults(
    faults: Fault, k: Array, signal: Array, target: int, held: Array
) -> tuple[Array, Array]:
    """Apply a stack of faults (leaves with a leading axis F) in order; ``held`` is (F,)."""

    def body(sig, fault_and_held):
        one, h = fault_and_held
        return apply_fault(one, k, sig, target, h)

    return jax.lax.scan(body, signal, (faults, held))
