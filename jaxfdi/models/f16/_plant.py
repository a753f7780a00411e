"""The F-16 as a sampled plant: RK4 with gusts, noisy sensors, and the controller's view whose body rates
are a *selected* rate (Park, Kim, Park & Roh 2004); loop stages in ``jaxfdi.control._f16_loop``.

State ``x_s = [x (13), w_g, v_g]``: aircraft, vertical and lateral gust velocity (ft/s), first-order
Gauss-Markov (Dryden-like) ``g[k+1] = a g[k] + sigma_g sqrt(1 - a^2) n[k]``, ``a = exp(-V0 dt / L)``, seen
as ``alpha_g = w_g / VT``, ``beta_g = v_g / VT`` (``f16_dynamics(gust=...)``). One sample ``dt``:
``substeps`` RK4 steps, controls (saturated) and gust held (``sampled_transition``).

``y`` (``MEASUREMENT_NAMES``): air data ``[VT, alpha, beta]``, attitude ``[phi, theta, psi]``, altitude,
power, rate sensors ``m = H [P, Q, R]`` (``rate_axes``, one row per input axis), white Gaussian noise
(``measurement_cov``). Park et al. fly three 2-DOF rate sensors, ``H`` 6x3 (``skewed_rate_axes``),
sigma = 0.01 rad/s; other noise is "an appropriate level" (defaults: ``f16_sensors``). The controller reads a
``FlightView`` whose rates an FDI stage selects, e.g. ``(H^T H)^-1 H^T m`` (``rate_estimator``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.models._integrate import rk4
from jaxfdi.models.f16._dynamics import (
    ALPHA,
    BETA,
    PHI,
    POW,
    PSI,
    THETA,
    VT,
    F16Params,
    H,
    P,
    R,
    f16_dynamics,
    saturate,
)

#: the components of ``y`` before the rate-sensor axes
MEASUREMENT_NAMES = ("VT", "alpha", "beta", "phi", "theta", "psi", "h", "pow")
#: the states those components read
MEASURED_STATES = (VT, ALPHA, BETA, PHI, THETA, PSI, H, POW)
#: index in ``y`` of the first rate-sensor axis
RATE_OFFSET = len(MEASUREMENT_NAMES)


class F16Sensors(NamedTuple):
    """Sensor layout and noise (standard deviations).

    Attributes:
      rate_axes: (m_r, 3) H: the input axis of each rate-sensor channel (rows, unit vectors)
      rate_sigma: () rad/s per channel
      air_data_sigma: (3,) VT ft/s, alpha rad, beta rad
      attitude_sigma: (3,) phi, theta, psi rad
      altitude_sigma: () ft, altimeter noise
      power_sigma: () %
    """

    rate_axes: Array
    rate_sigma: Array
    air_data_sigma: Array
    attitude_sigma: Array
    altitude_sigma: Array
    power_sigma: Array


class SampledF16(NamedTuple):
    """Parameters of the sampled plant (a pytree: vmap over the aircraft's leaves).

    Attributes:
      aircraft: the aircraft's parameters
      rate_axes: (m_r, 3) H of the rate sensors
      dt: () s, sample period
      gust_decay: () a = exp(-V0 dt / L)
    """

    aircraft: F16Params
    rate_axes: Array
    dt: Array
    gust_decay: Array


class FlightView(NamedTuple):
    """What the flight controller reads at step ``k``.

    Attributes:
      air_data: (3,) VT, alpha, beta
      attitude: (3,) phi, theta, psi
      altitude: () h, ft
      power: () engine power, %
      rates: (3,) the selected body rates P, Q, R
    """

    air_data: Array
    attitude: Array
    altitude: Array
    power: Array
    rates: Array


def skewed_rate_axes(dtype=None) -> Array:
    """The three 2-DOF rate sensors of Park et al. (2004) (spec, isotropic ``H^T H = 2 I``): sensor 1 in
    the x-y plane at +-45 deg, sensor 2 in x-z, sensor 3 in y-z; rows are the six axes."""
    dtype = dtype or jnp.result_type(float)
    s = 1.0 / math.sqrt(2.0)
    return jnp.asarray([[s, s, 0], [-s, s, 0], [s, 0, s], [-s, 0, s], [0, s, s], [0, -s, s]], dtype)


def f16_sensors(
    rate_axes: Array | None = None,
    rate_sigma: float = 0.01,
    air_data_sigma=(0.5, 1e-3, 1e-3),
    attitude_sigma=(1e-3, 1e-3, 1e-3),
    altitude_sigma: float = 2.0,
    power_sigma: float = 0.1,
    dtype=None,
) -> F16Sensors:
    """Flight sensors: Park et al.'s rate sensors (0.01 rad/s) by default; our choices (the paper gives only
    the rates'): air data 0.5 ft/s and 1 mrad (0.06 deg), attitude 1 mrad, altitude 2 ft, power 0.1 %.

    Returns:
      ``F16Sensors`` in ``dtype`` (``rate_axes`` default ``skewed_rate_axes``, m_r = 6).
    """
    dtype = dtype or jnp.result_type(float)
    axes = skewed_rate_axes(dtype) if rate_axes is None else jnp.asarray(rate_axes, dtype)
    checks.check_shape(
        "rate_axes", axes, (None, 3), "one body-axis direction per rate-sensor channel"
    )
    for name, value in (
        ("rate_sigma", rate_sigma),
        ("air_data_sigma", air_data_sigma),
        ("attitude_sigma", attitude_sigma),
        ("altitude_sigma", altitude_sigma),
        ("power_sigma", power_sigma),
    ):
        _check_sigma(name, value)
    a = lambda v: jnp.asarray(v, dtype)
    sensors = F16Sensors(
        axes, a(rate_sigma), a(air_data_sigma), a(attitude_sigma), a(altitude_sigma), a(power_sigma)
    )
    checks.check_shape("air_data_sigma", sensors.air_data_sigma, (3,), "VT, alpha, beta")
    checks.check_shape("attitude_sigma", sensors.attitude_sigma, (3,), "phi, theta, psi")
    return sensors


def _check_sigma(name: str, value) -> None:
    """Real, finite and >= 0 (when concrete): a standard deviation."""
    checks.check_real(name, value, "standard deviations")
    checks.check_finite(name, value, "standard deviations")
    concrete = checks.concrete(value)
    if concrete is not None and np.any(concrete < 0):
        raise ValueError(
            f"{name}: expected standard deviations >= 0, got {checks.received(concrete)}"
        )


def measurement_cov(sensors: F16Sensors) -> Array:
    """(8 + m_r, 8 + m_r) diagonal covariance of ``y``.

    Returns:
      the diagonal measurement covariance ``R``.
    """
    m_r = sensors.rate_axes.shape[0]
    sigma = jnp.concatenate(
        [
            sensors.air_data_sigma,
            sensors.attitude_sigma,
            sensors.altitude_sigma[None],
            sensors.power_sigma[None],
            jnp.broadcast_to(sensors.rate_sigma, (m_r,)),
        ]
    )
    return jnp.diag(sigma * sigma)


def sampled_transition(substeps: int = 1):
    """``f(x_s, u, plant) -> x_s[k+1]`` of the sampled plant (module doc), without noise.

    Rematerialised (``jax.checkpoint``): reverse mode keeps each sample's inputs, not the RK4
    intermediates (memory per step ~ the state, not ~10^4 values). RK4 stages as a loop
    (``rk4(loop_stages=True)``): the tables compile once, not four times.

    Returns:
      the transition function ``f(x_s, u, plant)``.
    """

    @jax.checkpoint
    def transition(xs: Array, u: Array, plant: SampledF16) -> Array:
        x, gust = xs[:13], xs[13:]
        angles, u_sat = gust / x[VT], saturate(u, plant.aircraft)
        x_next = rk4(
            lambda x, t: f16_dynamics(x, u_sat, plant.aircraft, angles),
            x,
            plant.dt,
            substeps,
            loop_stages=True,
        )
        return jnp.concatenate([x_next, plant.gust_decay * gust])

    return transition


def sampled_observation(xs: Array, u: Array, plant: SampledF16) -> Array:
    """``y`` without noise: the measured states and ``H [P, Q, R]``.

    Returns:
      the (8 + m_r,) noise-free measurement.
    """
    return jnp.concatenate([xs[jnp.array(MEASURED_STATES)], plant.rate_axes @ xs[P : R + 1]])


def rate_estimator(rate_axes: Array) -> Array:
    """``(H^T H)^-1 H^T`` (3, m_r): the least-squares body rates from every rate channel.

    Returns:
      the (3, m_r) least-squares matrix.
    """
    checks.check_matrix(
        "rate_axes", rate_axes, (None, 3), "one body-axis direction per rate channel"
    )
    return jnp.linalg.solve(rate_axes.T @ rate_axes, rate_axes.T)


def flight_view(y: Array, rates: Array) -> FlightView:
    """The controller's view of ``y`` with the given (selected) body rates.

    Returns:
      the ``FlightView`` (measured states and the body rates the controller flies on).
    """
    return FlightView(y[0:3], y[3:6], y[6], y[7], rates)
