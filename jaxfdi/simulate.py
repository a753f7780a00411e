"""Scan simulator of a (linear or nonlinear) plant with noise and faults.

``x[k+1] = f(x[k], u_f[k], params) + w[k]``, ``y[k] = h(x[k], u[k], params) + v[k]``
then sensor faults act on ``y[k]``; ``u_f`` is the commanded ``u`` after actuator
faults. The feed-through in ``h`` sees the *commanded* input, as in seed 003 eq. (4)
(``y = C x + D u + v + nu_y``). Noise for step ``k`` comes from ``fold_in(key, k)``,
so a run is reproducible step by step and independent of chunking or sharding.

Like a filter, the simulator is a ``Simulator(init, step)`` pair, so a Monte Carlo run
can fuse simulation, filtering, detection and metrics in one scan (see ``monitor``).
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import _checks, _linalg
from jaxfdi.faults import Fault, Target, apply_faults, fault_label, is_active, no_fault
from jaxfdi.models.linear import LinearGaussianModel, linear_observation, linear_transition, validate_linear_model


class SimState(NamedTuple):
    state: Array  # (n,) true state x[k]
    held: Array   # (F,) values held by STUCK faults


class SimStep(NamedTuple):
    """Labelled truth of one step (stacked over time by ``simulate``)."""

    state: Array           # (n,)  true x[k]
    measurement: Array     # (m,)  y[k], noisy and faulty
    applied_input: Array   # (nu,) u after actuator faults
    actuator_fault: Array  # (nu,) applied - commanded input
    sensor_fault: Array    # (m,)  fault added to y[k]
    fault_active: Array    # (F,)  bool per fault
    mode: Array            # ()    int label of the first active fault, 0 if none


class Simulator(NamedTuple):
    init: Callable[[Array], SimState]
    step: Callable[[SimState, Array, Array, Array], tuple[SimState, SimStep]]


def _as_stack(f: Fault) -> Fault:
    return jax.tree_util.tree_map(lambda leaf: jnp.reshape(leaf, (-1,)) if jnp.ndim(leaf) == 0 else leaf, f)


def simulator(
    f: Callable[[Array, Array, Any], Array],
    h: Callable[[Array, Array, Any], Array],
    Q: Array,
    R: Array,
    params: Any = None,
    fault: Fault | None = None,
) -> Simulator:
    """Simulator of ``f``/``h`` with additive Gaussian noise ``N(0, Q)``, ``N(0, R)``.

    Args:
      f, h: plant functions of ``(x, u, params)``.
      Q: (n, n), R: (m, m) noise covariances (positive semi-definite; zero = noise-free).
      params: pytree for ``f`` and ``h``.
      fault: a ``Fault`` with scalar leaves, or a stack (leading axis F) acting together;
        ``None`` for a fault-free plant.
    """
    n = _checks.check_covariance("Q", Q)
    m = _checks.check_covariance("R", R)
    faults = _as_stack(no_fault() if fault is None else fault)
    if any(jnp.ndim(leaf) != 1 for leaf in faults):
        raise ValueError("fault: expected scalar leaves or a stack with shape (F,) leaves")
    num_faults = faults.kind.shape[0]
    sqrt_Q = _linalg.psd_sqrt(jnp.asarray(Q))
    sqrt_R = _linalg.psd_sqrt(jnp.asarray(R))

    def init(x0: Array) -> SimState:
        _checks.check_shape("x0", x0, (n,), "initial true state")
        x0 = jnp.asarray(x0)
        return SimState(x0, jnp.zeros((num_faults,), x0.dtype))

    def step(sim: SimState, k: Array, u: Array, key: Array):
        _checks.check_shape("u", u, (None,), "one commanded input")
        key_w, key_v = jax.random.split(jax.random.fold_in(key, k))
        x = sim.state
        u_applied, held = apply_faults(faults, k, u, Target.ACTUATOR, sim.held)
        y_clean = h(x, u, params) + sqrt_R @ jax.random.normal(key_v, (m,), x.dtype)
        y, held = apply_faults(faults, k, y_clean, Target.SENSOR, held)
        x_next = f(x, u_applied, params) + sqrt_Q @ jax.random.normal(key_w, (n,), x.dtype)
        active = jax.vmap(is_active, in_axes=(0, None))(faults, k)
        labels = jax.vmap(fault_label, in_axes=(0, None))(faults, u.shape[0])
        mode = jnp.where(jnp.any(active), labels[jnp.argmax(active)], 0)
        out = SimStep(x, y, u_applied, u_applied - u, y - y_clean, active, mode)
        return SimState(x_next, held), out

    return Simulator(init, step)


def linear_simulator(model: LinearGaussianModel, fault: Fault | None = None) -> Simulator:
    """``simulator`` for a ``LinearGaussianModel`` (its own ``Q`` and ``R``)."""
    validate_linear_model(model)
    return simulator(linear_transition, linear_observation, model.Q, model.R, model, fault)


def simulate(sim: Simulator, x0: Array, us: Array, key: Array) -> tuple[SimState, SimStep]:
    """Run a simulator over ``us`` (T, nu); returns the final state and the (T, ...) truth."""
    us = jnp.asarray(us)
    if us.ndim != 2:
        raise ValueError(f"us: expected shape (T, nu), got {tuple(us.shape)}")
    steps = jnp.arange(us.shape[0])

    def body(state, ku):
        k, u = ku
        return sim.step(state, k, u, key)

    return jax.lax.scan(body, sim.init(x0), (steps, us))
