"""Trim of the F-16 for steady flight: level, climbing, coordinated turn and pull-up (Stevens & Lewis 2003, sec. 3.6),
solved by Levenberg-Marquardt (``jaxfdi._numerics.levenberg_marquardt``).

A ``TrimCondition`` fixes ``VT``, ``h``, ``gamma``, ``psi'`` and ``theta'``; unknowns
``z = [thtl, el, ail, rdr, alpha, beta]``; the rest follows from constraints:

- bank, turn coordination (Stevens & Lewis eq. 3.6-5), ``G = psi' VT / g``,
  ``a = 1 - G tan(alpha) sin(beta)``, ``b = sin(gamma)/cos(beta)``, ``c = 1 + G^2 cos^2(beta)``::

      tan(phi) = G cos(beta)/cos(alpha) [(a - b^2) + b tan(alpha) sqrt(c (1 - b^2) + G^2 sin^2(beta))]
                 / [a^2 - b^2 (1 + c tan^2(alpha))]

  (``phi = 0`` without a turn);
- pitch, rate of climb (eq. 3.6-3), ``a = cos(alpha) cos(beta)``,
  ``b = sin(phi) sin(beta) + cos(phi) sin(alpha) cos(beta)``::

      tan(theta) = (a b + sin(gamma) sqrt(a^2 - sin^2(gamma) + b^2)) / (a^2 - sin^2(gamma));

- body rates from Euler rates ``(0, theta', psi')``: ``P = -psi' sin(theta)``,
  ``Q = theta' cos(phi) + psi' sin(phi) cos(theta)``, ``R = -theta' sin(phi) + psi' cos(phi) cos(theta)``;
- engine power at its commanded value ``P = P_c(thtl)`` (no lag), ``psi = pn = pe = 0``.

Residuals ``[VT', alpha', beta', P', Q', R']`` of ``f16_dynamics``: a square system solved to round-off
(the book's simplex minimised a weighted sum of squares). Pure JAX: ``jax.vmap`` over conditions (and
``params`` leaves such as ``xcg``) trims an envelope in one solve.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics.levenberg_marquardt import levenberg_marquardt
from jaxfdi.models.f16._dynamics import ALPHA, BETA, VT, F16Params, P, Q, R, f16_dynamics
from jaxfdi.models.f16._engine import throttle_gearing

#: the trim unknowns, in order
TRIM_VARIABLES = ("thtl", "el", "ail", "rdr", "alpha", "beta")
#: the state derivatives the trim sets to zero, in order
TRIM_RESIDUALS = ("VT", "alpha", "beta", "P", "Q", "R")


class TrimCondition(NamedTuple):
    """A steady flight condition (a pytree of scalars; stack them to vmap).

    Attributes:
      airspeed: () VT, ft/s
      altitude: () h, ft
      climb_angle: () gamma, rad
      turn_rate: () psi', rad/s
      pull_up_rate: () theta', rad/s (wings level)
    """

    airspeed: Array
    altitude: Array
    climb_angle: Array
    turn_rate: Array
    pull_up_rate: Array


class TrimResult(NamedTuple):
    """A trim: state, controls, residual, convergence and whether the controls are within limits.

    Attributes:
      state: (13,) trimmed state
      control: (4,) [thtl, el, ail, rdr]
      residual: (6,) [VT', alpha', beta', P', Q', R'] at the trim
      converged: () bool: the solver stopped with max |residual| <= tolerance
      within_limits: () bool: controls inside params' limits
      steps: () int, Levenberg-Marquardt iterations
    """

    state: Array
    control: Array
    residual: Array
    converged: Array
    within_limits: Array
    steps: Array


def trim_condition(
    airspeed, altitude=0.0, climb_angle=0.0, turn_rate=0.0, pull_up_rate=0.0, dtype=None
) -> TrimCondition:
    """A ``TrimCondition``; equal-shape arrays give a stack (vmap over axis 0). Checked when concrete:
    ``airspeed`` [ft/s] positive finite, ``altitude`` [ft] in 0-50 000 (the thrust tables' range), climb
    angle in (-pi/2, pi/2) rad, finite angles and rates."""
    dtype = dtype or jnp.result_type(float)
    for name, value, valid, expected in (
        ("airspeed", airspeed, lambda v: v > 0.0, "a positive finite airspeed [ft/s]"),
        (
            "altitude",
            altitude,
            lambda v: (v >= 0.0) & (v <= 50000.0),
            "an altitude in [0, 50000] ft",
        ),
        (
            "climb_angle",
            climb_angle,
            lambda v: np.abs(v) < 0.5 * np.pi,
            "a flight-path angle in (-pi/2, pi/2) rad",
        ),
    ):
        checks.check_real(name, value)
        concrete = checks.concrete(value)
        if concrete is not None and not np.all(np.isfinite(concrete) & valid(concrete)):
            raise ValueError(f"{name}: expected {expected}, got {checks.received(concrete)}")
    for name, value in (("turn_rate", turn_rate), ("pull_up_rate", pull_up_rate)):
        checks.check_real(name, value)
        checks.check_finite(name, value)
    values = [
        jnp.asarray(v, dtype) for v in (airspeed, altitude, climb_angle, turn_rate, pull_up_rate)
    ]
    try:
        shape = jnp.broadcast_shapes(*(v.shape for v in values))
    except ValueError:
        raise ValueError(
            "airspeed, altitude, climb_angle, turn_rate, pull_up_rate: expected arrays that broadcast "
            f"together, got shapes {[v.shape for v in values]}"
        ) from None
    return TrimCondition(*(jnp.broadcast_to(v, shape) for v in values))


def level_flight(airspeed, altitude=0.0, dtype=None) -> TrimCondition:
    """Steady wings-level flight at ``airspeed`` [ft/s] and ``altitude`` [ft].

    Returns:
      the ``TrimCondition`` for ``trim``.
    """
    return trim_condition(airspeed, altitude, dtype=dtype)


def climb(airspeed, climb_angle, altitude=0.0, dtype=None) -> TrimCondition:
    """A steady climb at ``climb_angle`` [rad] and ``airspeed`` [ft/s].

    Returns:
      the ``TrimCondition`` for ``trim``.
    """
    return trim_condition(airspeed, altitude, climb_angle=climb_angle, dtype=dtype)


def coordinated_turn(
    airspeed, turn_rate, altitude=0.0, climb_angle=0.0, dtype=None
) -> TrimCondition:
    """A steady coordinated turn at ``turn_rate`` [rad/s] and ``airspeed`` [ft/s].

    Returns:
      the ``TrimCondition`` for ``trim``.
    """
    return trim_condition(
        airspeed, altitude, climb_angle=climb_angle, turn_rate=turn_rate, dtype=dtype
    )


def pull_up(airspeed, pull_up_rate, altitude=0.0, climb_angle=0.0, dtype=None) -> TrimCondition:
    """A steady pull-up at ``pull_up_rate`` [rad/s] and ``airspeed`` [ft/s].

    Returns:
      the ``TrimCondition`` for ``trim``.
    """
    return trim_condition(
        airspeed, altitude, climb_angle=climb_angle, pull_up_rate=pull_up_rate, dtype=dtype
    )


def coordinated_bank(alpha: Array, beta: Array, condition: TrimCondition, gravity: Array) -> Array:
    """Bank angle ``phi`` of a coordinated turn (Stevens & Lewis eq. 3.6-5)."""
    G = condition.turn_rate * condition.airspeed / gravity
    tan_alpha = jnp.tan(alpha)
    a = 1.0 - G * tan_alpha * jnp.sin(beta)
    b = jnp.sin(condition.climb_angle) / jnp.cos(beta)
    c = 1.0 + G * G * jnp.cos(beta) ** 2
    root = jnp.sqrt(c * (1.0 - b * b) + G * G * jnp.sin(beta) ** 2)
    num = (a - b * b) + b * tan_alpha * root
    den = a * a - b * b * (1.0 + c * tan_alpha**2)
    return jnp.arctan(G * jnp.cos(beta) / jnp.cos(alpha) * num / den)


def climb_pitch(alpha: Array, beta: Array, phi: Array, climb_angle: Array) -> Array:
    """Pitch angle ``theta`` of the rate-of-climb constraint (Stevens & Lewis eq. 3.6-3)."""
    a = jnp.cos(alpha) * jnp.cos(beta)
    b = jnp.sin(phi) * jnp.sin(beta) + jnp.cos(phi) * jnp.sin(alpha) * jnp.cos(beta)
    sg = jnp.sin(climb_angle)
    return jnp.arctan((a * b + sg * jnp.sqrt(a * a - sg * sg + b * b)) / (a * a - sg * sg))


def trim_point(z: Array, condition: TrimCondition, params: F16Params) -> tuple[Array, Array]:
    """``(x (13,), u (4,))`` of the unknowns ``z = [thtl, el, ail, rdr, alpha, beta]`` under
    the constraints of ``condition`` (module doc)."""
    thtl, alpha, beta = z[0], z[4], z[5]
    phi = coordinated_bank(alpha, beta, condition, params.gravity)
    theta = climb_pitch(alpha, beta, phi, condition.climb_angle)
    psi_dot, theta_dot = condition.turn_rate, condition.pull_up_rate
    p = -psi_dot * jnp.sin(theta)
    q = theta_dot * jnp.cos(phi) + psi_dot * jnp.sin(phi) * jnp.cos(theta)
    r = -theta_dot * jnp.sin(phi) + psi_dot * jnp.cos(phi) * jnp.cos(theta)
    zero = jnp.zeros_like(alpha)
    power = throttle_gearing(thtl, params.engine)
    x = jnp.stack(
        [
            condition.airspeed,
            alpha,
            beta,
            phi,
            theta,
            zero,
            p,
            q,
            r,
            zero,
            zero,
            condition.altitude,
            power,
        ]
    )
    return x, z[:4]


def trim_residual(z: Array, condition: TrimCondition, params: F16Params) -> Array:
    """``[VT', alpha', beta', P', Q', R']`` (6,) at the point of ``z``."""
    x, u = trim_point(z, condition, params)
    return f16_dynamics(x, u, params)[jnp.array([VT, ALPHA, BETA, P, Q, R])]


def initial_guess(condition: TrimCondition, params: F16Params) -> Array:
    """Start from the needed lift: load factor ``n`` (turn, pull-up), ``C_L = n W / (qbar S)``,
    ``alpha = (C_L - 0.1) / 0.063`` deg (CZ table near 0-10 deg) clipped to -5..40; throttle 0.5, surfaces 0."""
    g, vt = params.gravity, condition.airspeed
    G = condition.turn_rate * vt / g
    load = jnp.sqrt(1.0 + G * G) + vt * condition.pull_up_rate / g
    tfac = 1.0 - params.atmosphere.tfac_slope * condition.altitude
    qbar = 0.5 * params.atmosphere.rho0 * tfac**params.atmosphere.exponent * vt * vt
    lift = load * params.mass * g / (qbar * params.area)
    alpha = jnp.radians(jnp.clip((lift - 0.1) / 0.063, -5.0, 40.0))
    zero = jnp.zeros_like(alpha)
    return jnp.stack([zero + 0.5, zero, zero, zero, alpha, zero])


def trim(
    params: F16Params,
    condition: TrimCondition,
    guess: Array | None = None,
    max_steps: int = 200,
    tolerance: float | None = None,
) -> TrimResult:
    """Trim the aircraft at ``condition`` (module doc).

    Args:
      params: the aircraft (``f16_params``).
      condition: a ``TrimCondition`` with scalar leaves (``jax.vmap`` for a stack).
      guess: (6,) starting ``[thtl, el, ail, rdr, alpha, beta]`` (default ``initial_guess``).
      max_steps: most Levenberg-Marquardt iterations.
      tolerance: ``converged`` requires ``max |residual| <=`` this (default
        ``1000 eps g``: 7e-12 in float64, 4e-3 in float32).

    Returns:
      ``TrimResult`` (``psi = pn = pe = 0``, power at its commanded value; ``converged``: finite and
      ``max |residual| <= tolerance``).
    """
    for name, leaf in zip(TrimCondition._fields, condition):
        checks.check_shape(
            f"condition.{name}", leaf, (), "a scalar (vmap over a stack of conditions)"
        )
    dtype = params.mass.dtype
    z0 = initial_guess(condition, params) if guess is None else jnp.asarray(guess, dtype)
    checks.check_shape("guess", z0, (6,), "[thtl, el, ail, rdr, alpha, beta]")
    eps = jnp.finfo(dtype).eps
    tol = 1e3 * eps * params.gravity if tolerance is None else jnp.asarray(tolerance, dtype)
    solution = levenberg_marquardt(
        trim_residual,
        z0,
        (condition, params),
        max_steps=max_steps,
        residual_tol=10.0 * eps * params.gravity,
    )
    x, u = trim_point(solution.x, condition, params)
    inside = jnp.all((u >= params.control_lower) & (u <= params.control_upper))
    ok = jnp.all(jnp.isfinite(solution.residual)) & (jnp.max(jnp.abs(solution.residual)) <= tol)
    return TrimResult(x, u, solution.residual, ok, inside, solution.steps)


@jax.jit
def trim_batch(params: F16Params, conditions: TrimCondition, xcg: Array) -> TrimResult:
    """``trim`` of stacked conditions (leaves (N,)) at ``xcg`` (N,), other parameters shared: one vmapped
    solve (compiled per N).

    Returns:
      the ``TrimResult`` with (N, ...) leaves.
    """
    checks.check_shape(
        "xcg", xcg, checks.shape_of(conditions.airspeed)[:1], "one c.g. per condition"
    )
    return jax.vmap(lambda c, x: trim(params._replace(xcg=x), c))(conditions, xcg)
