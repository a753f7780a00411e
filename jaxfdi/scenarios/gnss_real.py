"""Real receivers: GPS integrity on an hour of two GEONET stations, beside RTKLIB, and
every constellation on four smartphone traces, beside Google and gnss_lib_py.

Data: GEONET stations 0759 and 3040 (GSI, Japan; 3.3 km apart), 2005-04-02 00:00-00:59:30 GPST, 30 s,
Trimble 5700, RINEX 2.10 with broadcast ephemerides (RTKLIB's test data, in ``jaxfdi/data``); truth:
the header's surveyed ``APPROX POSITION XYZ``.

Each epoch: ``gnss.monitor_receiver`` on C1 with RTKLIB's single-point model (broadcast orbits and
clocks, Klobuchar, Saastamoinen, 15 deg mask, its weights), parity test at ``P_fa = 1e-3`` (RTKLIB's
chi-square level), slope protection levels at ``P_md = 1e-3``, exclusion; solution-separation levels
(``solution_separation``: ARAIM LPV-200 budgets, ``P_sat = 1e-5``).

- **positions**: per station, horizontal/vertical errors from the surveyed position, largest
  difference from RTKLIB's fixes (with pyrtklib), alarms, misleading information (error beyond the
  level without alarm) for both levels: the Stanford diagrams.
- **step** / **ramp** on station 0759's real pseudoranges: ``b`` m on one satellite at one epoch (snapshot test), or
  ``r`` m/s from one epoch to the end of the hour; ``runs`` (satellite, epoch) pairs drawn with ``seed`` among those the
  fix uses. Step rows: detection by both tests, correct exclusion by each (parity's isolated satellite; solution
  separation's largest separation relative to its threshold), RTKLIB's RAIM FDE on the same trials (with pyrtklib:
  agreement, largest fix difference), detection among trials with bias >= the slope level's minimum detectable bias
  (``1 - P_md`` promised there). Ramp rows: detection within the hour, delay, bias at detection beside that epoch's MDB.
- **channel**: on the ramps' trials the channel stops at that epoch: frozen at its last pseudorange (the range moves up
  to hundreds of m per 30 s) or dead (infinite, left out and flagged). Rows: detection (parity alarm or dead flag),
  exclusion of that satellite, delay, range moved from the frozen value when caught.
- **phones**: four Google Smartphone Decimeter Challenge traces (2021-2023; GPS, GLONASS, Galileo, BeiDou, QZSS; in
  ``jaxfdi/data``) through ``gnss.monitor_receiver``: a clock per constellation, the phone's pseudorange uncertainty as
  sigma, no mask, up to ``PHONE_EXCLUSIONS`` greedy exclusions. Per trace: alarms, epochs with an exclusion, signals
  excluded, epochs still alarming, median ``TS_D / dof`` (1 when the uncertainties are right), delivered fix against
  Google's WLS and the ground truth, both levels and misleading epochs where there is truth.
- **phone-peers** (with gnss_lib_py): gnss_lib_py 1.1's ``solve_wls`` (unit weights, one clock) against ours so
  configured, and its greedy residual FDE (Blanch, Walter & Enge 2015) against our parity test and exclusion at the same
  threshold on the same unweighted statistic. Its first exclusion divides by ``1 - h_ii`` of the geometry without the
  clock column; ``explained`` counts differing exclusions its formula with the clock column would have made ours;
  ``same_exclusion_set``: epochs where up to ``PHONE_EXCLUSIONS`` exclusions agree on both sides.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxfdi import rate_interval, status, study_result, text_table
from jaxfdi.data import data_path
from jaxfdi.gnss import (
    MASK_ANGLE,
    PhoneEpochs,
    ReceiverEpochs,
    ecef_to_ned,
    integrity_outcomes,
    monitor_receiver,
    raim_tables,
    read_android,
    read_observations,
    read_rinex_nav,
    receiver_epochs,
    separate_epochs,
)
from jaxfdi.plotting import caption_figure, column_subplots, stanford_regions
from jaxfdi.scenarios._common import check_study, require_x64

#: station -> RINEX file stem in jaxfdi/data
STATIONS = {"0759": "07590920.05", "3040": "30400920.05"}
#: the station whose pseudoranges carry the injected faults
FAULT_STATION = "0759"
STEP_SIZES = (10.0, 20.0, 30.0, 50.0, 100.0)  # m
RAMP_RATES = (0.05, 0.1, 0.2, 0.5)  # m/s
#: RTKLIB's largest GDOP for a solution (pos1-maxgdop): epochs beyond it are not scored
MAX_GDOP = 30.0
#: the phone traces: label -> (measurement file, ground-truth file or None) in jaxfdi/data
PHONES = {
    "GSDC 2021 Pixel 4 XL": ("gsdc2021_Pixel4XL_derived.csv", None),
    "GSDC 2021 Pixel 4": ("gsdc2021_Pixel4_derived.csv", "gsdc2021_Pixel4_ground_truth.csv"),
    "GSDC 2022": ("gsdc2022_device_gnss.csv", "gsdc2022_ground_truth.csv"),
    "GSDC 2023 Pixel 7 Pro": ("gsdc2023_device_gnss.csv", "gsdc2023_ground_truth.csv"),
}
#: gnss_lib_py's default residual threshold [m^2] (``fde_greedy_residual``), used by both sides of the agreement table
PEER_THRESHOLD = 3000.0
#: the most satellites excluded from a phone's epoch, one after another (``monitor_receiver(exclude=)``)
PHONE_EXCLUSIONS = 3


@study_result(group="section")
class GnssRealStudy(NamedTuple):
    """Rows (per station, step size, ramp rate) and per-epoch arrays per station for the figures (``epochs[station]``:
    ``horizontal_error``, ``vertical_error``, ``hpl``, ``vpl``, ``ss_hpl``, ``ss_vpl``, ``alarm``, ``gdop``)."""

    config: dict
    rows: list[dict]
    epochs: dict

    def table(self) -> str:
        """The study's frame (``to_frame``) as text: a block per section, transposed where it is wide."""
        return text_table(self.to_frame(), group="section")


