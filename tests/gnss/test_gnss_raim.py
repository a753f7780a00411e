"""Parity RAIM and protection levels against NumPy/SciPy references and statistically:
P H = 0 and P P^T = I, the fault-free statistic chi-square(n - 4) (KS test), a bias
detected and isolated at the rate its noncentrality predicts, the HPL bounding the
horizontal error at P_md with the worst-case bias on the worst satellite, eq. 8 against
the chi-square threshold, exclusion, and one compiled program for every satellite count."""

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import optimize, stats

from jaxfdi import simulate
from jaxfdi._simulation import faults
from jaxfdi.data import data_path
from jaxfdi.gnss import (
    PositionFix,
    ecef_to_ned,
    elevation_sigma,
    ephemeris_table,
    geodetic_to_ecef,
    monitor_epochs,
    parity_check,
    protection_levels,
    raim_tables,
    read_rinex_nav,
    read_yuma,
    receiver_plant,
    select_orbits,
    solve_position,
)
from jaxfdi.gnss._integrity import geometry_fix
from jaxfdi.gnss._orbits import SPEED_OF_LIGHT, transmission_geometry
from jaxfdi.gnss._positioning import dops
from jaxfdi.gnss._raim import paper_threshold, parity_matrix

N = 2048  # epochs per batched call (one compiled program for every test)
SITE = geodetic_to_ecef(math.radians(37.5419), math.radians(127.0782), 60.0)
MASK = math.radians(5.0)
T0 = 259200.0 + 2700.0
CLOCK = 1234.5  # receiver clock bias [m]


@pytest.fixture(scope="module")
def table():
    return ephemeris_table(read_rinex_nav(data_path("gps_nav_rinex2_sugl0010.20n")), 2086)


@pytest.fixture(scope="module")
def measure(table):
    """(times (N,), bias (N, S), key) -> pseudoranges (N, S): the receiver at SITE, clock
    CLOCK, noise sigma(el), NaN below the mask; sigma (N, S) too."""

    def one(t, bias, key):
        orbit, ok = select_orbits(table, t)
        _, ranges, _, clock = transmission_geometry(orbit, t - CLOCK / SPEED_OF_LIGHT, SITE)
        fix = geometry_fix(table, t, SITE, MASK, elevation_sigma)
        rho = (
            ranges
            + CLOCK
            - SPEED_OF_LIGHT * clock
            + fix.sigma * jax.random.normal(key, ranges.shape)
            + bias
        )
        return jnp.where(fix.used & ok, rho, jnp.nan), fix.sigma

    return jax.jit(
        lambda times, bias, key: jax.vmap(one)(times, bias, jax.random.split(key, times.shape[0]))
    )


@pytest.fixture(scope="module")
def monitor(table):
    return jax.jit(
        lambda times, rho, tables: monitor_epochs(table, times, rho, tables, elevation_sigma)
    )


@pytest.fixture(scope="module")
def default_tables():
    return raim_tables(32)


def test_fault_free_statistic_is_chi_square(measure, monitor, default_tables):
    times = T0 + jnp.arange(N) * 40.0  # 23 h of geometries, 5-12 satellites
    rho, _ = measure(times, jnp.zeros((N, 32)), jax.random.key(0))
    result = monitor(times, rho, default_tables)
    dof = np.asarray(result.check.dof)
    assert dof.min() >= 1 and np.all(np.asarray(result.fix.healthy))
    u = stats.chi2.cdf(np.asarray(result.check.statistic), dof)
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert (
        stats.kstest(np.asarray(result.check.statistic)[dof == 4], stats.chi2(4).cdf).pvalue > 1e-3
    )
    assert np.mean(result.check.alarm) < 0.005  # P_fa 1/15000
    error = np.asarray(ecef_to_ned(result.fix.position, SITE))
    # the weighted fix is unbiased with the covariance its geometry predicts: chi-square(3)
    assert (
        abs(np.mean(error[:, 0])) < 0.2
        and abs(np.mean(np.asarray(result.fix.clock_bias) - CLOCK)) < 1.0
    )


def synthetic_fix(h, used, residual):
    """A fix with geometry ``h`` (S, 4), unit sigmas and whitened residuals."""
    return PositionFix(
        jnp.zeros(3),
        jnp.zeros(()),
        jnp.where(used, residual, 0.0),
        jnp.where(used[:, None], h, 0.0),
        jnp.ones(used.shape),
        used,
        jnp.sum(used),
        jnp.zeros(used.shape),
        jnp.zeros(used.shape),
        dops(jnp.where(used[:, None], h, 0.0), used),
        jnp.asarray(True),
    )


