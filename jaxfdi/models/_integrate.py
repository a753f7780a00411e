"""Fixed-step integration of ``x' = field(x, t)``: the classical Runge-Kutta method
(Kutta 1901), used by every sampled nonlinear model."""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
from jax import Array


def rk4(
    field: Callable[[Array, Array], Array],
    x: Array,
    dt: Array,
    substeps: int = 1,
    loop_stages: bool = False,
) -> Array:
    """``substeps`` classical RK4 steps of ``x' = field(x, t)`` over ``[0, dt]``, ``h = dt / substeps``:

    ``x+ = x + h/6 (k1 + 2 k2 + 2 k3 + k4)``, ``k1 = f(x, t)``, ``k2 = f(x + h/2 k1, t + h/2)``,
    ``k3 = f(x + h/2 k2, t + h/2)``, ``k4 = f(x + h k3, t + h)``.

    ``t``: time since the interval's start; held inputs are closed over by ``field``. ``substeps`` static (``fori_loop``
    when > 1). ``loop_stages``: the four stages a loop too, ``field`` compiled once (F-16: compiles faster, a batch
    of flights runs as fast or faster, a single flight slower by the loop's overhead per step;
    ``benchmarks/bench_f16_flight.py``)."""
    h = dt / substeps

    def unrolled(x, t):
        k1 = field(x, t)
        k2 = field(x + 0.5 * h * k1, t + 0.5 * h)
        k3 = field(x + 0.5 * h * k2, t + 0.5 * h)
        k4 = field(x + h * k3, t + h)
        return k1 + 2 * k2 + 2 * k3 + k4

    dtype = jnp.result_type(x)
    nodes, weights = (
        jnp.asarray((0.0, 0.5, 0.5, 1.0), dtype),
        jnp.asarray((1.0, 2.0, 2.0, 1.0), dtype),
    )

    def stage(i, carry):  # k_i = f(x + c_i h k_(i-1), t + c_i h); s += b_i k_i
        x, t, k, s = carry
        c = nodes[i] * h
        k = field(x + c * k, t + c)
        return x, t, k, s + weights[i] * k

    def looped(x, t):
        return jax.lax.fori_loop(0, 4, stage, (x, t, jnp.zeros_like(x), jnp.zeros_like(x)))[3]

    def one(i, x):
        return x + h / 6.0 * (looped if loop_stages else unrolled)(x, i * h)

    return jax.lax.fori_loop(0, substeps, one, x) if substeps > 1 else one(0, x)


__all__ = ["rk4"]
