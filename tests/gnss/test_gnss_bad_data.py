"""GNSS integrity from the data at hand (issue 37): tables too small for the fix are
refused, a satellite listed twice is refused, a broadcast record that describes no orbit
is excluded alone with its reason, and a dead (infinite) pseudorange alarms on its
satellite; the receiver plant reports a DEAD fault on a tracked satellite as that dead
channel (+inf) and keeps NaN for a satellite it does not track. References: the same
computation on clean data (the record or satellite left out, the pseudorange not
measured), and tables large enough, which must agree exactly."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfdi import concat_faults, fault
from jaxfdi.data import data_path
from jaxfdi.gnss import (
    elevation_sigma,
    ephemeris_table,
    geodetic_to_ecef,
    monitor_epoch,
    parity_check,
    protection_levels,
    raim_output,
    raim_tables,
    read_rinex_nav,
    receiver_plant,
    select_orbits,
)
from jaxfdi.gnss._integrity import geometry_fix
from jaxfdi.gnss._orbits import ORBIT_PROBLEMS, SPEED_OF_LIGHT, transmission_geometry

SITE = geodetic_to_ecef(math.radians(37.5419), math.radians(127.0782), 60.0)
T = 259200.0 + 2700.0
CLOCK = 1234.5


@pytest.fixture(scope="module")
def ephemerides():
    return read_rinex_nav(data_path("gps_nav_rinex2_sugl0010.20n"))


def _epoch(table):
    """Noise-free pseudoranges of the satellites above 5 deg at T (NaN elsewhere), from
    ``table``'s orbits, and the one compiled monitor for any table of 32 slots."""
    orbit, ok = select_orbits(table, T)
    _, ranges, _, clock = transmission_geometry(orbit, T - CLOCK / SPEED_OF_LIGHT, SITE)
    fix = geometry_fix(table, T, SITE, math.radians(5.0), elevation_sigma)
    return jnp.where(fix.used & ok, ranges + CLOCK - SPEED_OF_LIGHT * clock, jnp.nan)


MONITOR = jax.jit(
    lambda table, rho, tables: monitor_epoch(
        *select_orbits(table, T), T, rho, tables, elevation_sigma
    )
)


def test_tables_smaller_than_the_fix_are_refused_and_larger_ones_agree(ephemerides):
    table = ephemeris_table(ephemerides, 2086)
    rho = _epoch(table)
    exact = MONITOR(table, rho, raim_tables(32))
    assert int(exact.check.dof) >= 2
    with pytest.raises(
        ValueError, match=r"tables: built for 8 satellite slots .* raim_tables\(32\)"
    ):
        parity_check(exact.fix, raim_tables(8))
    with pytest.raises(ValueError, match="tables: built for 8"):
        protection_levels(exact.fix, raim_tables(8))
    larger = MONITOR(table, rho, raim_tables(40))
    assert float(larger.check.threshold) == float(exact.check.threshold)
    assert float(larger.protection.hpl) == float(exact.protection.hpl)


def test_a_satellite_listed_twice_is_refused(ephemerides):
    with pytest.raises(ValueError, match=r"slot_prns: .* PRN \[2\] more than once"):
        ephemeris_table(ephemerides, 2086, slot_prns=[1, 2, 2, 3, 4, 5])


def test_an_impossible_orbit_is_excluded_alone_with_its_reason(ephemerides):
    """Three visible satellites get impossible records (eccentricity 1.5, sqrt(a) = 0, a
    NaN element): the table refuses exactly those records and says why; the fix, the
    parity test and the protection levels equal those of the clean table with the three
    satellites not measured (to 1e-9 relative), and stay finite."""
    clean = ephemeris_table(ephemerides, 2086)
    rho = _epoch(clean)
    visible = np.flatnonzero(np.isfinite(np.asarray(rho)))
    prns = [int(clean.prn[s]) for s in visible[:3]]
    eph = ephemerides
    ecc, sqrt_a, crs = (np.array(a, float) for a in (eph.eccentricity, eph.sqrt_a, eph.crs))
    ecc[eph.prn == prns[0]] = 1.5
    sqrt_a[eph.prn == prns[1]] = 0.0
    crs[eph.prn == prns[2]] = np.nan
    broken = ephemeris_table(eph._replace(eccentricity=ecc, sqrt_a=sqrt_a, crs=crs), 2086)
    problem = np.asarray(broken.problem)
    for prn, code in zip(prns, (2, 3, 1)):
        slot = int(np.flatnonzero(np.asarray(broken.prn) == prn)[0])
        present = np.flatnonzero(np.asarray(clean.valid[slot]))
        assert np.all(problem[slot, present] == code), ORBIT_PROBLEMS[code]
        assert not np.any(np.asarray(broken.valid[slot]))
    assert np.sum(problem > 0) == sum(int(np.sum(eph.prn == p)) for p in prns)
    got = MONITOR(broken, rho, raim_tables(32))
    want = MONITOR(clean, rho.at[visible[:3]].set(jnp.nan), raim_tables(32))
    assert bool(got.fix.healthy) and np.all(np.isfinite(np.asarray(got.fix.position)))
    for a, b in (
        (got.fix.position, want.fix.position),
        (got.check.statistic, want.check.statistic),
        (got.protection.hpl, want.protection.hpl),
    ):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-6)
    assert int(got.fix.num_used) == len(visible) - 3


