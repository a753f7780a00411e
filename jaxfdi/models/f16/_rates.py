"""The F-16's body rates alone: the UKF process model of Park, Kim, Park & Roh (2004,
Sec. III: "the UKF's system model is the moment equations (34)-(36) only").

State ``w = [P, Q, R]`` (rad/s); input ``v = [VT, alpha, beta, h, thtl, el, ail, rdr]`` (``RATE_INPUT_NAMES``): measured
air data and altitude (taken as known) and the commanded controls. Derivative: ``moment_equations`` (Stevens & Lewis eq.
2.5-16 with engine momentum) with ``Cl (1 + e_l)``, ``Cm (1 + e_m)``, ``Cn (1 + e_n)`` (the paper's coefficient errors:
the method needs no exact model); the model's c.g. is the design's, not the flight's.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.models._integrate import rk4
from jaxfdi.models.f16._atmosphere import air_data
from jaxfdi.models.f16._dynamics import VT, F16Params, H, aero_coefficients, moment_equations

#: the rate model's input, in order
RATE_INPUT_NAMES = ("VT", "alpha", "beta", "h", "thtl", "el", "ail", "rdr")


class RateModel(NamedTuple):
    """Parameters of the rate model (a pytree).

    Attributes:
      aircraft: the aircraft's parameters
      coefficient_scale: (3,) multipliers of Cl, Cm, Cn: 1 + the coefficient errors
      rate_axes: (m_r, 3) H of the rate sensors
      dt: () s, sample period
    """

    aircraft: F16Params
    coefficient_scale: Array
    rate_axes: Array
    dt: Array


def rate_model(
    aircraft: F16Params, rate_axes: Array, dt: float = 0.01, coefficient_error=(0.0, 0.0, 0.0)
) -> RateModel:
    """The rate model of ``aircraft`` with relative errors ``coefficient_error`` (3,) on ``Cl, Cm, Cn`` (e.g.
    ``(0.1, -0.1, 0.1)``: roll and yaw moments 10 % too large, pitch 10 % too small).

    Returns:
      ``RateModel`` in ``aircraft.mass``'s dtype, ``coefficient_scale = 1 + coefficient_error``; the params
      of ``rate_transition`` and ``rate_observation``.
    """
    dtype = aircraft.mass.dtype
    checks.check_matrix(
        "rate_axes", rate_axes, (None, 3), "one body-axis direction per rate channel"
    )
    checks.check_matrix(
        "coefficient_error", coefficient_error, (3,), "relative errors of Cl, Cm, Cn"
    )
    checks.check_positive("dt", dt, "a positive sample period (s)")
    scale = 1.0 + jnp.asarray(coefficient_error, dtype)
    return RateModel(aircraft, scale, jnp.asarray(rate_axes, dtype), jnp.asarray(dt, dtype))


def rate_model_input(y: Array, u: Array) -> Array:
    """(8,) the rate model's input from the F-16's measurement ``y`` (``plant``'s layout:
    ``[VT, alpha, beta, phi, theta, psi, h, pow, rate channels]``) and the controls ``u`` (4,).

    Returns:
      (8,) ``[VT (ft/s), alpha, beta (rad), h (ft), thtl, el, ail, rdr (deg)]`` (``RATE_INPUT_NAMES``) in ``y``'s
      dtype.
    """
    shape = checks.shape_of(y)
    if len(shape) != 1 or shape[0] < 8:
        raise ValueError(
            f"y: expected the F-16's measurement [VT, alpha, beta, phi, theta, psi, h, pow, rate "
            f"channels], shape (8 + m_r,), got {shape}"
        )
    checks.check_shape("u", u, (4,), "[thtl, el, ail, rdr]")
    return jnp.concatenate([y[0:3], y[6:7], jnp.asarray(u, y.dtype)])


def rate_derivative(rates: Array, inputs: Array, model: RateModel) -> Array:
    """``[P', Q', R']`` (Park et al. 2004, eqs. 34-36) with the model's coefficient errors."""
    aircraft = model.aircraft
    vt, alpha, beta, altitude = inputs[0], inputs[1], inputs[2], inputs[3]
    zero = jnp.zeros((), rates.dtype)
    x = jnp.stack(
        [
            vt,
            alpha,
            beta,
            zero,
            zero,
            zero,
            rates[0],
            rates[1],
            rates[2],
            zero,
            zero,
            altitude,
            zero,
        ]
    )
    c = aero_coefficients(aircraft, x, inputs[4:8])
    scale = model.coefficient_scale
    c = c._replace(Cl=c.Cl * scale[0], Cm=c.Cm * scale[1], Cn=c.Cn * scale[2])
    qs = air_data(x[VT], x[H], aircraft.atmosphere).dynamic_pressure * aircraft.area
    return jnp.stack(moment_equations(rates[0], rates[1], rates[2], c, qs, aircraft))


def rate_transition(rates: Array, inputs: Array, model: RateModel) -> Array:
    """``w[k+1]``: one RK4 step over ``model.dt``, input held (stages a loop: the tables compile once).

    Returns:
      (3,) body rates ``[P, Q, R]`` [rad/s] one sample later.
    """
    return rk4(lambda x, t: rate_derivative(x, inputs, model), rates, model.dt, loop_stages=True)


def rate_observation(rates: Array, inputs: Array, model: RateModel) -> Array:
    """``H w`` (m_r,): the rate channels without noise (``H``: ``rate_axes``, a row per input axis).

    Returns:
      (m_r,) noise-free rate-sensor readings [rad/s]; ``inputs`` unused.
    """
    return model.rate_axes @ rates


__all__ = [
    "RATE_INPUT_NAMES",
    "RateModel",
    "rate_model",
    "rate_model_input",
    "rate_derivative",
    "rate_transition",
    "rate_observation",
]
