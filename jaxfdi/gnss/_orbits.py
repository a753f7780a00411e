"""GPS satellite positions and clocks from broadcast ephemerides and almanacs (JAX).

Positions: IS-GPS-200 (rev. N, 2022) Table 20-IV: ``n = sqrt(mu / A^3) + delta n``; ``M = M0 + n t_k``; Kepler
``M = E - e sin E`` by a fixed count of Newton iterations from ``E = M`` (vmaps); ``Phi = nu + omega``; harmonic
corrections ``du, dr, di`` from ``2 Phi``, applied by angle addition (two ``sin``/``cos`` pairs and the node's per
satellite); ``Omega = Omega0 + (Omega_dot - Omega_e) t_k - Omega_e t_oe``; rotation to ECEF. Almanac (Table 20-VI; YUMA
gives the full inclination): the same with no harmonics, ``delta n = IDOT = 0``, ``t_oa`` for ``t_oe``.

Clock (20.3.3.3.3.1-2): ``dt_sv = af0 + af1 (t - t_oc) + af2 (t - t_oc)^2 + F e sqrt(A) sin E``,
``F = -2 sqrt(mu) / c^2``, less ``T_GD`` for an L1-only user; almanac ``af0 + af1 t_k`` (20.3.3.5.2.3, no
relativistic term, as RTKLIB's ``alm2pos``). Time differences wrapped into +/- half a week.

``t``: GPS seconds from the start of a caller-chosen *reference week* (float64 keeps sub-microsecond resolution).
``Orbit``: one element set per slot (leaves (S,)); ``OrbitTable``: every record (leaves (S, R), padded);
``select_orbits`` picks each slot's nearest valid record (RTKLIB's rule), so one compiled function serves a whole day.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.gnss._frames import WGS84_A
from jaxfdi.gnss._rinex import SECONDS_PER_WEEK, Ephemerides
from jaxfdi.gnss._yuma import Almanac

#: WGS-84 / IS-GPS-200 constants
MU = 3.986005e14  # m^3/s^2, Earth's gravitational parameter (GPS value)
OMEGA_E = 7.2921151467e-5  # rad/s, Earth rotation rate
SPEED_OF_LIGHT = 299792458.0  # m/s
RELATIVITY_F = -4.442807633e-10  # s/m^0.5, -2 sqrt(mu) / c^2
HALF_WEEK = 302400.0
#: validity half-width of a broadcast ephemeris with fit interval 0 / 4 h [s]
EPHEMERIS_VALIDITY = 7200.0
#: Newton iterations for Kepler's equation from E = M (|dE| < 1e-15 rad for e < 0.05 after 5)
KEPLER_ITERATIONS = 6


class Orbit(NamedTuple):
    """Broadcast elements of S satellite slots (leaves (S,), or (S, R) in a table).

    Attributes:
      toe: s, reference time of the ephemeris, from the reference week's start
      week_start: s, start of the week of toe, from the reference week's start
      sqrt_a: m^0.5, square root of the semi-major axis
      eccentricity: orbital eccentricity (dimensionless)
      i0: rad, inclination at toe
      omega0: rad, longitude of the ascending node at the weekly epoch
      argument_of_perigee: rad, argument of perigee
      m0: rad, mean anomaly at toe
      delta_n: rad/s, mean motion correction
      omega_dot: rad/s, rate of right ascension
      idot: rad/s, rate of inclination
      cuc: rad, cosine harmonic correction to the argument of latitude
      cus: rad, sine harmonic correction to the argument of latitude
      crc: m, cosine harmonic correction to the orbit radius
      crs: m, sine harmonic correction to the orbit radius
      cic: rad, cosine harmonic correction to the inclination
      cis: rad, sine harmonic correction to the inclination
      toc: s, clock reference time, from the reference week's start
      af0: s, clock bias at toc
      af1: s/s, clock drift
      af2: s/s^2, clock drift rate
      tgd: s, group delay differential
      relativity: 1: the clock includes the relativistic term (ephemeris); 0: almanac
    """

    toe: Array
    week_start: Array
    sqrt_a: Array
    eccentricity: Array
    i0: Array
    omega0: Array
    argument_of_perigee: Array
    m0: Array
    delta_n: Array
    omega_dot: Array
    idot: Array
    cuc: Array
    cus: Array
    crc: Array
    crs: Array
    cic: Array
    cis: Array
    toc: Array
    af0: Array
    af1: Array
    af2: Array
    tgd: Array
    relativity: Array


class OrbitTable(NamedTuple):
    """Every record of S slots, padded to R records a slot (leaves (S, R)).

    Attributes:
      orbit: the records' elements, leaves (S, R)
      valid: (S, R) bool: a real, healthy, physically possible record
      validity: (S, R) s, the record serves epochs with |t - toe| <= validity
      prn: (S,) int, PRN of each slot
      problem: (S, R) int: why a present record was refused (``ORBIT_PROBLEMS``; 0: none)
    """

    orbit: Orbit
    valid: Array
    validity: Array
    prn: Array
    problem: Array


#: why a broadcast record is impossible (``orbit_problem``'s codes)
ORBIT_PROBLEMS = (
    "none",
    "a non-finite element",
    "an eccentricity outside [0, 1)",
    "a semi-major axis <= 0",
    "a perigee inside the Earth (a (1 - e) below the WGS-84 equatorial radius)",
)


def orbit_problem(orbit: Orbit) -> Array:
    """Per record, the first reason it describes no orbit (index into ``ORBIT_PROBLEMS``; 0: none). Such
    a record is excluded alone (Kepler has no solution; it would turn the whole fix NaN)."""
    finite = jnp.all(jnp.stack([jnp.isfinite(jnp.asarray(leaf)) for leaf in orbit]), axis=0)
    e, sqrt_a = jnp.asarray(orbit.eccentricity), jnp.asarray(orbit.sqrt_a)
    inside = sqrt_a**2 * (1 - e) < WGS84_A
    return jnp.where(
        ~finite,
        1,
        jnp.where((e < 0) | (e >= 1), 2, jnp.where(sqrt_a <= 0, 3, jnp.where(inside, 4, 0))),
    )


def _wrap_half_week(dt: Array) -> Array:
    return jnp.where(
        dt > HALF_WEEK, dt - SECONDS_PER_WEEK, jnp.where(dt < -HALF_WEEK, dt + SECONDS_PER_WEEK, dt)
    )


def _sin_cos_step(sin_x: Array, cos_x: Array, step: Array) -> tuple[Array, Array]:
    """``(sin(x + d), cos(x + d))`` for |d| < 0.1 by angle addition, ``sin d``, ``cos d`` as Taylor series
    to 7th/8th order (truncation < 1e-16): no transcendental call."""
    d2 = step * step
    sin_d = step * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0)))
    cos_d = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0)))
    return sin_x * cos_d + cos_x * sin_d, cos_x * cos_d - sin_x * sin_d


def kepler(
    mean_anomaly: Array, eccentricity: Array, iterations: int = KEPLER_ITERATIONS
) -> tuple[Array, Array, Array]:
    """``(E, sin E, cos E)`` with ``M = E - e sin E``: fixed-count Newton from ``E = M``, ``sin E``/``cos E``
    carried by angle addition (steps <= ``e / (1 - e)``): one ``sin``/``cos`` pair per solve."""
    E = mean_anomaly
    sin_e, cos_e = jnp.sin(E), jnp.cos(E)
    for _ in range(int(iterations)):
        step = -(E - eccentricity * sin_e - mean_anomaly) / (1.0 - eccentricity * cos_e)
        E = E + step
        sin_e, cos_e = _sin_cos_step(sin_e, cos_e, step)
    return E, sin_e, cos_e


def _anomaly(orbit: Orbit, t: Array) -> tuple[Array, Array, Array, Array]:
    """``(t_k, sin E, cos E, A)`` of every slot at time ``t``."""
    a = orbit.sqrt_a**2
    tk = _wrap_half_week(t - orbit.toe)
    n = jnp.sqrt(MU / a**3) + orbit.delta_n
    _, sin_e, cos_e = kepler(orbit.m0 + n * tk, orbit.eccentricity)
    return tk, sin_e, cos_e, a


def _position(orbit: Orbit, tk: Array, sin_e: Array, cos_e: Array, a: Array) -> Array:
    e = orbit.eccentricity
    denom = 1.0 - e * cos_e
    sin_nu, cos_nu = jnp.sqrt(1.0 - e**2) * sin_e / denom, (cos_e - e) / denom
    sin_w, cos_w = jnp.sin(orbit.argument_of_perigee), jnp.cos(orbit.argument_of_perigee)
    sin_phi, cos_phi = (
        sin_nu * cos_w + cos_nu * sin_w,
        cos_nu * cos_w - sin_nu * sin_w,
    )  # Phi = nu + omega
    sin2, cos2 = 2.0 * sin_phi * cos_phi, cos_phi**2 - sin_phi**2
    sin_u, cos_u = _sin_cos_step(sin_phi, cos_phi, orbit.cus * sin2 + orbit.cuc * cos2)
    r = a * denom + orbit.crs * sin2 + orbit.crc * cos2
    sin_i, cos_i = _sin_cos_step(
        jnp.sin(orbit.i0), jnp.cos(orbit.i0), orbit.cis * sin2 + orbit.cic * cos2 + orbit.idot * tk
    )
    x_plane, y_plane = r * cos_u, r * sin_u
    toe_of_week = orbit.toe - orbit.week_start
    node = orbit.omega0 + (orbit.omega_dot - OMEGA_E) * tk - OMEGA_E * toe_of_week
    cos_node, sin_node = jnp.cos(node), jnp.sin(node)
    return jnp.stack(
        [
            x_plane * cos_node - y_plane * cos_i * sin_node,
            x_plane * sin_node + y_plane * cos_i * cos_node,
            y_plane * sin_i,
        ],
        axis=-1,
    )


def _clock(orbit: Orbit, t: Array, sin_e: Array, l1_group_delay: bool) -> Array:
    dt = _wrap_half_week(t - orbit.toc)
    clock = (
        orbit.af0
        + orbit.af1 * dt
        + orbit.af2 * dt**2
        + orbit.relativity * RELATIVITY_F * orbit.eccentricity * orbit.sqrt_a * sin_e
    )
    return clock - orbit.tgd if l1_group_delay else clock


def satellite_position(orbit: Orbit, t: Array) -> Array:
    """Positions of the S slots at GPS time ``t`` (IS-GPS-200 Table 20-IV; harmonic corrections and
    ``IDOT t_k``, below 1e-4 rad, by angle addition).

    Returns:
      (S, 3) ECEF positions [m] at GPS time ``t``, in the Earth-fixed frame of the same
      instant (no light-time or Sagnac correction: ``transmission_geometry``).
    """
    tk, sin_e, cos_e, a = _anomaly(orbit, t)
    return _position(orbit, tk, sin_e, cos_e, a)


def satellite_state(orbit: Orbit, t: Array, l1_group_delay: bool = True) -> tuple[Array, Array]:
    """``(positions (S, 3), clocks (S,))`` at ``t`` from one Kepler solve."""
    tk, sin_e, cos_e, a = _anomaly(orbit, t)
    return _position(orbit, tk, sin_e, cos_e, a), _clock(orbit, t, sin_e, l1_group_delay)


def satellite_velocity(orbit: Orbit, t: Array) -> Array:
    """(S, 3) ECEF velocities [m/s] at ``t``: ``d/dt satellite_position`` by forward AD (Earth-fixed frame)."""
    t = jnp.asarray(t, jnp.result_type(orbit.toe))
    return jax.jvp(lambda s: satellite_position(orbit, s), (t,), (jnp.ones_like(t),))[1]


def satellite_clock(orbit: Orbit, t: Array, l1_group_delay: bool = True) -> Array:
    """(S,) clock offset ``dt_sv`` [s] at ``t``: polynomial + relativistic term, less ``T_GD`` when
    ``l1_group_delay`` (L1 C/A user)."""
    _, sin_e, _, _ = _anomaly(orbit, t)
    return _clock(orbit, t, sin_e, l1_group_delay)


def earth_rotation(position: Array, travel_time: Array) -> Array:
    """(..., 3) positions rotated about z by ``-Omega_e * travel_time``: from the ECEF frame of transmission
    to that of reception (Sagnac correction)."""
    angle = OMEGA_E * travel_time  # < 1e-6 rad: series to 4th order, exact in float64
    c, s = 1.0 - 0.5 * angle**2 * (1.0 - angle**2 / 12.0), angle * (1.0 - angle**2 / 6.0)
    x, y, z = position[..., 0], position[..., 1], position[..., 2]
    return jnp.stack([c * x + s * y, -s * x + c * y, z], axis=-1)


def transmission_geometry(
    orbit: Orbit, t_receive: Array, receiver_ecef: Array, iterations: int = 3
) -> tuple[Array, Array, Array, Array]:
    """Light-time solution for a receiver at ``receiver_ecef`` (3,) at true GPS time ``t_receive``:
    ``tau = |R(tau) r_s(t - tau) - r_r| / c`` by fixed point (contracts ~1e-5 a step: pm after 3).

    Returns ``(positions, ranges, t_transmit, clocks)``: (S, 3) positions at transmission in the ECEF
    frame of reception, (S,) ranges [m], (S,) transmission times, (S,) clocks [s] (``satellite_clock``, L1).
    """
    checks.check_shape("receiver_ecef", receiver_ecef, (3,), "the receiver's ECEF position [m]")
    receiver_ecef = jnp.asarray(receiver_ecef)
    tau = jnp.full(orbit.toe.shape, 0.075, jnp.result_type(receiver_ecef, orbit.toe))
    for _ in range(int(iterations)):
        position = earth_rotation(satellite_position(orbit, t_receive - tau), tau)
        tau = jnp.linalg.norm(position - receiver_ecef, axis=-1) / SPEED_OF_LIGHT
    position, clock = satellite_state(orbit, t_receive - tau)
    position = earth_rotation(position, tau)
    return position, jnp.linalg.norm(position - receiver_ecef, axis=-1), t_receive - tau, clock


# --- from records to tables ------------------------------------------------------------


def _table(
    prns: np.ndarray,
    slot_prns: np.ndarray,
    columns: dict,
    valid: np.ndarray,
    validity: np.ndarray,
    dtype,
) -> OrbitTable:
    slot_prns = np.asarray(slot_prns, int)
    repeated = sorted({int(p) for p in slot_prns if np.sum(slot_prns == p) > 1})
    if repeated:
        raise ValueError(
            f"slot_prns: expected each satellite once, got PRN {repeated} more than once "
            f"(it would be counted twice in every fix)"
        )
    counts = [int(np.sum(prns == p)) for p in slot_prns]
    width = max(max(counts), 1)
    index = np.zeros((slot_prns.size, width), int)
    present = np.zeros((slot_prns.size, width), bool)
    for s, p in enumerate(slot_prns):
        rows = np.flatnonzero(prns == p)
        index[s, : rows.size] = rows
        present[s, : rows.size] = True
    take = lambda values: jnp.asarray(
        np.where(present, np.asarray(values, float)[index], 0.0), dtype
    )
    orbit = Orbit(**{name: take(columns[name]) for name in Orbit._fields})
    raw = Orbit(**{name: np.asarray(columns[name], float)[index] for name in Orbit._fields})
    problem = np.where(present, np.asarray(orbit_problem(raw)), 0)
    return OrbitTable(
        orbit,
        jnp.asarray(present & np.asarray(valid)[index] & (problem == 0)),
        jnp.asarray(np.where(present, np.asarray(validity, float)[index], 0.0), dtype),
        jnp.asarray(slot_prns, jnp.int32),
        jnp.asarray(problem, jnp.int32),
    )


def ephemeris_table(
    ephemerides: Ephemerides,
    reference_week: int,
    slot_prns=None,
    include_unhealthy: bool = False,
    dtype=None,
) -> OrbitTable:
    """The RINEX records as an ``OrbitTable`` with times from the start of ``reference_week``.

    Args:
      ephemerides: ``rinex.read_rinex_nav``'s records.
      reference_week: the GPS week whose start is ``t = 0``.
      slot_prns: (S,) PRN of each slot (default 1..32: slot ``s`` is PRN ``s + 1``).
      include_unhealthy: keep records whose health word is not 0 (default: dropped).
      dtype: float dtype (default: JAX's default float).

    Returns:
      ``OrbitTable`` of the S slots, leaves (S, R) padded to the most records a slot holds; each record serves
      epochs within half its fit interval of ``toe`` (``EPHEMERIS_VALIDITY`` for a fit interval of 4 h or less).
    """
    dtype = dtype or jnp.result_type(float)
    eph = ephemerides
    week_start = (eph.week - int(reference_week)) * SECONDS_PER_WEEK
    columns = {
        "toe": week_start + eph.toe,
        "week_start": week_start,
        "sqrt_a": eph.sqrt_a,
        "eccentricity": eph.eccentricity,
        "i0": eph.i0,
        "omega0": eph.omega0,
        "argument_of_perigee": eph.argument_of_perigee,
        "m0": eph.m0,
        "delta_n": eph.delta_n,
        "omega_dot": eph.omega_dot,
        "idot": eph.idot,
        "cuc": eph.cuc,
        "cus": eph.cus,
        "crc": eph.crc,
        "crs": eph.crs,
        "cic": eph.cic,
        "cis": eph.cis,
        "toc": (eph.toc_week - int(reference_week)) * SECONDS_PER_WEEK + eph.toc,
        "af0": eph.af0,
        "af1": eph.af1,
        "af2": eph.af2,
        "tgd": eph.tgd,
        "relativity": np.ones(eph.prn.shape),
    }
    validity = np.where(eph.fit_interval > 4.0, eph.fit_interval * 1800.0, EPHEMERIS_VALIDITY)
    valid = np.ones(eph.prn.shape, bool) if include_unhealthy else eph.health == 0
    slot_prns = np.arange(1, 33) if slot_prns is None else np.asarray(slot_prns)
    return _table(eph.prn, slot_prns, columns, valid, validity, dtype)


def almanac_table(
    almanac: Almanac,
    reference_week: int | None = None,
    slot_prns=None,
    include_unhealthy: bool = False,
    dtype=None,
) -> OrbitTable:
    """An almanac as an ``OrbitTable`` (one record a slot, valid at any time); ``reference_week``
    defaults to the almanac's, slots to its PRNs in file order.

    Returns:
      ``OrbitTable`` of the S slots, leaves (S, R) (R = 1 unless a PRN repeats), validity ``inf`` (records never
      expire), no harmonic corrections, ``af0``/``af1`` clocks and no relativistic term.
    """
    dtype = dtype or jnp.result_type(float)
    alm = almanac
    reference_week = int(alm.week[0]) if reference_week is None else int(reference_week)
    week_start = (alm.week - reference_week) * SECONDS_PER_WEEK
    zeros = np.zeros(alm.prn.shape)
    columns = {
        "toe": week_start + alm.toa,
        "week_start": week_start,
        "sqrt_a": alm.sqrt_a,
        "eccentricity": alm.eccentricity,
        "i0": alm.inclination,
        "omega0": alm.omega0,
        "argument_of_perigee": alm.argument_of_perigee,
        "m0": alm.mean_anomaly,
        "delta_n": zeros,
        "omega_dot": alm.omega_dot,
        "idot": zeros,
        "cuc": zeros,
        "cus": zeros,
        "crc": zeros,
        "crs": zeros,
        "cic": zeros,
        "cis": zeros,
        "toc": week_start + alm.toa,
        "af0": alm.af0,
        "af1": alm.af1,
        "af2": zeros,
        "tgd": zeros,
        "relativity": zeros,
    }
    valid = np.ones(alm.prn.shape, bool) if include_unhealthy else alm.health == 0
    slot_prns = alm.prn if slot_prns is None else np.asarray(slot_prns)
    return _table(alm.prn, slot_prns, columns, valid, np.full(alm.prn.shape, np.inf), dtype)


def orbit_table(
    records: Ephemerides | Almanac,
    reference_week: int | None = None,
    slot_prns=None,
    include_unhealthy: bool = False,
    dtype=None,
) -> OrbitTable:
    """Broadcast records (``read_rinex_nav``'s ephemerides or ``read_yuma``'s almanac) as the ``OrbitTable`` that
    ``select_orbits``, ``monitor_epochs`` and the receiver chain read, times ``t`` from the start of ``reference_week``.

    Args:
      records: ``Ephemerides`` or ``Almanac``.
      reference_week: the GPS week whose start is ``t = 0`` (default: the records' first week).
      slot_prns: (S,) PRN of each slot (default: PRNs 1..32 for ephemerides, the almanac's in file order).
      include_unhealthy: keep records whose health word is not 0 (default: dropped).
      dtype: float dtype (default: JAX's default float).

    Returns:
      ``OrbitTable``: every record of the S slots, padded (leaves (S, R)); an almanac's records never expire.
    """
    if isinstance(records, Almanac):
        return almanac_table(records, reference_week, slot_prns, include_unhealthy, dtype)
    if not isinstance(records, Ephemerides):
        raise TypeError(
            f"records: expected Ephemerides (read_rinex_nav) or an Almanac (read_yuma), got "
            f"{checks.received(records)}"
        )
    week = int(np.min(records.week)) if reference_week is None else reference_week
    return ephemeris_table(records, week, slot_prns, include_unhealthy, dtype)


def select_orbits(table: OrbitTable, t: Array) -> tuple[Orbit, Array]:
    """Each slot's record for epoch ``t``: smallest ``|t - toe|`` among valid records within their validity (RTKLIB's
    ``seleph``), never one with an ``orbit_problem``; a slot with none is unavailable (its orbit then is filler, never
    to be used).

    Returns:
      ``(orbit, available)``: the ``Orbit`` with (S,) leaves that ``satellite_position`` and ``solve_position`` take,
      and (S,) bool.
    """
    age = jnp.abs(_wrap_half_week(t - table.orbit.toe))
    usable = table.valid & (age <= table.validity) & (orbit_problem(table.orbit) == 0)
    index = jnp.argmin(jnp.where(usable, age, jnp.inf), axis=1)
    orbit = jax.tree_util.tree_map(
        lambda leaf: jnp.take_along_axis(leaf, index[:, None], axis=1)[:, 0], table.orbit
    )
    return orbit, jnp.any(usable, axis=1)
