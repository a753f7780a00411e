"""Attitude algebra (the strapdown INS, the spacecraft's truth and attitude control): unit quaternions (Hamilton, scalar
first), direction cosine matrices, rotation vectors, Euler angles and the cross-product matrix. Components run along
axis 0, so every function also takes a batch in trailing axes ((4, N) quaternions, (3, N) vectors).

``q``: body-to-reference (NED for the INS, inertial for the spacecraft), ``v^n = C(q) v^b = (q (x) [0, v^b] (x) q*)_v``.
Rotation vector ``r``: ``exp(r) = [cos(|r|/2), sin(|r|/2) r / |r|]``, ``log`` its inverse on ``q_0 >= 0`` (Groves 2013,
App. E.6; Titterton & Weston 2004, sec. 3.6). Series near the identity keep values and two derivatives finite (the EKF
differentiates through them). Euler: roll, pitch, yaw, ``C = R_z(yaw) R_y(pitch) R_x(roll)``.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks

__all__ = [
    "quaternion_multiply",
    "quaternion_conjugate",
    "rotate",
    "cross",
    "quaternion_to_dcm",
    "rotation_quaternion",
    "small_rotation_quaternion",
    "rotation_vector",
    "euler_to_quaternion",
    "quaternion_to_euler",
    "skew",
]

#: below this squared angle [rad^2] the series forms are used (their error is ~1e-20)
_SMALL = 1e-10


def _check_leading(name: str, value: Array, size: int, meaning: str) -> None:
    """The components run along axis 0 (trace time): a shorter axis would be read out of bounds, silently clamped."""
    shape = checks.shape_of(value)
    if not shape or shape[0] != size:
        raise ValueError(f"{name}: expected {meaning}, shape ({size}, ...), got {shape}")


def quaternion_multiply(p: Array, q: Array) -> Array:
    """Hamilton product ``p (x) q`` of (4,) quaternions.

    Returns:
      the (4,) quaternion ``p (x) q`` (the rotation ``q`` then ``p``).
    """
    p0, p1, p2, p3 = p[0], p[1], p[2], p[3]
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    return jnp.stack(
        [
            p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
            p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
            p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
        ]
    )


def quaternion_conjugate(q: Array) -> Array:
    """``q* = [q0, -q1, -q2, -q3]``: the inverse rotation of a unit quaternion.

    Returns:
      the (4,) conjugate quaternion.
    """
    return jnp.stack([q[0], -q[1], -q[2], -q[3]])


def rotate(q: Array, v: Array) -> Array:
    """``C(q) v`` as ``v + q0 t + q_v x t``, ``t = 2 q_v x v``, element-wise (no (3, 3) ``C(q)`` is formed).

    Returns:
      the (3,) vector ``v`` rotated by the unit quaternion ``q`` (body to reference).
    """
    t = 2.0 * cross(q[1:], v)
    return v + q[0] * t + cross(q[1:], t)


def cross(a: Array, b: Array) -> Array:
    """The cross product ``a x b`` of (3,) vectors, element-wise.

    Returns:
      the (3,) vector ``a x b``.
    """
    return jnp.stack(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def quaternion_to_dcm(q: Array) -> Array:
    """The direction cosine matrix ``C(q)`` of a unit quaternion, ``C(q) v = (q (x) [0, v] (x) q*)_v``.

    Returns:
      the (3, 3) ``C(q)`` (body to NED for the attitude quaternion).
    """
    _check_leading("q", q, 4, "a quaternion [q0, q1, q2, q3]")
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    return jnp.stack(
        [
            jnp.stack(
                [
                    q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3,
                    2 * (q1 * q2 - q0 * q3),
                    2 * (q1 * q3 + q0 * q2),
                ]
            ),
            jnp.stack(
                [
                    2 * (q1 * q2 + q0 * q3),
                    q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3,
                    2 * (q2 * q3 - q0 * q1),
                ]
            ),
            jnp.stack(
                [
                    2 * (q1 * q3 - q0 * q2),
                    2 * (q2 * q3 + q0 * q1),
                    q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3,
                ]
            ),
        ]
    )


def rotation_quaternion(rotation: Array) -> Array:
    """``exp(r) = [cos(|r|/2), sin(|r|/2) r / |r|]``, by its series below ``|r|^2 = 1e-10``.

    Returns:
      the (4,) unit quaternion of the (3,) rotation vector ``rotation`` [rad].
    """
    angle2 = jnp.sum(rotation**2, axis=0)
    small = angle2 < _SMALL
    angle = jnp.sqrt(jnp.where(small, 1.0, angle2))
    scale = jnp.where(small, 0.5 - angle2 / 48.0, jnp.sin(0.5 * angle) / angle)
    real = jnp.where(small, 1.0 - angle2 / 8.0, jnp.cos(0.5 * angle))
    return jnp.concatenate([real[None], scale * rotation])


def small_rotation_quaternion(rotation: Array) -> Array:
    """``exp(r)`` by its series to sixth order (error < 1e-15 for ``|r| <= 0.1`` rad; no transcendental
    call; strapdown turns are a few mrad).

    Returns:
      the (4,) quaternion of the small (3,) rotation vector ``rotation`` [rad].
    """
    x2 = jnp.sum(rotation**2, axis=0)
    real = 1.0 - x2 / 8.0 + x2 * x2 / 384.0 - x2 * x2 * x2 / 46080.0
    scale = 0.5 - x2 / 48.0 + x2 * x2 / 3840.0 - x2 * x2 * x2 / 645120.0
    return jnp.concatenate([real[None], scale * rotation])


def rotation_vector(q: Array) -> Array:
    """``log(q)``, the inverse of ``rotation_quaternion`` on ``q0 >= 0`` (``q`` and ``-q`` alike).

    Returns:
      the (3,) rotation vector [rad] of the unit quaternion ``q``.
    """
    q = jnp.where(q[0] < 0, -q, q)
    vector = q[1:]
    norm2 = jnp.sum(vector**2, axis=0)
    small = norm2 < _SMALL
    norm = jnp.sqrt(jnp.where(small, 1.0, norm2))
    # 2 atan2(|v|, w) / |v| = 2 / w (1 - |v|^2 / (3 w^2) + ...) near the identity
    scale = jnp.where(
        small, 2.0 / q[0] * (1.0 - norm2 / (3.0 * q[0] ** 2)), 2.0 * jnp.arctan2(norm, q[0]) / norm
    )
    return scale * vector


def euler_to_quaternion(roll: Array, pitch: Array, yaw: Array) -> Array:
    """The attitude quaternion of z-y-x Euler angles, ``C = R_z(yaw) R_y(pitch) R_x(roll)``.

    Returns:
      the (4,) unit quaternion of ``roll``, ``pitch``, ``yaw`` [rad].
    """
    cr, sr = jnp.cos(0.5 * roll), jnp.sin(0.5 * roll)
    cp, sp = jnp.cos(0.5 * pitch), jnp.sin(0.5 * pitch)
    cy, sy = jnp.cos(0.5 * yaw), jnp.sin(0.5 * yaw)
    return jnp.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def quaternion_to_euler(q: Array) -> Array:
    """The z-y-x Euler angles of an attitude quaternion (the inverse of ``euler_to_quaternion``).

    Returns:
      (3,) roll, pitch, yaw [rad].
    """
    c = quaternion_to_dcm(q)
    return jnp.stack(
        [
            jnp.arctan2(c[2, 1], c[2, 2]),
            -jnp.arcsin(jnp.clip(c[2, 0], -1.0, 1.0)),
            jnp.arctan2(c[1, 0], c[0, 0]),
        ]
    )


def skew(v: Array) -> Array:
    """The cross-product matrix ``[v x]``, ``[v x] a = v x a``.

    Returns:
      the (3, 3) skew-symmetric matrix of the (3,) vector ``v``.
    """
    zero = jnp.zeros_like(v[0])
    return jnp.stack(
        [
            jnp.stack([zero, -v[2], v[1]]),
            jnp.stack([v[2], zero, -v[0]]),
            jnp.stack([-v[1], v[0], zero]),
        ]
    )
