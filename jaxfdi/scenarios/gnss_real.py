"""Real receivers: GPS integrity on an hour of two GEONET stations, beside RTKLIB.

Data: GEONET stations 0759 and 3040 (GSI, Japan; 3.3 km apart), 2005-04-02
00:00-00:59:30 GPST, 30 s, Trimble 5700, RINEX 2.10 with the broadcast ephemerides
(RTKLIB's test data, shipped in ``jaxfdi/data``). The header's ``APPROX POSITION XYZ``
is the surveyed position: the truth at every epoch.

Each epoch is fixed by ``gnss.monitor_receiver``: C1 pseudoranges, RTKLIB's
single-point model (broadcast orbits and clocks, Klobuchar, Saastamoinen, 15 deg mask,
its weights), the parity test at ``P_fa = 1e-3`` (RTKLIB's chi-square level), slope
protection levels at ``P_md = 1e-3``, exclusion; and solution-separation protection
levels (``solution_separation``: ARAIM's LPV-200 budgets, ``P_sat = 1e-5``).

- **positions**: per station, the horizontal and vertical errors from the surveyed
  position, the largest difference from RTKLIB's own fixes of the same epochs (when
  pyrtklib is installed), alarms, and misleading information (an error beyond its
  protection level without an alarm) for both protection levels: the Stanford diagrams.
- **step** and **ramp**: faults injected into station 0759's real pseudoranges. A step of
  ``b`` metres on one satellite at one epoch (a snapshot test sees one epoch at a time),
  and a ramp of ``r`` m/s on one satellite from one epoch to the end of the hour, on
  ``runs`` (satellite, epoch) pairs drawn with ``seed`` among those the fix uses. The
  step rows give the detection rate of both tests, correct exclusion, and the detection
  rate among the trials whose bias is at least the minimum detectable bias that the
  slope protection level assumes (``1 - P_md`` is promised there); the ramp rows the
  detection within the hour, the delay and the bias at detection beside that epoch's
  minimum detectable bias.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxfdi._frame import study_result
from jaxfdi._metrics import rate_interval
from jaxfdi.data import data_path
from jaxfdi.gnss._frames import ecef_to_ned
from jaxfdi.gnss._receiver import ReceiverEpochs, monitor_receiver, receiver_epochs
from jaxfdi.gnss._rinex import read_rinex_nav
from jaxfdi.gnss._rinex_obs import read_rinex_obs
from jaxfdi.gnss._solution_separation import solution_separation
from jaxfdi.plotting import COLUMN_WIDTH_IN, save_figure
from jaxfdi.scenarios._common import check_study, require_x64

#: station -> RINEX file stem in jaxfdi/data
STATIONS = {"0759": "07590920.05", "3040": "30400920.05"}
#: the station whose pseudoranges carry the injected faults
FAULT_STATION = "0759"
STEP_SIZES = (10.0, 20.0, 30.0, 50.0, 100.0)          # m
RAMP_RATES = (0.05, 0.1, 0.2, 0.5)                    # m/s
#: RTKLIB's largest GDOP for a solution (pos1-maxgdop): epochs beyond it are not scored
MAX_GDOP = 30.0


@study_result(group="section")
class GnssRealStudy(NamedTuple):
    """The study's rows (one per station, step size and ramp rate) and, for the figures,
    the per-epoch arrays of each station (``epochs[station]``: ``horizontal_error``,
    ``vertical_error``, ``hpl``, ``vpl``, ``ss_hpl``, ``ss_vpl``, ``alarm``, ``gdop``)."""
    config: dict
    rows: list[dict]
    epochs: dict

    def table(self) -> str:
        """The rows as text, a block per section."""
        out = []
        for row in self.rows:
            fields = ", ".join(f"{k} {_fmt(v)}" for k, v in row.items() if k != "section")
            out.append(f"{row['section']:<9} {fields}")
        return "\n".join(out)


def _fmt(value) -> str:
    if isinstance(value, float):
        return "-" if not math.isfinite(value) else f"{value:.4g}"
    return str(value)


def local_errors(position: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal and vertical (absolute) errors [m] of (E, 3) ECEF fixes from ``truth``, in
    the north-east-down axes at ``truth``."""
    ned = np.asarray(ecef_to_ned(position, truth))
    return np.hypot(ned[:, 0], ned[:, 1]), np.abs(ned[:, 2])


