"""Scan simulator of a (linear or nonlinear) plant with noise and faults.

``x[k+1] = f(x[k], u_f[k] + w_u[k], params) + G w[k]``, ``y[k] = h(x[k], u[k], params) + v[k]``
then sensor faults act on ``y[k]``; ``u_f`` is the commanded ``u`` after actuator
faults, ``w_u ~ N(0, Q_u)`` optional input noise (IMU noise driving an INS, motor torque
noise), ``G`` an optional process-noise gain (default identity). The feed-through in ``h``
sees the input given to ``measure`` (eq. (4) of Han et al. 2022, ``y = C x + D u + v + nu_y``).

Time enters in three ways, each optional:

- ``time_varying=True``: the plant functions are ``f(x, u, k, params)``, ``h(x, u, k, params)``;
- ``Q``, ``R``, ``input_noise`` are constant (n, n) arrays, per-step (T, n, n) arrays, or
  callables ``k -> (n, n)``;
- ``available``: which measurement components exist at step ``k`` (a (T, m) bool array
  or a callable ``(k, x) -> (m,)``); the others are NaN, which the filters built with
  ``missing_measurements=True`` skip: a satellite that sets is a NaN pseudorange.

Noise for step ``k`` comes from ``fold_in(key, k)``, so a run is reproducible step by step
and independent of chunking or sharding.

The simulator is a ``Simulator(init, measure, advance)``: ``measure`` reads the
sensors at step ``k`` and ``advance`` moves the plant with the input applied at ``k``,
which is what a closed loop needs (``jaxfdi._simulation.loop``: the controller acts between the two);
``step`` is the two together, for open-loop runs (``simulate``).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi._simulation.faults import (
    Fault,
    Target,
    active_label,
    apply_faults,
    as_stack,
    is_active,
    no_fault,
)
from jaxfdi.models import (
    LinearGaussianModel,
    linear_observation,
    linear_transition,
    validate_linear_model,
)


class SimState(NamedTuple):
    """The simulator's carry: the true state and the values stuck faults hold.

    Attributes:
      state: (n,) true state x[k]
      held: (F,) values held by STUCK faults
    """

    state: Array
    held: Array


class Sensed(NamedTuple):
    """What ``measure`` returns besides the state: the step's labelled truth as its sensors saw it.

    Attributes:
      state: (n,) true x[k]
      measurement: (m,) y[k], noisy and faulty (NaN where not available)
      sensor_fault: (m,) fault added to y[k]
      fault_active: (F,) bool per fault
      mode: () int label of the first active fault, 0 if none
    """

    state: Array
    measurement: Array
    sensor_fault: Array
    fault_active: Array
    mode: Array


class Actuated(NamedTuple):
    """What ``advance`` returns besides the state: what the actuators applied.

    Attributes:
      applied_input: (nu,) u after actuator faults (and input noise)
      actuator_fault: (nu,) applied - commanded input
    """

    applied_input: Array
    actuator_fault: Array


class Simulator(NamedTuple):
    """A plant with its sensors, in two halves a closed loop can put its controller between.

    Attributes:
      init: ``init(x0) -> SimState``
      measure: ``measure(state, k, u, step_key) -> (state, Sensed)`` (``u``: the input the
        feed-through sees), with the step's key ``fold_in(key, k)``
      advance: ``advance(state, k, u, step_key) -> (state, Actuated)``, the same key
      horizon: the most steps it can run (a simulator replaying T steps of tables: T), or ``None`` (unbounded)
    """

    init: Callable[[Array], SimState]
    measure: Callable[[SimState, Array, Array, Array], tuple[SimState, Sensed]]
    advance: Callable[[SimState, Array, Array, Array], tuple[SimState, Actuated]]
    horizon: int | None = None

    def step(
        self, sim: SimState, k: Array, u: Array, key: Array
    ) -> tuple[SimState, tuple[Sensed, Actuated]]:
        """One open-loop step with the run's ``key``: ``measure`` then ``advance`` on ``fold_in(key, k)``,
        and their records ``(Sensed, Actuated)``."""
        step_key = jax.random.fold_in(key, k)
        sim, sensed = self.measure(sim, k, u, step_key)
        sim, moved = self.advance(sim, k, u, step_key)
        return sim, (sensed, moved)


def per_step(name: str, value: Any, size: int) -> Callable[[Array], Array]:
    """``k -> (size, size)`` from a constant matrix, a (T, size, size) array or a callable
    (checked once at trace time, on step 0)."""
    if callable(value):
        checks.check_covariance(f"{name}(0)", value(jnp.asarray(0)), size)
        return value
    shape = checks.shape_of(value)
    if len(shape) == 3:
        checks.check_matrix(
            name, value, (None, size, size), f"T per-step ({size}, {size}) covariances"
        )
        table = checks.concrete(value)
        for k in range(table.shape[0] if table is not None else 0):
            checks.check_covariance(f"{name}[{k}]", table[k], size)
        value = jnp.asarray(value)
        return lambda k: value[k]
    checks.check_covariance(name, value, size)
    value = jnp.asarray(value)
    return lambda k: value


def _noise_sqrt(name: str, value: Any, size: int) -> Callable[[Array], Array]:
    """``k -> L`` with ``L L^T`` the step's covariance; computed once when constant."""
    if callable(value) or len(checks.shape_of(value)) == 3:
        cov = per_step(name, value, size)
        return lambda k: _linalg.psd_sqrt(cov(k))
    checks.check_covariance(name, value, size)
    sqrt = _linalg.psd_sqrt(jnp.asarray(value))
    return lambda k: sqrt


