"""The seed-002 GPS scenario end to end (small): the campus case's HDOP > 4 and HPL > 556 m
where the wall hides the eastern sky while the parity test stays quiet, the park case's
Table 2 faults detected, isolated and excluded, JSON-ready rows and the figures; beyond the
paper (issue 37), a dead and a frozen channel on the same satellite, against closed forms:
the dead one alarms at the epoch it dies, the frozen one within the epochs its range rate
needs to cross the RAIM threshold (orbits, geometry and the chi-square quantile computed
here with NumPy / SciPy)."""

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _frames import assert_table_is_the_json
from scipy import stats

from jaxfdi.data import data_path
from jaxfdi.gnss import (
    ClockModel,
    ephemeris_table,
    geodetic_to_ecef,
    racetrack_ecef,
    read_rinex_nav,
    satellite_position,
    select_orbits,
    visibility,
)
from jaxfdi.gnss._orbits import SPEED_OF_LIGHT, satellite_clock
from jaxfdi.scenarios.gnss_campus import (
    DT,
    MASK_DEG,
    PARK,
    PARK_FAULTS,
    PARK_PATH,
    START_TOW,
    TABLE2_FAULTS,
    WEEK,
    gnss_campus_study,
    plot_gnss_campus,
)


@pytest.fixture(scope="module")
def study():
    return gnss_campus_study(runs=2, seed=0, all_satellites=False, beyond=False)


def test_campus_geometry_not_the_statistic(study):
    campus = study.rows[0]
    assert campus["case"] == "campus"
    high, over = set(campus["hdop_over_4_epochs"]), set(campus["hpl_over_556_epochs"])
    assert (
        len(high) >= 10
        and len(over) >= 8
        and over <= high | {e + 1 for e in high} | {e - 1 for e in high}
    )
    assert {480, 790} <= over  # the paper's epochs
    assert campus["alarm_rate_where_hpl_over"] == 0.0  # the parity test cannot see geometry
    assert (
        campus["horizontal_error_p95_where_hpl_over_m"]
        > 3 * campus["horizontal_error_p95_elsewhere_m"]
    )
    assert campus["unhealthy_epochs"] == 0 and 0.95 < campus["availability_npa"] < 1.0
    # the satellites the wall hides are "not measured" (NaN), never dead channels: no epoch of
    # the first fault-free run (the series kept) has a dead slot's infinite statistic, and the
    # alarms of both (2 runs x 1000 epochs at P_fa = 1/15000) stay within the binomial 99.9 % bound
    assert np.all(np.isfinite(study.campus["statistic"]))
    alarms = int(round(float(study.campus["alarm_rate"].sum()) * 2))
    assert alarms <= stats.binom.ppf(
        0.999, 2 * study.campus["alarm_rate"].size, study.config["pfa"]
    )


def test_park_faults_detected_isolated_excluded(study):
    park = [r for r in study.rows if r["case"] == "park"]
    assert len(park) == len(PARK_FAULTS) == 5 and all(
        r["headline"] and r["unhealthy_runs"] == 0 for r in park
    )
    assert [r["paper"] for r in park] == ["detected"] * 3 + ["beyond the paper"] * 2
    by_fault = {r["fault"].split()[0]: r for r in park}
    assert by_fault["impulse"]["detected"] == 1.0 and by_fault["bias"]["detected"] == 1.0
    assert by_fault["impulse"]["excluded"] == 1.0 and by_fault["bias"]["isolated"] == 1.0
    assert by_fault["drift"]["detected"] == 1.0 and 10 <= by_fault["drift"]["delay_median_s"] <= 60
    assert float(np.max(study.park["hdop"])) < 1.8 and float(np.max(study.park["hpl"])) < 556.0
    json.dumps({"config": study.config, "rows": study.rows})  # JSON-ready
    table = study.table()
    assert "Campus" in table and all(name in table for name, *_ in PARK_FAULTS)
    assert table.count("beyond the paper") == 2 and len(TABLE2_FAULTS) == 3


