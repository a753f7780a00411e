"""A tactical-grade IMU: turn-on biases, bias random walks, white noise, scale factors.

A sample is the interval's mean ``[f^b (m/s^2), w_ib^b (rad/s)]`` (increments / ``dt``); over one sample
(Groves 2013, sec. 4.4; Titterton & Weston 2004, ch. 8):

    f_meas = (1 + s_a) f + b_a + VRW / sqrt(dt) n_a,   w_meas = (1 + s_g) w + b_g + ARW / sqrt(dt) n_g,

``n ~ N(0, I)`` white (increments are random walks of density VRW, ARW); ``b_a``, ``b_g`` drawn at
turn-on, random walks in flight (``walk_biases``, ``*_bias_walk``); ``s_a``, ``s_g`` per-axis scale
factors (0 by default: the 15-state filter does not model them).

``hg1900()``: numbers from Honeywell's tactical-grade brochure (HG1700, N61-1619-000-001) as quoted by NavToolkit's
``hg1700_model`` (1 sigma): accelerometer bias 1 mg, VRW 0.065 ft/s/sqrt(h), gyro bias 1 deg/h, ARW 0.125 deg/sqrt(h)
(HG1900, MEMS, is the same class). ``*_bias_walk`` (1 deg/h and 0.1 mg drift over an hour, 1 sigma) is this library's
assumption (the brochure quotes none).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.ins._error_state import ImuNoise

DEG_PER_HOUR = math.radians(1.0) / 3600.0  # rad/s
MILLI_G = 9.80665e-3  # m/s^2
FEET = 0.3048


class ImuModel(NamedTuple):
    """1-sigma error parameters (SI units; see ``hg1900``).

    Attributes:
      accel_bias: m/s^2, turn-on
      gyro_bias: rad/s, turn-on
      velocity_random_walk: m/s/sqrt(s)
      angle_random_walk: rad/sqrt(s)
      accel_bias_walk: m/s^2/sqrt(s)
      gyro_bias_walk: rad/s/sqrt(s)
      accel_scale: dimensionless (ppm * 1e-6)
      gyro_scale: dimensionless (ppm * 1e-6)
    """

    accel_bias: float
    gyro_bias: float
    velocity_random_walk: float
    angle_random_walk: float
    accel_bias_walk: float
    gyro_bias_walk: float
    accel_scale: float = 0.0
    gyro_scale: float = 0.0


class ImuErrors(NamedTuple):
    """One IMU's current systematic errors (a run's draw; leaves may be batched).

    Attributes:
      accel_bias: (3,) accelerometer bias [m/s^2]
      gyro_bias: (3,) gyro bias [rad/s]
      accel_scale: (3,) accelerometer scale-factor errors
      gyro_scale: (3,) gyro scale-factor errors
    """

    accel_bias: Array
    gyro_bias: Array
    accel_scale: Array
    gyro_scale: Array


def hg1900(accel_scale_ppm: float = 0.0, gyro_scale_ppm: float = 0.0) -> ImuModel:
    """An HG1900-class tactical IMU (module doc for the numbers and their source).

    Returns:
      ``ImuModel`` of 1-sigma SI floats (module doc's numbers), scale factors ``accel_scale_ppm * 1e-6``,
      ``gyro_scale_ppm * 1e-6``.
    """
    for name, value in (("accel_scale_ppm", accel_scale_ppm), ("gyro_scale_ppm", gyro_scale_ppm)):
        checks.check_scalar(name, value, 0.0, meaning="a scale-factor sigma >= 0 in ppm")
    return ImuModel(
        accel_bias=1.0 * MILLI_G,
        gyro_bias=1.0 * DEG_PER_HOUR,
        velocity_random_walk=0.065 * FEET / 60.0,
        angle_random_walk=math.radians(0.125) / 60.0,
        accel_bias_walk=0.1 * MILLI_G / 60.0,
        gyro_bias_walk=1.0 * DEG_PER_HOUR / 60.0,
        accel_scale=accel_scale_ppm * 1e-6,
        gyro_scale=gyro_scale_ppm * 1e-6,
    )


def noise_model(model: ImuModel) -> ImuNoise:
    """The densities a filter needs (``error_state.ImuNoise``)."""
    return ImuNoise(
        model.velocity_random_walk,
        model.angle_random_walk,
        model.accel_bias_walk,
        model.gyro_bias_walk,
    )


def draw_errors(key: Array, model: ImuModel, dtype=None) -> ImuErrors:
    """Turn-on biases and scale factors of one unit.

    Returns:
      ``ImuErrors`` in ``dtype`` (default float): (3,) each, zero-mean normal with ``model``'s 1-sigma values,
      biases in m/s^2 and rad/s.
    """
    dtype = dtype or jnp.result_type(float)
    z = jax.random.normal(key, (4, 3), dtype)
    return ImuErrors(
        model.accel_bias * z[0],
        model.gyro_bias * z[1],
        model.accel_scale * z[2],
        model.gyro_scale * z[3],
    )


def walk_biases(errors: ImuErrors, key: Array, model: ImuModel, interval: float) -> ImuErrors:
    """The biases after ``interval`` [s] of random walk."""
    checks.check_scalar("interval", interval, 0.0, meaning="a duration >= 0 (s)")
    z = jax.random.normal(key, (2, 3), errors.accel_bias.dtype)
    root = math.sqrt(interval)
    return errors._replace(
        accel_bias=errors.accel_bias + model.accel_bias_walk * root * z[0],
        gyro_bias=errors.gyro_bias + model.gyro_bias_walk * root * z[1],
    )


def sample_sigma(model: ImuModel, dt: float, dtype=None) -> Array:
    """(6,) white noise of a sample ``dt`` [s] long: ``[VRW] * 3 + [ARW] * 3`` over ``sqrt(dt)``."""
    checks.check_positive("dt", dt, "a positive sample interval (s)")
    dtype = dtype or jnp.result_type(float)
    return jnp.asarray(
        [model.velocity_random_walk] * 3 + [model.angle_random_walk] * 3, dtype
    ) / math.sqrt(dt)


def measure(
    true_samples: Array, errors: ImuErrors, key: Array, model: ImuModel, dt: float
) -> Array:
    """(n, 6) measured samples of (n, 6) error-free ones (module doc)."""
    checks.check_shape(
        "true_samples", true_samples, (None, 6), "n samples of [f^b (3), w_ib^b (3)]"
    )
    noise = jax.random.normal(key, true_samples.shape, true_samples.dtype)
    scale = jnp.concatenate([1.0 + errors.accel_scale, 1.0 + errors.gyro_scale])
    bias = jnp.concatenate([errors.accel_bias, errors.gyro_bias])
    return true_samples * scale + bias + sample_sigma(model, dt, true_samples.dtype) * noise
