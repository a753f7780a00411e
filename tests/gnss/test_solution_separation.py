"""Solution-separation protection levels (ARAIM, Blanch et al. 2015) against a NumPy/SciPy
reference written from the same equations but computed the long way: each fault-tolerant
solution by least squares on its own rows, the separation as the difference of two
solutions, its variance as ``(S_k - S_0) C (S_k - S_0)^T``, each level by Brent's method.
On the GEONET hour (GPS, one clock: the constellation mode is unmonitorable) and on a
two-clock geometry (the almanac's satellites split into two constellations). And the
property that the levels never fall below the fault-free ones, on every epoch."""

import jax
import numpy as np
import pytest
import scipy.optimize
from scipy.stats import norm

from jaxfdi.data import data_path
from jaxfdi.gnss import (
    PositionFix,
    monitor_receiver,
    read_observations,
    read_rinex_nav,
    receiver_epochs,
    separate_epochs,
)
from jaxfdi.gnss._positioning import dops
from jaxfdi.gnss._solution_separation import (
    P_CONSTELLATION,
    P_FA_HORIZONTAL,
    P_FA_VERTICAL,
    P_HMI_HORIZONTAL,
    P_HMI_VERTICAL,
    P_SATELLITE,
    fault_free_levels,
    solution_separation,
)


def reference(geometry, sigma, residuals, used, p_const):
    """The ARAIM MHSS levels the long way (module docstring). Returns hpl, vpl, thresholds (K, 3)."""
    rows = np.flatnonzero(used)
    g, s, r = geometry[rows], sigma[rows], residuals[rows]
    n, u = g.shape
    clocks = u - 3
    const = np.argmax(np.abs(g[:, 3:]), axis=1)
    w = np.diag(1.0 / s**2)

    def projector(keep):
        cols = [0, 1, 2] + [3 + c for c in range(clocks) if np.any(const[keep] == c)]
        gk = g[np.ix_(keep, cols)]
        sk = np.linalg.solve(gk.T @ w[np.ix_(keep, keep)] @ gk, gk.T @ w[np.ix_(keep, keep)])
        full = np.zeros((3, n))
        full[:, keep] = sk[:3]
        return full, len(keep) >= len(cols)

    s0, _ = projector(np.arange(n))
    x0 = s0 @ r
    modes = [(np.delete(np.arange(n), i), P_SATELLITE) for i in range(n)]
    modes += [(np.flatnonzero(const != c), p_const[c]) for c in range(clocks) if np.any(const == c)]
    cov = np.diag(s**2)
    sig0 = np.sqrt(np.diag(s0 @ cov @ s0.T))
    kept = []
    p_nm = 0.5 * (n * P_SATELLITE) ** 2
    for keep, prior in modes:
        sk, ok = projector(keep) if len(keep) else (None, False)
        if not ok:
            p_nm += prior
            continue
        diff = sk - s0
        kept.append(
            (
                sk @ r - x0,
                np.sqrt(np.diag(sk @ cov @ sk.T)),
                np.sqrt(np.diag(diff @ cov @ diff.T)),
                prior,
            )
        )
    count = len(kept)
    k_fa = norm.isf(np.array([P_FA_HORIZONTAL / 4, P_FA_HORIZONTAL / 4, P_FA_VERTICAL / 2]) / count)
    scale = 1.0 - p_nm / (P_HMI_HORIZONTAL + P_HMI_VERTICAL)
    levels = []
    for q, budget in ((0, P_HMI_HORIZONTAL / 2), (1, P_HMI_HORIZONTAL / 2), (2, P_HMI_VERTICAL)):

        def excess(pl):
            total = 2 * norm.sf(pl / sig0[q])
            for _, sig, sig_ss, prior in kept:
                total += prior * norm.sf((pl - k_fa[q] * sig_ss[q]) / sig[q])
            return total - budget * scale

        levels.append(scipy.optimize.brentq(excess, 0.0, 1e12, xtol=1e-10, rtol=1e-14))
    thresholds = np.array([k_fa * sig_ss for _, _, sig_ss, _ in kept])
    separations = np.array([dx for dx, _, _, _ in kept])
    return np.hypot(levels[0], levels[1]), levels[2], thresholds, separations


@pytest.fixture(scope="module")
def geonet():
    obs = read_observations(data_path("07590920.05o"))
    result = monitor_receiver(
        receiver_epochs(obs, read_rinex_nav(data_path("07590920.05n"))), exclude=False
    )
    return jax.tree_util.tree_map(np.asarray, result.fix)


