"""The closed loop's stage types (``loop.run_loop``): plant, FDI, controller, scorer; types only, so any layer can build
a stage without importing the loop."""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

from jax import Array


class Plant(NamedTuple):
    """A plant's two halves, ``step_key = fold_in(key, k)``; ``Simulator`` has these fields.

    Attributes:
      init: ``init(x0) -> state``, the plant's initial state from the true initial state
      measure: ``measure(state, k, u, step_key) -> (state, sensed)``: the sensors read ``x[k]``; ``sensed`` is ``y[k]``
        or has it as its ``measurement`` field (e.g. ``Sensed``)
      advance: ``advance(state, k, u, step_key) -> (state, moved)``: actuator faults and dynamics with ``u[k]``;
        ``moved`` is kept in the loop's trace (e.g. ``Actuated``)
      horizon: the most steps the plant can run (a plant replaying T steps of tables: T), or ``None`` (unbounded);
        ``run_loop`` refuses more
    """

    init: Callable[[Array], Any]
    measure: Callable[[Any, Array, Array, Array], tuple[Any, Any]]
    advance: Callable[[Any, Array, Array, Array], tuple[Any, Any]]
    horizon: int | None = None


class FDI(NamedTuple):
    """An FDI stage, built like a ``Filter``: ``init`` makes its state, ``observe`` runs before the controller
    (``None``: the controller sees ``y``), ``step`` after it.

    Attributes:
      init: ``init(*args) -> state``, the FDI's initial state from its own arguments (e.g. its filter's prior ``(mean,
        cov)``); a stateless FDI's ``init()`` gives ``None``
      step: ``step(state, k, y, u) -> (state, output)``: the FDI's step after the controller (time update, detectors,
        decisions); ``output`` is what a ``Scorer`` folds
      observe: ``observe(state, k, y) -> (state, view)``, the part the controller waits for, or ``None``
    """

    init: Callable[..., Any]
    step: Callable[[Any, Array, Any, Array], tuple[Any, Any]]
    observe: Callable[[Any, Array, Any], tuple[Any, Any]] | None = None


class Controller(NamedTuple):
    """A controller; ``feedforward=True``: called with ``view=None`` before the sensors read, so their feed-through sees
    this step's ``u``.

    Attributes:
      init: ``init() -> state``, the controller's initial state
      step: ``step(state, k, view, exogenous) -> (state, u)``: ``u`` (nu,) is ``u[k]``; ``exogenous`` is step ``k``'s
        slice of the loop's per-step data
      feedforward: bool, ``u`` does not depend on ``view`` (default False)
    """

    init: Callable[[], Any]
    step: Callable[[Any, Array, Any, Any], tuple[Any, Array]]
    feedforward: bool = False


class Scorer(NamedTuple):
    """Metrics folded over a run; ``example()`` gives the FDI output's structure (``jax.ShapeDtypeStruct`` leaves; it
    traces one step: call it only when the score's shape depends on the output).

    Attributes:
      init: ``init(example) -> score``, the score before the first step
      update: ``update(score, k, output) -> score``, folds step ``k``'s FDI output in
    """

    init: Callable[[Any], Any]
    update: Callable[[Any, Array, Any], Any]
