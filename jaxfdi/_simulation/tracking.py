"""Scores of a plant's true state folded over a closed-loop run (tracking errors).

``run_loop``'s scorers see the FDI outputs; tracking is a property of the *true* state, which only the plant knows, so
``tracked_plant`` folds a ``TrackingScore`` into the plant's state: ``3 d`` numbers per run instead of a (T, n) history,
read at ``LoopResult.final[0][1]``.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi._simulation.stages import Plant


class TrackingScore(NamedTuple):
    """A scorer's carry: tracking errors accumulated over the scored steps.

    Attributes:
      sum_sq: (d,) sum of error^2 over the scored steps
      max_abs: (d,) largest |error|
      count: (d,) int, steps scored
    """

    sum_sq: Array
    max_abs: Array
    count: Array

    def rms(self) -> Array:
        """(d,) root mean square error (NaN where no step was scored)."""
        return jnp.sqrt(self.sum_sq / jnp.where(self.count > 0, self.count, jnp.nan))


def tracking_init(size: int, dtype=None) -> TrackingScore:
    dtype = dtype or jnp.result_type(float)
    return TrackingScore(
        jnp.zeros((size,), dtype), jnp.zeros((size,), dtype), jnp.zeros((size,), jnp.int32)
    )


def tracking_update(score: TrackingScore, error: Array, active: Array) -> TrackingScore:
    """Fold one step's ``error`` (d,) into ``score`` where ``active`` (d,) bool."""
    error = jnp.asarray(error, score.sum_sq.dtype)
    return TrackingScore(
        score.sum_sq + jnp.where(active, error * error, 0.0),
        jnp.where(active, jnp.maximum(score.max_abs, jnp.abs(error)), score.max_abs),
        score.count + active.astype(jnp.int32),
    )


def tracked_plant(
    plant,
    error: Callable[[Array, Any], Array],
    size: int,
    active: Callable[[Array], Array] | None = None,
    dtype=None,
) -> Plant:
    """``plant`` (a ``loop.Plant``) whose state is ``(state, TrackingScore)`` of ``error(k, sensed)`` over the steps
    where ``active(k)`` (``sensed``: what ``measure`` returned, e.g. a ``simulate.Sensed`` with the true ``state``).

    Args:
      plant: the plant to wrap.
      error: ``(k, sensed) -> (size,)`` the error at step ``k`` from what ``measure`` returns.
      size: number of error components ``d``.
      active: ``k -> (size,) bool`` steps scored per component (default: all).
      dtype: dtype of the score (default JAX's default float).

    Returns:
      ``Plant(init, measure, advance)`` of state ``(plant's state, TrackingScore)``, the score zero at ``init(x0)``;
      ``measure`` and ``advance`` give ``plant``'s ``sensed`` and ``moved``, ``measure`` folding ``error(k, sensed)``
      in where ``active(k)``. After ``run_loop`` the score is ``LoopResult.final[0][1]``.
    """
    if int(size) < 1:
        raise ValueError(f"size: expected a positive number of error components, got {size}")

    def init(x0):
        return plant.init(x0), tracking_init(int(size), dtype)

    def measure(state, k, u, step_key):
        inner, score = state
        inner, sensed = plant.measure(inner, k, u, step_key)
        on = (
            jnp.ones((int(size),), bool)
            if active is None
            else jnp.broadcast_to(active(k), (int(size),))
        )
        return (inner, tracking_update(score, error(k, sensed), on)), sensed

    def advance(state, k, u, step_key):
        inner, score = state
        inner, moved = plant.advance(inner, k, u, step_key)
        return (inner, score), moved

    return Plant(init, measure, advance, getattr(plant, "horizon", None))
