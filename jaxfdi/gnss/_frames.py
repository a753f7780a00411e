"""WGS-84 frames: ECEF <-> geodetic, local NED, elevation and azimuth (JAX).

WGS-84 (NIMA TR8350.2, 2000): ``a = 6378137 m``, ``1/f = 298.257223563``. Geodetic -> ECEF:
``x = (N + h) cos(lat) cos(lon)``, ..., ``N = a / sqrt(1 - e^2 sin^2 lat)``; ECEF -> geodetic: a fixed 5
iterations of Bowring's (1976) latitude update (sub-mm after 3 near the Earth; jits and vmaps). Local
frame NED at the geodetic point (Misra & Enge 2011, sec. 4.2); azimuth clockwise from north.

Angles are radians; every function takes leading batch axes (``...``).
"""

from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks

#: WGS-84 semi-major axis [m] and flattening
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_B = WGS84_A * (1.0 - WGS84_F)


def geodetic_to_ecef(lat: Array, lon: Array, height: Array) -> Array:
    """ECEF coordinates of geodetic latitude, longitude [rad] and ellipsoidal height [m]
    (WGS-84, closed form); the three broadcast together.

    Returns:
      (..., 3) ECEF ``[x, y, z]`` [m], ``...`` the broadcast shape of the inputs.
    """
    checks.check_angle("lat", lat, -math.pi / 2, math.pi / 2, "a geodetic latitude")
    checks.check_angle("lon", lon, -2 * math.pi, 2 * math.pi, "a longitude")
    lat, lon, height = jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(height)
    try:
        jnp.broadcast_shapes(lat.shape, lon.shape, height.shape)
    except ValueError:
        raise ValueError(
            f"lat, lon, height: expected arrays that broadcast together, got shapes {lat.shape}, "
            f"{lon.shape}, {height.shape}"
        ) from None
    return _geodetic_to_ecef(lat, lon, height)


@jax.jit
def _geodetic_to_ecef(lat: Array, lon: Array, height: Array) -> Array:
    """``geodetic_to_ecef`` after the checks, one program (compiled once per shape; likewise the other
    ``_`` programs here)."""
    sin_lat = jnp.sin(lat)
    radius = WGS84_A / jnp.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    return jnp.stack(
        [
            (radius + height) * jnp.cos(lat) * jnp.cos(lon),
            (radius + height) * jnp.cos(lat) * jnp.sin(lon),
            (radius * (1.0 - WGS84_E2) + height) * sin_lat,
        ],
        axis=-1,
    )


def ecef_to_geodetic(ecef: Array, iterations: int = 5) -> tuple[Array, Array, Array]:
    """Geodetic coordinates of (..., 3) ECEF points [m] (``iterations`` Bowring updates); valid for
    ``|r| > 100 km``; height in a form well conditioned at every latitude.

    Returns:
      ``(lat, lon, height)`` [rad, rad, m], each of shape (...): geodetic latitude,
      longitude in [-pi, pi] and height above the WGS-84 ellipsoid.
    """
    _check_points("ecef", ecef)
    return _ecef_to_geodetic(jnp.asarray(ecef), int(iterations))


@partial(jax.jit, static_argnums=1)
def _ecef_to_geodetic(ecef: Array, iterations: int) -> tuple[Array, Array, Array]:
    x, y, z = ecef[..., 0], ecef[..., 1], ecef[..., 2]
    p = jnp.hypot(x, y)
    lon = jnp.arctan2(y, x)
    ep2 = WGS84_E2 / (1.0 - WGS84_E2)
    beta = jnp.arctan2(z, (1.0 - WGS84_F) * p)  # parametric latitude, first guess
    lat = beta
    for _ in range(iterations):
        lat = jnp.arctan2(
            z + ep2 * WGS84_B * jnp.sin(beta) ** 3, p - WGS84_E2 * WGS84_A * jnp.cos(beta) ** 3
        )
        beta = jnp.arctan2((1.0 - WGS84_F) * jnp.sin(lat), jnp.cos(lat))
    sin_lat, cos_lat = jnp.sin(lat), jnp.cos(lat)
    radius = WGS84_A / jnp.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    height = p * cos_lat + z * sin_lat - radius * (1.0 - WGS84_E2 * sin_lat**2)
    return lat, lon, height