def one(fix, e):
    return jax.tree_util.tree_map(lambda a: a[e], fix)


def test_levels_match_the_long_way_on_the_geonet_hour(geonet):
    worst = 0.0
    for e in range(0, 120, 7):
        fix = one(geonet, e)
        ours = solution_separation(fix)
        hpl, vpl, thresholds, separations = reference(
            fix.geometry, fix.sigma, fix.residuals, fix.used, [P_CONSTELLATION]
        )
        monitored = np.asarray(ours.monitored)
        assert monitored.sum() == int(
            fix.used.sum()
        )  # the singles; the one-constellation mode removes everything
        np.testing.assert_allclose(
            np.asarray(ours.threshold)[monitored], thresholds, rtol=1e-9, atol=1e-9
        )  # metres: 1 nm
        np.testing.assert_allclose(
            np.asarray(ours.separation)[monitored], separations, rtol=1e-7, atol=1e-6
        )  # the fix converged to < 1e-7 m
        worst = max(worst, abs(float(ours.hpl) / hpl - 1), abs(float(ours.vpl) / vpl - 1))
    assert worst < 1e-9, worst


def test_levels_match_the_long_way_with_two_clocks():
    """The almanac's satellites above 5 deg at a point, odd PRNs as one constellation and
    even as another (a second clock column); the constellation modes are then monitored
    with their own priors."""
    from jaxfdi.gnss import (
        almanac_table,
        geodetic_to_ecef,
        read_yuma,
        satellite_position,
        select_orbits,
    )
    from jaxfdi.gnss._frames import elevation_azimuth, line_of_sight_ned

    table = almanac_table(read_yuma(data_path("gps_almanac_2086.yuma.txt")))
    receiver = np.asarray(geodetic_to_ecef(np.radians(37.4), np.radians(-122.2), 30.0))
    rng = np.random.default_rng(3)
    odd = np.asarray(table.prn) % 2 == 1
    checked = 0
    for t in np.arange(503808.0, 503808.0 + 86400.0, 1800.0):
        orbit, available = select_orbits(table, t)
        sats = satellite_position(orbit, t)
        elevation, _ = elevation_azimuth(receiver, sats)
        used = np.asarray(available) & (np.asarray(elevation) > np.radians(5.0))
        if min((used & odd).sum(), (used & ~odd).sum()) < 5:
            continue  # a constellation mode would leave too few satellites (unmonitorable at prior 1e-4)
        checked += 1
        los = np.asarray(line_of_sight_ned(receiver, sats))
        geometry = (
            np.concatenate([-los, odd[:, None], ~odd[:, None]], axis=1).astype(float)
            * used[:, None]
        )
        sigma = np.where(used, rng.uniform(0.5, 2.0, used.size), 1.0)
        residuals = np.where(used, rng.normal(0.0, sigma), 0.0)
        fix = PositionFix(
            np.zeros(3),
            np.zeros(()),
            residuals,
            geometry,
            sigma,
            used,
            used.sum(),
            np.zeros(used.size),
            np.zeros(used.size),
            dops(geometry, used),
            np.asarray(True),
        )
        p_const = np.array([1e-4, 1e-8])
        ours = solution_separation(fix, p_constellation=p_const)
        hpl, vpl, thresholds, _ = reference(geometry, sigma, residuals, used, p_const)
        monitored = np.asarray(ours.monitored)
        assert monitored[-2:].all() and monitored.sum() == used.sum() + 2
        np.testing.assert_allclose(
            np.asarray(ours.threshold)[monitored], thresholds, rtol=1e-9, atol=1e-9
        )  # metres: 1 nm
        assert float(ours.hpl) == pytest.approx(hpl, rel=1e-9) and float(ours.vpl) == pytest.approx(
            vpl, rel=1e-9
        )
    assert checked >= 5


def test_levels_never_fall_below_the_fault_free_ones(geonet):
    """On every epoch of the hour (5 to 7 satellites)."""
    ss = jax.vmap(solution_separation)(geonet)
    hff, vff = jax.vmap(fault_free_levels)(geonet)
    assert np.all(np.asarray(ss.hpl) >= np.asarray(hff)) and np.all(
        np.asarray(ss.vpl) >= np.asarray(vff)
    )
    assert np.all(np.isfinite(np.asarray(ss.hpl)[:115]))


