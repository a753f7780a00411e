"""One open-loop Monte Carlo run as one fused scan: plant -> filter -> detector -> metrics.

Fusing the four in a single ``lax.scan`` means nothing of length T is stored unless
asked (``keep_history=True``): a run costs a ``DetectionRecord`` of a few numbers, which
is what lets 10^5 runs fit in memory. The filter may be any ``Filter`` (KF, IMM, ...) and
the detector any ``Detector``; ``detector_input`` picks what the detector reads from the
filter's info (the NIS by default; innovations for a GLRT, mode probabilities for an IMM).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.loop import detection_scorer, feedforward, run_loop
from jaxfdi._simulation.simulate import Actuated, Sensed, Simulator
from jaxfdi._simulation.stages import FDI
from jaxfdi._studies.metrics import DetectionRecord, record_init, record_update, step_health
from jaxfdi.detection import Detector, flag_dead
from jaxfdi.filters import Filter, FilterInfo


class MonitorHistory(NamedTuple):
    """Per-step history of a monitored run: labelled truth, actuation, filter outputs, statistic, alarm and label.

    Attributes:
      truth: (T, ...) labelled truth, the simulator's ``Sensed``
      moved: (T, ...) what the actuators applied, the simulator's ``Actuated``
      info: (T, ...) filter outputs
      statistic: (T,) test statistic
      alarm: (T,) bool decision
      label: (T,) int isolated label (-1: the detector does not isolate)
      estimate: (T,) the detector's fault estimate (NaN: none)
    """

    truth: Sensed
    moved: Actuated
    info: FilterInfo
    statistic: Array
    alarm: Array
    label: Array
    estimate: Array


class MonitorResult(NamedTuple):
    """What ``monitor`` returns: the run's detection record and, optionally, its history.

    Attributes:
      record: the run's ``DetectionRecord`` (scalar fields: first alarm, detection step, ...)
      history: the ``MonitorHistory`` of (T, ...) per-step arrays with ``keep_history=True``,
        else ``None``
    """

    record: DetectionRecord
    history: MonitorHistory | None


def dead_channels(info: Any) -> Array | None:
    """(m,) bool, the channels a filter step reported dead (``filters._base``): NaN in a
    ``FilterInfo``'s innovation, an ``IMMInfo``'s ``dead``; ``None`` for other infos."""
    if isinstance(info, FilterInfo):
        return jnp.isnan(info.innovation)
    return getattr(info, "dead", None)


def filter_detector(
    filt: Filter,
    detector: Detector,
    detector_input: Callable[[Any], Array] | None = None,
    channel_labels: Array | None = None,
) -> FDI:
    """The open-loop FDI: a fault-blind filter and a detector reading its info (``detector_input``; the NIS by
    default). Its state is ``(filter state, detector state)``, from ``init(*args)``: the filter's ``init(*args)`` and
    the detector's ``init()``; its output ``(info, Decision)``. A step whose filter reports a dead channel ``j``
    alarms, with label ``channel_labels[j]`` (``chi2.flag_dead``; ``None``: the detector's own label), whatever the
    detector reads."""
    detector_input = detector_input or (lambda info: info.nis)

    def step(state, k, y, u):
        filt_state, det_state = state
        filt_state, info = filt.step(filt_state, y, u)
        det_state, decision = detector.step(det_state, detector_input(info))
        dead = dead_channels(info)
        if dead is not None:
            decision = flag_dead(decision, dead, channel_labels)
        return (filt_state, det_state), (info, decision)

    return FDI(lambda *args, **kwargs: (filt.init(*args, **kwargs), detector.init()), step)


def monitor(
    sim: Simulator,
    filt: Filter,
    detector: Detector,
    x0: Array,
    filter_state0: Any,
    us: Array,
    key: Array,
    onset: Array,
    keep_history: bool = False,
    detector_input: Callable[[Any], Array] | None = None,
    estimate_delay: int = 0,
    channel_labels: Array | None = None,
) -> MonitorResult:
    """Simulate, filter and test one run; return its detection record (and history).

    The open-loop case of ``loop.run_loop``: ``feedforward()`` controller, the
    ``filter_detector`` FDI, a ``detection_scorer``.

    Args:
      sim: the (faulty) plant; filt: the fault-blind filter; detector: fed ``info.nis``.
      x0: (n,) true initial state; filter_state0: ``filt.init(...)``.
      us: (T, nu) commanded inputs; key: PRNG key of the run.
      onset: () fault onset step used for the metrics (``faults.NEVER`` if none).
      keep_history: also return the (T, ...) history (memory grows with T).
      detector_input: ``info -> detector input``; default ``lambda info: info.nis``.
      estimate_delay: the record keeps the detector's estimate of the isolated fault,
        the latest within this many steps after the detection step (an estimate taken
        at the alarm itself is biased by the selection: the noise that crossed the
        threshold is in it; steps whose label differs from the isolated one are skipped).
        A step whose filter is unhealthy or whose statistic is NaN marks the record's
        ``first_unhealthy`` (an infinite statistic, a dead sensor, is an alarm).
      channel_labels: (m,) the fault label of each measurement channel, which a step with
        a dead channel isolates (``filter_detector``).

    Returns:
      ``MonitorResult(record, history)``: the run's ``DetectionRecord`` and, with
      ``keep_history=True``, its ``MonitorHistory`` (truth ``Sensed``, ``Actuated``, filter info,
      statistic, alarm, label and estimate, each with a leading time axis T), else ``None``.
    """
    us = checks.check_inputs(us)
    scorer = detection_scorer(
        onset,
        lambda out: out[1],
        lambda out: out[0].healthy,
        estimate_delay,
        jnp.asarray(x0).dtype,
        single=True,
    )
    result = run_loop(
        sim,
        filter_detector(filt, detector, detector_input, channel_labels),
        feedforward(),
        x0,
        (filter_state0, detector.init()),
        key,
        exogenous=us,
        scorer=scorer,
        keep_history=keep_history,
    )
    history = None
    if keep_history:
        trace = result.history
        info, decision = trace.output
        history = MonitorHistory(trace.sensed, trace.moved, info, *decision)
    return MonitorResult(result.score, history)


def replay_detector(
    detector: Detector,
    inputs: Any,
    onset: Array,
    estimate_delay: int = 0,
    healthy: Array | None = None,
    dead: Array | None = None,
    channel_labels: Array | None = None,
) -> DetectionRecord:
    """The detection record of ``detector`` over a stored (T, ...) input sequence, the
    detector half of ``monitor`` without the plant and filter (e.g. to try thresholds on
    mode probabilities computed once, or after a batch filter kernel). ``healthy`` (T,)
    bool, the filter's health per step (``info.healthy``): with ``None`` only the
    statistic (NaN: ``metrics.step_health``) marks ``first_unhealthy``; given, the record
    is ``monitor``'s. ``dead`` (T, m) bool, the channels the filter reported dead at each
    step (``dead_channels``), alarm with ``channel_labels`` as in ``filter_detector``.

    Returns:
      ``DetectionRecord`` (scalar fields) of the T steps, its ``estimate`` of the inputs' dtype.
    """
    checks.check_int_array("estimate_delay", estimate_delay, 0, meaning="a number of steps >= 0")
    steps = jnp.arange(jax.tree.leaves(inputs)[0].shape[0])
    healthy = jnp.ones(steps.shape, bool) if healthy is None else jnp.asarray(healthy, bool)
    checks.check_shape("healthy", healthy, steps.shape, "one flag per step of inputs (T,)")

    dead = jnp.zeros(steps.shape + (0,), bool) if dead is None else jnp.asarray(dead, bool)

    def body(carry, k_input):
        det_state, record = carry
        k, x, ok, dead_k = k_input
        det_state, decision = detector.step(det_state, x)
        decision = flag_dead(decision, dead_k, channel_labels)
        ok = step_health(ok, decision.statistic)
        return (
            det_state,
            record_update(
                record,
                k,
                decision.alarm,
                decision.label,
                decision.estimate,
                estimate_delay,
                healthy=ok,
            ),
        ), None

    dtype = jnp.result_type(*jax.tree.leaves(inputs))
    (_, record), _ = jax.lax.scan(
        body, (detector.init(), record_init(onset, dtype)), (steps, inputs, healthy, dead)
    )
    return record