def _frozen_delay_bound(prn: int, z: float = 4.0) -> tuple[int, int]:
    """``(bound, window)``: epochs after the onset within which RAIM must alarm on a channel
    frozen at the onset, and the episode's length.

    The channel holds ``rho(k0) = g(k0) + b(k0) + sigma n0``, with ``g = |r_sat - x| - c dt_sat``;
    the model at ``k0 + j`` wants ``g(k0 + j) + b(k0 + j)``: a one-channel error
    ``e_j = -(dg_j + db_j) + sigma n0``. In the whitened parity space (``S = I - H (H^T H)^-1 H^T``,
    ``H`` the rows ``[-u^T, 1] / sigma`` of the used satellites) ``TS_D >= (|e_j| sqrt(S_ii) /
    sigma_i - |w|)^2``, ``w ~ N(0, <= 1)`` the other channels' noise along channel i's unit parity
    direction, so the test alarms once ``|e_j| >= sigma_i (sqrt(T) + z) / sqrt(S_ii)`` with
    ``T = chi2.isf(P_fa, n - 4)`` and ``|w| <= z``. With ``|n0| <= z`` and the receiver clock
    (``x' = [[1, 1], [0, 1]] x + w``, ``w ~ N(0, Q)``, Q of Brown & Hwang 2012 sec. 9.3:
    ``|d(k0)| <= D = |d0| + z sqrt(k0 Q11)``, and over j steps ``db_j - d(k0) j`` has the variance
    ``sum_l Q00 + 2 l Q01 + l^2 Q11``, l = 0..j-1), ``|e_j| >= |dg_j| - D j - z sqrt(var_j) -
    z sigma_i``; 1 m more covers the light time and Earth rotation left out of ``dg``. Each
    ``|.| <= z`` fails with probability 6e-5 at z = 4."""
    _, _, k0, end, *_ = next(f for f in PARK_FAULTS if f[1] == "stuck")
    table = ephemeris_table(read_rinex_nav(data_path("gps_nav_rinex2_sugl0010.20n")), WEEK)
    slot = int(np.flatnonzero(np.asarray(table.prn) == prn)[0])
    origin = geodetic_to_ecef(math.radians(PARK[0]), math.radians(PARK[1]), PARK[2])
    steps = np.arange(k0, end)
    path = racetrack_ecef(jnp.asarray(steps * DT), origin, *PARK_PATH)
    times = START_TOW + jnp.asarray(steps * DT)

    def sky(t, x):
        orbit, _ = select_orbits(table, t)
        return (
            satellite_position(orbit, t)[slot],
            satellite_clock(orbit, t)[slot],
            *visibility(table, t, x, math.radians(MASK_DEG)),
        )

    sat, clock, seen, el, az = (np.asarray(a) for a in jax.jit(jax.vmap(sky))(times, path))
    g = np.linalg.norm(sat - np.asarray(path), axis=1) - SPEED_OF_LIGHT * clock
    dg = np.abs(g - g[0])
    h0, h2, c2 = ClockModel().h0, ClockModel().h_minus2, SPEED_OF_LIGHT**2
    qb, qd = (
        0.5 * h0 * c2 * DT,
        2 * math.pi**2 * h2 * c2 * DT,
    )  # Q = [[qb + qd/3, qd/2], [qd/2, qd]] (1 s)
    q00, q01, q11 = qb + qd / 3, qd / 2, qd
    drift = abs(ClockModel().drift) + z * math.sqrt(k0 * q11)
    for j in range(1, steps.size):
        used = seen[j]
        sigma = np.sqrt(9.0 + 9.0 / np.sin(el[j]) ** 2)
        los = np.stack(
            [np.cos(el[j]) * np.cos(az[j]), np.cos(el[j]) * np.sin(az[j]), -np.sin(el[j])], axis=1
        )
        h = (np.concatenate([-los, np.ones((los.shape[0], 1))], axis=1) / sigma[:, None])[used]
        s = np.eye(h.shape[0]) - h @ np.linalg.solve(h.T @ h, h.T)
        i = int(np.flatnonzero(np.flatnonzero(used) == slot)[0])
        threshold = stats.chi2.isf(1.0 / 15000.0, h.shape[0] - 4)
        needed = sigma[slot] * (math.sqrt(threshold) + z) / math.sqrt(s[i, i])
        walk = sum(q00 + 2 * m * q01 + m**2 * q11 for m in range(j))
        error = dg[j] - drift * j - z * math.sqrt(walk) - z * sigma[slot] - 1.0
        if error >= needed:
            return j, steps.size
    return steps.size, steps.size


def test_dead_and_frozen_channels_detected_isolated_excluded(study):
    """Beyond the paper: a dead channel (tracked, no value) alarms, isolates and excludes its
    satellite at the epoch it dies (delay 0); a frozen one at the first epochs its range has
    moved past the threshold (bound derived above; none at the onset, where the held value
    is the measurement); the fix without it stays within the alert limit."""
    by_fault = {r["fault"].split()[0]: r for r in study.rows if r["case"] == "park"}
    dead, frozen = by_fault["dead"], by_fault["frozen"]
    for row in (dead, frozen):
        assert row["runs"] == 2 and row["unhealthy_runs"] == 0
        assert row["detected"] == row["isolated"] == row["excluded"] == 1.0
        assert np.isfinite(row["horizontal_error_after_exclusion_p95_m"])
        assert (
            row["horizontal_error_after_exclusion_p95_m"] < study.config["horizontal_alert_limit_m"]
        )
    assert dead["delay_median_s"] == dead["delay_p90_s"] == 0.0
    bound, window = _frozen_delay_bound(frozen["prn"])
    assert bound < window  # the derivation: detected within the episode
    assert 1.0 <= frozen["delay_median_s"] <= frozen["delay_p90_s"] <= bound * DT


def test_figures(study, tmp_path):
    """The study's figures are captioned ``Figure`` s a notebook shows; ``save_figures`` writes
    each under its file name."""
    from matplotlib.figure import Figure

    from jaxfdi.plotting import save_figures

    figures = plot_gnss_campus(study)
    assert len(figures) == 3 and all(isinstance(f, Figure) for f in figures.values())
    save_figures(figures, tmp_path)
    assert all((tmp_path / name).stat().st_size > 10_000 for name in figures)


def test_the_table_as_a_data_frame_is_the_rows(study):
    """``to_frame()`` holds every row's numbers (the JSON the CLI writes), one row per
    method and case; ``_repr_html_`` renders it for a notebook."""
    assert_table_is_the_json(study.to_frame(), study.rows)
    assert "<table" in study._repr_html_()
