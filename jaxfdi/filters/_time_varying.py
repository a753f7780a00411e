"""Time-varying filters: any filter whose model changes with the step.

``time_varying(filter_at)`` turns a factory ``k -> Filter`` (``kalman_filter`` of the step's matrices, an EKF of
``f(x, u, k, params)``, ...) into one ``Filter`` whose state carries the step counter: at step ``k`` it conditions on
``y[k]`` with the step-``k`` measurement model and predicts with the step-``k`` transition:
``x[k+1] = Phi_k x[k] + Gamma_k u[k] + w[k]``, ``w[k] ~ N(0, Q_k)``, ``y[k] = C_k x[k] + D_k u[k] + v[k]``,
``v[k] ~ N(0, R_k)``. The factory gets a traced step inside the scan, so it must build its filter from arrays (index
a (T, ...) table, or compute from ``k``); shapes are checked at trace time. Linear per-step matrices:
``model_at(model, Q=Qs, ...)``.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.filters._base import Filter
from jaxfdi.models import LinearGaussianModel


class TimedState(NamedTuple):
    """A time-varying filter's state: the step index and the wrapped filter's state.

    Attributes:
      step: () int, the step the inner state is the prior of
      inner: the wrapped filter's state
    """

    step: Array
    inner: Any


def time_varying(filter_at: Callable[[Array], Filter], start: int = 0) -> Filter:
    """A ``Filter`` running ``filter_at(k)`` at step ``k`` (counted from ``start``).

    ``init(*args)`` is ``filter_at(start).init(*args)`` plus the counter; ``update``/``predict`` are not exposed (a
    multiple-model filter over time-varying modes uses modes that read the step themselves).

    Returns:
      ``Filter(init, step)``, state ``TimedState(step, inner)``; ``step`` is the step-``k`` filter's (its info).
    """
    checks.check_callable(
        "filter_at", filter_at, "a function k -> Filter (e.g. lambda k: kalman_filter(at(k)))"
    )
    start = checks.check_int("start", start, 0, meaning="the first step's index")

    def init(*args, **kwargs) -> TimedState:
        return TimedState(
            jnp.asarray(start, jnp.int32),
            filter_at(jnp.asarray(start, jnp.int32)).init(*args, **kwargs),
        )

    def step(state: TimedState, y: Array, u: Array):
        inner, info = filter_at(state.step).step(state.inner, y, u)
        return TimedState(state.step + 1, inner), info

    return Filter(init, step)


def model_at(
    model: LinearGaussianModel, **per_step: Array
) -> Callable[[Array], LinearGaussianModel]:
    """``k -> model`` with the named fields (``Phi``, ``Gamma``, ``C``, ``D``, ``Q``, ``R``) from (T, ...) per-step
    arrays, the others constant; e.g. ``time_varying(lambda k: kalman_filter(at(k)))``,
    ``at = model_at(model, Q=Qs, R=Rs, C=Cs)``.
    """
    fields = LinearGaussianModel._fields
    lengths = set()
    for name, table in per_step.items():
        if name not in fields:
            raise ValueError(
                f"{name}: not a LinearGaussianModel field; expected one of {list(fields)}"
            )
        constant = checks.shape_of(getattr(model, name))
        checks.check_matrix(
            name, table, (None,) + constant, f"T per-step copies of model.{name} {constant}"
        )
        if name in ("Q", "R"):
            value = checks.concrete(table)
            for k in range(value.shape[0] if value is not None else 0):
                checks.check_covariance(f"{name}[{k}]", value[k], constant[0])
        lengths.add(checks.shape_of(table)[0])
    if len(lengths) > 1:
        raise ValueError(
            f"per-step tables: expected the same number of steps T, got {sorted(lengths)}"
        )
    tables = {name: jnp.asarray(table) for name, table in per_step.items()}

    def at(k: Array) -> LinearGaussianModel:
        return model._replace(**{name: table[k] for name, table in tables.items()})

    return at
