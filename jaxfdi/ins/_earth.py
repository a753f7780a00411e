"""The Earth an INS navigates on: WGS-84 radii of curvature, normal gravity, Earth and
transport rates in local North-East-Down axes.

Ellipsoid constants from ``jaxfdi.gnss._frames`` (NIMA TR8350.2, 2000), Earth rate from ``jaxfdi.gnss._orbits``
(IS-GPS-200). Latitude ``L`` and longitude in rad, height ``h`` ellipsoidal [m]; scalar functions (``vmap`` for
batches).

- Radii (Groves 2013, eqs. 2.105-2.106): ``R_N = a (1 - e^2) / (1 - e^2 sin^2 L)^(3/2)``,
  ``R_E = a / sqrt(1 - e^2 sin^2 L)``.
- Normal gravity (Somigliana; NIMA TR8350.2 eq. 4-1): ``g0(L) = g_e (1 + k sin^2 L) / sqrt(1 - e^2 sin^2 L)``,
  ``g_e = 9.7803253359``, ``k = 0.00193185265241``; above it (Groves 2013, eq. 2.139):
  ``g_D = g0(L) [1 - 2 (1 + f (1 - 2 sin^2 L) + w^2 a^2 b / mu) h / a + 3 h^2 / a^2]``, ``g_N = -8.08e-9 h sin 2L``
  [m/s^2], ``g_E = 0`` (gravitation + centrifugal: what the velocity equation adds to the specific force).
- ``w_ie^n = W [cos L, 0, -sin L]``; ``w_en^n = [v_E / (R_E + h), -v_N / (R_N + h), -v_E tan L / (R_E + h)]``
  (Groves 2013, eqs. 2.123, 5.44; Titterton & Weston 2004, sec. 3.5).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi.gnss import OMEGA_E, WGS84_A, WGS84_B, WGS84_E2, WGS84_F

#: WGS-84 gravitational constant (with the atmosphere) [m^3/s^2] and normal gravity
#: at the equator and pole [m/s^2] (NIMA TR8350.2, Tables 3.1 and 3.4)
WGS84_MU = 3.986004418e14
GRAVITY_EQUATOR = 9.7803253359
GRAVITY_POLE = 9.8321849378
SOMIGLIANA_K = 0.00193185265241


class LocalEarth(NamedTuple):
    """What the navigation equations need at one point (``local_earth``).

    Attributes:
      sin_lat: sine of the latitude
      cos_lat: cosine of the latitude
      meridian_radius: R_N [m]
      transverse_radius: R_E [m]
      gravity: (3,) g^n [m/s^2], NED
      earth_rate: (3,) w_ie^n [rad/s]
    """

    sin_lat: Array
    cos_lat: Array
    meridian_radius: Array
    transverse_radius: Array
    gravity: Array
    earth_rate: Array


def _inverse_w(sin_lat: Array) -> Array:
    """``1 / sqrt(1 - e^2 sin^2 L)``, shared by both radii and Somigliana's formula."""
    return jax.lax.rsqrt(1.0 - WGS84_E2 * sin_lat**2)


def radii_of_curvature(sin_lat: Array) -> tuple[Array, Array]:
    """``(R_N, R_E)`` [m] at a latitude given by its sine."""
    inverse_w = _inverse_w(sin_lat)
    transverse = WGS84_A * inverse_w
    return transverse * (1.0 - WGS84_E2) * inverse_w**2, transverse


def surface_gravity(sin_lat: Array, inverse_w: Array | None = None) -> Array:
    """Somigliana's normal gravity on the ellipsoid [m/s^2]."""
    inverse_w = _inverse_w(sin_lat) if inverse_w is None else inverse_w
    return GRAVITY_EQUATOR * (1.0 + SOMIGLIANA_K * sin_lat**2) * inverse_w


def gravity_ned(
    sin_lat: Array, cos_lat: Array, height: Array, inverse_w: Array | None = None
) -> Array:
    """(3,) gravity ``g^n`` [m/s^2] at a latitude (its sine and cosine) and height [m]."""
    s2 = sin_lat**2
    m = OMEGA_E**2 * WGS84_A**2 * WGS84_B / WGS84_MU
    down = surface_gravity(sin_lat, inverse_w) * (
        1.0
        - 2.0 / WGS84_A * (1.0 + WGS84_F * (1.0 - 2.0 * s2) + m) * height
        + 3.0 * height**2 / WGS84_A**2
    )
    north = -8.08e-9 * height * 2.0 * sin_lat * cos_lat
    return jnp.stack([north, jnp.zeros_like(down), down])


def earth_rate_ned(sin_lat: Array, cos_lat: Array) -> Array:
    """(3,) ``w_ie^n`` [rad/s]."""
    return OMEGA_E * jnp.stack([cos_lat, jnp.zeros_like(cos_lat), -sin_lat])


def transport_rate(velocity: Array, height: Array, earth: LocalEarth) -> Array:
    """(3,) ``w_en^n`` [rad/s] of a NED velocity [m/s] at ``height``."""
    east_radius = earth.transverse_radius + height
    return jnp.stack(
        [
            velocity[1] / east_radius,
            -velocity[0] / (earth.meridian_radius + height),
            -velocity[1] * earth.sin_lat / (earth.cos_lat * east_radius),
        ]
    )


def local_earth(position: Array) -> LocalEarth:
    """The ``LocalEarth`` at ``position = [lat, lon, h]``."""
    sin_lat, cos_lat = jnp.sin(position[0]), jnp.cos(position[0])
    inverse_w = _inverse_w(sin_lat)
    transverse = WGS84_A * inverse_w
    meridian = transverse * (1.0 - WGS84_E2) * inverse_w**2
    return LocalEarth(
        sin_lat,
        cos_lat,
        meridian,
        transverse,
        gravity_ned(sin_lat, cos_lat, position[2], inverse_w),
        earth_rate_ned(sin_lat, cos_lat),
    )
