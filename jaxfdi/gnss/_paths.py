"""Receiver trajectories: a UAV flying a racetrack circuit at constant speed and height.

Two legs of length ``straight`` joined by half circles of ``radius``: north along ``east = 0``, back south
along ``east = -2 radius``, from ``(north, east) = (-straight / 2, 0)``; local NED about a geodetic origin,
then ECEF (``frames.ned_to_ecef``) at the receiver's tags; ``phase`` [m] shifts the start along the circuit.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi.gnss._frames import ned_to_ecef


def racetrack_ned(
    times: Array, straight: float, radius: float, speed: float, height: float, phase: float = 0.0
) -> Array:
    """(T, 3) NED positions [m] at ``times`` [s from the start]; ``height`` above the origin."""
    finite = all(
        bool(np.all(np.isfinite(np.asarray(v)))) for v in (straight, radius, speed, height, phase)
    )
    if not (finite and straight >= 0 and radius > 0 and speed > 0):
        raise ValueError(
            f"straight, radius, speed, height, phase: expected finite values, straight >= 0, radius > 0, "
            f"speed > 0, got {straight}, {radius}, {speed}, {height}, {phase}"
        )
    times = jnp.asarray(times)
    lap = 2.0 * straight + 2.0 * jnp.pi * radius
    s = jnp.mod(phase + speed * times, lap)
    half = jnp.pi * radius
    # leg 1: north along east = 0; turn 1 about (straight/2, -radius); leg 2: south; turn 2
    on_leg1 = s < straight
    on_turn1 = (s >= straight) & (s < straight + half)
    on_leg2 = (s >= straight + half) & (s < 2 * straight + half)
    a1 = (s - straight) / radius
    a2 = (s - 2 * straight - half) / radius
    north = jnp.select(
        [on_leg1, on_turn1, on_leg2],
        [
            -straight / 2 + s,
            straight / 2 + radius * jnp.sin(a1),
            straight / 2 - (s - straight - half),
        ],
        -straight / 2 - radius * jnp.sin(a2),
    )
    east = jnp.select(
        [on_leg1, on_turn1, on_leg2],
        [jnp.zeros_like(s), -radius + radius * jnp.cos(a1), jnp.full_like(s, -2 * radius)],
        -radius - radius * jnp.cos(a2),
    )
    return jnp.stack([north, east, jnp.full_like(s, -height)], axis=-1)


def racetrack_ecef(
    times: Array,
    origin_ecef: Array,
    straight: float,
    radius: float,
    speed: float,
    height: float,
    phase: float = 0.0,
) -> Array:
    """(T, 3) ECEF positions of ``racetrack_ned`` about ``origin_ecef``.

    Returns:
      (T, 3) ECEF positions [m] at ``times`` [s from the start], ``height`` [m] above the origin on the circuit.
    """
    return ned_to_ecef(racetrack_ned(times, straight, radius, speed, height, phase), origin_ecef)
