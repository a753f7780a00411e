"""The INS error state and its dynamics, by automatic differentiation of the strapdown
equations (no hand-typed blocks: F11..F35 as printed in Yoo et al. (2010) carry typos).

Error state (15): ``[dp (3), dv (3), psi (3), db_a (3), db_g (3)]``, INS minus truth:

- ``dp`` (NED m): ``[(R_N + h)(L_ins - L), (R_E + h) cos L_ins (lon_ins - lon), -(h_ins - h)]``, radii at
  the INS point (Yoo et al.'s ``dLlh`` in metres: a well-conditioned covariance);
- ``dv = v_ins - v``; ``psi``: ``C(q_ins) = exp([psi x]) C(q)`` (Groves 2013, eq. 5.111's ``I + [psi x]`` made exact);
- ``db = b - b_hat``: bias not yet removed (``f_ins = f + db_a``).

``correct(ins, dx)``, the exact inverse of ``navigation_error``, is the EKF's feedback: INS
``correct(ins, dx_hat)``, biases ``b_hat + db_hat``, error estimate reset to zero.

Dynamics: INS driven by ``f_hat = f_meas - b_hat``, truth by ``f_hat - db - n`` (``n`` white noise); the error rate is
``navigation_error``'s derivative along both (one ``jax.jvp``); ``F = d(error rate) / d(dx)`` at ``dx = 0`` by
``jax.jacfwd`` (``error_jacobian``); noise enters like the bias, ``G = F[:, 9:15]``; biases are random walks. Over ``T``
with the interval's mean ``F`` (``discretize``): ``Phi = I + A + A^2/2 + A^3/6`` (``A = F T``; exact to round-off for
``T = 1 s``: ``A^4`` terms are Schuler or Earth-rate products < 1e-6),
``Q_d = Q T + (F Q + Q F^T) T^2 / 2 + F Q F^T T^3 / 3`` (Brown & Hwang 2012, sec. 3.9).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.ins import _mechanization as mechanization
from jaxfdi.ins._earth import radii_of_curvature
from jaxfdi.ins._mechanization import NavState
from jaxfdi.rotation import (
    quaternion_conjugate,
    quaternion_multiply,
    rotation_quaternion,
    rotation_vector,
)

#: sizes and slices of the error state
STATE_SIZE = 15
POSITION, VELOCITY, ATTITUDE, ACCEL_BIAS, GYRO_BIAS = (
    slice(0, 3),
    slice(3, 6),
    slice(6, 9),
    slice(9, 12),
    slice(12, 15),
)
STATE_NAMES = (
    "dp_N",
    "dp_E",
    "dp_D",
    "dv_N",
    "dv_E",
    "dv_D",
    "psi_N",
    "psi_E",
    "psi_D",
    "db_ax",
    "db_ay",
    "db_az",
    "db_gx",
    "db_gy",
    "db_gz",
)


class ImuNoise(NamedTuple):
    """White-noise and bias random-walk densities of an IMU (1-sigma, per axis).

    Attributes:
      velocity_random_walk: () m/s/sqrt(s)
      angle_random_walk: () rad/sqrt(s)
      accel_bias_walk: () m/s^2/sqrt(s)
      gyro_bias_walk: () rad/s/sqrt(s)
    """

    velocity_random_walk: Array
    angle_random_walk: Array
    accel_bias_walk: Array
    gyro_bias_walk: Array


def navigation_error(ins: NavState, truth: NavState) -> Array:
    """(9,) ``[dp, dv, psi]`` of ``ins`` against ``truth`` (module doc).

    Returns:
      (9,) INS minus truth: ``dp`` NED [m] (radii at the INS point), ``dv`` NED [m/s], ``psi`` the attitude error's
      rotation vector [rad].
    """
    lat, height = ins.position[0], ins.position[2]
    meridian, transverse = radii_of_curvature(jnp.sin(lat))
    delta = ins.position - truth.position
    position = jnp.stack(
        [(meridian + height) * delta[0], (transverse + height) * jnp.cos(lat) * delta[1], -delta[2]]
    )
    attitude = rotation_vector(
        quaternion_multiply(ins.attitude, quaternion_conjugate(truth.attitude))
    )
    return jnp.concatenate([position, ins.velocity - truth.velocity, attitude])


def correct(ins: NavState, error: Array) -> NavState:
    """The state whose ``navigation_error`` from ``ins`` is ``error[:9]`` (exact inverse).

    Returns:
      ``NavState``: ``ins`` with ``error[:9]`` ``[dp, dv, psi]`` removed (the bias entries ``error[9:]`` unused), its
      attitude renormalised.
    """
    lat, height = ins.position[0], ins.position[2]
    meridian, transverse = radii_of_curvature(jnp.sin(lat))
    position = ins.position - jnp.stack(
        [
            error[0] / (meridian + height),
            error[1] / ((transverse + height) * jnp.cos(lat)),
            -error[2],
        ]
    )
    attitude = quaternion_multiply(rotation_quaternion(-error[6:9]), ins.attitude)
    return NavState(position, ins.velocity - error[3:6], attitude / jnp.sqrt(jnp.sum(attitude**2)))


def error_rate(error: Array, ins: NavState, specific_force: Array, angular_rate: Array) -> Array:
    """(15,) ``d(dx)/dt`` for the error ``dx`` of an INS at ``ins`` driven by the corrected
    ``f_hat`` and ``w_hat`` (module doc); bias errors are constant (their noise is apart)."""
    truth = correct(ins, error)
    ins_rates = mechanization.rates(ins, specific_force, angular_rate)
    true_rates = mechanization.rates(
        truth, specific_force - error[ACCEL_BIAS], angular_rate - error[GYRO_BIAS]
    )
    _, nav_rate = jax.jvp(navigation_error, (ins, truth), (ins_rates, true_rates))
    return jnp.concatenate([nav_rate, jnp.zeros((6,), nav_rate.dtype)])


def error_jacobian(ins: NavState, specific_force: Array, angular_rate: Array) -> Array:
    """The error-state system matrix at the INS state (module doc).

    Returns:
      (15, 15) ``F = d(error rate)/d(dx)`` at ``dx = 0`` for ``[dp, dv, psi, db_a, db_g]`` and the IMU
      sample ``(f^b, w_ib^b)``.
    """
    zero = jnp.zeros((STATE_SIZE,), ins.velocity.dtype)
    return jax.jacfwd(error_rate)(zero, ins, specific_force, angular_rate)


def continuous_noise(jacobian: Array, noise: ImuNoise) -> Array:
    """(15, 15) ``Q_c = G diag(VRW^2, ARW^2) G^T + diag(0, bias walks^2)``, ``G = F[:, 9:]``."""
    dtype = jacobian.dtype
    white = jnp.concatenate(
        [
            jnp.full((3,), noise.velocity_random_walk**2, dtype),
            jnp.full((3,), noise.angle_random_walk**2, dtype),
        ]
    )
    gain = jacobian[:, 9:]
    walks = jnp.concatenate(
        [
            jnp.zeros((9,), dtype),
            jnp.full((3,), noise.accel_bias_walk**2, dtype),
            jnp.full((3,), noise.gyro_bias_walk**2, dtype),
        ]
    )
    return (gain * white) @ gain.T + jnp.diag(walks)


def discretize(jacobian: Array, noise: ImuNoise, interval: Array) -> tuple[Array, Array]:
    """``(Phi, Q_d)`` over ``interval`` [s] for the interval's mean ``F`` (module doc)."""
    checks.check_shape("jacobian", jacobian, (STATE_SIZE, STATE_SIZE), "the error state's F")
    eye = jnp.eye(STATE_SIZE, dtype=jacobian.dtype)
    a = jacobian * interval
    a2 = a @ a
    transition = eye + a + 0.5 * a2 + a2 @ a / 6.0
    q = continuous_noise(jacobian, noise)
    fq = jacobian @ q
    process = q * interval + 0.5 * (fq + fq.T) * interval**2 + fq @ jacobian.T * interval**3 / 3.0
    return transition, 0.5 * (process + process.T)