def _check_points(name: str, points) -> None:
    """(..., 3) coordinates (trace time): another last axis would be read out of bounds silently (clamped)."""
    shape = checks.shape_of(points)
    if not shape or shape[-1] != 3:
        raise ValueError(f"{name}: expected points of shape (..., 3) [m], got {shape}")


def ned_rotation(lat: Array, lon: Array) -> Array:
    """(..., 3, 3) ``C_e^n``: rows are the North, East and Down unit vectors in ECEF."""
    lat, lon = jnp.asarray(lat), jnp.asarray(lon)
    sl, cl, so, co = jnp.sin(lat), jnp.cos(lat), jnp.sin(lon), jnp.cos(lon)
    zero = jnp.zeros_like(sl * so)
    north = jnp.stack([-sl * co, -sl * so, cl + zero], axis=-1)
    east = jnp.stack([-so + zero, co + zero, zero], axis=-1)
    down = jnp.stack([-cl * co, -cl * so, -sl + zero], axis=-1)
    return jnp.stack([north, east, down], axis=-2)


def ecef_to_ned(ecef: Array, origin_ecef: Array) -> Array:
    """(..., 3) NED [m] of ECEF points relative to ``origin_ecef``: ``R (x - x0)`` with
    ``R = ned_rotation`` at the origin.

    Returns:
      (..., 3) north, east, down offsets [m] in the origin's local level frame (WGS-84 geodetic latitude), the
      broadcast shape of ``ecef`` and ``origin_ecef``.
    """
    return _local_frame("ecef", ecef, origin_ecef)


def ned_to_ecef(ned: Array, origin_ecef: Array) -> Array:
    """(..., 3) ECEF of NED offsets [m] from ``origin_ecef``: ``x0 + R^T n`` (inverse of ``ecef_to_ned``)."""
    return _local_frame("ned", ned, origin_ecef)


def _local_frame(given: str, points: Array, origin_ecef: Array) -> Array:
    _check_points(given, points)
    _check_points("origin_ecef", origin_ecef)
    return _rotate(given, jnp.asarray(points), jnp.asarray(origin_ecef))


@partial(jax.jit, static_argnums=0)
def _rotate(given: str, points: Array, origin_ecef: Array) -> Array:
    rotation = ned_rotation(*ecef_to_geodetic(origin_ecef)[:2])
    if given == "ecef":
        return jnp.einsum("...ij,...j->...i", rotation, points - origin_ecef)
    return origin_ecef + jnp.einsum("...ji,...j->...i", rotation, points)


def line_of_sight_ned(receiver_ecef: Array, satellite_ecef: Array) -> Array:
    """(..., 3) unit vector from the receiver to the satellite in the receiver's NED axes."""
    _check_points("receiver_ecef", receiver_ecef)
    _check_points("satellite_ecef", satellite_ecef)
    lat, lon, _ = ecef_to_geodetic(receiver_ecef)
    delta = jnp.asarray(satellite_ecef) - jnp.asarray(receiver_ecef)
    ned = jnp.einsum("...ij,...j->...i", ned_rotation(lat, lon), delta)
    return ned / jnp.linalg.norm(ned, axis=-1, keepdims=True)


def elevation_azimuth(receiver_ecef: Array, satellite_ecef: Array) -> tuple[Array, Array]:
    """``(elevation, azimuth)`` [rad] of satellites seen from a receiver; azimuth in
    [0, 2 pi) clockwise from north. Broadcasts ``receiver_ecef`` (..., 3) against
    ``satellite_ecef`` (..., S, 3) when given as ``receiver_ecef[..., None, :]``."""
    los = line_of_sight_ned(receiver_ecef, satellite_ecef)
    elevation = jnp.arcsin(jnp.clip(-los[..., 2], -1.0, 1.0))
    azimuth = jnp.mod(jnp.arctan2(los[..., 1], los[..., 0]), 2.0 * jnp.pi)
    return elevation, azimuth