def random_geometry(rng, n, slots=32):
    el = rng.uniform(0.1, 1.5, slots)
    az = rng.uniform(0, 2 * np.pi, slots)
    h = np.concatenate(
        [
            -np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], 1),
            np.ones((slots, 1)),
        ],
        axis=1,
    )
    used = np.zeros(slots, bool)
    used[rng.choice(slots, n, replace=False)] = True
    return h, used


@pytest.mark.parametrize("clocks", [1, 2])
def test_parity_matrix_and_statistics_match_numpy(clocks):
    """Against a NumPy complete QR of the visible rows; ``clocks = 2``: a second receiver
    clock (a second constellation: half the slots), u = 5 unknowns, so n - 5 degrees of
    freedom and the threshold and protection level of n - 5; where one constellation has
    no satellite in view its clock is no unknown (the reference drops the column: u = 4)."""
    rng = np.random.default_rng(3)
    tables = raim_tables(32)
    explicit = jax.jit(lambda h, used, y: parity_matrix(synthetic_fix(h, used, y)))
    check = jax.jit(lambda h, used, y: parity_check(synthetic_fix(h, used, y), tables))
    levels = jax.jit(lambda h, used, y: protection_levels(synthetic_fix(h, used, y), tables))
    cases = [(n, None) for n in (3 + clocks + 1, 3 + clocks + 2, 9, 13, 32)]
    if clocks == 2:
        cases += [(n, 2) for n in (5, 6, 9)]  # every used satellite on the first clock
    for n, only in cases:
        h, used = random_geometry(rng, n, slots=32 if only is None else 16)
        u = 3 + clocks
        if clocks == 2:  # slots 16-31 on the second clock
            if only is not None:
                h, used = np.concatenate([h, h]), np.concatenate([used, np.zeros(16, bool)])
            second = np.arange(32) >= 16
            h = np.concatenate([h[:, :3], (~second)[:, None] * 1.0, second[:, None] * 1.0], axis=1)
            if not (used & second).any() or not (used & ~second).any():
                u = 4
        y = rng.normal(size=32) * 3.0
        P, valid = map(np.asarray, explicit(h, used, y))
        Pv = P[valid]
        assert Pv.shape == (n - u, 32)
        np.testing.assert_allclose(Pv @ (h * used[:, None]), 0.0, atol=1e-12)  # P H = 0
        np.testing.assert_allclose(Pv @ Pv.T, np.eye(n - u), atol=1e-12)  # P P^T = I
        assert np.all(Pv[:, ~used] == 0.0) and np.all(P[~valid] == 0.0)
        # NumPy reference on the visible rows only (complete QR, the paper's construction)
        hv, yv = h[used], y[used]
        hv = hv[:, np.any(hv != 0.0, axis=0)]  # a clock out of view is no unknown
        q, _ = np.linalg.qr(hv, mode="complete")
        p_ref = q[:, u:].T @ yv
        result = check(h, used, y)
        assert float(result.statistic) == pytest.approx(p_ref @ p_ref, rel=1e-10)
        assert int(result.dof) == n - u
        assert float(result.threshold) == pytest.approx(
            stats.chi2.isf(1.0 / 15000.0, n - u), rel=1e-8
        )
        cols = q[:, u:].T
        # a satellite alone on its clock has S_jj = 0 (its clock absorbs it): unobservable,
        # no isolation statistic and no slope (the library's rule, S_jj <= 1e-9)
        norms = np.linalg.norm(cols, axis=0)
        seen = norms**2 > 1e-9
        ts_ref = np.where(seen, (p_ref @ cols) / np.where(seen, norms, 1.0), 0.0)  # eq. 9
        np.testing.assert_allclose(np.asarray(result.isolation)[used], ts_ref, atol=1e-10)
        assert int(result.isolated) == (
            np.flatnonzero(used)[np.argmax(np.abs(ts_ref))] if n >= u + 2 else -1
        )
        # protection level by eqs. 10-11 with sigma = 1: A = (H^T H)^-1 H^T, S = P^T P
        A = np.linalg.solve(hv.T @ hv, hv.T)
        S = cols.T @ cols
        root = np.sqrt(np.where(seen, np.diag(S), 1.0))
        slope = np.where(seen, np.hypot(A[0], A[1]) / root, 0.0)
        threshold = stats.chi2.isf(1.0 / 15000.0, n - u)
        lam = optimize.brentq(
            lambda v: stats.ncx2.cdf(threshold, n - u, v) - 1e-3, 1e-6, 500.0, xtol=1e-13
        )
        pl = levels(h, used, y)
        # the reference's normal equations lose digits where a constellation has one or two
        # satellites (S_ii near 0, HPL ~ 1e4 m): 1e-6 there
        rel = 1e-8 if clocks == 1 else 1e-6
        assert float(pl.hpl) == pytest.approx(slope.max() * np.sqrt(lam), rel=rel)
        assert float(pl.vpl) == pytest.approx(
            np.max(np.where(seen, np.abs(A[2]) / root, 0.0)) * np.sqrt(lam), rel=rel
        )
        np.testing.assert_allclose(
            np.asarray(pl.minimum_detectable_bias)[used],
            np.where(seen, np.sqrt(lam) / root, np.inf),
            rtol=rel,
        )


