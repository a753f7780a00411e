"""Satellite positions and clocks against RTKLIB (pyrtklib: eph2pos / alm2pos / eph2clk),
WGS-84 conversions and look angles against pymap3d and RTKLIB, DOPs against RTKLIB."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pymap3d
import pyrtklib as rtk
import pytest

from jaxfdi.data import data_path
from jaxfdi.gnss import (
    OMEGA_E,
    almanac_table,
    ecef_to_geodetic,
    ecef_to_ned,
    ephemeris_table,
    geodetic_to_ecef,
    orbit_table,
    read_rinex_nav,
    read_yuma,
    satellite_position,
    select_orbits,
)
from jaxfdi.gnss._frames import elevation_azimuth, ned_to_ecef
from jaxfdi.gnss._orbits import (
    SPEED_OF_LIGHT,
    Orbit,
    satellite_clock,
    satellite_velocity,
    transmission_geometry,
)
from jaxfdi.gnss._positioning import dops

C = 299792458.0
OFFSETS = np.array([-5400.0, -1800.5, 0.0, 1234.5, 3600.0, 7199.0])  # s from each record's toe


def vec(values):
    a = rtk.Arr1Ddouble(len(values))
    for i, v in enumerate(values):
        a[i] = float(v)
    return a


@pytest.fixture(scope="module")
def ephemerides():
    return read_rinex_nav(data_path("gps_nav_rinex2_sugl0010.20n"))


@pytest.fixture(scope="module")
def record_orbits(ephemerides):
    """Every record as its own slot (R = 418 slots of one record each)."""
    table = ephemeris_table(ephemerides, 2086, slot_prns=None, include_unhealthy=True)
    eph = ephemerides
    rank = np.array([np.sum(eph.prn[:k] == eph.prn[k]) for k in range(eph.prn.size)])
    return jax.tree_util.tree_map(lambda leaf: leaf[eph.prn - 1, rank], table.orbit)


def rtklib_eph(eph, k):
    e = rtk.eph_t()
    e.sat, e.week, e.iode, e.iodc, e.svh = (
        int(eph.prn[k]),
        int(eph.week[k]),
        int(eph.iode[k]),
        int(eph.iodc[k]),
        0,
    )
    e.A, e.e, e.i0, e.OMG0, e.omg, e.M0 = (
        eph.sqrt_a[k] ** 2,
        eph.eccentricity[k],
        eph.i0[k],
        eph.omega0[k],
        eph.argument_of_perigee[k],
        eph.m0[k],
    )
    e.deln, e.OMGd, e.idot = eph.delta_n[k], eph.omega_dot[k], eph.idot[k]
    e.crc, e.crs, e.cuc, e.cus, e.cic, e.cis = (
        eph.crc[k],
        eph.crs[k],
        eph.cuc[k],
        eph.cus[k],
        eph.cic[k],
        eph.cis[k],
    )
    e.toes = eph.toe[k]
    e.toe = rtk.gpst2time(int(eph.week[k]), float(eph.toe[k]))
    e.toc = rtk.gpst2time(int(eph.toc_week[k]), float(eph.toc[k]))
    e.f0, e.f1, e.f2 = eph.af0[k], eph.af1[k], eph.af2[k]
    return e


def test_broadcast_positions_and_clocks_match_rtklib(ephemerides, record_orbits):
    """All 418 records at 6 times within +/- 2 h of toe: 1 mm asked, ~1e-7 m found."""
    eph = ephemerides
    times = (eph.week[:, None] - 2086) * 604800.0 + eph.toe[:, None] + OFFSETS[None, :]
    ours = jax.jit(jax.vmap(lambda t: satellite_position(record_orbits, t), in_axes=1, out_axes=1))(
        times
    )
    clocks = jax.jit(
        jax.vmap(
            lambda t: satellite_clock(record_orbits, t, l1_group_delay=False), in_axes=1, out_axes=1
        )
    )(times)
    ours, clocks = np.asarray(ours), np.asarray(clocks)
    rs, dts, var = rtk.Arr1Ddouble(3), rtk.Arr1Ddouble(1), rtk.Arr1Ddouble(1)
    worst_pos = worst_clock = 0.0
    for k in range(eph.prn.size):
        e = rtklib_eph(eph, k)
        for j, offset in enumerate(OFFSETS):
            t = rtk.gpst2time(int(eph.week[k]), float(eph.toe[k] + offset))
            rtk.eph2pos(t, e, rs, dts, var)  # clock incl. the relativistic term
            worst_pos = max(worst_pos, float(np.max(np.abs(ours[k, j] - [rs[0], rs[1], rs[2]]))))
            worst_clock = max(worst_clock, abs(clocks[k, j] - dts[0]) * C)
    assert worst_pos < 1e-3 and worst_clock < 1e-3, (worst_pos, worst_clock)
    # RTKLIB's eph2clk is the polynomial alone: check the relativistic term apart
    t = rtk.gpst2time(int(eph.week[0]), float(eph.toe[0] + 1000.0))
    polynomial = rtk.eph2clk(t, rtklib_eph(eph, 0))
    record0 = jax.tree_util.tree_map(lambda leaf: leaf[:1], record_orbits)
    assert float(satellite_clock(record0, eph.toe[0] + 1000.0, False)[0]) != pytest.approx(
        polynomial, abs=1e-12
    )
    assert float(satellite_clock(record0, eph.toe[0] + 1000.0, True)[0]) == pytest.approx(
        float(satellite_clock(record0, eph.toe[0] + 1000.0, False)[0]) - eph.tgd[0], abs=1e-18
    )


def test_velocity_matches_rtklib_finite_difference(ephemerides, record_orbits):
    eph = ephemerides
    rs, dts, var = rtk.Arr1Ddouble(3), rtk.Arr1Ddouble(1), rtk.Arr1Ddouble(1)
    velocity = np.asarray(satellite_velocity(record_orbits, jnp.asarray(eph.toe + 600.0)))
    for k in range(0, eph.prn.size, 7):
        e, pos = rtklib_eph(eph, k), []
        for h in (-0.05, 0.05):
            rtk.eph2pos(rtk.gpst2time(2086, float(eph.toe[k] + 600.0 + h)), e, rs, dts, var)
            pos.append([rs[0], rs[1], rs[2]])
        # central difference: truncation a h^2 / 6 < 1e-6 m/s, rounding ~1e-7 m / 0.1 s
        np.testing.assert_allclose(velocity[k], (np.array(pos[1]) - pos[0]) / 0.1, atol=1e-4)


def test_almanac_matches_rtklib_and_the_broadcast_orbits(ephemerides):
    almanac = read_yuma(data_path("gps_almanac_2086.yuma.txt"), rollovers=2)
    table = almanac_table(almanac, include_unhealthy=True)
    rs, dts = rtk.Arr1Ddouble(3), rtk.Arr1Ddouble(1)
    for t in (259200.0 + 3600.0, 503808.0, 600000.0):
        ours = np.asarray(
            satellite_position(jax.tree_util.tree_map(lambda x: x[:, 0], table.orbit), t)
        )
        clocks = np.asarray(
            satellite_clock(jax.tree_util.tree_map(lambda x: x[:, 0], table.orbit), t, False)
        )
        for s in range(almanac.prn.size):
            a = rtk.alm_t()
            a.sat, a.week, a.e, a.i0 = (
                int(almanac.prn[s]),
                2086,
                almanac.eccentricity[s],
                almanac.inclination[s],
            )
            a.A, a.OMG0, a.omg = (
                almanac.sqrt_a[s] ** 2,
                almanac.omega0[s],
                almanac.argument_of_perigee[s],
            )
            a.M0, a.OMGd, a.f0, a.f1 = (
                almanac.mean_anomaly[s],
                almanac.omega_dot[s],
                almanac.af0[s],
                almanac.af1[s],
            )
            a.toas, a.toa = almanac.toa[s], rtk.gpst2time(2086, float(almanac.toa[s]))
            rtk.alm2pos(rtk.gpst2time(2086, t), a, rs, dts)
            np.testing.assert_allclose(ours[s], [rs[0], rs[1], rs[2]], atol=1e-3)
            assert clocks[s] == pytest.approx(dts[0], abs=1e-15)  # af0 + af1 t_k
    # the almanac (TOA 2.8 days later) and the broadcast orbits agree to a few km on 2020-01-01
    broadcast = orbit_table(ephemerides, 2086)  # the public path to both tables
    alm_table = orbit_table(almanac, slot_prns=np.arange(1, 33))
    t = 259200.0 + 6 * 3600.0
    (orbit_b, ok_b), (orbit_a, ok_a) = select_orbits(broadcast, t), select_orbits(alm_table, t)
    both = np.asarray(ok_b & ok_a)
    gap = np.linalg.norm(
        np.asarray(satellite_position(orbit_b, t) - satellite_position(orbit_a, t)), axis=1
    )
    assert both.sum() == 30 and np.max(gap[both]) < 10e3, np.round(gap[both])


def test_orbit_table_is_the_records_table_from_their_first_week(ephemerides):
    """``orbit_table`` of ephemerides, week defaulted, is ``ephemeris_table`` at the records' first GPS week; a
    record set of another kind is refused by name."""
    week = int(np.min(ephemerides.week))
    jax.tree_util.tree_map(
        np.testing.assert_array_equal, orbit_table(ephemerides), ephemeris_table(ephemerides, week)
    )
    with pytest.raises(TypeError, match="^records: expected Ephemerides"):
        orbit_table({"prn": [1]})


def test_select_orbits_takes_the_nearest_valid_record(ephemerides):
    table = ephemeris_table(ephemerides, 2086)
    eph = ephemerides
    for t in (
        259200.0 + 100.0,
        259200.0 + 40000.0,
        259200.0 + 86000.0,
        259200.0 + 86400.0 + 8000.0,
    ):
        orbit, ok = select_orbits(table, t)
        for s, prn in enumerate(range(1, 33)):
            rows = np.flatnonzero(
                (eph.prn == prn) & (eph.health == 0) & (np.abs(eph.toe - t) <= 7200.0)
            )
            assert bool(ok[s]) == (rows.size > 0)
            if rows.size:
                best = rows[np.argmin(np.abs(eph.toe[rows] - t))]
                assert float(orbit.toe[s]) == eph.toe[best] and float(orbit.m0[s]) == eph.m0[best]


def test_light_time_solution_is_consistent(ephemerides):
    orbit, ok = select_orbits(ephemerides_table := ephemeris_table(ephemerides, 2086), 262000.0)
    receiver = geodetic_to_ecef(math.radians(37.5), math.radians(127.0), 50.0)
    position, ranges, t_tx, _ = transmission_geometry(orbit, 262000.0, receiver)
    # range = c * travel time (to the float64 resolution of t_tx ~ 2.6e5 s: 6e-11 s, 2 cm), the
    # range is the distance to the position, the position the orbit at t_tx rotated by Omega_e tau
    tau = 262000.0 - np.asarray(t_tx)
    np.testing.assert_allclose(np.asarray(ranges), C * tau, rtol=0, atol=2e-2)
    np.testing.assert_allclose(
        np.asarray(ranges), np.linalg.norm(np.asarray(position) - receiver, axis=1), atol=1e-7
    )
    raw = np.asarray(satellite_position(orbit, t_tx))
    angle = OMEGA_E * tau
    rotated = np.stack(
        [
            np.cos(angle) * raw[:, 0] + np.sin(angle) * raw[:, 1],
            -np.sin(angle) * raw[:, 0] + np.cos(angle) * raw[:, 1],
            raw[:, 2],
        ],
        axis=1,
    )
    np.testing.assert_allclose(np.asarray(position), rotated, atol=1e-6)
    assert ephemerides_table.prn.shape == (32,)


def test_frames_match_pymap3d_and_rtklib():
    rng = np.random.default_rng(0)
    lat = np.concatenate([rng.uniform(-89.9, 89.9, 200), [90.0, -90.0, 0.0, 37.5419]])
    lon = np.concatenate([rng.uniform(-180, 180, 200), [0.0, 10.0, -180.0, 127.0782]])
    h = np.concatenate([rng.uniform(-400, 30000, 200), [0.0, 1000.0, 20200e3, 60.0]])
    ecef = np.asarray(geodetic_to_ecef(np.radians(lat), np.radians(lon), h))
    ref = np.stack(pymap3d.geodetic2ecef(lat, lon, h), axis=1)
    np.testing.assert_allclose(ecef, ref, atol=1e-6)
    back = np.stack(ecef_to_geodetic(ecef), axis=1)
    ref_lat, ref_lon, ref_h = pymap3d.ecef2geodetic(*ref.T)
    np.testing.assert_allclose(np.degrees(back[:, 0]), ref_lat, atol=1e-9)
    np.testing.assert_allclose(
        back[:, 2], ref_h, atol=1e-4
    )  # 0.1 mm (pymap3d's own iteration tolerance)
    away = np.abs(lat) < 89.0
    np.testing.assert_allclose(np.degrees(back[away, 1]), ref_lon[away], atol=1e-9)
    pos = rtk.Arr1Ddouble(3)
    for k in range(0, 204, 17):
        rtk.ecef2pos(vec(ecef[k]), pos)
        assert back[k, 0] == pytest.approx(pos[0], abs=1e-11) and back[k, 2] == pytest.approx(
            pos[2], abs=1e-4
        )
    # NED offsets and look angles
    origin = ecef[-1]
    targets = origin + rng.normal(scale=2e7, size=(50, 3))
    ned = np.asarray(ecef_to_ned(targets, origin))
    ref_ned = np.stack(pymap3d.ecef2ned(*targets.T, 37.5419, 127.0782, 60.0), axis=1)
    np.testing.assert_allclose(ned, ref_ned, atol=1e-5)
    np.testing.assert_allclose(np.asarray(ned_to_ecef(ned, origin)), targets, atol=1e-5)
    el, az = elevation_azimuth(origin, targets)
    ref_az, ref_el, _ = pymap3d.ecef2aer(*targets.T, 37.5419, 127.0782, 60.0)
    np.testing.assert_allclose(np.degrees(np.asarray(el)), ref_el, atol=1e-9)
    np.testing.assert_allclose(np.degrees(np.asarray(az)), ref_az, atol=1e-9)
    azel = rtk.Arr1Ddouble(2)
    for k in range(0, 50, 7):
        rtk.satazel(
            vec([math.radians(37.5419), math.radians(127.0782), 60.0]),
            vec((targets[k] - origin) / np.linalg.norm(targets[k] - origin)),
            azel,
        )
        assert (float(az[k]), float(el[k])) == pytest.approx((azel[0], azel[1]), abs=1e-12)


def test_dops_match_rtklib():
    rng = np.random.default_rng(1)
    for n in (4, 5, 7, 12):
        el = rng.uniform(0.1, 1.5, n)
        az = rng.uniform(0, 2 * np.pi, n)
        los = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], axis=1)
        geometry = np.zeros((32, 4))
        used = np.zeros(32, bool)
        slots = rng.choice(32, n, replace=False)
        geometry[slots] = np.concatenate([-los, np.ones((n, 1))], axis=1)
        used[slots] = True
        ours = dops(jnp.asarray(geometry), jnp.asarray(used))
        out = rtk.Arr1Ddouble(4)
        rtk.dops(n, vec(np.stack([az, el], axis=1).ravel()), 0.0, out)  # GDOP, PDOP, HDOP, VDOP
        np.testing.assert_allclose(
            [ours.gdop, ours.pdop, ours.hdop, ours.vdop], [out[i] for i in range(4)], rtol=1e-10
        )
    assert Orbit._fields[0] == "toe" and SPEED_OF_LIGHT == C
