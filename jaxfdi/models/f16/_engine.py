"""The F-16's F100 engine model of Stevens & Lewis (2003, sec. 3.4 and ``TGEAR``,
``PDOT``, ``RTAU``, ``THRUST`` of App. A; data after NASA TP-1538).

- Throttle gearing, commanded power ``P_c`` (%) from the throttle ``t`` in [0, 1]:
  ``P_c = 64.94 t`` for ``t <= 0.77``, else ``217.38 t - 117.38`` (afterburner above 50 %).
- Power lag, ``P' = rate (target - P)``: with ``P_c >= 50``: ``P >= 50`` gives ``(5, P_c)``, else
  ``(rtau(60 - P), 60)``; with ``P_c < 50``: ``P >= 50`` gives ``(5, 40)``, else ``(rtau(P_c - P), P_c)``;
  ``rtau(dp)`` = 1 for ``dp <= 25``, 0.1 for ``dp >= 50``, ``1.9 - 0.036 dp`` between (1/s).
- Thrust (lbf), bilinear in Mach and altitude (``tables.lookup2``): below 50 % power
  ``T = T_idle + (T_mil - T_idle) P / 50``, above ``T = T_mil + (T_max - T_mil)(P - 50)/50``.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array

from jaxfdi.models.f16._tables import EngineData, lookup2


def throttle_gearing(throttle: Array, engine: EngineData) -> Array:
    """Commanded power ``P_c`` (%) of the throttle setting (0..1)."""
    return jnp.where(
        throttle <= engine.gear_break,
        engine.gear_low * throttle,
        engine.gear_high * throttle + engine.gear_offset,
    )


def reciprocal_time_constant(dp: Array, engine: EngineData) -> Array:
    """``rtau(dp)`` (1/s) of the power lag."""
    dp_low, r_low, dp_high, r_high, intercept, slope = (engine.rtau[i] for i in range(6))
    return jnp.where(dp <= dp_low, r_low, jnp.where(dp >= dp_high, r_high, intercept + slope * dp))


def power_rate(power: Array, commanded: Array, engine: EngineData) -> Array:
    """``P'`` (%/s) of the actual power ``P`` towards the commanded ``P_c``."""
    lit = power >= engine.afterburner
    want_lit = commanded >= engine.afterburner
    target = jnp.where(
        want_lit,
        jnp.where(lit, commanded, engine.lit_target),
        jnp.where(lit, engine.unlit_target, commanded),
    )
    rate = jnp.where(lit, engine.fast_rate, reciprocal_time_constant(target - power, engine))
    return rate * (target - power)


def thrust(power: Array, altitude: Array, mach: Array, engine: EngineData) -> Array:
    """Installed thrust (lbf) at ``power`` (%), altitude (ft) and Mach."""
    idle = lookup2(mach, engine.mach, altitude, engine.altitude_ft, engine.idle)
    military = lookup2(mach, engine.mach, altitude, engine.altitude_ft, engine.military)
    maximum = lookup2(mach, engine.mach, altitude, engine.altitude_ft, engine.maximum)
    below = idle + (military - idle) * power * 0.02
    above = military + (maximum - military) * (power - 50.0) * 0.02
    return jnp.where(power < 50.0, below, above)