#: Galileo's nominal constellation as the ARAIM studies use it: Walker 24/3/1, a = 29 600.318
#: km, i = 56 deg (EU-U.S. Working Group C, ARAIM Technical Subgroup, Milestone 3 Report, 2016)
GALILEO_WALKER = dict(
    a=29_600_318.0, inclination=np.radians(56.0), planes=3, per_plane=8, phasing=1
)
GM = 3.986004418e14


def circular_positions(a, inclination, raan, argument_of_latitude):
    """(S, 3) inertial positions of circular orbits."""
    cu, su, co, so, ci, si = (
        np.cos(argument_of_latitude),
        np.sin(argument_of_latitude),
        np.cos(raan),
        np.sin(raan),
        np.cos(inclination),
        np.sin(inclination),
    )
    return np.stack(
        [a * (cu * co - su * ci * so), a * (cu * so + su * ci * co), a * su * si], axis=1
    )


def gps_and_galileo_nominal(t):
    """(48, 3) positions of the RTCA MOPS (DO-229) 24-satellite GPS almanac and Galileo's
    Walker 24/3/1 at ``t`` s after the almanac's reference time, both as circular orbits in
    one inertial snapshot, and the (48,) constellation index (0 GPS, 1 Galileo)."""
    alm = read_yuma(data_path("gps_almanac_0703_rtca_mops24.yuma.txt"))
    assert np.all(np.asarray(alm.eccentricity) == 0.0)
    a = np.asarray(alm.sqrt_a) ** 2
    gps = circular_positions(
        a,
        np.asarray(alm.inclination),
        np.asarray(alm.omega0),
        np.asarray(alm.argument_of_perigee) + np.asarray(alm.mean_anomaly) + np.sqrt(GM / a**3) * t,
    )
    w = GALILEO_WALKER
    plane, slot = np.divmod(np.arange(w["planes"] * w["per_plane"]), w["per_plane"])
    total = w["planes"] * w["per_plane"]
    galileo = circular_positions(
        w["a"],
        w["inclination"],
        2 * np.pi * plane / w["planes"],
        2 * np.pi * (slot / w["per_plane"] + w["phasing"] * plane / total)
        + np.sqrt(GM / w["a"] ** 3) * t,
    )
    return np.concatenate([gps, galileo]), np.repeat([0, 1], [len(gps), total])


