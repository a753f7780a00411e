"""UAV flights and the perfect IMU that flies them.

Legs ``(duration [s], turn rate [deg/s], climb rate [m/s], acceleration [m/s^2])``, blended over ``blend``
s by ``10 s^3 - 15 s^4 + 6 s^5`` (C2: bank and pitch rates continuous); speed, heading, height integrated;
coordinated flight: yaw = heading, pitch ``asin(climb / V)`` (zero alpha), roll ``atan(V turn_rate / g0)``.
Positions by the INS's trapezoidal rule (``mechanization.integrate_position``), IMU samples the exact
inverse step (``mechanization.inverse_step``): an error-free IMU reproduces the truth to round-off.
``park_legs``: Yoo et al.'s (2010) park case as the GPS half's racetrack (600 m legs, 200 m turns, 12 m/s)
after a climb, with a climb and a descent on the way; ``manoeuvre_legs``: the paper's strong-manoeuvre
caveat (25 m/s, S-turns at 20 deg/s, 42 deg bank, pull-ups and dives, 2 m/s^2 speed changes).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.ins import _mechanization as mechanization
from jaxfdi.ins._mechanization import NavState
from jaxfdi.rotation import euler_to_quaternion

#: standard gravity used for the coordinated-turn bank angle [m/s^2]
G0 = 9.80665


class Trajectory(NamedTuple):
    """A flight sampled at the IMU rate: N + 1 states and N IMU samples.

    Attributes:
      dt: s, IMU sample period
      position: (N + 1, 3) lat, lon [rad], h [m]
      velocity: (N + 1, 3) NED [m/s]
      attitude: (N + 1, 4) body-to-NED quaternion
      imu: (N, 6) error-free [f^b (m/s^2), w_ib^b (rad/s)] over each interval
    """

    dt: float
    position: Array
    velocity: Array
    attitude: Array
    imu: Array

    def state(self, index) -> NavState:
        return NavState(self.position[index], self.velocity[index], self.attitude[index])


def _smoothstep(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def command_profiles(legs, times, blend: float) -> np.ndarray:
    """(T, 3) turn rate [rad/s], climb rate [m/s], acceleration [m/s^2] at ``times`` (NumPy)."""
    legs = np.asarray(legs, float)
    times = np.asarray(times, float)
    starts = np.concatenate([[0.0], np.cumsum(legs[:, 0])[:-1]])
    commands = np.stack([np.radians(legs[:, 1]), legs[:, 2], legs[:, 3]], axis=1)
    value = np.broadcast_to(commands[0], (times.shape[0], 3)).copy()
    for i in range(1, len(legs)):  # each change blends in from the leg's start
        value += _smoothstep((times - starts[i]) / blend)[:, None] * (commands[i] - commands[i - 1])
    return value


def _check_start(start) -> None:
    """``(lat deg, lon deg, h m)``, finite, latitude strictly inside (-90, 90) (the
    navigation equations divide by cos(lat))."""
    value = np.asarray(start, float) if np.ndim(start) == 1 and len(start) == 3 else None
    if value is None or not np.all(np.isfinite(value)) or not abs(value[0]) < 90.0:
        raise ValueError(
            f"start: expected (latitude deg in (-90, 90), longitude deg, height m), finite, got "
            f"{checks.received(start)}"
        )


def fly(
    legs,
    start: tuple[float, float, float],
    speed: float,
    heading_deg: float = 0.0,
    rate: float = 100.0,
    blend: float = 5.0,
    dtype=None,
) -> Trajectory:
    """The flight of ``legs`` (module doc) from ``start`` = (lat deg, lon deg, h m) at
    ``speed`` [m/s] and ``heading_deg``, sampled at ``rate`` [Hz].

    Returns:
      ``Trajectory`` in ``dtype``, ``dt = 1 / rate``, ``N = round(sum of durations * rate)``.

    Raises:
      ValueError: malformed ``legs`` or ``start``, or a flight that stalls or climbs faster than it flies.
    """
    legs = np.asarray(legs, float)
    if legs.ndim != 2 or legs.shape[1] != 4 or np.any(legs[:, 0] <= 0):
        raise ValueError(
            f"legs: expected rows (duration > 0, turn deg/s, climb m/s, accel m/s^2), got "
            f"{checks.received(legs)}"
        )
    checks.check_positive("speed", speed, "a positive airspeed in m/s")
    checks.check_positive("rate", rate, "a positive IMU rate in Hz")
    checks.check_positive("blend", blend, "a positive blending time in s")
    checks.check_scalar("heading_deg", heading_deg, meaning="a heading in degrees")
    _check_start(start)
    dtype = dtype or jnp.result_type(float)
    dt = 1.0 / float(rate)
    steps = int(round(float(legs[:, 0].sum()) * rate))
    commands = jnp.asarray(command_profiles(legs, np.arange(steps + 1) * dt, blend), dtype)
    position0 = jnp.asarray([math.radians(start[0]), math.radians(start[1]), start[2]], dtype)
    trajectory, slowest, steepest = _fly(
        commands,
        position0,
        jnp.asarray(speed, dtype),
        jnp.asarray(math.radians(heading_deg), dtype),
        jnp.asarray(dt, dtype),
    )
    if float(slowest) <= 0.0 or float(steepest) >= 1.0:
        raise ValueError("legs: the flight stalls (speed <= 0) or climbs faster than it flies")
    return trajectory._replace(dt=dt)


@jax.jit
def _fly(commands, position0, speed, heading0, dt):
    """``fly`` once its legs are sampled, as one program: the trajectory, the lowest
    airspeed and the steepest climb (``|climb| / airspeed``)."""

    def integral(values):  # trapezoidal cumulative integral on the sample grid
        return jnp.concatenate(
            [jnp.zeros((1,), values.dtype), jnp.cumsum(0.5 * (values[1:] + values[:-1]) * dt)]
        )

    turn, climb, accel = commands[:, 0], commands[:, 1], commands[:, 2]
    airspeed = speed + integral(accel)
    heading = heading0 + integral(turn)
    gamma = jnp.arcsin(climb / airspeed)
    velocity = jnp.stack(
        [
            airspeed * jnp.cos(gamma) * jnp.cos(heading),
            airspeed * jnp.cos(gamma) * jnp.sin(heading),
            -climb,
        ],
        axis=1,
    )
    attitude = jax.vmap(euler_to_quaternion)(jnp.arctan(airspeed * turn / G0), gamma, heading)
    return (
        _from_samples(position0, velocity, attitude, dt),
        jnp.min(airspeed),
        jnp.max(jnp.abs(climb) / airspeed),
    )


@jax.jit
def _integrate_positions(position0, velocity, dt):
    def body(position, pair):
        nxt = mechanization.integrate_position(position, pair[0], pair[1], dt)
        return nxt, nxt

    _, rest = jax.lax.scan(body, position0, (velocity[:-1], velocity[1:]))
    return jnp.concatenate([position0[None], rest])


@jax.jit
def _imu_samples(position, velocity, attitude, dt):
    def one(p, v, q, v_next, q_next):
        f, w = mechanization.inverse_step(NavState(p, v, q), v_next, q_next, dt)
        return jnp.concatenate([f, w])

    return jax.vmap(one)(position[:-1], velocity[:-1], attitude[:-1], velocity[1:], attitude[1:])


def _from_samples(position0, velocity, attitude, dt) -> Trajectory:
    position = _integrate_positions(position0, velocity, dt)
    return Trajectory(
        dt, position, velocity, attitude, _imu_samples(position, velocity, attitude, dt)
    )


def stationary(
    start: tuple[float, float, float],
    duration: float,
    rate: float = 100.0,
    attitude_deg: tuple[float, float, float] = (0.0, 0.0, 0.0),
    dtype=None,
) -> Trajectory:
    """A vehicle at rest at ``start`` for ``duration`` [s] with a fixed roll, pitch, yaw."""
    checks.check_scalar("duration", duration, 0.0, meaning="a duration >= 0 in s")
    checks.check_positive("rate", rate, "a positive IMU rate in Hz")
    _check_start(start)
    dtype = dtype or jnp.result_type(float)
    steps = int(round(duration * rate))
    q = euler_to_quaternion(*(jnp.asarray(math.radians(a), dtype) for a in attitude_deg))
    position0 = jnp.asarray([math.radians(start[0]), math.radians(start[1]), start[2]], dtype)
    return _from_samples(
        position0, jnp.zeros((steps + 1, 3), dtype), jnp.broadcast_to(q, (steps + 1, 4)), 1.0 / rate
    )


#: the park racetrack of the GPS half (600 m legs, 200 m radius, 12 m/s): a 180 deg turn
_PARK_TURN = (math.pi * 200.0 / 12.0, math.degrees(12.0 / 200.0))


def park_legs(duration: float = 1200.0) -> list[tuple[float, float, float, float]]:
    """Climb 60 m, then racetrack laps (50 s legs, 180 deg turns at 3.4 deg/s), one lap
    climbing 30 m and one descending, until ``duration`` [s].

    Returns:
      list of legs ``(duration [s], turn rate [deg/s], climb rate [m/s], acceleration [m/s^2])`` (``fly``'s), their
      durations summing to ``duration`` (the last leg cut short).
    """
    checks.check_positive("duration", duration, "a positive flight duration in s")
    legs = [(60.0, 0.0, 1.0, 0.0)]
    lap = 0
    while sum(leg[0] for leg in legs) < duration:
        climb = 0.6 if lap == 1 else (-0.6 if lap == 3 else 0.0)
        legs += [
            (50.0, 0.0, climb, 0.0),
            (_PARK_TURN[0], _PARK_TURN[1], 0.0, 0.0),
            (50.0, 0.0, 0.0, 0.0),
            (_PARK_TURN[0], _PARK_TURN[1], 0.0, 0.0),
        ]
        lap += 1
    return _cut_at(legs, duration)


def manoeuvre_legs(duration: float = 1200.0) -> list[tuple[float, float, float, float]]:
    """S-turns at +-20 deg/s (9 s each), pull-ups and dives at +-8 m/s, +-2 m/s^2 speed
    changes, until ``duration`` [s]; starts at 25 m/s.

    Returns:
      list of legs ``(duration [s], turn rate [deg/s], climb rate [m/s], acceleration [m/s^2])``: 20 s straight, then
      the 58 s pattern repeated, durations summing to ``duration`` (the last leg cut short).
    """
    checks.check_positive("duration", duration, "a positive flight duration in s")
    pattern = [
        (9.0, 20.0, 0.0, 0.0),
        (9.0, -20.0, 0.0, 0.0),
        (6.0, 0.0, 8.0, 2.0),
        (6.0, 0.0, -8.0, -2.0),
        (9.0, -20.0, 4.0, 0.0),
        (9.0, 20.0, -4.0, 0.0),
        (5.0, 0.0, 0.0, 1.0),
        (5.0, 0.0, 0.0, -1.0),
    ]
    legs = [(20.0, 0.0, 0.0, 0.0)]
    while sum(leg[0] for leg in legs) < duration:
        legs += pattern
    return _cut_at(legs, duration)


def _cut_at(legs: list[tuple], duration: float) -> list[tuple]:
    """``legs`` (each ``(seconds, ...)``) up to ``duration`` [s], the last one cut short."""
    total, cut = 0.0, []
    for leg in legs:
        take = min(leg[0], duration - total)
        if take > 0:
            cut.append((take,) + tuple(leg[1:]))
        total += take
    return cut
