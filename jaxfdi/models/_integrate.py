"""Fixed-step integration of ``x' = field(x, t)``: the classical Runge-Kutta method
(Kutta 1901), used by every sampled nonlinear model."""
from __future__ import annotations

from typing import Callable

import jax
from jax import Array


def rk4(field: Callable[[Array, Array], Array], x: Array, dt: Array, substeps: int = 1) -> Array:
    """``substeps`` classical RK4 steps of ``x' = field(x, t)`` over ``[0, dt]``, ``h = dt / substeps``:

    ``x+ = x + h/6 (k1 + 2 k2 + 2 k3 + k4)``, ``k1 = f(x, t)``, ``k2 = f(x + h/2 k1, t + h/2)``,
    ``k3 = f(x + h/2 k2, t + h/2)``, ``k4 = f(x + h k3, t + h)``.

    ``t`` is the time since the start of the interval; inputs held over it are closed
    over by ``field``. ``substeps`` is static (a ``fori_loop`` when > 1)."""
    h = dt / substeps

    def one(i, x):
        t = i * h
        k1 = field(x, t)
        k2 = field(x + 0.5 * h * k1, t + 0.5 * h)
        k3 = field(x + 0.5 * h * k2, t + 0.5 * h)
        k4 = field(x + h * k3, t + h)
        return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    return jax.lax.fori_loop(0, substeps, one, x) if substeps > 1 else one(0, x)


__all__ = ["rk4"]
