"""One closed-loop run as one ``lax.scan``: plant -> sensors -> FDI -> controller -> plant.

Every scenario, open or closed loop, is this scan with three parts (types: ``jaxfdi._simulation.stages``): a **plant**
``(init, measure, advance)`` (a ``Simulator``, or a model's own halves, e.g. the reaction wheels); an **FDI**
``(step, observe)`` (estimator, detector, isolator, reconfiguration); a **controller** ``(init, step)``. Step ``k``
(``Ts`` apart):

1. ``measure(plant, k, u_s, step_key) -> (plant, sensed)``, ``step_key = fold_in(key, k)``: sensors read ``x[k]``
   (noise, sensor faults), ``sensed.measurement`` is ``y[k]``; the feed-through sees ``u_s = u[k]`` for a feed-forward
   controller (computed first), else ``u[k-1]``, still held by the zero-order hold (no algebraic loop);
2. ``observe(fdi, k, y) -> (fdi, view)``: what the controller waits for (estimator update, selected or compensated
   measurements, isolated label, reconfiguration); without ``observe`` the view is ``y``;
3. ``controller.step(ctrl, k, view, exogenous[k]) -> (ctrl, u[k])``;
4. ``fdi.step(fdi, k, y, u) -> (fdi, output)``: the rest (time update with the input the plant is believed to get,
   filter banks, detectors, decisions);
5. ``advance(plant, k, u, step_key) -> (plant, moved)``: actuator faults, dynamics;
6. ``scorer.update(score, k, output)``: metrics folded into the carry (a ``DetectionRecord`` per decision, peaks, ...);
   ``keep_history=True`` also keeps the (T, ...) trace.

``monitor`` (open loop: precomputed inputs, one filter, one detector) is this scan with ``feedforward()``. A part that
re-runs a filter over its last ``L`` steps (Park et al. 2004's UKF restarts 2-3 steps before the detection) keeps a
fixed-size ``filters.history.RingBuffer`` and replays it with ``filters.history.replay_filter`` (bounded, jit/vmap).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.stages import FDI, Controller, Plant, Scorer
from jaxfdi._studies.metrics import (
    DetectionRecord,
    EpisodeRecord,
    episode_record_init,
    episode_record_update,
    record_init,
    record_update,
    step_health,
)
from jaxfdi._studies.montecarlo import is_key
from jaxfdi.detection import Decision


class LoopTrace(NamedTuple):
    """One step of a run (stacked over time with ``keep_history=True``).

    Attributes:
      sensed: what ``measure`` returned (e.g. ``simulate.Sensed``)
      view: what the controller saw
      control: u[k]
      output: what ``fdi.step`` returned
      moved: what ``advance`` returned (e.g. ``simulate.Actuated``)
    """

    sensed: Any
    view: Any
    control: Array
    output: Any
    moved: Any


class LoopResult(NamedTuple):
    """What ``run_loop`` returns: the scorer's final value, the history (optional) and the final states.

    Attributes:
      score: ``scorer``'s final value (``None`` without a scorer)
      history: (T, ...) with ``keep_history=True``
      final: (plant, fdi, controller) states after the last step
    """

    score: Any
    history: LoopTrace | None
    final: Any = None


def feedforward() -> Controller:
    """The open-loop controller: ``u[k] = exogenous[k]`` (precomputed inputs).

    Returns:
      ``Controller(init, step, feedforward=True)`` with no state (``init() -> None``):
      ``step(None, k, view, exogenous) -> (None, jnp.asarray(exogenous))``, ``view`` unused (``None``).
    """
    return Controller(
        lambda: None, lambda state, k, view, u: (state, jnp.asarray(u)), feedforward=True
    )


def state_feedback(gain: Array, reference: Callable[[Array], Array] | None = None) -> Controller:
    """``u[k] = -K (x_hat[k] - x_ref[k])`` on the view (an estimate; ``u = -K x`` as SciPy's LQR), with ``x_ref`` from
    ``reference(exogenous)`` or zero.

    Returns:
      ``Controller(init, step)`` (not feed-forward) with no state (``init() -> None``):
      ``step(None, k, view, exogenous) -> (None, u)``, ``u`` (nu,) for a ``gain`` (nu, n) and a view (n,).
    """
    checks.check_matrix("gain", gain, (None, None), "K: nu inputs x n states, u = -K x")
    gain = jnp.asarray(gain)

    def step(state, k, view, exogenous):
        error = view if reference is None else view - reference(exogenous)
        return state, -gain @ error

    return Controller(lambda: None, step)


def measurement_of(sensed: Any) -> Any:
    """``y[k]`` of what a plant's ``measure`` returned: its ``measurement`` field if it has one, else the value
    itself."""
    return getattr(sensed, "measurement", sensed)


def run_loop(
    plant: Plant,
    fdi: FDI,
    controller: Controller,
    x0: Any,
    fdi_state0: Any,
    key: Array,
    steps: int | None = None,
    *,
    exogenous: Any = None,
    controller_state0: Any = None,
    u0: Array | None = None,
    scorer: Scorer | None = None,
    keep_history: bool = False,
) -> LoopResult:
    """Run ``steps`` steps of the closed loop (module doc) and return its ``LoopResult``.

    Args:
      plant, fdi, controller: the three parts (``Plant``, ``FDI``, ``Controller``).
      x0: the plant's initial state (``plant.init(x0)``).
      fdi_state0: the FDI's initial state, ``fdi.init(...)``.
      key: PRNG key of the run (the plant draws step ``k``'s noise from it).
      steps: number of steps T; may be omitted when ``exogenous`` is given.
      exogenous: pytree of (T, ...) per-step data for the controller (feed-forward inputs, references), or ``None``.
      controller_state0: the controller's initial state (default ``controller.init()``).
      u0: the input held before step 0 (what the feed-through sees at step 0 in closed loop); required unless the
        controller is feed-forward.
      scorer: ``Scorer`` of the FDI outputs (e.g. ``detection_scorer``), or ``None``.
      keep_history: also return the stacked ``LoopTrace`` (memory grows with T).

    Returns:
      ``LoopResult(score, history, final)``: the scorer's final value (``None`` without a scorer); with
      ``keep_history=True`` the ``LoopTrace`` of every step stacked along a leading time axis T (else ``None``); and the
      ``(plant, fdi, controller)`` states after the last step.
    """
    for name, part, needed in (
        ("plant", plant, ("init", "measure", "advance")),
        ("fdi", fdi, ("init", "step")),
        ("controller", controller, ("init", "step")),
        ("scorer", scorer, () if scorer is None else ("init", "update")),
    ):
        if not all(callable(getattr(part, field, None)) for field in needed):
            raise TypeError(
                f"{name}: expected an object with callable {', '.join(needed)} (a "
                f"{name.capitalize() if name != 'fdi' else 'FDI'}), got {checks.received(part)}"
            )
    if not is_key(key) or (
        jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key) and key.shape != ()
    ):
        raise TypeError(
            f"key: expected one PRNG key (jax.random.key(seed)), got {checks.received(key)}"
        )
    for leaf in jax.tree_util.tree_leaves(exogenous):
        if jnp.ndim(leaf) == 0:
            raise ValueError(
                f"exogenous: expected (T, ...) leaves with a leading axis of steps, got a scalar leaf "
                f"{checks.received(leaf)}"
            )
    lengths = {leaf.shape[0] for leaf in jax.tree_util.tree_leaves(exogenous)}
    if len(lengths) > 1:
        raise ValueError(
            f"exogenous: every leaf needs the same leading number of steps T, got {sorted(lengths)}"
        )
    if steps is None:
        if not lengths:
            raise ValueError(
                "steps: expected the number of steps (no exogenous data to take it from)"
            )
        steps = lengths.pop()
    steps = checks.check_int("steps", steps, 1, meaning="a positive number of steps")
    horizon = getattr(plant, "horizon", None)
    if horizon is not None and steps > horizon:  # the plant would read its tables past their end
        raise ValueError(
            f"steps: expected at most the plant's {horizon} steps (its tables' length), got {steps}"
        )
    if lengths and lengths != {steps}:
        raise ValueError(f"exogenous: expected {steps} steps along axis 0, got {sorted(lengths)}")
    if not controller.feedforward and u0 is None:
        raise ValueError(
            "u0: a closed loop needs the input held before step 0 (e.g. jnp.zeros(nu))"
        )
    ctrl0 = controller.init() if controller_state0 is None else controller_state0
    held0 = None if controller.feedforward else jax.tree_util.tree_map(jnp.asarray, u0)

    def one_step(plant_state, fdi_state, ctrl_state, held, k, exo):
        step_key = jax.random.fold_in(key, k)
        if controller.feedforward:
            ctrl_state, u = controller.step(ctrl_state, k, None, exo)
            plant_state, sensed = plant.measure(plant_state, k, u, step_key)
            y = measurement_of(sensed)
            fdi_state, view = (
                (fdi_state, y) if fdi.observe is None else fdi.observe(fdi_state, k, y)
            )
        else:
            plant_state, sensed = plant.measure(plant_state, k, held, step_key)
            y = measurement_of(sensed)
            fdi_state, view = (
                (fdi_state, y) if fdi.observe is None else fdi.observe(fdi_state, k, y)
            )
            ctrl_state, u = controller.step(ctrl_state, k, view, exo)
        fdi_state, output = fdi.step(fdi_state, k, y, u)
        plant_state, moved = plant.advance(plant_state, k, u, step_key)
        return (plant_state, fdi_state, ctrl_state, None if held is None else u), LoopTrace(
            sensed, view, u, output, moved
        )

    plant0 = plant.init(x0)
    score0 = None
    if scorer is not None:  # the scorer sizes its records from the output's structure
        exo0 = jax.tree_util.tree_map(lambda leaf: leaf[0], exogenous)
        cache = []

        def example():
            if not cache:
                cache.append(
                    jax.eval_shape(
                        lambda: (
                            one_step(plant0, fdi_state0, ctrl0, held0, jnp.arange(1)[0], exo0)[
                                1
                            ].output
                        )
                    )
                )
            return cache[0]

        score0 = scorer.init(example)

    def body(carry, k_exo):
        states, score = carry
        states, trace = one_step(*states, *k_exo)
        if scorer is not None:
            score = scorer.update(score, k_exo[0], trace.output)
        return (states, score), (trace if keep_history else None)

    ((plant_state, fdi_state, ctrl_state, _), score), history = jax.lax.scan(
        body, ((plant0, fdi_state0, ctrl0, held0), score0), (jnp.arange(int(steps)), exogenous)
    )
    return LoopResult(score, history, (plant_state, fdi_state, ctrl_state))


# --- scoring ----------------------------------------------------------------------


def _decisions(value: Any) -> Any:
    """``value``, a ``Decision`` or a tuple / named tuple / dict of them, checked: a ``TypeError`` names anything
    else."""
    leaves = jax.tree_util.tree_leaves(value, is_leaf=lambda x: isinstance(x, Decision))
    for leaf in leaves:
        if not isinstance(leaf, Decision):
            raise TypeError(
                f"decisions: expected the output's Decision, or a tuple / dict of Decisions, got "
                f"{checks.received(leaf)} in a {type(value).__name__}"
            )
    return value


def _per_decision_scorer(
    decisions: Callable[[Any], Any],
    healthy: Callable[[Any], Array] | None,
    new_record: Callable[[], Any],
    fold: Callable[..., Any],
    record_type: type,
    single: bool,
) -> Scorer:
    """A record (``new_record()``) per decision of the output, each folded with ``fold(record, k, decision, good)``,
    ``good`` = the step healthy and the decision's statistic not NaN (``metrics.step_health``). ``single``:
    ``decisions`` gives one decision (no trace to find out)."""

    def is_healthy(output):
        return (
            healthy(output)
            if healthy is not None
            else getattr(output, "healthy", jnp.ones((), bool))
        )

    def init(example):
        if single:
            return new_record()
        found = jax.eval_shape(lambda out: _decisions(decisions(out)), example())
        return jax.tree_util.tree_map(
            lambda _: new_record(), found, is_leaf=lambda x: isinstance(x, Decision)
        )

    def update(score, k, output):
        found = _decisions(decisions(output))
        ok = jnp.all(is_healthy(output))

        def one(record, decision: Decision):
            return fold(record, k, decision, step_health(ok, decision.statistic))

        return jax.tree_util.tree_map(
            one, score, found, is_leaf=lambda x: isinstance(x, (Decision, record_type))
        )

    return Scorer(init, update)


def detection_scorer(
    onset: Array,
    decisions: Callable[[Any], Any],
    healthy: Callable[[Any], Array] | None = None,
    estimate_delay: int = 0,
    dtype=None,
    single: bool = False,
) -> Scorer:
    """One ``DetectionRecord`` per decision of the FDI output (``metrics``).

    Args:
      onset: () fault onset step (``faults.NEVER`` for a fault-free run).
      decisions: ``output -> Decision``, or a tuple / dict of them: the score is the same structure of records.
      healthy: ``output -> () bool``: the step's numerics were sound (default: the output's ``healthy`` field when it
        has one); with the decision's statistic not NaN, it decides the record's ``first_unhealthy``.
      estimate_delay: as for ``monitor``.
      single: ``decisions`` returns one decision: the record is built without tracing a step to find the structure (a
        structure of several is found by one extra trace).

    Returns:
      ``Scorer`` whose score is a ``DetectionRecord`` (scalar fields) per decision, in the structure ``decisions``
      returns (one record with ``single=True``); ``LoopResult.score`` after the run.
    """
    checks.check_int_array("estimate_delay", estimate_delay, 0, meaning="a number of steps >= 0")
    dtype = dtype or jnp.result_type(float)

    def fold(record: DetectionRecord, k, decision: Decision, good) -> DetectionRecord:
        return record_update(
            record,
            k,
            decision.alarm,
            decision.label,
            decision.estimate,
            estimate_delay,
            healthy=good,
        )

    return _per_decision_scorer(
        decisions, healthy, lambda: record_init(onset, dtype), fold, DetectionRecord, single
    )


def episode_scorer(
    episodes: tuple[Array, Array, Array],
    decisions: Callable[[Any], Any],
    healthy: Callable[[Any], Array] | None = None,
    grace: int = 0,
    single: bool = False,
) -> Scorer:
    """One ``EpisodeRecord`` per decision, for a run with several fault episodes.

    Args:
      episodes: ``(onsets, ends, labels)``, each (E,) (``faults.episodes(fault, nu)``).
      decisions, healthy, single: as for ``detection_scorer``.
      grace: steps after an episode's end still credited to it (``metrics``).

    Returns:
      ``Scorer`` whose score is an ``EpisodeRecord`` ((E,) episode fields, scalar run fields) per decision, in the
      structure ``decisions`` returns (one record with ``single=True``).
    """
    checks.check_int_array("grace", grace, 0, meaning="a number of steps >= 0")

    def fold(record: EpisodeRecord, k, decision: Decision, good) -> EpisodeRecord:
        return episode_record_update(record, k, decision.alarm, decision.label, healthy=good)

    return _per_decision_scorer(
        decisions,
        healthy,
        lambda: episode_record_init(*episodes, grace),
        fold,
        EpisodeRecord,
        single,
    )


def peak_scorer(
    values: Callable[[Any], Array], active: Callable[[Array], Array], dtype=None
) -> Scorer:
    """Running maxima: ``score[i] = max over the steps k with active(k)[i] of values(output)[i]`` (``-inf`` before
    any such step), e.g. the largest statistic before the onset.

    Returns:
      ``Scorer`` whose score is an (n,) array (``dtype``, default float) of the running maxima, ``-inf`` where no
      step was active.
    """
    checks.check_callable("values", values, "a function output -> (n,) values")
    checks.check_callable("active", active, "a function k -> (n,) bool")
    dtype = dtype or jnp.result_type(float)

    def init(example):
        return jnp.full(jax.eval_shape(values, example()).shape, -jnp.inf, dtype)

    def update(score, k, output):
        return jnp.where(active(k), jnp.maximum(score, values(output)), score)

    return Scorer(init, update)


def health_scorer(healthy: Callable[[Any], Array] | None = None) -> Scorer:
    """() bool: every step healthy (default: the output's ``healthy`` field).

    Returns:
      ``Scorer`` whose score is a () bool: True until a step whose ``healthy(output)`` has a False entry.
    """
    if healthy is None:

        def healthy(output):
            if not hasattr(output, "healthy"):
                raise TypeError(
                    "healthy: the loop's output has no 'healthy' field; pass healthy=lambda output: ..., "
                    f"a function output -> bool, got output {type(output).__name__}"
                )
            return output.healthy

    checks.check_callable("healthy", healthy, "a function output -> bool")

    def init(example):
        jax.eval_shape(healthy, example())  # a missing field is an error now, not inside the loop
        return jnp.ones((), bool)

    return Scorer(init, lambda score, k, output: score & jnp.all(healthy(output)))


def combine_scorers(**scorers: Scorer) -> Scorer:
    """Several scorers side by side; the score is a dict by name.

    Returns:
      ``Scorer`` whose score is ``{name: that scorer's score}``, each updated with the same outputs.
    """

    def init(example):
        return {name: scorer.init(example) for name, scorer in scorers.items()}

    def update(score, k, output):
        return {name: scorer.update(score[name], k, output) for name, scorer in scorers.items()}

    return Scorer(init, update)