def local_errors(position: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Absolute horizontal and vertical errors [m] of (E, 3) ECEF fixes, NED axes at ``truth``."""
    ned = np.asarray(ecef_to_ned(position, truth))
    return np.hypot(ned[:, 0], ned[:, 1]), np.abs(ned[:, 2])


def _load(station: str) -> tuple[ReceiverEpochs, np.ndarray]:
    obs = read_observations(data_path(STATIONS[station] + "o"))
    return receiver_epochs(
        obs, read_rinex_nav(data_path(STATIONS[station] + "n"))
    ), obs.approx_position


def _rtklib_difference(station: str, position: np.ndarray, times: np.ndarray) -> float | None:
    """Largest distance [m] from RTKLIB's single-point fixes of the same epochs (pyrtklib's
    ``postpos`` with the same models), ``None`` without pyrtklib."""
    try:
        import pyrtklib as rtk
    except ImportError:
        return None
    import tempfile
    from pathlib import Path

    popt, sopt, fopt = _rtklib_options(rtk)
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "rtklib.pos"
        name = rtk.Arr1Dchar(1024)
        for i, c in enumerate(str(out)):
            name[i] = c
        files = [str(data_path(STATIONS[station] + "o")), str(data_path(STATIONS[station] + "n"))]
        if (
            rtk.postpos(
                rtk.gtime_t(), rtk.gtime_t(), 0.0, 0.0, popt, sopt, fopt, files, 2, name, "", ""
            )
            != 0
        ):
            return None
        lines = [line.split() for line in out.read_text().splitlines() if not line.startswith("%")]
    worst = 0.0
    for fields in lines:
        hour, minute, second = fields[1].split(":")
        seconds = int(hour) * 3600 + int(minute) * 60 + float(second)
        at = np.flatnonzero(np.abs(np.mod(times, 86400.0) - seconds) < 0.1)
        if at.size:
            worst = max(
                worst,
                float(np.linalg.norm(position[at[0]] - np.array([float(v) for v in fields[2:5]]))),
            )
    return worst


def _rtklib_options(rtk):
    """RTKLIB's default options with the study's model: single point, GPS, the 15 deg mask,
    broadcast ionosphere, Saastamoinen troposphere, ECEF output."""
    rtk.resetsysopts()
    popt, sopt, fopt = rtk.prcopt_t(), rtk.solopt_t(), rtk.filopt_t()
    rtk.getsysopts(popt, sopt, fopt)
    popt.mode, popt.navsys, popt.elmin = rtk.PMODE_SINGLE, rtk.SYS_GPS, MASK_ANGLE
    popt.ionoopt, popt.tropopt, sopt.posf = rtk.IONOOPT_BRDC, rtk.TROPOPT_SAAS, rtk.SOLF_XYZ
    return popt, sopt, fopt


def _rtklib_fde(station: str):
    """RTKLIB's RAIM FDE (``pntpos``, ``posopt[4]`` = ``pos1-raimfde``: after a failed chi-square test,
    re-solve without each satellite, keep the passing solution of smallest residual RMS) as
    ``decide(epoch, prn, bias) -> (decision, position)``, bias added to that C1; ``decision``: "none",
    "x<prn>" (excluded) or "no fix". ``None`` without pyrtklib."""
    try:
        import pyrtklib as rtk
    except ImportError:
        return None
    obs, nav, sta = rtk.obs_t(), rtk.nav_t(), rtk.sta_t()
    for kind, suffix in ((1, "o"), (2, "n")):
        rtk.readrnx(str(data_path(STATIONS[station] + suffix)), kind, "", obs, nav, sta)
    rtk.sortobs(obs)
    popt, _, _ = _rtklib_options(rtk)
    popt.posopt[4] = 1
    starts = (
        [0]
        + [i for i in range(1, obs.n) if rtk.timediff(obs.data[i].time, obs.data[i - 1].time) != 0]
        + [obs.n]
    )

    def decide(epoch: int, prn: int, bias: float):
        first, end = starts[epoch], starts[epoch + 1]
        record = next(obs.data[i] for i in range(first, end) if obs.data[i].sat == prn)
        clean = record.P[0]
        solution, status, message = rtk.sol_t(), rtk.Arr1Dssat_t(rtk.MAXSAT), rtk.Arr1Dchar(256)
        record.P[0] = clean + bias
        before = [obs.data[i].sat for i in range(first, end)]
        ok = rtk.pntpos(
            obs.data[first],
            end - first,
            nav,
            popt,
            solution,
            rtk.Arr1Ddouble(2 * (end - first)),
            status[0],
            message,
        )
        record.P[0] = clean
        position = np.array([solution.rr[i] for i in range(3)])
        if not ok:
            return "no fix", position
        # a satellite RTKLIB checked (azimuth/elevation set) but left out of the solution
        gone = [
            sat
            for sat in before
            if status[sat - 1].azel[1] >= MASK_ANGLE and not status[sat - 1].vs
        ]
        return ("x" + ",".join(map(str, gone)) if gone else "none"), position

    return decide


def _position_row(
    station: str, result, separation, truth: np.ndarray, times: np.ndarray
) -> tuple[dict, dict]:
    fix = result.fix
    position = np.asarray(fix.position)
    horizontal, vertical = local_errors(position, truth)
    gdop = np.asarray(fix.dops.gdop)
    scored = gdop <= MAX_GDOP
    alarm = np.asarray(result.check.alarm)
    hpl, vpl = np.asarray(result.protection.hpl), np.asarray(result.protection.vpl)
    ss_hpl, ss_vpl = np.asarray(separation.hpl), np.asarray(separation.vpl)

    def misleading(error, level):  # quiet scored epochs beyond their level (no alert limit)
        return integrity_outcomes(error[scored], level[scored], alarm=alarm[scored]).misleading

    row = {
        "section": "positions",
        "station": f"GEONET {station}",
        "epochs": int(times.size),
        "scored_epochs": int(scored.sum()),
        "horizontal_error_median_m": float(np.median(horizontal[scored])),
        "horizontal_error_95_m": float(np.percentile(horizontal[scored], 95)),
        "horizontal_error_max_m": float(horizontal[scored].max()),
        "vertical_error_median_m": float(np.median(vertical[scored])),
        "vertical_error_95_m": float(np.percentile(vertical[scored], 95)),
        "vertical_error_max_m": float(vertical[scored].max()),
        "rtklib_max_difference_m": _rtklib_difference(station, position, times),
        "parity_alarms": int(alarm[scored].sum()),
        "ss_alarms": int(np.asarray(separation.alarm)[scored].sum()),
        "hpl_median_m": float(np.median(hpl[scored])),
        "vpl_median_m": float(np.median(vpl[scored])),
        "ss_hpl_median_m": float(np.median(ss_hpl[scored])),
        "ss_vpl_median_m": float(np.median(ss_vpl[scored])),
        "misleading_slope": misleading(horizontal, hpl) + misleading(vertical, vpl),
        "misleading_ss": misleading(horizontal, ss_hpl) + misleading(vertical, ss_vpl),
    }
    arrays = {
        "horizontal_error": horizontal,
        "vertical_error": vertical,
        "hpl": hpl,
        "vpl": vpl,
        "ss_hpl": ss_hpl,
        "ss_vpl": ss_vpl,
        "alarm": alarm,
        "gdop": gdop,
    }
    return row, arrays


def load_phone(label: str) -> PhoneEpochs:
    """The phone trace ``label`` of ``PHONES`` (with its ground truth where there is one)."""
    measurements, truth = PHONES[label]
    return read_android(data_path(measurements), None if truth is None else data_path(truth))


def _phone_row(label: str, phone: PhoneEpochs, result, separation) -> tuple[dict, dict]:
    """The ``phones`` row of a trace and its per-epoch arrays (module docstring)."""
    excluded = np.any(result.exclusions & ~result.dead, axis=1)
    delivered = result.fix_excluded.position
    alarm, dof = result.check.alarm, result.check.dof
    low, high = rate_interval(int(alarm.sum()), int(alarm.size), 0.95)
    hpl, vpl = result.protection.hpl, result.protection.vpl
    row = {
        "section": "phones",
        "trace": label,
        "epochs": int(alarm.size),
        "measurements": int(result.fix.num_used.sum()),
        "constellations": "".join(np.unique(phone.constellation)),
        "dof_median": float(np.median(dof)),
        "parity_alarms": int(alarm.sum()),
        "alarm_rate_low": low,
        "alarm_rate_high": high,
        "exclusions": int(excluded.sum()),
        "excluded_signals": int(np.sum(result.exclusions & ~result.dead)),
        "alarm_after_exclusion": int(np.sum(alarm & result.check_excluded.alarm)),
        "ss_alarms": int(separation.alarm.sum()),
        "statistic_per_dof_median": float(np.median(result.check.statistic / np.maximum(dof, 1))),
        "hpl_median_m": float(np.median(hpl)),
        "ss_hpl_median_m": float(np.median(separation.hpl)),
    }
    google = np.all(np.isfinite(phone.wls_position), axis=1)
    row["google_difference_median_m"] = (
        float(np.median(np.linalg.norm(delivered - phone.wls_position, axis=1)[google]))
        if google.any()
        else float("nan")
    )
    truth = np.all(np.isfinite(phone.truth), axis=1)
    arrays = {
        "alarm": alarm,
        "hpl": hpl,
        "vpl": vpl,
        "ss_hpl": separation.hpl,
        "ss_vpl": separation.vpl,
        "truth": truth,
    }
    row["truth_epochs"] = int(truth.sum())
    if truth.any():
        horizontal, vertical = local_errors(delivered[truth], phone.truth[truth])
        fix_h, fix_v = local_errors(result.fix.position[truth], phone.truth[truth])
        row.update(
            {
                "horizontal_error_median_m": float(np.median(horizontal)),
                "horizontal_error_max_m": float(horizontal.max()),
                "vertical_error_median_m": float(np.median(vertical)),
                "vertical_error_max_m": float(vertical.max()),
            }
        )
        if google[truth].all():
            g_h, g_v = local_errors(phone.wls_position[truth], phone.truth[truth])
            row.update(
                {
                    "google_horizontal_error_median_m": float(np.median(g_h)),
                    "google_vertical_error_median_m": float(np.median(g_v)),
                }
            )
        quiet = ~alarm[truth]
        row["misleading_slope"] = int(np.sum(quiet & ((fix_h > hpl[truth]) | (fix_v > vpl[truth]))))
        row["misleading_ss"] = int(
            np.sum(quiet & ((fix_h > separation.hpl[truth]) | (fix_v > separation.vpl[truth])))
        )
        arrays.update({"horizontal_error": fix_h, "vertical_error": fix_v})
    return row, arrays


def _peer_navdata(phone: PhoneEpochs):
    """gnss_lib_py's NavData of the trace's usable measurements, with their (epoch, slot)."""
    from gnss_lib_py.navdata.navdata import NavData

    at, slot = np.nonzero(
        np.isfinite(phone.pseudorange)
        & np.all(np.isfinite(phone.satellite), axis=2)
        & (phone.sigma > 0)
    )
    nav = NavData()
    nav["gps_millis"] = phone.gps_millis[at].astype(float)
    nav["corr_pr_m"] = phone.pseudorange[at, slot]
    for i, axis in enumerate("xyz"):
        nav[f"{axis}_sv_m"] = phone.satellite[at, slot, i]
    nav["b_sv_m"] = np.zeros(at.size)
    return nav, at, slot


def _peer_row(label: str, phone: PhoneEpochs) -> dict | None:
    """The ``phone-peers`` row of a trace (module docstring); ``None`` without gnss_lib_py."""
    try:
        from gnss_lib_py.algorithms.fde import solve_fde
        from gnss_lib_py.algorithms.snapshot import solve_wls
    except ImportError:
        return None
    import warnings

    nav, at, slot = _peer_navdata(phone)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        state = solve_wls(nav)
        faults, greedy = (
            np.asarray(
                solve_fde(nav.copy(), method="residual", threshold=PEER_THRESHOLD, max_faults=k)[
                    "fault_residual"
                ]
            )
            for k in (1, PHONE_EXCLUSIONS)
        )
    theirs_position = np.stack([np.asarray(state[f"{axis}_rx_wls_m"]) for axis in "xyz"], axis=1)
    epochs = phone.gps_millis.size
    if not np.array_equal(np.asarray(state["gps_millis"]).astype(np.int64), phone.gps_millis):
        raise RuntimeError(
            f"{label}: gnss_lib_py's solve_wls returned other epochs than the trace's"
        )
    unit = phone._replace(sigma=np.where(np.isfinite(phone.sigma), 1.0, np.nan))
    slots = len(phone.signal)
    tables = raim_tables(max(slots, 5))
    tables = tables._replace(
        threshold=jnp.where(jnp.arange(tables.threshold.shape[0]) > 0, PEER_THRESHOLD, jnp.inf)
    )
    ours = jax.tree_util.tree_map(
        np.asarray, monitor_receiver(unit, tables=tables, clocks="one", exclude=PHONE_EXCLUSIONS)
    )
    theirs_excluded = np.full(epochs, -1)
    theirs_excluded[at[faults == 1]] = slot[faults == 1]
    theirs_alarm = theirs_excluded >= 0
    theirs_set = np.zeros(ours.exclusions.shape, bool)
    theirs_set[at[greedy == 1], slot[greedy == 1]] = True
    ours_alarm, ours_excluded = ours.check.alarm, ours.excluded
    both = ours_alarm & theirs_alarm
    differ = both & (ours_excluded != theirs_excluded)
    explained = 0
    for k in np.flatnonzero(
        differ
    ):  # gnss_lib_py's normalised residual with and without the clock column
        used = ours.fix.used[k]
        r, h = ours.fix.residuals[k][used], ours.fix.geometry[k][used]
        lever = lambda g: np.einsum("ij,jk,ik->i", g, np.linalg.inv(g.T @ g), g)
        slots_k = np.flatnonzero(used)
        without_clock = slots_k[np.argmax(r**2 / (1.0 - lever(h[:, :3])))]
        with_clock = slots_k[np.argmax(r**2 / (1.0 - lever(h)))]
        explained += int(without_clock == theirs_excluded[k] and with_clock == ours_excluded[k])
    return {
        "section": "phone-peers",
        "trace": label,
        "epochs": epochs,
        "wls_max_difference_m": float(
            np.max(np.linalg.norm(ours.fix.position - theirs_position, axis=1))
        ),
        "threshold_m2": PEER_THRESHOLD,
        "both_alarm": int(both.sum()),
        "jaxfdi_only": int((ours_alarm & ~theirs_alarm).sum()),
        "gnss_lib_py_only": int((~ours_alarm & theirs_alarm).sum()),
        "neither": int((~ours_alarm & ~theirs_alarm).sum()),
        "same_exclusion": int((both & ~differ).sum()),
        "different_exclusion": int(differ.sum()),
        "explained": explained,
        "greedy_rounds": PHONE_EXCLUSIONS,
        "same_exclusion_set": int(
            np.all((ours.exclusions & ~ours.dead) == theirs_set, axis=1).sum()
        ),
    }


def _trials(result, runs: int, seed: int, last: int) -> tuple[np.ndarray, np.ndarray]:
    """``runs`` (epoch, slot) pairs drawn among the scored epochs before ``last`` and the slots each fix uses."""
    used = np.asarray(result.fix.used) & (np.asarray(result.fix.dops.gdop) <= MAX_GDOP)[:, None]
    used[last:] = False
    epochs, slots = np.nonzero(used)
    pick = np.random.default_rng(seed).choice(epochs.size, size=runs, replace=True)
    return epochs[pick], slots[pick]


def gnss_real_study(
    runs: int = 200,
    seed: int = 0,
    progress: bool = False,
    step_sizes=STEP_SIZES,
    ramp_rates=RAMP_RATES,
) -> GnssRealStudy:
    """The study of the module docstring.

    Args:
      runs: (satellite, epoch) trials per step size and per ramp rate.
      seed: draws the trials.
      progress: print a line per stage.
      step_sizes: step biases [m]; ramp_rates: ramp rates [m/s].

    Returns:
      ``GnssRealStudy`` with a ``positions`` row per station, a ``step`` row per size and a
      ``ramp`` row per rate (rates with their 95 % Clopper-Pearson intervals).
    """
    check_study(runs=runs, seed=seed)
    require_x64("gnss_real_study")
    rows, epochs_out = [], {}
    loaded = {}
    for station in STATIONS:
        epochs, truth = _load(station)
        result = jax.tree_util.tree_map(np.asarray, monitor_receiver(epochs))
        loaded[station] = epochs, result
        separation = jax.tree_util.tree_map(np.asarray, separate_epochs(result.fix))
        row, arrays = _position_row(station, result, separation, truth, np.asarray(epochs.times))
        rows.append(row)
        epochs_out[station] = arrays
        if progress:
            status(f"gnss-real: station {station}: {row['scored_epochs']} epochs scored")

    epochs, clean = loaded[FAULT_STATION]
    rho = np.asarray(epochs.pseudoranges)
    times = np.asarray(epochs.times)
    mdb_all = np.asarray(clean.protection.minimum_detectable_bias)
    at, slot = _trials(clean, runs, seed, last=rho.shape[0])
    rtklib = _rtklib_fde(FAULT_STATION)
    prns = np.asarray(epochs.table.prn)
    for size in step_sizes:
        faulty = rho[at].copy()
        faulty[np.arange(runs), slot] += size
        trial = epochs._replace(times=jnp.asarray(times[at]), pseudoranges=jnp.asarray(faulty))
        out = jax.tree_util.tree_map(np.asarray, monitor_receiver(trial))
        same, worst = None, None
        if rtklib is not None:
            # ours in RTKLIB's terms: no alarm; excluded (the fix without it passes); no fix
            passed = ~out.check_excluded.alarm
            ours = np.where(
                ~out.check.alarm,
                "none",
                np.where(
                    passed,
                    np.char.add("x", prns[np.maximum(out.excluded, 0)].astype(str)),
                    "no fix",
                ),
            )
            delivered = np.where(
                out.check.alarm[:, None], out.fix_excluded.position, out.fix.position
            )
            same, worst = 0, 0.0
            for r in range(runs):
                decision, position = rtklib(int(at[r]), int(prns[slot[r]]), float(size))
                same += int(decision == ours[r])
                if decision == ours[r] and decision != "no fix":
                    worst = max(worst, float(np.linalg.norm(position - delivered[r])))
        ss = jax.tree_util.tree_map(np.asarray, separate_epochs(out.fix))
        detected, ss_detected = out.check.alarm, ss.alarm
        excluded = out.excluded == slot
        mdb = mdb_all[at, slot]
        above = size >= mdb
        low, high = rate_interval(int(detected[above].sum()), int(above.sum()), 0.95)
        rows.append(
            {
                "section": "step",
                "bias_m": float(size),
                "runs": runs,
                "detection_rate": float(detected.mean()),
                "ss_detection_rate": float(ss_detected.mean()),
                "exclusion_rate": float(excluded.mean()),
                "ss_exclusion_rate": float((ss.isolated == slot).mean()),
                "mdb_median_m": float(np.median(mdb)),
                "runs_at_or_above_mdb": int(above.sum()),
                "detection_rate_at_or_above_mdb": float(detected[above].mean())
                if above.any()
                else float("nan"),
                "detection_rate_at_or_above_mdb_low": low,
                "detection_rate_at_or_above_mdb_high": high,
                "rtklib_same_decision": same,
                "rtklib_max_difference_m": worst,
            }
        )
        if progress:
            status(f"gnss-real: step {size:g} m: detection {detected.mean():.3f}")

    last = rho.shape[0] - 10  # a ramp has ten epochs (5 min) or more to grow
    # every run's (E, S) pseudoranges of the station, one run after another: one program
    # for every ramp rate and channel kind
    monitor_runs = jax.jit(
        lambda runs: jax.lax.map(lambda r: monitor_receiver(epochs._replace(pseudoranges=r)), runs)
    )
    at, slot = _trials(clean, runs, seed + 1, last=last)
    steps = np.arange(rho.shape[0])
    for rate in ramp_rates:
        grow = np.clip(steps[None, :] - at[:, None], 0, None) * 30.0 * rate  # (runs, E)
        faulty = np.repeat(rho[None], runs, axis=0)  # (runs, E, S)
        faulty[np.arange(runs), :, slot] += grow
        out = jax.tree_util.tree_map(np.asarray, monitor_runs(jnp.asarray(faulty)))
        alarm = out.check.alarm & (steps[None, :] >= at[:, None])
        detected = alarm.any(axis=1)
        first = np.argmax(alarm, axis=1)
        delay = (first - at)[detected] * 30.0
        bias = grow[np.arange(runs), first][detected]
        mdb = mdb_all[first, slot][detected]
        rows.append(
            {
                "section": "ramp",
                "rate_m_s": float(rate),
                "runs": runs,
                "detection_rate": float(detected.mean()),
                "delay_median_s": float(np.median(delay)) if delay.size else float("nan"),
                "bias_at_detection_median_m": float(np.median(bias)) if bias.size else float("nan"),
                "bias_at_detection_min_m": float(bias.min()) if bias.size else float("nan"),
                "mdb_at_detection_median_m": float(np.median(mdb)) if mdb.size else float("nan"),
            }
        )
        if progress:
            status(f"gnss-real: ramp {rate:g} m/s: detection {detected.mean():.3f}")

    # a channel that stops: frozen at its last value, or dead (an infinite pseudorange)
    tracked = np.isfinite(rho)
    for kind in ("frozen", "dead"):
        faulty = np.repeat(rho[None], runs, axis=0)
        after = (steps[None, :] >= at[:, None]) & tracked[:, slot].T  # (runs, E)
        held = rho[at, slot][:, None] if kind == "frozen" else np.inf
        faulty[np.arange(runs)[:, None], steps[None, :], slot[:, None]] = np.where(
            after, held, rho[:, slot].T
        )
        out = jax.tree_util.tree_map(np.asarray, monitor_runs(jnp.asarray(faulty)))
        flagged = out.check.alarm | out.dead.any(axis=2)
        alarm = flagged & after
        detected = alarm.any(axis=1)
        first = np.argmax(alarm, axis=1)
        isolated = out.excluded[np.arange(runs), first] == slot
        moved = np.abs(rho[first, slot] - rho[at, slot])[detected]
        rows.append(
            {
                "section": "channel",
                "kind": kind,
                "runs": runs,
                "detection_rate": float(detected.mean()),
                "exclusion_rate": float((detected & isolated).mean()),
                "delay_median_s": float(np.median((first - at)[detected] * 30.0))
                if detected.any()
                else float("nan"),
                "range_change_at_detection_median_m": float(np.median(moved))
                if kind == "frozen" and moved.size
                else float("nan"),
            }
        )
        if progress:
            status(f"gnss-real: {kind} channel: detection {detected.mean():.3f}")

    for label in PHONES:
        phone = load_phone(label)
        result = jax.tree_util.tree_map(
            np.asarray, monitor_receiver(phone, exclude=PHONE_EXCLUSIONS)
        )
        separation = jax.tree_util.tree_map(np.asarray, separate_epochs(result.fix))
        row, arrays = _phone_row(label, phone, result, separation)
        rows.append(row)
        epochs_out[label] = arrays
        peers = _peer_row(label, phone)
        if peers is not None:
            rows.append(peers)
        if progress:
            status(f"gnss-real: {label}: {row['epochs']} epochs, {row['parity_alarms']} alarms")
    config = {
        "stations": list(STATIONS),
        "fault_station": FAULT_STATION,
        "runs": runs,
        "seed": seed,
        "mask_deg": 15.0,
        "pfa": 1e-3,
        "pmd": 1e-3,
        "max_gdop": MAX_GDOP,
        "data": "GEONET 2005-04-02 00:00-01:00 GPST",
        "phones": list(PHONES),
        "phone_clocks": "one per constellation",
        "phone_mask_deg": None,
    }
    return GnssRealStudy(config, rows, epochs_out)


def plot_gnss_real(study: GnssRealStudy) -> dict[str, Any]:
    """Stanford diagrams (error vs slope and solution-separation levels, H and V) of both stations,
    captioned; returns the figure by file name (``plotting.save_figures`` writes it)."""

    fig, axes = column_subplots(6.5, 2, 2)
    count = sum(int((study.epochs[station]["gdop"] <= MAX_GDOP).sum()) for station in STATIONS)
    phones = {
        label: arrays
        for label, arrays in study.epochs.items()
        if label in PHONES and arrays["truth"].any()
    }
    count_phones = sum(int(arrays["truth"].sum()) for arrays in phones.values())
    for row, (method, prefix) in enumerate((("slope", ""), ("solution separation", "ss_"))):
        for col, (axis, error) in enumerate(
            (("horizontal", "horizontal_error"), ("vertical", "vertical_error"))
        ):
            ax = axes[row, col]
            level = prefix + ("hpl" if axis == "horizontal" else "vpl")
            for station in STATIONS:
                arrays = study.epochs[station]
                scored = arrays["gdop"] <= MAX_GDOP
                ax.loglog(
                    arrays[error][scored],
                    arrays[level][scored],
                    ".",
                    ms=3,
                    label=f"station {station}",
                )
            for label, arrays in phones.items():
                truth = arrays["truth"]
                alarm = arrays["alarm"][truth]
                ax.loglog(arrays[error], arrays[level][truth], "x", ms=4, label=label)
                ax.loglog(
                    arrays[error][alarm],
                    arrays[level][truth][alarm],
                    "o",
                    ms=6,
                    mfc="none",
                    mec="k",
                    lw=0.5,
                    label="_alarm" if label != next(iter(phones)) else "parity alarm (phones)",
                )
            stanford_regions(ax, limits=(0.05, 1e5))
            ax.set(
                xlim=(0.05, 1e3),
                ylim=(1.0, 1e5),
                xlabel=f"{axis} error [m]",
                ylabel=f"{level.replace('ss_', '').upper()} [m]",
                title=f"{axis}, {method}",
            )
    axes[0, 0].legend(fontsize=6, loc="upper left", ncol=2)
    fig = caption_figure(
        fig,
        f"Stanford diagrams of {count} epochs of GEONET stations 0759 and 3040 (one hour at 30 s, "
        "2005-04-02, GDOP <= 30), error from the surveyed position, and of the "
        f"{count_phones} smartphone epochs with ground truth (GSDC 2021-2023, crosses; circled: a "
        "parity alarm), against the slope protection levels (P_fa = P_md = 1e-3, top) and the "
        "solution-separation ones (ARAIM LPV-200 budgets, bottom). A point in the red region "
        "without an alarm is misleading information: the table counts them.",
    )
    return {"gnss-real-stanford.png": fig}
