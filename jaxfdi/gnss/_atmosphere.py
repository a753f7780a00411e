"""Broadcast atmospheric delays of a pseudorange (JAX): Klobuchar ionosphere and
Saastamoinen troposphere, with the error variances single-point positioning weights by.

Ionosphere (Klobuchar 1987; IS-GPS-200 20.3.3.5.2.5), semicircles, ``E`` elevation: Earth-central angle
``psi = 0.0137 / (E + 0.11) - 0.022``; pierce point ``phi_i = phi_u + psi cos A`` (clipped to +/-0.416),
``lambda_i = lambda_u + psi sin A / cos(phi_i)``; geomagnetic ``phi_m = phi_i + 0.064 cos(lambda_i - 1.617)``;
local time ``t = 43200 lambda_i + t_GPS`` (mod 1 day); obliquity ``F = 1 + 16 (0.53 - E)^3``;
``AMP = max(sum alpha_n phi_m^n, 0)``, ``PER = max(sum beta_n phi_m^n, 72000)``, ``x = 2 pi (t - 50400) / PER``;
L1 delay ``c F (5e-9 + AMP (1 - x^2/2 + x^4/24))`` for ``|x| < 1.57``, else ``c F 5e-9``.

Troposphere (Saastamoinen 1972, standard atmosphere at ellipsoidal height ``h`` [m], humidity 0.7, as
RTKLIB): ``p = 1013.25 (1 - 2.2557e-5 h)^5.2568`` hPa, ``T = 288.16 - 6.5e-3 h`` K,
``e = 6.108 rh exp((17.15 T - 4684) / (T - 38.45))`` hPa, zenith angle ``z``:
``0.0022768 p / ((1 - 0.00266 cos 2 phi - 0.00028 h / 1000) cos z) + 0.002277 (1255 / T + 0.05) e / cos z``.

Error variances (RTKLIB manual, Takasu 2013, E.6): ``(0.5 I)^2`` (ionosphere ``I``), ``(0.3 / (sin E + 0.1))^2``. Both
delays are zero below the horizon and for a receiver > 1 km below the ellipsoid (troposphere: outside
-100 m to 10 km), so an iteration from the Earth's centre sees none.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi.gnss._frames import ecef_to_geodetic
from jaxfdi.gnss._orbits import SPEED_OF_LIGHT

#: RTKLIB's default broadcast ionosphere (2004-01-01), used when a file gives none
DEFAULT_ION_ALPHA = (0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06)
DEFAULT_ION_BETA = (0.1167e06, -0.2294e06, -0.1311e06, 0.1049e07)
#: relative humidity of the Saastamoinen standard atmosphere
HUMIDITY = 0.7
#: the error model: broadcast ionosphere error factor, Saastamoinen error [m]
IONOSPHERE_ERROR_FACTOR = 0.5
TROPOSPHERE_ERROR = 0.3


class Atmosphere(NamedTuple):
    """The broadcast ionosphere of a navigation file (a pytree).

    Attributes:
      ion_alpha: (4,) Klobuchar amplitude coefficients [s, s/semicircle, s/semicircle^2, s/semicircle^3]
      ion_beta: (4,) Klobuchar period coefficients [s, s/semicircle, s/semicircle^2, s/semicircle^3]
    """

    ion_alpha: Array
    ion_beta: Array


def broadcast_atmosphere(ion_alpha=None, ion_beta=None) -> Atmosphere:
    """The ``Atmosphere`` of a navigation file's ``ION ALPHA``/``ION BETA`` (``Ephemerides.ion_alpha``,
    ``ion_beta``); RTKLIB's defaults where they are missing (NaN or ``None``).

    Returns:
      ``Atmosphere`` with (4,) float arrays.
    """
    alpha = np.asarray(DEFAULT_ION_ALPHA if ion_alpha is None else ion_alpha, float)
    beta = np.asarray(DEFAULT_ION_BETA if ion_beta is None else ion_beta, float)
    for name, value in (("ion_alpha", alpha), ("ion_beta", beta)):
        if value.shape != (4,):
            raise ValueError(
                f"{name}: expected the 4 Klobuchar coefficients of a navigation header, got shape "
                f"{value.shape}"
            )
    if not (np.all(np.isfinite(alpha)) and np.all(np.isfinite(beta))):
        alpha, beta = np.asarray(DEFAULT_ION_ALPHA), np.asarray(DEFAULT_ION_BETA)
    return Atmosphere(jnp.asarray(alpha), jnp.asarray(beta))


def klobuchar_delay(
    ion_alpha: Array,
    ion_beta: Array,
    latitude: Array,
    longitude: Array,
    height: Array,
    elevation: Array,
    azimuth: Array,
    time_of_week: Array,
) -> Array:
    """L1 ionospheric delay of the broadcast model (module docstring).

    Returns:
      Delay [m], the broadcast shape of the inputs (angles in rad); 0 below the horizon or
      for a receiver more than 1 km below the ellipsoid.
    """
    e = elevation / jnp.pi
    psi = 0.0137 / (e + 0.11) - 0.022
    phi = jnp.clip(latitude / jnp.pi + psi * jnp.cos(azimuth), -0.416, 0.416)
    lam = longitude / jnp.pi + psi * jnp.sin(azimuth) / jnp.cos(phi * jnp.pi)
    phi = phi + 0.064 * jnp.cos((lam - 1.617) * jnp.pi)
    local = jnp.mod(43200.0 * lam + time_of_week, 86400.0)
    obliquity = 1.0 + 16.0 * (0.53 - e) ** 3
    a, b = jnp.asarray(ion_alpha), jnp.asarray(ion_beta)
    amplitude = jnp.maximum(a[0] + phi * (a[1] + phi * (a[2] + phi * a[3])), 0.0)
    period = jnp.maximum(b[0] + phi * (b[1] + phi * (b[2] + phi * b[3])), 72000.0)
    x = 2.0 * jnp.pi * (local - 50400.0) / period
    day = 5e-9 + amplitude * (1.0 + x * x * (-0.5 + x * x / 24.0))
    delay = SPEED_OF_LIGHT * obliquity * jnp.where(jnp.abs(x) < 1.57, day, 5e-9)
    return jnp.where((height < -1e3) | (elevation <= 0.0), 0.0, delay)


def saastamoinen_delay(
    latitude: Array, height: Array, elevation: Array, humidity: float = HUMIDITY
) -> Array:
    """Tropospheric delay of the Saastamoinen model in the standard atmosphere (module docstring).

    Returns:
      Delay [m], the broadcast shape of the inputs; 0 below the horizon or for a height outside -100 m to 10 km.
    """
    h = jnp.maximum(height, 0.0)
    pressure = 1013.25 * (1.0 - 2.2557e-5 * h) ** 5.2568
    temperature = 15.0 - 6.5e-3 * h + 273.16
    vapour = 6.108 * humidity * jnp.exp((17.15 * temperature - 4684.0) / (temperature - 38.45))
    cos_z = jnp.sin(elevation)  # cos of the zenith angle
    hydrostatic = (
        0.0022768 * pressure / (1.0 - 0.00266 * jnp.cos(2.0 * latitude) - 0.00028 * h / 1e3) / cos_z
    )
    wet = 0.002277 * (1255.0 / temperature + 0.05) * vapour / cos_z
    outside = (height < -100.0) | (height > 1e4) | (elevation <= 0.0)
    return jnp.where(outside, 0.0, hydrostatic + wet)


def atmosphere_corrections(
    atmosphere: Atmosphere, time: Array, receiver_ecef: Array, elevation: Array, azimuth: Array
) -> tuple[Array, Array]:
    """Delays and model error variances for satellites at ``elevation``/``azimuth`` (S,) [rad] from
    ``receiver_ecef`` (3,) at GPS ``time`` [s from any week's start: read modulo a day].

    Returns:
      ``(delay, variance)``, (S,) each: Klobuchar + Saastamoinen [m], their variances [m^2] (module doc).
    """
    lat, lon, height = ecef_to_geodetic(receiver_ecef)
    ionosphere = klobuchar_delay(
        atmosphere.ion_alpha, atmosphere.ion_beta, lat, lon, height, elevation, azimuth, time
    )
    troposphere = saastamoinen_delay(lat, height, elevation)
    variance = (IONOSPHERE_ERROR_FACTOR * ionosphere) ** 2 + (
        TROPOSPHERE_ERROR / (jnp.sin(jnp.maximum(elevation, 0.0)) + 0.1)
    ) ** 2
    return ionosphere + troposphere, variance