def _load(station: str) -> tuple[ReceiverEpochs, np.ndarray]:
    obs = read_rinex_obs(data_path(STATIONS[station] + "o"))
    return receiver_epochs(obs, read_rinex_nav(data_path(STATIONS[station] + "n"))), obs.approx_position


def _rtklib_difference(station: str, position: np.ndarray, times: np.ndarray) -> float | None:
    """Largest distance [m] from RTKLIB's single-point fixes of the same epochs (pyrtklib's
    ``postpos`` with the same models), ``None`` without pyrtklib."""
    try:
        import pyrtklib as rtk
    except ImportError:
        return None
    import tempfile
    from pathlib import Path

    rtk.resetsysopts()
    popt, sopt, fopt = rtk.prcopt_t(), rtk.solopt_t(), rtk.filopt_t()
    rtk.getsysopts(popt, sopt, fopt)
    popt.mode, popt.navsys, popt.elmin = rtk.PMODE_SINGLE, rtk.SYS_GPS, math.radians(15.0)
    popt.ionoopt, popt.tropopt, sopt.posf = rtk.IONOOPT_BRDC, rtk.TROPOPT_SAAS, rtk.SOLF_XYZ
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "rtklib.pos"
        name = rtk.Arr1Dchar(1024)
        for i, c in enumerate(str(out)):
            name[i] = c
        files = [str(data_path(STATIONS[station] + "o")), str(data_path(STATIONS[station] + "n"))]
        if rtk.postpos(rtk.gtime_t(), rtk.gtime_t(), 0.0, 0.0, popt, sopt, fopt, files, 2, name, "", "") != 0:
            return None
        lines = [line.split() for line in out.read_text().splitlines() if not line.startswith("%")]
    worst = 0.0
    for fields in lines:
        hour, minute, second = fields[1].split(":")
        seconds = int(hour) * 3600 + int(minute) * 60 + float(second)
        at = np.flatnonzero(np.abs(np.mod(times, 86400.0) - seconds) < 0.1)
        if at.size:
            worst = max(worst, float(np.linalg.norm(position[at[0]] - np.array([float(v) for v in fields[2:5]]))))
    return worst


def _position_row(station: str, result, separation, truth: np.ndarray, times: np.ndarray) -> tuple[dict, dict]:
    fix = result.fix
    position = np.asarray(fix.position)
    horizontal, vertical = local_errors(position, truth)
    gdop = np.asarray(fix.dops.gdop)
    scored = gdop <= MAX_GDOP
    alarm = np.asarray(result.check.alarm)
    hpl, vpl = np.asarray(result.protection.hpl), np.asarray(result.protection.vpl)
    ss_hpl, ss_vpl = np.asarray(separation.hpl), np.asarray(separation.vpl)

    def misleading(error, level):
        return int(np.sum(scored & ~alarm & (error > level)))

    row = {
        "section": "positions", "station": f"GEONET {station}", "epochs": int(times.size), "scored_epochs": int(scored.sum()),
        "horizontal_error_median_m": float(np.median(horizontal[scored])),
        "horizontal_error_95_m": float(np.percentile(horizontal[scored], 95)),
        "horizontal_error_max_m": float(horizontal[scored].max()),
        "vertical_error_median_m": float(np.median(vertical[scored])),
        "vertical_error_95_m": float(np.percentile(vertical[scored], 95)),
        "vertical_error_max_m": float(vertical[scored].max()),
        "rtklib_max_difference_m": _rtklib_difference(station, position, times),
        "parity_alarms": int(alarm[scored].sum()), "ss_alarms": int(np.asarray(separation.alarm)[scored].sum()),
        "hpl_median_m": float(np.median(hpl[scored])), "vpl_median_m": float(np.median(vpl[scored])),
        "ss_hpl_median_m": float(np.median(ss_hpl[scored])), "ss_vpl_median_m": float(np.median(ss_vpl[scored])),
        "misleading_slope": misleading(horizontal, hpl) + misleading(vertical, vpl),
        "misleading_ss": misleading(horizontal, ss_hpl) + misleading(vertical, ss_vpl),
    }
    arrays = {"horizontal_error": horizontal, "vertical_error": vertical, "hpl": hpl, "vpl": vpl, "ss_hpl": ss_hpl,
              "ss_vpl": ss_vpl, "alarm": alarm, "gdop": gdop}
    return row, arrays


