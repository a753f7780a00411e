"""Smartphone traces (Google Smartphone Decimeter Challenge 2021-2023, every constellation)
against gnss_lib_py 1.1 (Stanford NavLab), NumPy/SciPy and the files' own fields.

- Reader: the 2022/2023 files against gnss_lib_py's parsers, value for value (corrected
  pseudorange, satellite position, Google's fix; the same measurements kept); the 2021
  files against pandas with the data notes' formula and the one-epoch time shift, which
  must put every kept signal's flight time where a satellite's can be; ground truth
  against gnss_lib_py's parsers (ECEF within 1 mm: two closed forms of the same
  conversion). Damaged copies name the file and line.
- Positions: unit weights and one clock against gnss_lib_py's ``solve_wls`` within 1 mm
  (both iterate Gauss-Newton to convergence on the same equations; its Sagnac rotation
  uses the measured instead of the geometric flight time, 33 ns apart for 10 m of
  residual: 0.06 mm at the satellite).
- Fault detection and exclusion at gnss_lib_py's threshold (3000 m^2 on the unweighted
  residual sum of squares, one exclusion) against its greedy residual FDE: the same
  alarm at every epoch, and every exclusion that differs is the one its normalised
  residual without the clock column picks (``1 - h_ii`` of the line-of-sight columns
  alone), ours being the one with it.
- One clock per constellation: the slope protection level, minimum detectable biases
  and the parity statistic with its ``n - 3 - C`` degrees of freedom against a NumPy /
  SciPy computation on every epoch of the four traces (rel 1e-8).
- Padding: the traces share one compiled program, and the padded result cut back equals
  each trace solved at its own shape (positions within 1 um).
- Bad channels in a padded trace: a NaN channel equals the trace without it, an infinite
  one is a dead channel (flagged, excluded, alarmed), a frozen one is isolated and excluded.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest
from scipy import optimize, stats

from jaxfdi.data import data_path
from jaxfdi.gnss import (
    ecef_to_geodetic,
    geodetic_to_ecef,
    monitor_receiver,
    raim_output,
    raim_tables,
    read_android,
)
from jaxfdi.gnss._android import read_android_ground_truth
from jaxfdi.scenarios.gnss_real import (
    PEER_THRESHOLD,
    PHONE_EXCLUSIONS,
    PHONES,
    _peer_navdata,
    _peer_row,
    load_phone,
)

gnss_lib_py = pytest.importorskip("gnss_lib_py")
from gnss_lib_py.algorithms.snapshot import solve_wls  # noqa: E402 (after importorskip)
from gnss_lib_py.parsers import google_decimeter as glp  # noqa: E402

LETTER = {"gps": "G", "glonass": "R", "qzss": "J", "beidou": "C", "galileo": "E"}


@pytest.mark.parametrize(
    "name, parser",
    [
        ("gsdc2022_device_gnss.csv", glp.AndroidDerived2022),
        ("gsdc2023_device_gnss.csv", glp.AndroidDerived2023),
    ],
)
def test_device_gnss_files_read_as_gnss_lib_py_reads_them(name, parser):
    ours = read_android(data_path(name))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nav = parser(str(data_path(name)))
    raw = pd.read_csv(data_path(name))
    signal = raw["SignalType"].fillna("").to_numpy() != ""  # rows without a signal type are skipped
    nav = nav.copy(cols=np.flatnonzero(signal))
    at = np.searchsorted(ours.gps_millis, np.asarray(nav["gps_millis"]).astype(np.int64))
    assert np.array_equal(ours.gps_millis[at], np.asarray(nav["gps_millis"]).astype(np.int64))
    names = [
        f"{LETTER[c]}{s:02d} {t}"
        for c, s, t in zip(nav["gnss_id"], raw["Svid"][signal], raw["SignalType"][signal])
    ]
    slot = np.array([ours.signal.index(n) for n in names])
    assert len(set(zip(at, slot))) == at.size == np.isfinite(ours.satellite[..., 0]).sum()
    np.testing.assert_array_equal(ours.pseudorange[at, slot], np.asarray(nav["corr_pr_m"]))
    np.testing.assert_array_equal(
        ours.satellite[at, slot], np.asarray(nav[["x_sv_m", "y_sv_m", "z_sv_m"]]).T
    )
    np.testing.assert_array_equal(
        ours.wls_position[at], np.asarray(nav[["x_rx_m", "y_rx_m", "z_rx_m"]]).T
    )
    np.testing.assert_array_equal(ours.sigma[at, slot], np.asarray(nav["raw_pr_sigma_m"]))
    np.testing.assert_array_equal(ours.cn0[at, slot], np.asarray(nav["cn0_dbhz"]))


@pytest.mark.parametrize("name", ["gsdc2021_Pixel4XL_derived.csv", "gsdc2021_Pixel4_derived.csv"])
def test_derived_2021_files_shift_one_epoch_and_drop_timing_outliers(name):
    """The data notes' corrections: the reception time is the stamp less one 1 Hz epoch;
    the kept rows' median flight time is then a signal's from 20 000 km (64-95 ms; the
    stamp itself gives 1077 ms and the previous row of the Pixel 4 XL file, 5 s before,
    a negative one)."""
    ours = read_android(data_path(name))
    raw = pd.read_csv(data_path(name))
    received = raw["millisSinceGpsEpoch"].to_numpy() - 1000
    flight = received - raw["receivedSvTimeInGpsNanos"].to_numpy() / 1e6
    kept = (flight > 0) & (flight < 300)
    assert 64.0 < np.median(flight[kept]) < 95.0
    corrected = (
        raw["rawPrM"] + raw["satClkBiasM"] - raw["isrbM"] - raw["ionoDelayM"] - raw["tropoDelayM"]
    ).to_numpy()
    letters = raw["constellationType"].map({1: "G", 3: "R", 4: "J", 5: "C", 6: "E"})
    names = [f"{c}{s:02d} {t}" for c, s, t in zip(letters, raw["svid"], raw["signalType"])]
    at = np.searchsorted(ours.gps_millis, received[kept])
    slot = np.array([ours.signal.index(n) for n, k in zip(names, kept) if k])
    np.testing.assert_array_equal(ours.gps_millis[at], received[kept])
    np.testing.assert_array_equal(ours.pseudorange[at, slot], corrected[kept])
    assert np.isfinite(ours.pseudorange).sum() == kept.sum()
    if name == "gsdc2021_Pixel4_derived.csv":
        # gnss_lib_py maps each stamp to the file's previous one: the same times at 1 Hz
        # (it drops the first epoch, which has no previous one)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            nav = glp.AndroidDerived2021(str(data_path(name)))
        assert np.array_equal(
            np.unique(np.asarray(nav["gps_millis"])).astype(np.int64), ours.gps_millis[1:]
        )


@pytest.mark.parametrize(
    "name, parser",
    [
        ("gsdc2021_Pixel4_ground_truth.csv", glp.AndroidGroundTruth2021),
        ("gsdc2022_ground_truth.csv", glp.AndroidGroundTruth2022),
        ("gsdc2023_ground_truth.csv", glp.AndroidGroundTruth2023),
    ],
)
def test_ground_truth_reads_as_gnss_lib_py_reads_it(name, parser):
    times, lat_lon_height = read_android_ground_truth(data_path(name))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nav = parser(str(data_path(name)))
    order = np.argsort(np.asarray(nav["gps_millis"]), kind="stable")
    np.testing.assert_array_equal(times, np.asarray(nav["gps_millis"])[order].astype(np.int64))
    np.testing.assert_array_equal(lat_lon_height[:, 0], np.asarray(nav["lat_rx_gt_deg"])[order])
    height = np.asarray(nav["alt_rx_gt_m"])[order]
    ecef = np.asarray(nav[["x_rx_gt_m", "y_rx_gt_m", "z_rx_gt_m"]]).T[order]
    if name.startswith("gsdc2021"):
        # the hosts' 61 m correction, which gnss_lib_py 1.1.0 applies twice (its heights are
        # the file's less 122 m): compare with its heights put back by one correction
        file_height = pd.read_csv(data_path(name)).sort_values("millisSinceGpsEpoch", kind="stable")
        np.testing.assert_allclose(
            height, file_height["heightAboveWgs84EllipsoidM"].to_numpy() - 122.0, atol=1e-9
        )
        height = height + 61.0
        ecef = np.asarray(
            geodetic_to_ecef(
                np.radians(lat_lon_height[:, 0]), np.radians(lat_lon_height[:, 1]), height
            )
        )
    np.testing.assert_allclose(lat_lon_height[:, 2], height, atol=1e-9)
    measurements = {
        "gsdc2021": "gsdc2021_Pixel4_derived.csv",
        "gsdc2022": "gsdc2022_device_gnss.csv",
        "gsdc2023": "gsdc2023_device_gnss.csv",
    }[name[:8]]
    phone = read_android(data_path(measurements), data_path(name))
    at = np.searchsorted(times, phone.gps_millis)
    assert np.all(times[at] == phone.gps_millis)
    np.testing.assert_allclose(phone.truth, ecef[at], atol=1e-3, rtol=0)


@pytest.mark.parametrize(
    "line, edit, message",
    [
        (
            5,
            lambda row: row.rsplit(",", 3)[0],
            "gsdc2022_device_gnss.csv:5: list index out of range",
        ),
        (
            8,
            lambda row: row.replace(",1,C,", ",1x,C,", 1),
            "gsdc2022_device_gnss.csv:8: invalid literal",
        ),
        (
            1,
            lambda row: "a,b,c",
            "gsdc2022_device_gnss.csv:1: expected a GSDC measurement CSV header",
        ),
        (
            9,
            lambda row: row.replace(",1,C,", ",2,C,", 1),
            "gsdc2022_device_gnss.csv:9: constellation type 2",
        ),
    ],
)
def test_damaged_phone_file_names_the_line(line, edit, message, tmp_path):
    rows = data_path("gsdc2022_device_gnss.csv").read_text().splitlines()
    assert ",1,C," in rows[line - 1] or line in (1, 5)
    rows[line - 1] = edit(rows[line - 1])
    damaged = tmp_path / "gsdc2022_device_gnss.csv"
    damaged.write_text("\n".join(rows) + "\n")
    with pytest.raises(ValueError, match=message):
        read_android(damaged)


def test_truncated_and_repeated_rows_are_named(tmp_path):
    rows = data_path("gsdc2022_device_gnss.csv").read_text().splitlines()
    short = tmp_path / "short.csv"
    short.write_text("\n".join(rows[:3] + [rows[3][:40]] + rows[4:]) + "\n")
    with pytest.raises(ValueError, match="short.csv:4: list index out of range"):
        read_android(short)
    twice = tmp_path / "twice.csv"
    twice.write_text("\n".join(rows[:2] + [rows[1]] + rows[2:]) + "\n")
    with pytest.raises(ValueError, match="twice.csv: two rows of G02 GPS_L1 at"):
        read_android(twice)


def test_monitor_receiver_names_what_it_needs():
    from jaxfdi.gnss import read_observations

    with pytest.raises(ValueError, match="ephemerides: expected the navigation file's records"):
        monitor_receiver(read_observations(data_path("07590920.05o")))
    with pytest.raises(TypeError, match="measurements: expected read_observations's Observations"):
        monitor_receiver(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="clocks: expected 'constellation' or 'one'"):
        monitor_receiver(load_phone("GSDC 2023 Pixel 7 Pro"), clocks="two")


@pytest.fixture(scope="module", params=list(PHONES))
def phone(request):
    return request.param, load_phone(request.param)


def test_unit_weight_fixes_match_gnss_lib_py(phone):
    _, trace = phone
    nav, _, _ = _peer_navdata(trace)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        state = solve_wls(nav)
    theirs = np.stack([np.asarray(state[f"{a}_rx_wls_m"]) for a in "xyz"], axis=1)
    assert np.array_equal(np.asarray(state["gps_millis"]).astype(np.int64), trace.gps_millis)
    unit = trace._replace(sigma=np.where(np.isfinite(trace.sigma), 1.0, np.nan))
    ours = np.asarray(monitor_receiver(unit, clocks="one", exclude=False).fix.position)
    assert np.max(np.linalg.norm(ours - theirs, axis=1)) < 1e-3


def test_fault_detection_and_exclusion_agree_with_gnss_lib_py(phone):
    label, trace = phone
    row = _peer_row(label, trace)
    assert row["threshold_m2"] == PEER_THRESHOLD
    assert row["jaxfdi_only"] == 0 and row["gnss_lib_py_only"] == 0
    assert row["both_alarm"] + row["neither"] == trace.gps_millis.size
    assert row["explained"] == row["different_exclusion"]
    assert row["same_exclusion"] + row["different_exclusion"] == row["both_alarm"]


def test_per_constellation_clocks_slope_levels_match_numpy(phone):
    """Every epoch: whitened geometry of the used slots with one clock column per
    constellation in view; ``A = (H^T H)^-1 H^T``, ``S = I - H A``, slopes
    ``|A_q,i| / sqrt(S_ii)``, ``lambda`` by SciPy's noncentral chi-square at the
    chi-square threshold of ``n - 3 - C`` degrees of freedom (Brown & Chin 1992)."""
    _, trace = phone
    tables = raim_tables(max(len(trace.signal), 5), pfa=1e-3, pmd=1e-3)
    result = jax.tree_util.tree_map(
        np.asarray, monitor_receiver(trace, tables=tables, exclude=False)
    )
    membership = trace.clocks()
    assert result.fix.geometry.shape[-1] == 3 + membership.shape[1]
    lam_of = {}
    for k in range(trace.gps_millis.size):
        used = result.fix.used[k]
        h = (result.fix.geometry[k] / result.fix.sigma[k][:, None])[used]
        h = np.concatenate([h[:, :3], h[:, 3:][:, np.any(membership[used], axis=0)]], axis=1)
        n, u = h.shape
        dof = n - u
        assert u == 3 + len(set(trace.constellation[used])) and result.check.dof[k] == dof
        y = (result.fix.residuals[k] / result.fix.sigma[k])[used]
        A = np.linalg.solve(h.T @ h, h.T)
        S = np.eye(n) - h @ A
        assert result.check.statistic[k] == pytest.approx(y @ S @ y, rel=1e-8)
        if dof not in lam_of:
            threshold = stats.chi2.isf(1e-3, dof)
            lam_of[dof] = optimize.brentq(
                lambda v: stats.ncx2.cdf(threshold, dof, v) - 1e-3, 1e-6, 1e3, xtol=1e-12
            )
        lam = lam_of[dof]
        seen = np.diag(S) > 1e-9
        root = np.sqrt(np.where(seen, np.diag(S), 1.0))
        hpl = np.max(np.where(seen, np.hypot(A[0], A[1]) / root, 0.0)) * np.sqrt(lam)
        vpl = np.max(np.where(seen, np.abs(A[2]) / root, 0.0)) * np.sqrt(lam)
        assert result.protection.hpl[k] == pytest.approx(hpl, rel=1e-8)
        assert result.protection.vpl[k] == pytest.approx(vpl, rel=1e-8)
        sigma = result.fix.sigma[k][used]
        np.testing.assert_allclose(
            result.protection.minimum_detectable_bias[k][used],
            np.where(seen, sigma * np.sqrt(lam) / root, np.inf),
            rtol=1e-8,
        )


def test_a_clock_per_constellation_costs_its_degrees_of_freedom(phone):
    _, trace = phone
    each = monitor_receiver(trace, exclude=False)
    one = monitor_receiver(trace, clocks="one", exclude=False)
    in_view = np.array([len(set(trace.constellation[u])) for u in np.asarray(each.fix.used)])
    np.testing.assert_array_equal(
        np.asarray(one.check.dof) - np.asarray(each.check.dof), in_view - 1
    )
    assert np.asarray(each.fix.clock_bias).shape == (trace.gps_millis.size, trace.clocks().shape[1])
    # a constellation without a used satellite keeps its clock at the start value
    in_use = np.asarray([np.any(trace.clocks()[u], axis=0) for u in np.asarray(each.fix.used)])
    assert np.all(np.asarray(each.fix.clock_bias)[~in_use] == 0.0)
    assert jnp.all(each.fix.healthy)


def test_greedy_exclusion_matches_numpy_rounds(phone):
    """Up to three exclusions against NumPy rounds of the same rule (Brown & Chin 1992's
    test iterated): each round solves the whitened least squares on the slots left (one
    clock column per constellation in view), alarms when ``y^T S y`` exceeds SciPy's
    chi-square quantile at ``n - 3 - C`` degrees of freedom, and leaves out the largest
    normalised residual ``|(S y)_j| / sqrt(S_jj)`` (``S_jj > 0``) while ``n >= u + 2``.
    The rounds are linearised at the full fix in its NED frame (our re-solve iterates the
    ranges: positions within 5 cm, statistics within 1 % on the 2021 phones'
    tens-of-metres outliers)."""
    _, trace = phone
    rounds = 3
    full = jax.tree_util.tree_map(np.asarray, monitor_receiver(trace, exclude=False))
    out = jax.tree_util.tree_map(np.asarray, monitor_receiver(trace, exclude=rounds))
    np.testing.assert_array_equal(out.fix.position, full.fix.position)
    membership = trace.clocks()
    for k in range(trace.gps_millis.size):
        keep = full.fix.used[k].copy()
        h_all = full.fix.geometry[k] / full.fix.sigma[k][:, None]
        y_all = full.fix.residuals[k] / full.fix.sigma[k]
        dropped, statistic, step = [], None, np.zeros(3)
        for _ in range(rounds + 1):
            clocks = np.any(membership[keep], axis=0)
            h = np.concatenate([h_all[keep, :3], h_all[keep, 3:][:, clocks]], axis=1)
            n, u = h.shape
            delta = np.linalg.lstsq(h, y_all[keep], rcond=None)[0]
            residual = y_all[keep] - h @ delta
            statistic, step = residual @ residual, delta[:3]
            dof = n - u
            alarm = dof > 0 and statistic > stats.chi2.isf(1e-3, dof)
            if not alarm or n < u + 2 or len(dropped) == rounds:
                break
            s = np.diag(np.eye(n) - h @ np.linalg.solve(h.T @ h, h.T))
            seen = s > 1e-9  # a satellite alone on its clock has no residual to test
            normalised = np.where(seen, np.abs(residual) / np.sqrt(np.where(seen, s, 1.0)), 0.0)
            worst = np.flatnonzero(keep)[np.argmax(normalised)]
            dropped.append(worst)
            keep[worst] = False
        assert sorted(np.flatnonzero(out.exclusions[k] & ~out.dead[k])) == sorted(dropped), k
        assert out.excluded[k] == (dropped[0] if dropped else -1)
        assert out.check_excluded.statistic[k] == pytest.approx(statistic, rel=1e-2, abs=1e-6)
        lat, lon, _ = (float(v) for v in ecef_to_geodetic(full.fix.position[k]))
        sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
        ecef_to_ned = np.array(
            [[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]]
        )
        np.testing.assert_allclose(
            ecef_to_ned @ (out.fix_excluded.position[k] - full.fix.position[k]), step, atol=0.05
        )


def test_exclude_counts_rounds():
    trace = load_phone("GSDC 2021 Pixel 4")
    one, true = (monitor_receiver(trace, exclude=e) for e in (1, True))
    jax.tree_util.tree_map(np.testing.assert_array_equal, one, true)
    with pytest.raises(
        ValueError,
        match=r"exclude: expected the most satellites to exclude .* in \[0, inf\], got -1",
    ):
        monitor_receiver(trace, exclude=-1)
    with pytest.raises(TypeError, match="exclude: expected the most satellites to exclude"):
        monitor_receiver(trace, exclude=1.5)


def test_traces_share_one_program_and_padding_changes_nothing():
    """The four traces (5-281 epochs, 26-48 signals, 3-5 constellations) run in one compiled
    program per option set: epochs in chunks of 64, slots padded to 64, clock columns to
    Android's seven. Cut back, the result is the trace solved at its own shape (the longest
    and the shortest trace): the same decisions and degrees of freedom, positions within
    1 um (round-off of longer sums)."""
    from jaxfdi.gnss import _receiver

    traces = [load_phone(label) for label in PHONES]
    assert len({(t.pseudorange.shape, t.clocks().shape[1]) for t in traces}) == len(traces)
    before = _receiver._monitor_phone._cache_size()
    padded = [
        jax.tree_util.tree_map(np.asarray, monitor_receiver(t, exclude=PHONE_EXCLUSIONS))
        for t in traces
    ]
    assert _receiver._monitor_phone._cache_size() - before <= 1  # 0: the file compiled it already
    longest, shortest = (
        np.argmax([t.gps_millis.size for t in traces]),
        np.argmin([t.gps_millis.size for t in traces]),
    )
    for trace, out in ((traces[longest], padded[longest]), (traces[shortest], padded[shortest])):
        slots = len(trace.signal)
        own = jax.tree_util.tree_map(
            np.asarray,
            _receiver._monitor_phone(
                jnp.asarray(trace.satellite),
                jnp.asarray(trace.pseudorange),
                jnp.asarray(trace.sigma),
                jnp.asarray(trace.clocks()),
                raim_tables(slots, pfa=1e-3, pmd=1e-3),
                None,
                "npa",
                PHONE_EXCLUSIONS,
            ),
        )
        jax.tree_util.tree_map(lambda a, b: np.testing.assert_equal(a.shape, b.shape), out, own)
        for a, b in (
            (out.excluded, own.excluded),
            (out.exclusions, own.exclusions),
            (out.check.alarm, own.check.alarm),
            (out.check.dof, own.check.dof),
            (out.fix.used, own.fix.used),
        ):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(out.fix.position, own.fix.position, rtol=0, atol=1e-6)
        np.testing.assert_allclose(
            out.fix_excluded.position, own.fix_excluded.position, rtol=0, atol=1e-6
        )
        np.testing.assert_allclose(out.fix.clock_bias, own.fix.clock_bias, rtol=0, atol=1e-6)
        np.testing.assert_allclose(out.protection.hpl, own.protection.hpl, rtol=1e-9)


def test_bad_channels_in_a_padded_trace_are_evidence():
    """A dead, missing or frozen channel inside a padded phone trace (the Pixel 7 Pro's, 34
    signals padded to 64), on its fastest-moving signal (range rate ~700 m/s):
    - NaN from epoch 1 on is not measured: the fixes equal the trace without the slot
      (within 1 um), nothing flagged;
    - infinite is a dead channel: flagged, excluded and alarmed at exactly those epochs
      (``raim_output`` labels the slot), its fix equal to the NaN one (never used);
    - frozen at its epoch-1 value, it is 700 m off one second later: the parity test alarms
      and excludes that slot at every later epoch."""
    trace = load_phone("GSDC 2023 Pixel 7 Pro")
    rho = trace.pseudorange
    measured = np.isfinite(rho).all(0)
    slot = int(np.argmax(np.where(measured, np.abs(np.diff(rho, axis=0)).min(0), 0.0)))
    assert np.abs(np.diff(rho[:, slot])).min() > 500.0

    def run(pseudorange):
        return jax.tree_util.tree_map(
            np.asarray,
            monitor_receiver(trace._replace(pseudorange=pseudorange), exclude=PHONE_EXCLUSIONS),
        )

    def edited(value):
        out = rho.copy()
        out[1:, slot] = value
        return out

    keep = np.arange(rho.shape[1]) != slot
    without = jax.tree_util.tree_map(
        np.asarray,
        monitor_receiver(
            trace._replace(
                signal=tuple(np.asarray(trace.signal)[keep]),
                constellation=trace.constellation[keep],
                pseudorange=rho[:, keep],
                sigma=trace.sigma[:, keep],
                cn0=trace.cn0[:, keep],
                satellite=trace.satellite[:, keep],
            ),
            exclude=PHONE_EXCLUSIONS,
        ),
    )
    missing, dead = run(edited(np.nan)), run(edited(np.inf))
    for out in (missing, dead):
        np.testing.assert_allclose(
            out.fix.position[1:], without.fix.position[1:], rtol=0, atol=1e-6
        )
        np.testing.assert_allclose(
            out.fix_excluded.position[1:], without.fix_excluded.position[1:], rtol=0, atol=1e-6
        )
        assert not out.fix.used[1:, slot].any() and out.fix.used[0, slot]
    assert not missing.dead.any() and not missing.exclusions[:, slot].any()
    np.testing.assert_array_equal(
        dead.dead, np.arange(rho.shape[0])[:, None] >= np.where(keep, rho.shape[0], 1)
    )
    assert dead.exclusions[1:, slot].all()
    decisions = jax.vmap(raim_output)(jax.tree_util.tree_map(jnp.asarray, dead)).decision
    assert decisions.alarm[1:].all() and (decisions.label[1:] == 1 + slot).all()
    frozen = run(edited(rho[1, slot]))
    assert frozen.check.alarm[2:].all() and (frozen.check.isolated[2:] == slot).all()
    assert frozen.exclusions[2:, slot].all() and not frozen.exclusions[:2, slot].any()
