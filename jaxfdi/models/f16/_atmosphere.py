"""The Stevens & Lewis air data computer (Stevens & Lewis 2003, sec. 2.3 and
``SUBROUTINE ADC`` of App. A): a troposphere with a linear temperature lapse and an
isothermal layer above 35 000 ft::

    tfac = 1 - 7.03e-6 h,   T = 519 tfac  (h < 35 000 ft)  else 390 deg R,
    rho = 2.377e-3 tfac^4.14,   Mach = V / sqrt(1.4 * 1716.3 * T),   qbar = rho V^2 / 2.

(The book uses ``tfac`` in the density at every altitude, as coded here.)
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi.models.f16._tables import AtmosphereData


class AirData(NamedTuple):
    """Air data: Mach number, dynamic pressure, density and temperature.

    Attributes:
      mach: () Mach number
      dynamic_pressure: () lbf/ft^2
      density: () slug/ft^3
      temperature: () deg R
    """

    mach: Array
    dynamic_pressure: Array
    density: Array
    temperature: Array


def air_data(vt: Array, altitude: Array, atm: AtmosphereData) -> AirData:
    """Mach number, dynamic pressure, density and temperature at true airspeed ``vt`` (ft/s) and altitude (ft)."""
    tfac = 1.0 - atm.tfac_slope * altitude
    temperature = jnp.where(altitude >= atm.strat_alt, atm.T_strat, atm.T0 * tfac)
    density = atm.rho0 * tfac**atm.exponent
    mach = vt / jnp.sqrt(atm.gamma * atm.gas_constant * temperature)
    return AirData(mach, 0.5 * density * vt * vt, density, temperature)