def _trials(result, runs: int, seed: int, last: int) -> tuple[np.ndarray, np.ndarray]:
    """``runs`` (epoch, slot) pairs drawn among the scored epochs before ``last`` and the
    slots each fix uses."""
    used = np.asarray(result.fix.used) & (np.asarray(result.fix.dops.gdop) <= MAX_GDOP)[:, None]
    used[last:] = False
    epochs, slots = np.nonzero(used)
    pick = np.random.default_rng(seed).choice(epochs.size, size=runs, replace=True)
    return epochs[pick], slots[pick]


def gnss_real_study(runs: int = 200, seed: int = 0, progress: bool = False,
                    step_sizes=STEP_SIZES, ramp_rates=RAMP_RATES) -> GnssRealStudy:
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
    separate = jax.jit(jax.vmap(solution_separation))
    loaded = {}
    for station in STATIONS:
        epochs, truth = _load(station)
        result = jax.tree_util.tree_map(np.asarray, monitor_receiver(epochs))
        loaded[station] = epochs, result
        separation = jax.tree_util.tree_map(np.asarray, separate(result.fix))
        row, arrays = _position_row(station, result, separation, truth, np.asarray(epochs.times))
        rows.append(row)
        epochs_out[station] = arrays
        if progress:
            print(f"gnss-real: station {station}: {row['scored_epochs']} epochs scored", flush=True)

    epochs, clean = loaded[FAULT_STATION]
    rho = np.asarray(epochs.pseudoranges)
    times = np.asarray(epochs.times)
    mdb_all = np.asarray(clean.protection.minimum_detectable_bias)
    at, slot = _trials(clean, runs, seed, last=rho.shape[0])
    for size in step_sizes:
        faulty = rho[at].copy()
        faulty[np.arange(runs), slot] += size
        trial = epochs._replace(times=jnp.asarray(times[at]), pseudoranges=jnp.asarray(faulty))
        out = jax.tree_util.tree_map(np.asarray, monitor_receiver(trial))
        ss = jax.tree_util.tree_map(np.asarray, separate(out.fix))
        detected, ss_detected = out.check.alarm, ss.alarm
        excluded = out.excluded == slot
        mdb = mdb_all[at, slot]
        above = size >= mdb
        low, high = rate_interval(int(detected[above].sum()), int(above.sum()), 0.95)
        rows.append({"section": "step", "bias_m": float(size), "runs": runs,
                     "detection_rate": float(detected.mean()), "ss_detection_rate": float(ss_detected.mean()),
                     "exclusion_rate": float(excluded.mean()), "mdb_median_m": float(np.median(mdb)),
                     "runs_at_or_above_mdb": int(above.sum()),
                     "detection_rate_at_or_above_mdb": float(detected[above].mean()) if above.any() else float("nan"),
                     "detection_rate_at_or_above_mdb_low": low, "detection_rate_at_or_above_mdb_high": high})
        if progress:
            print(f"gnss-real: step {size:g} m: detection {detected.mean():.3f}", flush=True)

    last = rho.shape[0] - 10   # a ramp has ten epochs (5 min) or more to grow
    at, slot = _trials(clean, runs, seed + 1, last=last)
    steps = np.arange(rho.shape[0])
    for rate in ramp_rates:
        grow = np.clip(steps[None, :] - at[:, None], 0, None) * 30.0 * rate          # (runs, E)
        faulty = np.repeat(rho[None], runs, axis=0)                                     # (runs, E, S)
        faulty[np.arange(runs), :, slot] += grow
        run_one = lambda r: monitor_receiver(epochs._replace(pseudoranges=r))  # noqa: E731
        out = jax.tree_util.tree_map(np.asarray, jax.lax.map(run_one, jnp.asarray(faulty)))
        alarm = out.check.alarm & (steps[None, :] >= at[:, None])
        detected = alarm.any(axis=1)
        first = np.argmax(alarm, axis=1)
        delay = (first - at)[detected] * 30.0
        bias = grow[np.arange(runs), first][detected]
        mdb = mdb_all[first, slot][detected]
        rows.append({"section": "ramp", "rate_m_s": float(rate), "runs": runs,
                     "detection_rate": float(detected.mean()),
                     "delay_median_s": float(np.median(delay)) if delay.size else float("nan"),
                     "bias_at_detection_median_m": float(np.median(bias)) if bias.size else float("nan"),
                     "bias_at_detection_min_m": float(bias.min()) if bias.size else float("nan"),
                     "mdb_at_detection_median_m": float(np.median(mdb)) if mdb.size else float("nan")})
        if progress:
            print(f"gnss-real: ramp {rate:g} m/s: detection {detected.mean():.3f}", flush=True)
    config = {"stations": list(STATIONS), "fault_station": FAULT_STATION, "runs": runs, "seed": seed,
              "mask_deg": 15.0, "pfa": 1e-3, "pmd": 1e-3, "max_gdop": MAX_GDOP,
              "data": "GEONET 2005-04-02 00:00-01:00 GPST"}
    return GnssRealStudy(config, rows, epochs_out)