def test_two_clock_slope_levels_on_the_nominal_gps_and_galileo_constellations():
    """The published dual-constellation geometry of ARAIM availability studies (GPS's
    DO-229 24 satellites, Galileo's Walker 24/3/1), seen from 12 users over 6 hours with a
    5 deg mask: ``H = [-u_NED^T, e_GPS, e_GAL]`` in NumPy, the parity statistic with
    ``n - 5`` degrees of freedom, slope HPL/VPL and minimum detectable biases (Brown & Chin
    1992) against SciPy's chi-square and noncentral chi-square, rel 1e-8."""
    tables = raim_tables(48, pfa=1e-3, pmd=1e-3)
    run = jax.jit(
        lambda h, used, y: (
            parity_check(synthetic_fix(h, used, y), tables),
            protection_levels(synthetic_fix(h, used, y), tables),
        )
    )
    rng = np.random.default_rng(11)
    lam_of, checked = {}, 0
    for lat, lon in zip(
        np.radians([-60, -30, 0, 20, 37.4, 52, 70, 80, 10, -45, 45, 65]),
        np.radians([0, 30, 60, 90, -122.1, 150, 180, -150, -90, -60, -30, 5]),
    ):
        user = (
            np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
            * 6_371_000.0
        )
        ned = np.array(
            [
                [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)],
                [-np.sin(lon), np.cos(lon), 0.0],
                user / -np.linalg.norm(user),
            ]
        )
        for t in np.arange(0.0, 6 * 3600.0, 3600.0):
            sats, system = gps_and_galileo_nominal(t)
            los = (sats - user) @ ned.T
            los /= np.linalg.norm(los, axis=1, keepdims=True)
            used = -los[:, 2] > np.sin(np.radians(5.0))
            h = np.concatenate(
                [-los, (system == 0)[:, None] * 1.0, (system == 1)[:, None] * 1.0], axis=1
            )
            y = rng.normal(size=48)
            check, levels = run(h, used, y)
            hv, yv = h[used], y[used]
            n = hv.shape[0]
            dof = n - 5
            assert (
                (system[used] == 0).sum() >= 4
                and (system[used] == 1).sum() >= 4
                and int(check.dof) == dof
            )
            A = np.linalg.solve(hv.T @ hv, hv.T)
            S = np.eye(n) - hv @ A
            assert float(check.statistic) == pytest.approx(yv @ S @ yv, rel=1e-8)
            if dof not in lam_of:
                threshold = stats.chi2.isf(1e-3, dof)
                lam_of[dof] = optimize.brentq(
                    lambda v: stats.ncx2.cdf(threshold, dof, v) - 1e-3, 1e-6, 1e3, xtol=1e-13
                )
            root = np.sqrt(np.diag(S))
            scale = np.sqrt(lam_of[dof])
            assert float(levels.hpl) == pytest.approx(
                np.max(np.hypot(A[0], A[1]) / root) * scale, rel=1e-8
            )
            assert float(levels.vpl) == pytest.approx(np.max(np.abs(A[2]) / root) * scale, rel=1e-8)
            np.testing.assert_allclose(
                np.asarray(levels.minimum_detectable_bias)[used], scale / root, rtol=1e-8
            )
            checked += 1
    assert checked == 72


def test_one_program_for_every_satellite_count():
    rng = np.random.default_rng(4)
    tables = raim_tables(32)

    @jax.jit
    @chex.assert_max_traces(n=1)
    def check(h, used, y):
        return parity_check(synthetic_fix(h, used, y), tables).statistic

    for n in (4, 5, 8, 20):
        h, used = random_geometry(rng, n)
        assert np.isfinite(float(check(h, used, rng.normal(size=32))))


def test_paper_threshold_against_chi_square():
    pfa = 0.02
    chi2_rule, paper_rule = raim_tables(32, pfa, rule="chi2"), raim_tables(32, pfa, rule="paper")
    dof = np.arange(1, 29)
    np.testing.assert_allclose(
        np.asarray(chi2_rule.threshold)[1:], stats.chi2.isf(pfa, dof), rtol=1e-10
    )
    # eq. 8 bounds the RMS parity: on p^T p it is 2 ln(1/pfa) for every n; exact for n - 4 = 2 only
    n = dof + 4
    np.testing.assert_allclose(
        np.asarray(paper_threshold(n, pfa, 3.0)) ** 2 * (n - 4) / 9.0, 2 * np.log(1 / pfa)
    )
    np.testing.assert_allclose(np.asarray(paper_rule.threshold)[1:], 2 * np.log(1 / pfa))
    assert float(paper_rule.threshold[2]) == pytest.approx(float(chi2_rule.threshold[2]), rel=1e-10)
    # Monte Carlo false-alarm rates of both rules, fault-free, n = 5, 6, 9 (dof 1, 2, 5)
    rng = np.random.default_rng(5)
    runs = 4000
    alarms = jax.jit(
        jax.vmap(
            lambda h, used, y, tab: parity_check(synthetic_fix(h, used, y), tab).alarm,
            in_axes=(None, None, 0, None),
        )
    )
    for n in (5, 6, 9):
        h, used = random_geometry(rng, n)
        y = rng.normal(size=(runs, 32))
        for tab, expected in (
            (chi2_rule, pfa),
            (paper_rule, stats.chi2.sf(2 * np.log(1 / pfa), n - 4)),
        ):
            rate = float(np.mean(alarms(h, used, y, tab)))
            low, high = stats.binomtest(int(rate * runs), runs, expected).proportion_ci(0.999)
            assert stats.binomtest(int(round(rate * runs)), runs, expected).pvalue > 1e-3, (
                n,
                rate,
                expected,
            )
    # the paper's rule is conservative at dof 1 and lax from dof 3 on
    assert stats.chi2.sf(2 * np.log(1 / pfa), 1) < pfa < stats.chi2.sf(2 * np.log(1 / pfa), 3)