def _matrix_size(name: str, value: Any) -> int:
    sample = value(jnp.asarray(0)) if callable(value) else value
    shape = checks.shape_of(sample)
    if len(shape) not in (2, 3) or shape[-1] != shape[-2]:
        raise ValueError(
            f"{name}: expected a (d, d) covariance, a (T, d, d) array or a callable k -> (d, d), "
            f"got shape {shape}"
        )
    return shape[-1]


def simulator(
    f: Callable[..., Array],
    h: Callable[..., Array],
    Q: Any,
    R: Any,
    params: Any = None,
    fault: Fault | None = None,
    *,
    time_varying: bool = False,
    noise_gain: Array | None = None,
    input_noise: Any = None,
    available: Any = None,
) -> Simulator:
    """Simulator of ``f``/``h`` with additive Gaussian noise ``N(0, Q)``, ``N(0, R)``.

    Args:
      f, h: plant functions of ``(x, u, params)``, or ``(x, u, k, params)`` with
        ``time_varying=True``.
      Q: process-noise covariance (n, n) — or (nw, nw) with ``noise_gain`` — constant,
        (T, ., .) per step, or a callable of the step (positive semi-definite).
      R: (m, m) measurement-noise covariance, in the same three forms.
      params: pytree for ``f`` and ``h``.
      fault: a ``Fault`` with scalar leaves, or a stack (leading axis F: several
        components of a group, several episodes) acting together; ``None`` for a
        fault-free plant.
      noise_gain: (n, nw) ``G`` of ``G w``, or ``None`` for the identity.
      input_noise: (nu, nu) covariance of noise added to the applied input (same forms
        as ``Q``), or ``None``.
      available: (T, m) bool array or callable ``(k, x) -> (m,) bool``: components that
        are measured at step ``k`` (the others are NaN), or ``None`` (all, always).

    Returns:
      ``Simulator(init, measure, advance)``: ``init(x0)`` takes the (n,) true initial
      state and gives a ``SimState`` (F held values, zero); ``measure(state, k, u,
      step_key) -> (state, Sensed)`` and ``advance(state, k, u, step_key) -> (state,
      Actuated)`` with the step's key ``fold_in(key, k)``; ``Simulator.step(state, k, u,
      key)`` is the two with the run's key.
    """
    checks.check_callable("f", f, "a plant function f(x, u, params) -> next state")
    checks.check_callable("h", h, "a sensor function h(x, u, params) -> measurement")
    nw = _matrix_size("Q", Q)
    m = _matrix_size("R", R)
    if noise_gain is not None:
        checks.check_matrix(
            "noise_gain", noise_gain, (None, nw), f"n states x {nw} noise inputs (Q is {nw} x {nw})"
        )
        G = jnp.asarray(noise_gain)
        n = G.shape[0]
    else:
        G, n = None, nw
    sqrt_Q = _noise_sqrt("Q", Q, nw)
    sqrt_R = _noise_sqrt("R", R, m)
    sqrt_U = (
        None
        if input_noise is None
        else _noise_sqrt("input_noise", input_noise, _matrix_size("input_noise", input_noise))
    )
    if available is not None and not callable(available):
        checks.check_shape(
            "available", available, (None, m), f"T steps x {m} measurement components"
        )
        available_table = jnp.asarray(available, bool)
        available = lambda k, x: available_table[k]
    if fault is not None and not isinstance(fault, Fault):
        raise TypeError(
            f"fault: expected a Fault (jaxfdi.fault, fault_group, concat_faults) or None, got "
            f"{checks.received(fault)}"
        )
    faults = as_stack(no_fault() if fault is None else fault)
    if any(jnp.ndim(leaf) != 1 for leaf in faults):
        raise ValueError("fault: expected scalar leaves or a stack with shape (F,) leaves")
    check_fault_components(faults, Target.SENSOR, m)
    num_faults = faults.kind.shape[0]
    plant_f = f if time_varying else (lambda x, u, k, p: f(x, u, p))
    plant_h = h if time_varying else (lambda x, u, k, p: h(x, u, p))

    def init(x0: Array) -> SimState:
        checks.check_real("x0", x0, "a real initial state")
        checks.check_shape("x0", x0, (n,), "initial true state")
        checks.check_finite("x0", x0, "initial true state")
        x0 = jnp.asarray(x0, checks.float_dtype(x0))
        return SimState(x0, jnp.zeros((num_faults,), x0.dtype))

    def measure(sim: SimState, k: Array, u: Array, step_key: Array):
        checks.check_shape("u", u, (None,), "one commanded input")
        x = sim.state
        _, key_v = jax.random.split(step_key)  # (process, measurement)
        y_clean = plant_h(x, u, k, params) + sqrt_R(k) @ jax.random.normal(key_v, (m,), x.dtype)
        y, held = apply_faults(faults, k, y_clean, Target.SENSOR, sim.held)
        if available is not None:
            y = jnp.where(available(k, x), y, jnp.nan)
        active = jax.vmap(is_active, in_axes=(0, None))(faults, k)
        mode = active_label(faults, k, u.shape[0])
        return SimState(x, held), Sensed(x, y, y - y_clean, active, mode)

    def advance(sim: SimState, k: Array, u: Array, step_key: Array):
        checks.check_shape("u", u, (None,), "one commanded input")
        x = sim.state
        key_w, _ = jax.random.split(step_key)
        check_fault_components(faults, Target.ACTUATOR, u.shape[0])
        if u.shape[0]:
            u_applied, held = apply_faults(faults, k, u, Target.ACTUATOR, sim.held)
        else:  # a plant without inputs: nothing for an actuator fault to act on
            u_applied, held = u, sim.held
        if sqrt_U is not None:
            key_u = jax.random.fold_in(key_w, 1)
            u_applied = u_applied + sqrt_U(k) @ jax.random.normal(key_u, (u.shape[0],), x.dtype)
        w = sqrt_Q(k) @ jax.random.normal(key_w, (nw,), x.dtype)
        x_next = plant_f(x, u_applied, k, params) + (w if G is None else G @ w)
        return SimState(x_next, held), Actuated(u_applied, u_applied - u)

    return Simulator(init, measure, advance)


