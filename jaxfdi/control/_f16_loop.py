"""The sampled F-16 (``models.f16.plant``) as ``jaxfdi._simulation.loop`` stages: the plant with noise, gusts and
faults, and the fault-free FDI stage that gives the flight controller its ``FlightView`` (Park, Kim, Park & Roh 2004).

``rate_passthrough_fdi`` flies the controller on the least-squares rate ``(H^T H)^-1 H^T m`` of all rate channels; an
isolating FDI stage (Park et al.'s parity space + UKF) returns the same view with its own selected rate.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.faults import Target, active_label, apply_faults, as_stack, is_active
from jaxfdi._simulation.simulate import Actuated, Sensed, SimState, check_fault_components
from jaxfdi._simulation.stages import FDI, Plant
from jaxfdi.models.f16 import (
    RATE_OFFSET,
    F16Params,
    F16Sensors,
    SampledF16,
    flight_view,
    measurement_cov,
    rate_estimator,
    sampled_observation,
    sampled_transition,
)


def f16_plant(
    aircraft: F16Params,
    sensors: F16Sensors,
    dt: float = 0.01,
    substeps: int = 1,
    gust_sigma: float = 0.0,
    gust_length: float = 1750.0,
    reference_speed: float = 502.0,
    fault=None,
) -> Plant:
    """The sampled F-16 as a ``loop.Plant`` with state ``simulate.SimState([x (13), w_g, v_g], held)``.

    One sample ``dt`` by ``sampled_transition``, ``y`` by ``sampled_observation`` + white noise
    (``measurement_cov``). As ``simulate.simulator`` (``split(step_key)`` into process and measurement keys;
    ``faults.apply_faults`` on ``y`` and ``u``, STUCK values in ``held``), but normal draws in float32, cast
    (same law; in float64 the draws are a large share of a vmapped flight's step).

    Args:
      aircraft: ``f16_params(...)``.
      sensors: ``f16_sensors(...)`` (noise of every channel, independent).
      dt: sample period, s (default 0.01: 100 Hz).
      substeps: RK4 steps per sample (static).
      gust_sigma: gust velocity standard deviation, ft/s (0: still air).
      gust_length: gust correlation length ``L``, ft (1750: MIL-F-8785C above 2000 ft).
      reference_speed: ``V0`` of the gust's correlation time ``L / V0``, ft/s.
      fault: sensor faults on ``y`` (components: ``MEASUREMENT_NAMES`` then the rate
        channels) and actuator faults on ``u`` (``jaxfdi.fault``), or ``None``.

    Returns:
      ``Plant(init, measure, advance)``: ``init(x0 (15,)) -> SimState`` (F held values, zero);
      ``measure(state, k, u, step_key) -> (state, Sensed)``, ``y`` (m,); ``advance(state, k, u, step_key)
      -> (state, Actuated)``, ``u`` (4,) ``[thtl, el, ail, rdr]``.
    """
    substeps = checks.check_int(
        "substeps", substeps, 1, meaning="a positive number of RK4 steps per sample"
    )
    checks.check_positive("dt", dt, "a positive sample period (s)")
    checks.check_scalar(
        "gust_sigma", gust_sigma, 0.0, meaning="a gust standard deviation >= 0 (ft/s)"
    )
    checks.check_positive("gust_length", gust_length, "a positive gust correlation length (ft)")
    checks.check_positive(
        "reference_speed", reference_speed, "a positive reference airspeed (ft/s)"
    )
    dtype = aircraft.mass.dtype
    dt_arr = jnp.asarray(dt, dtype)
    decay = jnp.exp(-jnp.asarray(reference_speed, dtype) * dt_arr / jnp.asarray(gust_length, dtype))
    plant = SampledF16(aircraft, jnp.asarray(sensors.rate_axes, dtype), dt_arr, decay)
    gust_std = jnp.asarray(gust_sigma, dtype) * jnp.sqrt(1.0 - decay**2)
    noise_std = jnp.sqrt(jnp.diagonal(measurement_cov(sensors))).astype(dtype)
    m = noise_std.shape[0]
    transition = sampled_transition(int(substeps))
    faults = None if fault is None else as_stack(fault)
    if faults is not None:
        check_fault_components(faults, Target.SENSOR, m)
        check_fault_components(faults, Target.ACTUATOR, 4)
    num_faults = 0 if faults is None else faults.kind.shape[0]
    noise_dtype = jnp.float32 if dtype == jnp.float64 else dtype

    def init(x0: Array):
        checks.check_shape("x0", x0, (15,), "[x (13), w_g, v_g]")
        x0 = jnp.asarray(x0, dtype)
        return SimState(x0, jnp.zeros((num_faults,), dtype))

    def measure(sim, k: Array, u: Array, step_key: Array):
        x = sim.state
        _, key_v = jax.random.split(step_key)
        noise = noise_std * jax.random.normal(key_v, (m,), noise_dtype).astype(dtype)
        y_clean = sampled_observation(x, u, plant) + noise
        if faults is None:
            return sim, Sensed(
                x, y_clean, jnp.zeros_like(y_clean), jnp.zeros((0,), bool), jnp.zeros((), jnp.int32)
            )
        y, held = apply_faults(faults, k, y_clean, Target.SENSOR, sim.held)
        active = jax.vmap(is_active, in_axes=(0, None))(faults, k)
        return SimState(x, held), Sensed(
            x, y, y - y_clean, active, active_label(faults, k, u.shape[0])
        )

    def advance(sim, k: Array, u: Array, step_key: Array):
        key_w, _ = jax.random.split(step_key)
        if faults is None:
            u_applied, held = u, sim.held
        else:
            u_applied, held = apply_faults(faults, k, u, Target.ACTUATOR, sim.held)
        x_next = transition(sim.state, u_applied, plant)
        gusts = gust_std * jax.random.normal(key_w, (2,), noise_dtype).astype(dtype)
        return SimState(x_next.at[13:].add(gusts), held), Actuated(u_applied, u_applied - u)

    return Plant(init, measure, advance)


def rate_passthrough_fdi(rate_axes: Array) -> FDI:
    """Fault-free ``loop.FDI``: no detection, least-squares rates of all channels (``init()``, state and output
    ``None``).

    Returns:
      ``FDI(init, step, observe)``: ``init() -> None``; ``observe(None, k, y) -> (None, FlightView)`` with the
      least-squares body rates (3,) of ``y``'s rate channels; ``step(None, k, y, u) -> (None, None)``.
    """
    estimator = rate_estimator(
        jnp.asarray(rate_axes)
    )  # once: a solve inside the step (vmapped LU) would cost more than the flight

    def observe(state, k, y):
        return state, flight_view(y, estimator.astype(y.dtype) @ y[RATE_OFFSET:])

    return FDI(lambda: None, lambda state, k, y, u: (state, None), observe)


__all__ = ["f16_plant", "rate_passthrough_fdi"]