@pytest.fixture(scope="module")
def fixed_epoch(table):
    """One geometry (T0) seen N times: its fault-free fix, whitened S, sigmas and slots."""
    fix = geometry_fix(table, T0, SITE, MASK, elevation_sigma)
    used = np.asarray(fix.used)
    hw = np.asarray(fix.geometry)[used] / np.asarray(fix.sigma)[used][:, None]
    S = np.eye(used.sum()) - hw @ np.linalg.solve(hw.T @ hw, hw.T)
    return fix, used, np.asarray(fix.sigma)[used], S


def test_bias_detected_and_isolated_at_the_predicted_rate(
    measure, monitor, default_tables, fixed_epoch
):
    fix, used, sigma, S = fixed_epoch
    slots = np.flatnonzero(used)
    n = slots.size
    j = int(np.argmax(np.diag(S)))  # the best-observed satellite
    lam = 16.0  # noncentrality of the injected bias
    bias_m = math.sqrt(lam / S[j, j]) * sigma[j]
    bias = jnp.zeros((N, 32)).at[:, slots[j]].set(bias_m)
    times = jnp.full(N, T0)
    rho, _ = measure(times, bias, jax.random.key(1))
    result = monitor(times, rho, default_tables)
    alarm = np.asarray(result.check.alarm)
    threshold = stats.chi2.isf(1.0 / 15000.0, n - 4)
    p_detect = stats.ncx2.sf(threshold, n - 4, lam)
    assert stats.binomtest(int(alarm.sum()), N, p_detect).pvalue > 1e-3, (alarm.mean(), p_detect)
    # detection and correct isolation: the Gaussian isolation vector of eq. 9 drawn with NumPy
    rng = np.random.default_rng(6)
    e = rng.normal(size=(400000, n))
    e[:, j] += bias_m / sigma[j]
    projected = e @ S
    ts = projected / np.sqrt(np.diag(S))
    predicted = np.mean(
        (np.sum(e * projected, axis=1) > threshold) & (np.argmax(np.abs(ts), axis=1) == j)
    )
    correct = alarm & (np.asarray(result.check.isolated) == slots[j])
    assert stats.binomtest(int(correct.sum()), N, predicted).pvalue > 1e-3, (
        correct.mean(),
        predicted,
    )
    assert np.all(np.asarray(result.excluded)[correct] == slots[j])


def test_protection_level_bounds_the_error_at_pmd(table, measure, monitor, fixed_epoch):
    pmd = 0.01
    tables = raim_tables(32, pmd=pmd)
    fix, used, sigma, S = fixed_epoch
    slots = np.flatnonzero(used)
    n = slots.size
    levels = protection_levels(fix, tables)
    worst = int(np.argmax(np.asarray(levels.slope_horizontal)[used]))
    lam = float(tables.noncentrality[n - 4])
    bias_m = (
        math.sqrt(lam / S[worst, worst]) * sigma[worst]
    )  # the bias missed with probability P_md
    times = jnp.full(N, T0)
    missed = hazardous = total = 0
    errors = []
    for seed in range(3):
        rho, _ = measure(
            times, jnp.zeros((N, 32)).at[:, slots[worst]].set(bias_m), jax.random.key(10 + seed)
        )
        result = monitor(times, rho, tables)
        ned = np.asarray(ecef_to_ned(result.fix.position, SITE))
        horizontal = np.hypot(ned[:, 0], ned[:, 1])
        no_alarm = ~np.asarray(result.check.alarm)
        missed += int(no_alarm.sum())
        hazardous += int((no_alarm & (horizontal > np.asarray(result.protection.hpl))).sum())
        total += N
        errors.append(horizontal)
    assert stats.binomtest(missed, total, pmd).pvalue > 1e-3, (missed / total, pmd)
    assert stats.binomtest(hazardous, total, pmd, alternative="greater").pvalue > 1e-3, (
        hazardous / total
    )
    assert 0 < hazardous < missed
    # the worst bias moves the fix by HPL (its slope times sqrt(lambda)) on average
    assert float(np.mean(np.concatenate(errors))) == pytest.approx(float(levels.hpl), rel=0.05)