def test_an_orbit_through_the_earth_gets_one_verdict_from_every_reader(ephemerides):
    """sqrt(a) = 2000 m^0.5 (a = 4000 km: a perigee inside the Earth) is no orbit a satellite flies: the broadcast
    table and the almanac table (YUMA) refuse that record alone with the same reason, and every other record stays."""
    from jaxfdi.gnss import almanac_table, read_yuma

    eph = ephemerides
    sqrt_a = np.array(eph.sqrt_a, float)
    sqrt_a[eph.prn == eph.prn[0]] = 2000.0
    broadcast = ephemeris_table(eph._replace(sqrt_a=sqrt_a), 2086)
    almanac = read_yuma(data_path("gps_almanac_2086.yuma.txt"))
    low = np.array(almanac.sqrt_a, float)
    low[0] = 2000.0
    table = almanac_table(almanac._replace(sqrt_a=low))
    for t, prn in ((broadcast, eph.prn[0]), (table, almanac.prn[0])):
        problem, slots = np.asarray(t.problem), np.asarray(t.prn)
        assert set(np.unique(problem[slots == prn])) <= {0, 4} and np.any(
            problem[slots == prn] == 4
        )
        assert np.all(problem[slots != prn] == 0), ORBIT_PROBLEMS[4]
        assert not np.any(np.asarray(t.valid)[slots == prn] & (problem[slots == prn] == 4))


def test_a_dead_pseudorange_alarms_on_its_satellite_and_the_fix_leaves_it_out(ephemerides):
    table = ephemeris_table(ephemerides, 2086)
    rho = _epoch(table)
    slot = int(np.flatnonzero(np.isfinite(np.asarray(rho)))[2])
    dead = MONITOR(table, rho.at[slot].set(jnp.inf), raim_tables(32))
    missing = MONITOR(table, rho.at[slot].set(jnp.nan), raim_tables(32))
    np.testing.assert_allclose(dead.fix.position, missing.fix.position, rtol=1e-12)
    decision = raim_output(dead).decision
    assert (
        bool(decision.alarm)
        and float(decision.statistic) == np.inf
        and int(decision.label) == 1 + slot
    )
    assert int(dead.excluded) == slot  # left out of the fix: reported as excluded
    np.testing.assert_array_equal(dead.fix_excluded.position, dead.fix.position)
    quiet = raim_output(missing).decision  # NaN: not measured, no evidence
    assert not bool(quiet.alarm) and int(quiet.label) == 0 and int(missing.excluded) == -1


def test_the_receiver_reports_a_dead_tracked_channel_as_inf_and_an_untracked_one_as_nan(
    ephemerides,
):
    """DEAD faults on a tracked slot and on a slot with an orbit below the mask: the plant
    gives +inf on the first (RAIM: alarm, its label, excluded) and NaN on the second (not
    measured: no evidence), every other tracked slot its finite pseudorange."""
    table = ephemeris_table(ephemerides, 2086)
    rho = _epoch(table)
    _, has_orbit = select_orbits(table, T)
    tracked = np.isfinite(np.asarray(rho))
    slot = int(np.flatnonzero(tracked)[2])
    hidden = int(np.flatnonzero(np.asarray(has_orbit) & ~tracked)[0])
    plant = receiver_plant(
        table,
        T,
        1.0,
        SITE[None],
        jnp.asarray(tracked)[None],
        jnp.full((1, 32), 3.0),
        fault=concat_faults(fault("dead", "sensor", slot, 0), fault("dead", "sensor", hidden, 0)),
    )
    _, sensed = plant.measure(
        plant.init(jnp.asarray([CLOCK, 0.0])), 0, jnp.zeros(0), jax.random.key(3)
    )
    y = np.asarray(sensed.measurement)
    assert y[slot] == np.inf and np.isnan(y[hidden])
    assert np.all(np.isfinite(np.delete(y, slot)[np.delete(tracked, slot)])) and np.all(
        np.isnan(y[~tracked])
    )
    result = MONITOR(table, jnp.asarray(y), raim_tables(32))
    decision = raim_output(result).decision
    assert bool(decision.alarm) and int(decision.label) == 1 + slot and int(result.excluded) == slot
    assert int(result.fix.num_used) == int(tracked.sum()) - 1 and bool(result.fix.healthy)


def test_an_epoch_is_as_healthy_as_the_fix_it_delivers(ephemerides):
    """A 50 km fault on one satellite: the fix with it does not converge in its fixed
    Gauss-Newton steps (measured: the 6th step still moves > 1 cm), RAIM isolates and
    excludes it, and the fix without it converges to the noise-free position; the epoch
    is healthy (the delivered fix), and without exclusion it is not."""
    table = ephemeris_table(ephemerides, 2086)
    rho = _epoch(table)
    slot = int(np.flatnonzero(np.isfinite(np.asarray(rho)))[2])
    result = MONITOR(table, rho.at[slot].add(5e4), raim_tables(32))
    assert not bool(result.fix.healthy) and int(result.excluded) == slot
    assert bool(result.fix_excluded.healthy)
    np.testing.assert_allclose(
        np.asarray(result.fix_excluded.position), np.asarray(SITE), atol=1e-3
    )
    assert bool(raim_output(result).healthy)
    kept = jax.jit(
        lambda rho: monitor_epoch(
            *select_orbits(table, T), T, rho, raim_tables(32), elevation_sigma, exclude=False
        )
    )(rho.at[slot].add(5e4))
    assert not bool(raim_output(kept).healthy)
