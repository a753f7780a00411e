"""Attitude control with reaction wheels: a rest-to-rest slew, quaternion PD with
feed-forward, and minimum-norm wheel torque allocation (Choi & Park 2009 leave the law open).

Reference: slew by ``angle`` about a fixed body axis ``e``, versine profile
``theta(s) = angle (s - sin(2 pi s) / (2 pi))``, ``s = (t - start) / duration`` in ``[0, 1]`` (zero rate
and acceleration at both ends; Wie 2008, sec. 7.3): ``q_ref = [cos(theta/2), sin(theta/2) e]``,
``w_ref = theta' e``, ``alpha_ref = theta'' e``.

Law (Wie, Weiss & Arapostathis 1989, with gyroscopic feed-forward), ``dq = q_ref^* (x) q`` (``dq_0 >= 0``:
the short way), ``dw = w - R(dq)^T w_ref``:

    T_c = I alpha_ref + w x (I w + h_w) - 2 K_p dq_vec - K_d dw,   K_p = I w_n^2,  K_d = 2 zeta w_n I.

The wheels deliver ``-H^T tau``, so ``tau = -H (H^T H)^-1 T_c`` (minimum norm), scaled down as a whole
(direction kept) if a wheel would exceed ``max_wheel_torque``. Loop parts (``jaxfdi._simulation.loop``):
``wheel_attitude_controller`` and ``wheel_plant``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.faults import Target, apply_fault
from jaxfdi._simulation.stages import Controller, Plant
from jaxfdi.models import (
    AttitudeReading,
    SpacecraftParams,
    WheelCommand,
    delivered_torque,
    spacecraft_step,
    stop_transfer,
    wheel_momentum,
)
from jaxfdi.rotation import quaternion_conjugate, quaternion_multiply, rotate


class Slew(NamedTuple):
    """An eigen-axis slew manoeuvre: rotation axis, angle, start time and duration.

    Attributes:
      axis: (3,) unit rotation axis in the body (= initial inertial) frame
      angle: () rad, slew angle
      start: () s, start time
      duration: () s, duration of the slew
    """

    axis: Array
    angle: Array
    start: Array
    duration: Array


class AttitudeGains(NamedTuple):
    """Quaternion PD attitude gains and the wheel torque limit.

    Attributes:
      kp: (3, 3) proportional gain on the attitude error
      kd: (3, 3) derivative gain on the rate error
      max_wheel_torque: () N m, torque limit of each wheel
    """

    kp: Array
    kd: Array
    max_wheel_torque: Array


def slew(
    axis=(1.0, 1.0, 1.0),
    angle_deg: float = 20.0,
    start: float = 0.0,
    duration: float = 40.0,
    dtype=None,
) -> Slew:
    """An eigen-axis slew of ``angle_deg`` degrees about ``axis`` from ``start`` over ``duration`` seconds.

    Returns:
      ``Slew`` in ``dtype`` (default float), ``axis`` normalised, ``angle`` in rad.
    """
    dtype = dtype or jnp.result_type(float)
    checks.check_matrix("axis", axis, (3,), "rotation axis")
    axis = jnp.asarray(axis, dtype)
    if float(jnp.linalg.norm(axis)) == 0.0:
        raise ValueError(f"axis: expected a non-zero rotation axis, got {checks.received(axis)}")
    checks.check_scalar("angle_deg", angle_deg, meaning="a slew angle in degrees")
    checks.check_scalar("start", start, meaning="a start time in seconds")
    checks.check_positive("duration", duration, "a positive slew time in seconds")
    return Slew(
        axis / jnp.linalg.norm(axis),
        jnp.asarray(math.radians(angle_deg), dtype),
        jnp.asarray(start, dtype),
        jnp.asarray(duration, dtype),
    )


def pd_gains(
    inertia: Array,
    natural_frequency: float = 0.1,
    damping: float = 0.9,
    max_wheel_torque: float = 0.02,
) -> AttitudeGains:
    """``K_p = I w_n^2``, ``K_d = 2 zeta w_n I`` (decoupled second-order axes).

    Returns:
      ``AttitudeGains(kp (3, 3), kd (3, 3), max_wheel_torque ())`` in ``inertia``'s float dtype, the torque limit
      in N m.
    """
    checks.check_covariance(
        "inertia", inertia, 3, definite=True
    )  # symmetric positive definite, like a covariance
    inertia = jnp.asarray(inertia, checks.float_dtype(inertia))
    checks.check_positive(
        "natural_frequency", natural_frequency, "a positive natural frequency in rad/s"
    )
    checks.check_positive("damping", damping, "a positive damping ratio")
    checks.check_positive("max_wheel_torque", max_wheel_torque, "a positive torque limit in N m")
    return AttitudeGains(
        inertia * natural_frequency**2,
        2.0 * damping * natural_frequency * inertia,
        jnp.asarray(max_wheel_torque, inertia.dtype),
    )


def slew_reference(t: Array, profile: Slew) -> tuple[Array, Array, Array]:
    """``(q_ref (4,), w_ref (3,), alpha_ref (3,))`` at time ``t``.

    Returns:
      ``(q_ref, w_ref, alpha_ref)``: the reference quaternion (4,) ``[q0, q_vec]``, rate (3,) [rad/s] and angular
      acceleration (3,) [rad/s^2]; before ``start`` the identity and zeros, after the slew ``angle`` held and zeros.
    """
    s = jnp.clip((t - profile.start) / profile.duration, 0.0, 1.0)
    inside = (t >= profile.start) & (t <= profile.start + profile.duration)
    two_pi = 2.0 * jnp.pi
    theta = profile.angle * (s - jnp.sin(two_pi * s) / two_pi)
    rate = jnp.where(inside, profile.angle / profile.duration * (1.0 - jnp.cos(two_pi * s)), 0.0)
    accel = jnp.where(
        inside, profile.angle / profile.duration**2 * two_pi * jnp.sin(two_pi * s), 0.0
    )
    q_ref = jnp.concatenate([jnp.cos(0.5 * theta)[None], jnp.sin(0.5 * theta) * profile.axis])
    return q_ref, rate * profile.axis, accel * profile.axis


def control_torque(
    q: Array,
    w: Array,
    wheel_momentum: Array,
    t: Array,
    profile: Slew,
    gains: AttitudeGains,
    inertia: Array,
) -> Array:
    """Commanded body torque from attitude ``q``, gyro rate ``w`` and the believed wheel momentum ``h_w``.

    Returns:
      (3,) ``T_c`` (module doc) in the body frame [N m] for the slew reference at ``t``.
    """
    q_ref, w_ref, alpha_ref = slew_reference(t, profile)
    dq = quaternion_multiply(quaternion_conjugate(q_ref), q)
    dq = jnp.where(dq[0] < 0, -dq, dq)
    w_ref_body = rotate(quaternion_conjugate(dq), w_ref)
    return (
        inertia @ alpha_ref
        + jnp.cross(w, inertia @ w + wheel_momentum)
        - 2.0 * gains.kp @ dq[1:]
        - gains.kd @ (w - w_ref_body)
    )


def allocate_wheel_torques(torque: Array, wheel_axes: Array, max_wheel_torque: Array) -> Array:
    """Motor torques ``tau`` (N,) with ``-H^T tau = T_c``, minimum norm, saturated by uniform scaling."""
    checks.check_shape("torque", torque, (None,), "the commanded body torque (3,)")
    size = checks.shape_of(torque)[0]
    checks.check_shape("wheel_axes", wheel_axes, (None, size), f"H: N wheels x {size} body axes")
    gram = wheel_axes.T @ wheel_axes
    tau = -wheel_axes @ jnp.linalg.solve(gram, torque)
    peak = jnp.max(jnp.abs(tau))
    return tau * jnp.minimum(1.0, max_wheel_torque / jnp.maximum(peak, 1e-30))


def wheel_attitude_controller(
    params: SpacecraftParams, gains: AttitudeGains, profile: Slew, initial_speeds: Array
) -> Controller:
    """The attitude loop as a ``loop.Controller`` on an ``AttitudeReading`` (``control_torque``,
    ``allocate_wheel_torques``); state: commanded speeds ``Omega_cmd[k+1] = Omega_cmd[k] + dt tau[k] / I_w``.
    Returns a ``WheelCommand``.

    Returns:
      ``Controller(init, step)`` (not feed-forward): ``init()`` gives ``initial_speeds`` (N,) [rad/s];
      ``step(Omega_cmd, k, AttitudeReading, exogenous) -> (Omega_cmd[k+1], WheelCommand(Omega_cmd[k], tau))``,
      ``tau`` (N,) motor torques [N m], ``exogenous`` unused.
    """

    def step(commanded: Array, k: Array, reading, exogenous):
        t = k * params.dt
        torque = control_torque(
            reading.quaternion,
            reading.rate,
            wheel_momentum(commanded, params),
            t,
            profile,
            gains,
            params.inertia,
        )
        tau = allocate_wheel_torques(torque, params.wheel_axes, gains.max_wheel_torque)
        return commanded + params.dt * tau / params.wheel_inertia, WheelCommand(commanded, tau)

    return Controller(lambda: jnp.asarray(initial_speeds), step)


# --- the truth as a closed-loop plant ----------------------------------------------


class WheelSensed(NamedTuple):
    """The spacecraft plant's output at step ``k``: the truth and the sensors' reading.

    Attributes:
      state: (7 + N,) true [q, w, Omega] at step k
      measurement: the attitude and the gyros' rates
    """

    state: Array
    measurement: AttitudeReading


def wheel_plant(
    params: SpacecraftParams,
    fault,
    gyro_sigma: Array,
    disturbance_sigma: Array,
    wheel_noise_sigma: Array,
) -> Plant:
    """The spacecraft truth as a ``loop.Plant`` under ``fault`` (scalar leaves): wheel (``Target.ACTUATOR``,
    component = wheel) or gyro (``Target.SENSOR``, component = axis; ``faults.apply_fault`` on the reading:
    DEAD = NaN, STUCK = onset reading held to the last bit).

    ``measure``: ``AttitudeReading(q, w + v)``, ``v ~ N(0, gyro_sigma^2 I)``, then the gyro fault;
    ``advance(WheelCommand)``: ``delivered_torque`` + white noise ``wheel_noise_sigma``, a stop's momentum
    to the body (``stop_transfer``), one RK4 step with white external torque ``disturbance_sigma``. Draws
    from ``fold_in(key, k)``; state ``(x, held)``: truth ``[q, w, Omega]`` and a STUCK gyro's value.

    Returns:
      ``Plant(init, measure, advance)``: ``init(x0 (7 + N,)) -> (x0, held)``; ``measure(state, k, command,
      step_key) -> (state, WheelSensed(x, AttitudeReading))``; ``advance(state, k, WheelCommand, step_key) ->
      (state, delivered)``, ``delivered`` (N,) the wheel torques applied [N m].
    """
    dtype = params.inertia.dtype
    N = params.wheel_axes.shape[0]

    def keys(step_key):
        return jax.random.split(step_key, 3)  # gyro, disturbance, wheel torque

    def init(x0: Array):
        checks.check_shape("x0", x0, (7 + N,), "[q (4), w (3), Omega (N)]")
        return jnp.asarray(x0), jnp.zeros((), dtype)

    def measure(plant, k: Array, command: WheelCommand, step_key: Array):
        state, held = plant
        k_gyro, _, _ = keys(step_key)
        rate = state[4:7] + gyro_sigma * jax.random.normal(k_gyro, (3,), dtype)
        rate, held = apply_fault(fault, k, rate, Target.SENSOR, held)
        return (state, held), WheelSensed(state, AttitudeReading(state[:4], rate))

    def advance(plant, k: Array, command: WheelCommand, step_key: Array):
        state, held = plant
        _, k_dist, k_wheel = keys(step_key)
        delivered = delivered_torque(
            fault, k, command.torque
        ) + wheel_noise_sigma * jax.random.normal(k_wheel, (N,), dtype)
        disturbance = disturbance_sigma * jax.random.normal(k_dist, (3,), dtype)
        state = spacecraft_step(
            stop_transfer(state, fault, k, params), delivered, disturbance, params
        )
        return (state, held), delivered

    return Plant(init, measure, advance)