def test_exclusion_removes_a_large_fault(measure, monitor, default_tables, fixed_epoch):
    fix, used, sigma, S = fixed_epoch
    slots = np.flatnonzero(used)
    target = slots[int(np.argmax(np.diag(S)))]
    times = jnp.full(N, T0)
    rho, _ = measure(times, jnp.zeros((N, 32)).at[:, target].set(300.0), jax.random.key(2))
    result = monitor(times, rho, default_tables)
    assert np.all(np.asarray(result.check.alarm)) and np.all(np.asarray(result.excluded) == target)
    after = np.asarray(result.check_excluded.alarm)
    assert after.mean() < 0.01
    ned = np.asarray(ecef_to_ned(result.fix_excluded.position, SITE))
    before = np.asarray(ecef_to_ned(result.fix.position, SITE))
    after_error, before_error = np.hypot(ned[:, 0], ned[:, 1]), np.hypot(before[:, 0], before[:, 1])
    assert np.percentile(after_error, 95) < 20.0 and np.median(after_error) < np.median(
        before_error
    )
    assert int(result.check_excluded.dof[0]) == int(result.check.dof[0]) - 1


def test_plant_and_solver_agree_and_faults_hit_their_slot(table):
    """The receiver plant (time tags in receiver time, light time, Sagnac, satellite clocks)
    and the solver invert each other to < 1 mm without noise; Table 2's faults act on
    their slot as the foundation's fault table says."""
    steps = 8
    path = jnp.tile(SITE, (steps, 1))
    visible = jnp.stack(
        [geometry_fix(table, T0 + k, SITE, MASK, elevation_sigma).used for k in range(steps)]
    )
    slot = int(np.flatnonzero(np.asarray(visible[0]))[0])
    fault = faults.concat_faults(
        faults.fault("impulse", "sensor", slot, 1, 100.0),
        faults.fault("bias", "sensor", slot, 3, 100.0, end=5),
        faults.fault("ramp", "sensor", slot, 5, 0.0, 1.0, end=7),
    )
    us = jnp.zeros((steps, 0))
    x0 = jnp.asarray([CLOCK, 0.3])
    _, clean, _ = simulate(
        receiver_plant(table, T0, 1.0, path, visible, jnp.zeros((steps, 32))),
        x0,
        us,
        jax.random.key(0),
    )
    _, faulty, _ = simulate(
        receiver_plant(table, T0, 1.0, path, visible, jnp.zeros((steps, 32)), fault=fault),
        x0,
        us,
        jax.random.key(0),
    )
    added = np.asarray(faulty.measurement - clean.measurement)[:, slot]
    np.testing.assert_allclose(added, [0, 100, 0, 100, 100, 0, 1, 0], atol=1e-6)
    assert np.all(
        np.asarray(faulty.mode) == [0, 1 + slot, 0, 1 + slot, 1 + slot, 1 + slot, 1 + slot, 0]
    )
    for k in (0, 6):
        orbit, ok = select_orbits(table, T0 + k)
        sol = solve_position(orbit, T0 + k, clean.measurement[k], ok)
        assert np.max(np.abs(np.asarray(sol.position - SITE))) < 1e-3
        assert float(sol.clock_bias) == pytest.approx(float(clean.state[k, 0]), abs=1e-3)


def test_raim_statistic_is_the_sensor_parity_statistic():
    """``TS_D`` (QR on the used slots) is ``detection.parity``'s ``p^T p`` of the explicit
    parity vector ``P y_w``, and ``P`` spans the same left null space as the sensors' SVD
    basis of the used rows (``V^T V = P^T P``)."""
    from jaxfdi.detection import _parity as ps

    rng = np.random.default_rng(11)
    tables = raim_tables(32)
    for n in (5, 8, 13):
        h, used = random_geometry(rng, n)
        fix = synthetic_fix(jnp.asarray(h), jnp.asarray(used), jnp.asarray(rng.normal(size=32)))
        P, valid = parity_matrix(fix)
        parity = P @ fix.residuals
        assert float(parity_check(fix, tables).statistic) == pytest.approx(
            float(ps.parity_statistic(parity, valid)), rel=1e-12
        )
        V = np.asarray(ps.parity_space(h[used]).V)
        Pv = np.asarray(P)[np.asarray(valid)][:, used]
        np.testing.assert_allclose(Pv.T @ Pv, V.T @ V, atol=1e-12)