def check_fault_components(faults: Fault, target: int, size: int) -> None:
    """Every (concrete) fault of the stack on ``target`` acts on a component in
    ``[0, size)``: a fault on a sensor that does not exist would label the run as faulty
    and change nothing."""
    kinds, targets, components = (
        checks.concrete(leaf) for leaf in (faults.kind, faults.target, faults.component)
    )
    if kinds is None or targets is None or components is None:
        return
    mine = (targets == target) & (kinds != 0)
    if np.any(mine & ((components < 0) | (components >= size))):
        what = "sensor" if target == Target.SENSOR else "actuator"
        signal = "y has" if target == Target.SENSOR else "u has"
        raise ValueError(
            f"fault: expected {what} components in [0, {size}) ({signal} {size} components), got "
            f"component(s) {sorted(set(components[mine].tolist()))}"
        )


def linear_simulator(
    model: LinearGaussianModel, fault: Fault | None = None, **options
) -> Simulator:
    """``simulator`` for a ``LinearGaussianModel`` (its own ``Q`` and ``R``); ``options``
    as for ``simulator`` (``input_noise``, ``available``, ...).

    Returns:
      ``Simulator`` of ``x[k+1] = Phi x[k] + Gamma u[k] + w[k]``, ``y[k] = C x[k] + D u[k] + v[k]``
      (as ``simulator`` returns).
    """
    validate_linear_model(model)
    return simulator(
        linear_transition, linear_observation, model.Q, model.R, model, fault, **options
    )


def simulate(sim: Simulator, x0: Array, us: Array, key: Array) -> tuple[SimState, Sensed, Actuated]:
    """Run a simulator over ``us`` (T, nu).

    Returns:
      ``(final, truth, moved)``: the final ``SimState`` (true state ``x[T]``, after the last step), and each step's
      ``Sensed`` (``truth.state`` (T, n), ``truth.measurement`` (T, m), ``truth.mode`` (T,), ...) and ``Actuated``
      (``moved.applied_input`` (T, nu), ``moved.actuator_fault`` (T, nu)) stacked along a leading time axis, as
      ``run_loop`` records them.
    """
    us = checks.check_inputs(us)
    steps = jnp.arange(us.shape[0])

    def body(state, ku):
        k, u = ku
        return sim.step(state, k, u, key)

    final, (truth, moved) = jax.lax.scan(body, sim.init(x0), (steps, us))
    return final, truth, moved