@pytest.mark.parametrize("label", ["GSDC 2021 Pixel 4 XL", "GSDC 2022", "GSDC 2023 Pixel 7 Pro"])
def test_levels_match_the_long_way_on_phone_epochs(label):
    """Real multi-constellation epochs (a clock per constellation, its constellation-wide
    fault mode monitored with ``P_const``), every 20th epoch of the trace, through
    ``separate_epochs`` (the trace padded to 64 slots and seven clocks, cut back) and
    ``solution_separation`` of the epoch alone (the same decisions)."""
    from jaxfdi.scenarios.gnss_real import load_phone

    phone = load_phone(label)
    fixes = jax.tree_util.tree_map(np.asarray, monitor_receiver(phone, exclude=False).fix)
    clocks = fixes.geometry.shape[-1] - 3
    assert clocks == phone.clocks().shape[1] >= 3
    batch = jax.tree_util.tree_map(np.asarray, separate_epochs(fixes))
    for e in range(0, phone.gps_millis.size, 20):
        fix = one(fixes, e)
        ours, alone = one(batch, e), solution_separation(fix)
        for field in ("monitored", "alarm", "isolated"):
            np.testing.assert_array_equal(getattr(ours, field), getattr(alone, field))
        hpl, vpl, thresholds, separations = reference(
            fix.geometry, fix.sigma, fix.residuals, fix.used, [P_CONSTELLATION] * clocks
        )
        monitored = np.asarray(ours.monitored)
        # a satellite alone on its clock: sigma_ss is 0 here, ~1e-10 m of round-off there
        np.testing.assert_allclose(
            np.asarray(ours.threshold)[monitored], thresholds, rtol=1e-8, atol=1e-6
        )
        np.testing.assert_allclose(
            np.asarray(ours.separation)[monitored], separations, rtol=1e-6, atol=1e-6
        )
        assert float(ours.hpl) == pytest.approx(hpl, rel=1e-8) and float(ours.vpl) == pytest.approx(
            vpl, rel=1e-8
        )


def test_the_isolated_mode_is_the_fix_without_the_faulty_satellite():
    """Exclusion by solution separation: a 100 m step on one satellite of a GEONET epoch
    alarms, the mode it points at is that satellite's, and its fault-tolerant solution
    is the least-squares fix re-solved without it, to 0.2 % (the separation is linear at
    the all-in-view fix; the re-solve takes its elevation weights and atmospheric delays
    at its own position, up to 80 m away: 10 cm on 82 m measured)."""
    from jaxfdi.gnss import ecef_to_ned

    obs = read_observations(data_path("07590920.05o"))
    epochs = receiver_epochs(obs, read_rinex_nav(data_path("07590920.05n")))
    e, checked = 30, 0
    rho = np.asarray(epochs.pseudoranges)
    clean = jax.tree_util.tree_map(np.asarray, monitor_receiver(epochs, exclude=False).fix)
    for slot in np.flatnonzero(clean.used[e]):
        faulty = rho[e : e + 1].copy()
        faulty[0, slot] += 100.0
        trial = epochs._replace(times=epochs.times[e : e + 1], pseudoranges=faulty)
        fix = one(jax.tree_util.tree_map(np.asarray, monitor_receiver(trial, exclude=False).fix), 0)
        ss = solution_separation(fix)
        if not bool(ss.alarm):
            continue
        assert int(ss.isolated) == slot
        keep = rho[e : e + 1].copy()
        keep[0, slot] = np.nan
        refit = one(
            jax.tree_util.tree_map(
                np.asarray,
                monitor_receiver(
                    epochs._replace(times=epochs.times[e : e + 1], pseudoranges=keep), exclude=False
                ).fix,
            ),
            0,
        )
        moved = np.asarray(ecef_to_ned(refit.position, fix.position))
        np.testing.assert_allclose(np.asarray(ss.separation)[slot], moved, rtol=2e-3, atol=1e-2)
        checked += 1
    assert checked >= 3


def test_fixes_of_every_shape_share_two_programs(geonet):
    """``separate_epochs`` pads epochs, slots and several clocks: the GEONET hour (one clock)
    and its first 20 epochs compile one program, the four phone traces (3-5 clocks) one more."""
    from jaxfdi.gnss._solution_separation import _separations
    from jaxfdi.scenarios.gnss_real import PHONES, load_phone

    _separations.clear_cache()
    whole = separate_epochs(geonet)
    first = separate_epochs(one(geonet, slice(0, 20)))
    np.testing.assert_array_equal(np.asarray(first.hpl), np.asarray(whole.hpl)[:20])
    assert _separations._cache_size() == 1
    for label in PHONES:
        separate_epochs(monitor_receiver(load_phone(label), exclude=False).fix)
    assert _separations._cache_size() == 2
