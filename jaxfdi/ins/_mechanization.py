"""Strapdown inertial navigation in local North-East-Down axes: one step, its exact
inverse, and the continuous-time equations.

One step of ``dt`` with the interval's mean ``f^b`` and ``w_ib^b`` (increments / ``dt``), the first-order
precision form of Groves (2013), sec. 5.4 (Titterton & Weston 2004, ch. 3):

1. attitude: ``q+ = exp(-w_in^n dt) (x) q (x) exp(w_ib^b dt)``, ``w_in = w_ie + w_en`` (``exp`` by its series, exact in
   float64 for turns below 0.1 rad per step), then one Newton step towards unit norm;
2. velocity: ``v+ = v + (C_avg f^b + g^n - (2 w_ie^n + w_en^n) x v) dt`` with ``C_avg = (C(q) + C(q+)) / 2`` (eq. 5.54);
3. position by the trapezoidal rule (eq. 5.56): ``h+ = h - dt (v_D + v_D+) / 2``, then
   latitude with ``R_N`` at the old latitude, longitude with both ends' ``R_E``.

``inverse_step`` solves 1-2 for ``(f^b, w_ib^b)`` (quaternion logarithm, 3 x 3 solve), so an IMU built from a trajectory
integrated by ``integrate_position`` reproduces it to round-off (``trajectory``). ``rates``: the continuous-time
equations (Groves 2013, eqs. 5.46, 5.53, 2.111), linearised by AD for the EKF (``error_state``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.ins._earth import LocalEarth, local_earth, radii_of_curvature, transport_rate
from jaxfdi.rotation import (
    cross,
    quaternion_conjugate,
    quaternion_multiply,
    quaternion_to_dcm,
    rotate,
    rotation_quaternion,
    rotation_vector,
    small_rotation_quaternion,
)


class NavState(NamedTuple):
    """An INS's (or the truth's) navigation state; leaves may carry leading batch axes.

    Attributes:
      position: (3,) latitude [rad], longitude [rad], ellipsoidal height [m]
      velocity: (3,) NED [m/s]
      attitude: (4,) body-to-NED unit quaternion, scalar first
    """

    position: Array
    velocity: Array
    attitude: Array


def navigation_rates(nav: NavState, earth: LocalEarth) -> tuple[Array, Array]:
    """``(w_ie^n, w_en^n)`` at the state."""
    return earth.earth_rate, transport_rate(nav.velocity, nav.position[2], earth)


def integrate_position(
    position: Array,
    velocity: Array,
    new_velocity: Array,
    dt: Array,
    earth: LocalEarth | None = None,
) -> Array:
    """Groves (2013) eq. 5.56: the position after ``dt`` from the velocities at both ends.

    ``earth``: the ``LocalEarth`` at ``position`` if computed. New latitude's sin/cos by angle addition
    to third order (exact in float64 for steps below 1e-4 rad, 600 m)."""
    lat, lon, height = position[0], position[1], position[2]
    if earth is None:
        sin_lat, cos_lat = jnp.sin(lat), jnp.cos(lat)
        meridian, transverse = radii_of_curvature(sin_lat)
    else:
        sin_lat, cos_lat, meridian, transverse = (
            earth.sin_lat,
            earth.cos_lat,
            earth.meridian_radius,
            earth.transverse_radius,
        )
    new_height = height - 0.5 * dt * (velocity[2] + new_velocity[2])
    new_lat = lat + 0.5 * dt * (
        velocity[0] / (meridian + height) + new_velocity[0] / (meridian + new_height)
    )
    d = new_lat - lat
    cos_d, sin_d = 1.0 - 0.5 * d * d, d * (1.0 - d * d / 6.0)
    new_sin, new_cos = sin_lat * cos_d + cos_lat * sin_d, cos_lat * cos_d - sin_lat * sin_d
    _, new_transverse = radii_of_curvature(new_sin)
    new_lon = lon + 0.5 * dt * (
        velocity[1] / ((transverse + height) * cos_lat)
        + new_velocity[1] / ((new_transverse + new_height) * new_cos)
    )
    return jnp.stack([new_lat, new_lon, new_height])


def strapdown_step(
    nav: NavState, specific_force: Array, angular_rate: Array, dt: Array
) -> NavState:
    """One strapdown update in NED (module doc) with the interval's mean ``f^b`` [m/s^2]
    and ``w_ib^b`` [rad/s], both already corrected for the estimated IMU errors.

    Returns:
      ``NavState`` after ``dt`` [s] (module doc's steps 1-3).

    Raises:
      ValueError: ``specific_force`` or ``angular_rate`` not of shape (3,).
    """
    for name, value in (("specific_force", specific_force), ("angular_rate", angular_rate)):
        shape = checks.shape_of(value)
        if not shape or shape[0] != 3:
            raise ValueError(f"{name}: expected a body-axis vector of shape (3,), got {shape}")
    earth = local_earth(nav.position)
    earth_rate, transport = navigation_rates(nav, earth)
    body_turn = small_rotation_quaternion(angular_rate * dt)
    frame_turn = small_rotation_quaternion(-(earth_rate + transport) * dt)
    attitude = quaternion_multiply(frame_turn, quaternion_multiply(nav.attitude, body_turn))
    attitude = attitude * (1.5 - 0.5 * jnp.sum(attitude**2, axis=0))  # one Newton step of 1 / |q|
    specific_force_n = 0.5 * (
        rotate(nav.attitude, specific_force) + rotate(attitude, specific_force)
    )
    acceleration = (
        specific_force_n + earth.gravity - cross(2.0 * earth_rate + transport, nav.velocity)
    )
    velocity = nav.velocity + acceleration * dt
    return NavState(
        integrate_position(nav.position, nav.velocity, velocity, dt, earth), velocity, attitude
    )


def inverse_step(
    nav: NavState, new_velocity: Array, new_attitude: Array, dt: Array
) -> tuple[Array, Array]:
    """``(f^b, w_ib^b)`` that take ``strapdown_step`` from ``nav`` to ``new_velocity`` and
    ``new_attitude`` in ``dt`` (the position then follows from ``integrate_position``)."""
    earth = local_earth(nav.position)
    earth_rate, transport = navigation_rates(nav, earth)
    frame_turn_back = rotation_quaternion((earth_rate + transport) * dt)
    body_turn = quaternion_multiply(
        quaternion_conjugate(nav.attitude), quaternion_multiply(frame_turn_back, new_attitude)
    )
    angular_rate = rotation_vector(body_turn) / dt
    mean_dcm = 0.5 * (quaternion_to_dcm(nav.attitude) + quaternion_to_dcm(new_attitude))
    specific_force_n = (
        (new_velocity - nav.velocity) / dt
        - earth.gravity
        + jnp.cross(2.0 * earth_rate + transport, nav.velocity)
    )
    return jnp.linalg.solve(mean_dcm, specific_force_n), angular_rate


def rates(nav: NavState, specific_force: Array, angular_rate: Array) -> NavState:
    """The continuous-time strapdown equations: ``d/dt`` of each field of ``nav`` for the
    instantaneous ``f^b`` and ``w_ib^b`` (a ``NavState`` of derivatives)."""
    earth = local_earth(nav.position)
    earth_rate, transport = navigation_rates(nav, earth)
    lat, height = nav.position[0], nav.position[2]
    position_rate = jnp.stack(
        [
            nav.velocity[0] / (earth.meridian_radius + height),
            nav.velocity[1] / ((earth.transverse_radius + height) * jnp.cos(lat)),
            -nav.velocity[2],
        ]
    )
    velocity_rate = (
        rotate(nav.attitude, specific_force)
        + earth.gravity
        - cross(2.0 * earth_rate + transport, nav.velocity)
    )
    body = jnp.concatenate([jnp.zeros((1,), angular_rate.dtype), angular_rate])
    frame = jnp.concatenate([jnp.zeros((1,), angular_rate.dtype), earth_rate + transport])
    attitude_rate = 0.5 * (
        quaternion_multiply(nav.attitude, body) - quaternion_multiply(frame, nav.attitude)
    )
    return NavState(position_rate, velocity_rate, attitude_rate)