def plot_gnss_real(study: GnssRealStudy, out_dir) -> list[str]:
    """The Stanford diagrams (error against protection level, slope and solution
    separation, horizontal and vertical) of both stations' epochs, as a PNG in ``out_dir``;
    returns its path."""
    from pathlib import Path

    from matplotlib.figure import Figure

    fig = Figure(figsize=(COLUMN_WIDTH_IN, 6.0), layout="constrained")
    axes = fig.subplots(2, 2)
    count = sum(int((arrays["gdop"] <= MAX_GDOP).sum()) for arrays in study.epochs.values())
    for row, (method, prefix) in enumerate((("slope", ""), ("solution separation", "ss_"))):
        for col, (axis, error) in enumerate((("horizontal", "horizontal_error"), ("vertical", "vertical_error"))):
            ax = axes[row, col]
            level = prefix + ("hpl" if axis == "horizontal" else "vpl")
            for station, arrays in study.epochs.items():
                scored = arrays["gdop"] <= MAX_GDOP
                ax.loglog(arrays[error][scored], arrays[level][scored], ".", ms=3, label=f"station {station}")
            ax.plot((10.0, 1e3), (10.0, 1e3), "k-", lw=0.8, label="error = PL")
            ax.fill_between((10.0, 1e3), (10.0, 10.0), (10.0, 1e3), color="r", alpha=0.1,
                            label="misleading (error > PL)")
            ax.set(xlim=(0.05, 1e3), ylim=(10.0, 1e5), xlabel=f"{axis} error [m]",
                   ylabel=f"{level.replace('ss_', '').upper()} [m]", title=f"{axis}, {method}")
            ax.legend(fontsize=6, loc="upper left")
    path = save_figure(fig, Path(out_dir) / "gnss-real-stanford.png",
                       f"Stanford diagrams of {count} epochs of GEONET stations 0759 and 3040 (one hour at 30 s, "
                       "2005-04-02, GDOP <= 30): error from the surveyed position against the slope protection levels "
                       "(P_fa = P_md = 1e-3, top) and the solution-separation ones (ARAIM LPV-200 budgets, bottom); no "
                       "epoch falls in the misleading region.")
    return [str(path)]
