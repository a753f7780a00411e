"""The 13-state nonlinear F-16 of Stevens & Lewis (2003, *Aircraft Control and Simulation*,
2nd ed., sec. 2.5 and ``SUBROUTINE F`` of App. A): rigid body, flat non-rotating earth,
constant mass; the aircraft of Park, Kim, Park & Roh (2004, eqs. 31-42).

``x = [VT, alpha, beta, phi, theta, psi, P, Q, R, pn, pe, h, pow]`` (ft/s, rad, rad/s, ft, power %),
``u = [thtl, el, ail, rdr]`` (throttle 0..1, surfaces in deg). Body velocities ``U = VT cos(alpha)
cos(beta)``, ``V = VT sin(beta)``, ``W = VT sin(alpha) cos(beta)``::

    U' = R V - Q W - g sin(theta) + (qbar S CX + T) / m
    V' = P W - R U + g cos(theta) sin(phi) + qbar S CY / m
    W' = Q U - P V + g cos(theta) cos(phi) + qbar S CZ / m
    VT' = (U U' + V V' + W W') / VT,  alpha' = (U W' - W U') / (U^2 + W^2),
    beta' = (VT V' - V VT') cos(beta) / (U^2 + W^2)
    P' = (c2 P + c1 R + c4 hx) Q + qbar S b (c3 Cl + c4 Cn)
    Q' = (c5 P - c7 hx) R + c6 (R^2 - P^2) + qbar S cbar c7 Cm
    R' = (c8 P - c2 R + c9 hx) Q + qbar S b (c4 Cl + c9 Cn)

(Stevens & Lewis eq. 2.5-16, engine momentum ``hx`` along body x; ``c1 .. c9`` eq. 2.4-6), Euler kinematics, navigation
(``h' = U sin(theta) - V sin(phi) cos(theta) - W cos(phi) cos(theta)``) and the engine's power lag (``engine``). C.g.
shift (fractions of ``cbar``), both aero models: ``Cm += CZ (xcg_ref - xcg)``, ``Cn -= CY (xcg_ref - xcg) cbar / b``.
``f16_dynamics`` does not clip (trims are found and checked without it; limits: ``saturate``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import checks
from jaxfdi.models.f16._aero import AeroCoefficients, table_coefficients
from jaxfdi.models.f16._atmosphere import air_data
from jaxfdi.models.f16._engine import power_rate, throttle_gearing, thrust
from jaxfdi.models.f16._morelli import (
    MorelliCoefficients,
    morelli_coefficients_data,
    polynomial_coefficients,
)
from jaxfdi.models.f16._tables import (
    AeroTables,
    AtmosphereData,
    EngineData,
    aero_tables,
    atmosphere_data,
    engine_data,
    stevens_lewis_data,
)

#: the 13 states, in order: airspeed, angles of attack and sideslip, Euler angles, body rates,
#: north and east position, altitude, engine power
STATE_NAMES = ("VT", "alpha", "beta", "phi", "theta", "psi", "P", "Q", "R", "pn", "pe", "h", "pow")
#: the 4 controls, in order: throttle, elevator, aileron, rudder
CONTROL_NAMES = ("thtl", "el", "ail", "rdr")
VT, ALPHA, BETA, PHI, THETA, PSI, P, Q, R, PN, PE, H, POW = range(13)
THTL, EL, AIL, RDR = range(4)
RAD_TO_DEG = 180.0 / jnp.pi


class F16Params(NamedTuple):
    """Everything ``f16_dynamics`` needs (a pytree: vmap over any leaf, e.g. ``xcg``).

    Attributes:
      aero: the aerodynamic model (its type selects it)
      engine: the F100 thrust tables and power lag
      atmosphere: the air data computer's constants
      mass: () slug, aircraft mass
      inertia: (4,) Jxx, Jyy, Jzz, Jxz, slug ft^2
      area: () S, ft^2
      span: () b, ft
      chord: () cbar, ft
      xcg_ref: () reference c.g. position, fraction of cbar
      xcg: () c.g. position, fraction of cbar
      engine_momentum: () hx, slug ft^2/s
      gravity: () acceleration of gravity, ft/s^2
      control_lower: (4,) lower control limits: thtl, el, ail, rdr
      control_upper: (4,) upper control limits: thtl, el, ail, rdr
    """

    aero: AeroTables | MorelliCoefficients
    engine: EngineData
    atmosphere: AtmosphereData
    mass: Array
    inertia: Array
    area: Array
    span: Array
    chord: Array
    xcg_ref: Array
    xcg: Array
    engine_momentum: Array
    gravity: Array
    control_lower: Array
    control_upper: Array


def f16_params(
    aero: str = "tables",
    profile: str = "stevens_lewis_2nd_ed",
    xcg: float = 0.35,
    mass: float | None = None,
    jxz: float | None = None,
    aileron_limit: float | None = None,
    dtype=None,
) -> F16Params:
    """The Stevens & Lewis F-16 (``f16_stevens_lewis.json``).

    Args:
      aero: ``"tables"`` (the book's, ``aero.py``) or ``"morelli"`` (Morelli's 1998 polynomial).
      profile: table version for ``aero="tables"`` and thrust (``tables.PROFILES``); default the
        2nd-edition tables, with which trim tables 3.6-2 and 3.6-3 were computed.
      xcg: centre of gravity, fraction of the mean chord (the book: 0.35; 0.30, 0.38).
      mass: slug (default 636.94 = 20 490.4 lbf / 32.17, the data file's).
      jxz: product of inertia ``Jxz`` (default 982 slug ft^2).
      aileron_limit: degrees (default the book's 21.5; Morelli clips at 20).
      dtype: float dtype of every leaf (default: JAX's default float).

    Returns:
      ``F16Params`` (every leaf in ``dtype``): ``aero`` an ``AeroTables`` or ``MorelliCoefficients``;
      control limits with aileron ``+-aileron_limit`` deg.
    """
    if aero not in ("tables", "morelli"):
        raise ValueError(f"aero: expected 'tables' or 'morelli', got {aero!r}")
    if mass is not None:
        checks.check_positive("mass", mass, "a positive mass [slug]")
    checks.check_scalar(
        "xcg", xcg, 0.0, 1.0, meaning="a centre of gravity in [0, 1] of the mean chord"
    )
    if aileron_limit is not None:
        checks.check_scalar(
            "aileron_limit",
            aileron_limit,
            0.0,
            90.0,
            low_open=True,
            meaning="an aileron deflection limit in (0, 90] degrees",
        )
    if jxz is not None:
        checks.check_scalar("jxz", jxz, meaning="a finite product of inertia [slug ft^2]")
    dtype = dtype or jnp.result_type(float)
    data = stevens_lewis_data()
    mg, lim = data["mass_geometry"], data["limits"]
    if (
        jxz is not None and checks.concrete(jxz) is not None
    ):  # positive definite: Jxx Jzz - Jxz^2 > 0
        bound = (mg["Jxx_slug_ft2"] * mg["Jzz_slug_ft2"]) ** 0.5
        if not abs(float(checks.concrete(jxz))) < bound:
            raise ValueError(
                f"jxz: expected |Jxz| < sqrt(Jxx Jzz) = {bound:.6g} slug ft^2 (a positive definite "
                f"inertia tensor), got {checks.received(jxz)}"
            )
    a = lambda v: jnp.asarray(v, dtype)
    model = aero_tables(profile, dtype) if aero == "tables" else morelli_coefficients_data(dtype)
    ail = lim["aileron_deg"][1] if aileron_limit is None else aileron_limit
    lower = [lim["throttle"][0], lim["elevator_deg"][0], -ail, lim["rudder_deg"][0]]
    upper = [lim["throttle"][1], lim["elevator_deg"][1], ail, lim["rudder_deg"][1]]
    inertia = [
        mg["Jxx_slug_ft2"],
        mg["Jyy_slug_ft2"],
        mg["Jzz_slug_ft2"],
        mg["Jxz_slug_ft2"] if jxz is None else jxz,
    ]
    return F16Params(
        model,
        engine_data(profile, dtype),
        atmosphere_data(dtype),
        a(mg["mass_slug"]["value"] if mass is None else mass),
        a(inertia),
        a(mg["S_ft2"]),
        a(mg["b_ft"]),
        a(mg["cbar_ft"]),
        a(mg["xcg_ref_frac_cbar"]),
        a(xcg),
        a(mg["hx_engine_angular_momentum_slug_ft2_s"]["value"]),
        a(mg["g0_ft_s2"]["value"]),
        a(lower),
        a(upper),
    )


def inertia_constants(inertia: Array) -> tuple[Array, ...]:
    """``c1 .. c9`` of Stevens & Lewis eq. 2.4-6 from ``(Jxx, Jyy, Jzz, Jxz)``."""
    jxx, jyy, jzz, jxz = (inertia[i] for i in range(4))
    gam = jxx * jzz - jxz * jxz
    return (
        ((jyy - jzz) * jzz - jxz * jxz) / gam,
        (jxx - jyy + jzz) * jxz / gam,
        jzz / gam,
        jxz / gam,
        (jzz - jxx) / jyy,
        jxz / jyy,
        1.0 / jyy,
        (jxx * (jxx - jyy) + jxz * jxz) / gam,
        jxx / gam,
    )


def aero_coefficients(
    params: F16Params, x: Array, u: Array, gust: Array | None = None
) -> AeroCoefficients:
    """Total coefficients at ``params.xcg`` (model by ``params.aero``'s type, plus the c.g. shift);
    ``gust`` (2,): alpha and beta increments (rad) seen by the aerodynamics only."""
    alpha, beta = x[ALPHA], x[BETA]
    if gust is not None:
        alpha, beta = alpha + gust[0], beta + gust[1]
    args = (
        alpha * RAD_TO_DEG,
        beta * RAD_TO_DEG,
        u[EL],
        u[AIL],
        u[RDR],
        x[P],
        x[Q],
        x[R],
        x[VT],
        params.span,
        params.chord,
    )
    if isinstance(params.aero, MorelliCoefficients):
        c = polynomial_coefficients(params.aero, *args)
    else:
        c = table_coefficients(params.aero, *args)
    shift = params.xcg_ref - params.xcg
    return c._replace(Cm=c.Cm + c.CZ * shift, Cn=c.Cn - c.CY * shift * params.chord / params.span)


def moment_equations(
    p: Array, q: Array, r: Array, c: AeroCoefficients, qs: Array, params: F16Params
) -> tuple[Array, Array, Array]:
    """``(P', Q', R')`` (Park et al. 2004, eqs. 34-36; Stevens & Lewis eq. 2.5-16 with ``hx``) from the
    coefficients ``c`` and ``qs = qbar S``; shared with ``models.f16.rates`` (the UKF's model)."""
    c1, c2, c3, c4, c5, c6, c7, c8, c9 = inertia_constants(params.inertia)
    hx = params.engine_momentum
    qsb = qs * params.span
    p_dot = (c2 * p + c1 * r + c4 * hx) * q + qsb * (c3 * c.Cl + c4 * c.Cn)
    q_dot = (c5 * p - c7 * hx) * r + c6 * (r * r - p * p) + qs * params.chord * c7 * c.Cm
    r_dot = (c8 * p - c2 * r + c9 * hx) * q + qsb * (c4 * c.Cl + c9 * c.Cn)
    return p_dot, q_dot, r_dot


def f16_dynamics(x: Array, u: Array, params: F16Params, gust: Array | None = None) -> Array:
    """``x'`` (13,) of the state ``x`` (13,) under the controls ``u`` (4,) (module doc).

    ``gust``: optional (2,) alpha and beta increments (rad), seen by the aerodynamics only.

    Returns:
      (13,) ``x'``: ``VT'`` [ft/s^2], angle rates [rad/s], ``P'``, ``Q'``, ``R'`` [rad/s^2], ``pn'``,
      ``pe'``, ``h'`` [ft/s] (north, east, up), ``pow'`` [%/s]; controls not clipped (``saturate``).
    """
    checks.check_real("x", x, "a real state")
    checks.check_real("u", u, "real controls")
    checks.check_shape("x", x, (13,), "[VT, alpha, beta, phi, theta, psi, P, Q, R, pn, pe, h, pow]")
    checks.check_shape("u", u, (4,), "[thtl, el, ail, rdr]")
    if gust is not None:
        checks.check_shape("gust", gust, (2,), "angle-of-attack and sideslip increments, rad")
    vt, alpha, beta, phi, theta, psi, p, q, r = (x[i] for i in range(9))
    altitude, power = x[H], x[POW]
    air = air_data(vt, altitude, params.atmosphere)
    power_dot = power_rate(power, throttle_gearing(u[THTL], params.engine), params.engine)
    engine_thrust = thrust(power, altitude, air.mach, params.engine)
    c = aero_coefficients(params, x, u, gust)

    cos_beta = jnp.cos(beta)
    u_b = vt * jnp.cos(alpha) * cos_beta
    v_b = vt * jnp.sin(beta)
    w_b = vt * jnp.sin(alpha) * cos_beta
    sth, cth = jnp.sin(theta), jnp.cos(theta)
    sph, cph = jnp.sin(phi), jnp.cos(phi)
    spsi, cpsi = jnp.sin(psi), jnp.cos(psi)
    qs = air.dynamic_pressure * params.area
    g, inv_mass = params.gravity, 1.0 / params.mass

    u_dot = r * v_b - q * w_b - g * sth + inv_mass * (qs * c.CX + engine_thrust)
    v_dot = p * w_b - r * u_b + g * cth * sph + inv_mass * qs * c.CY
    w_dot = q * u_b - p * v_b + g * cth * cph + inv_mass * qs * c.CZ
    uw2 = u_b * u_b + w_b * w_b
    vt_dot = (u_b * u_dot + v_b * v_dot + w_b * w_dot) / vt
    alpha_dot = (u_b * w_dot - w_b * u_dot) / uw2
    beta_dot = (vt * v_dot - v_b * vt_dot) * cos_beta / uw2

    phi_dot = p + (sth / cth) * (q * sph + r * cph)
    theta_dot = q * cph - r * sph
    psi_dot = (q * sph + r * cph) / cth

    p_dot, q_dot, r_dot = moment_equations(p, q, r, c, qs, params)

    # navigation: body velocities rotated to north-east-up (Stevens & Lewis eq. 2.5-18)
    north = (
        u_b * cth * cpsi
        + v_b * (sph * sth * cpsi - cph * spsi)
        + w_b * (cph * sth * cpsi + sph * spsi)
    )
    east = (
        u_b * cth * spsi
        + v_b * (sph * sth * spsi + cph * cpsi)
        + w_b * (cph * sth * spsi - sph * cpsi)
    )
    up = u_b * sth - v_b * sph * cth - w_b * cph * cth
    return jnp.stack(
        [
            vt_dot,
            alpha_dot,
            beta_dot,
            phi_dot,
            theta_dot,
            psi_dot,
            p_dot,
            q_dot,
            r_dot,
            north,
            east,
            up,
            power_dot,
        ]
    )


def saturate(u: Array, params: F16Params) -> Array:
    """``u`` clipped to the control limits (throttle 0..1, el +-25, ail +-21.5, rdr +-30 deg)."""
    shape = checks.shape_of(u)
    if not shape or shape[-1] != 4:
        raise ValueError(
            f"u: expected controls [thtl, el, ail, rdr] along the last axis, shape (..., 4), got "
            f"{shape}"
        )
    return jnp.clip(u, params.control_lower, params.control_upper)
