"""Snapshot RAIM + protection levels over 10^5 epochs: jaxfdi (vmapped) against a plain
NumPy loop and gnss-lib-py's residual fault detection and exclusion.

Data: 10^5 epochs over 2020-01-01 at 20 receivers (broadcast ephemerides of the shipped
RINEX file, 5 deg mask, 5-12 satellites), satellite positions and clocks at transmission
and pseudoranges with sigma = 5 m white noise, a 200 m bias on one satellite in 10 % of
the epochs. Every implementation gets the same satellite states and pseudoranges and
does, per epoch:

* jaxfdi: ``integrity.monitor_epoch`` (8 Gauss-Newton steps by masked Householder QR,
  parity statistic, threshold, isolation, slopes, HPL/VPL, availability, exclusion by a
  3-step re-solve), ``jit(vmap)`` over all epochs, fixed shapes: ``--channels`` slots
  (16, a receiver's channel count; the visible satellites first, the rest masked), vmapped
  over chunks of ``--batch`` epochs one after another (``lax.map``: cache-sized);
* numpy loop: the same algorithm written for one epoch with ``np.linalg.qr`` on the
  visible rows (complete QR for the parity matrix, as the paper), looped over
  ``--numpy-epochs`` epochs and scaled to 10^5;
* gnss-lib-py 1.1.0 ``solve_fde(method="residual")`` (greedy residual chi-square FDE,
  no protection levels) on ``--glp-epochs`` epochs, scaled; its single threshold is
  ``sigma^2`` times the chi-square threshold of the median degrees of freedom.

Agreement checked before timing: jaxfdi vs numpy statistic, HPL (relative 1e-6) and the
isolated satellite (equal); gnss-lib-py's flagged satellite on the faulted epochs is
reported. Compile time apart from run time (median of repeats).

Run:  python benchmarks/bench_gnss_raim.py                      (~3 minutes on 2 cores)
      python benchmarks/bench_gnss_raim.py --epochs 20000 --numpy-epochs 300 --glp-epochs 100   (quick)
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

from jaxfdi._io import files as _io
from jaxfdi.data import data_path
from jaxfdi.gnss import (
    OMEGA_E,
    ephemeris_table,
    geodetic_to_ecef,
    raim_tables,
    read_rinex_nav,
    select_orbits,
)
from jaxfdi.gnss import _integrity as integrity
from jaxfdi.gnss._frames import elevation_azimuth
from jaxfdi.gnss._orbits import SPEED_OF_LIGHT, transmission_geometry
from jaxfdi.gnss._positioning import transmit_states

SIGMA = 5.0
MASK = math.radians(5.0)
DAY0 = 259200.0


def compiled_timing(fn, args, repeats):
    """Compile ``jit(fn)`` (timed apart), run once, then the median of ``repeats`` runs."""
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    out = jax.block_until_ready(compiled(*args))
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        runs.append(time.perf_counter() - t0)
    return {
        "compile_s": compile_s,
        "median_s": float(np.median(runs)),
        "min_s": float(np.min(runs)),
    }, out


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def make_data(table, epochs: int, seed: int = 0):
    """(times, sat_tx (E,S,3), clocks (E,S), rho (E,S) NaN where not visible, faulted slot (E,))."""
    rng = np.random.default_rng(seed)
    sites = geodetic_to_ecef(
        jnp.radians(rng.uniform(-60, 60, 20)), jnp.radians(rng.uniform(-180, 180, 20)), 100.0
    )
    times = DAY0 + np.sort(rng.uniform(0, 86000, epochs))
    site_of = rng.integers(0, 20, epochs)
    fault_on = rng.uniform(size=epochs) < 0.1

    def one(t, site, key, faulty):
        orbit, ok = select_orbits(table, t)
        _, ranges, _, clock = transmission_geometry(orbit, t, site)
        el, _ = elevation_azimuth(site, orbit_positions(orbit, t))
        visible = ok & (el > MASK)
        rho = ranges - SPEED_OF_LIGHT * clock + SIGMA * jax.random.normal(key, ranges.shape)
        slot = jnp.argmax(
            jnp.where(visible, jax.random.uniform(jax.random.fold_in(key, 1), ranges.shape), -1.0)
        )
        rho = rho + jnp.where(faulty & (jnp.arange(rho.shape[0]) == slot), 200.0, 0.0)
        rho = jnp.where(visible, rho, jnp.nan)
        sat_tx, clk = transmit_states(orbit, t, rho)
        return sat_tx, clk, rho, jnp.where(faulty, slot, -1)

    from jaxfdi.gnss._orbits import satellite_position as orbit_positions

    keys = jax.random.split(jax.random.key(seed), epochs)
    out = jax.jit(jax.vmap(one))(jnp.asarray(times), sites[site_of], keys, jnp.asarray(fault_on))
    return (times,) + tuple(np.asarray(o) for o in out)


def jax_monitor(tables, batch_size):
    def one(t, sat_tx, clk, rho):
        used = jnp.isfinite(rho)
        sigma = jnp.full(rho.shape, SIGMA)
        result = integrity.monitor_epoch(None, used, t, rho, tables, sigma, transmit=(sat_tx, clk))
        return (
            result.check.statistic,
            result.protection.hpl,
            result.check.isolated,
            result.check.alarm,
            result.excluded,
            result.fix.position,
        )

    if not batch_size:
        return jax.vmap(one)
    return lambda *args: jax.lax.map(
        lambda a: one(*a), args, batch_size=batch_size
    )  # cache-sized chunks


# --- the NumPy loop ----------------------------------------------------------------------


def _geodetic(x):
    a, f = 6378137.0, 1.0 / 298.257223563
    e2, b = f * (2 - f), a * (1 - f)
    p = math.hypot(x[0], x[1])
    lon = math.atan2(x[1], x[0])
    beta = math.atan2(x[2], (1 - f) * p)
    for _ in range(5):
        lat = math.atan2(
            x[2] + e2 / (1 - e2) * b * math.sin(beta) ** 3, p - e2 * a * math.cos(beta) ** 3
        )
        beta = math.atan2((1 - f) * math.sin(lat), math.cos(lat))
    return lat, lon


def _wls(sat, clk, rho, sigma, x, iterations):
    for _ in range(iterations):
        tau = np.linalg.norm(sat - x[:3], axis=1) / SPEED_OF_LIGHT
        ang = OMEGA_E * tau
        rot = np.stack(
            [
                np.cos(ang) * sat[:, 0] + np.sin(ang) * sat[:, 1],
                -np.sin(ang) * sat[:, 0] + np.cos(ang) * sat[:, 1],
                sat[:, 2],
            ],
            axis=1,
        )
        d = rot - x[:3]
        r = np.linalg.norm(d, axis=1)
        h = np.hstack([-d / r[:, None], np.ones((len(r), 1))]) / sigma[:, None]
        dy = (rho - (r + x[3] - SPEED_OF_LIGHT * clk)) / sigma
        q, rr = np.linalg.qr(h)
        x = x + np.linalg.solve(rr, q.T @ dy)
    return x, rot


def _assess(sat_rot, x, rho, clk, sigma, threshold, lam):
    lat, lon = _geodetic(x)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    ned = np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])
    d = sat_rot - x[:3]
    r = np.linalg.norm(d, axis=1)
    hw = np.hstack([-(d / r[:, None]) @ ned.T, np.ones((len(r), 1))]) / sigma[:, None]
    yw = (rho - (r + x[3] - SPEED_OF_LIGHT * clk)) / sigma
    n = len(r)
    q, rr = np.linalg.qr(hw, mode="complete")
    p = q[:, 4:].T @ yw
    stat = float(p @ p)
    cols = q[:, 4:].T
    s_diag = np.sum(cols**2, axis=0)
    ts = (p @ cols) / np.sqrt(s_diag)
    gain = np.linalg.solve(rr[:4], q[:, :4].T)
    slope = np.hypot(gain[0], gain[1]) / np.sqrt(s_diag)
    dof = n - 4
    return (
        stat,
        threshold[dof],
        float(slope.max() * math.sqrt(lam[dof])),
        int(np.argmax(np.abs(ts))) if n >= 6 else -1,
    )


def numpy_epoch(t, sat_tx, clk, rho, threshold, lam):
    used = np.flatnonzero(np.isfinite(rho))
    sat, c, y = sat_tx[used], clk[used], rho[used]
    sigma = np.full(len(used), SIGMA)
    x, rot = _wls(sat, c, y, sigma, np.zeros(4), 8)
    stat, thr, hpl, iso = _assess(rot, x, y, c, sigma, threshold, lam)
    excluded = -1
    if stat > thr and iso >= 0:
        keep = np.arange(len(used)) != iso
        x2, rot2 = _wls(sat[keep], c[keep], y[keep], sigma[keep], x, 3)
        _assess(rot2, x2, y[keep], c[keep], sigma[keep], threshold, lam)
        excluded = int(used[iso])
    return stat, hpl, int(used[iso]) if iso >= 0 else -1, excluded


# --- gnss-lib-py ---------------------------------------------------------------------------


def glp_navdata(times, sat_tx, clk, rho):
    from gnss_lib_py.navdata.navdata import NavData

    rows = {
        k: [] for k in ("gps_millis", "sv_id", "x_sv_m", "y_sv_m", "z_sv_m", "b_sv_m", "corr_pr_m")
    }
    for e in range(len(times)):
        for s in np.flatnonzero(np.isfinite(rho[e])):
            rows["gps_millis"].append((2086 * 604800.0 + times[e]) * 1e3)
            rows["sv_id"].append(s + 1)
            rows["x_sv_m"].append(sat_tx[e, s, 0])
            rows["y_sv_m"].append(sat_tx[e, s, 1])
            rows["z_sv_m"].append(sat_tx[e, s, 2])
            rows["b_sv_m"].append(SPEED_OF_LIGHT * clk[e, s])
            rows["corr_pr_m"].append(rho[e, s] + SPEED_OF_LIGHT * clk[e, s])
    nav = NavData()
    for key, values in rows.items():
        nav[key] = np.asarray(values)
    nav["gnss_id"] = np.array(["gps"] * len(rows["sv_id"]))
    return nav


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--epochs", type=int, default=100_000)
    parser.add_argument("--numpy-epochs", type=int, default=2000)
    parser.add_argument("--glp-epochs", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--channels", type=int, default=16, help="receiver channels (fixed slots) for jaxfdi"
    )
    parser.add_argument(
        "--batch", type=int, default=128, help="epochs per vmapped chunk (0: all at once)"
    )
    parser.add_argument(
        "--out", default=os.path.join(os.path.dirname(__file__), "results_gnss_raim.json")
    )
    args = parser.parse_args(argv)

    table = ephemeris_table(read_rinex_nav(data_path("gps_nav_rinex2_sugl0010.20n")), 2086)
    tables = raim_tables(32)
    t0 = time.perf_counter()
    times, sat_tx, clk, rho, faulted = make_data(table, args.epochs)
    print(
        f"data: {args.epochs} epochs, {np.isfinite(rho).sum(1).min()}-{np.isfinite(rho).sum(1).max()} satellites, "
        f"{(faulted >= 0).mean():.1%} faulted ({time.perf_counter() - t0:.1f} s)",
        flush=True,
    )

    # a receiver's fixed channel count: the visible satellites first, CHANNELS slots an epoch
    order = np.argsort(~np.isfinite(rho), axis=1, kind="stable")[:, : args.channels]
    assert np.isfinite(rho).sum(1).max() <= args.channels
    take = lambda a: np.take_along_axis(a, order.reshape(order.shape + (1,) * (a.ndim - 2)), axis=1)
    inputs = tuple(jnp.asarray(a) for a in (times, take(sat_tx), take(clk), take(rho)))
    channel_tables = raim_tables(args.channels)
    timing, out = compiled_timing(jax_monitor(channel_tables, args.batch), inputs, args.repeats)
    stat, hpl, iso, alarm, excluded, _ = (np.asarray(o) for o in out)
    slot_of = lambda c: np.where(
        c >= 0, np.take_along_axis(order, np.maximum(c, 0)[:, None], 1)[:, 0], -1
    )
    iso, excluded = slot_of(iso), slot_of(excluded)
    jax_epoch_us = timing["median_s"] / args.epochs * 1e6
    print(
        f"jaxfdi: compile {timing['compile_s']:.1f} s, run {timing['median_s']:.3f} s for {args.epochs} epochs "
        f"({jax_epoch_us:.2f} us/epoch)",
        flush=True,
    )

    threshold, lam = np.asarray(tables.threshold), np.asarray(tables.noncentrality)
    picks = np.linspace(0, args.epochs - 1, args.numpy_epochs).astype(int)
    t0 = time.perf_counter()
    ref = [numpy_epoch(times[e], sat_tx[e], clk[e], rho[e], threshold, lam) for e in picks]
    numpy_s = time.perf_counter() - t0
    numpy_epoch_us = numpy_s / len(picks) * 1e6
    ref_stat, ref_hpl, ref_iso, ref_excl = (np.asarray(v) for v in zip(*ref))
    worst_stat = float(np.max(np.abs(stat[picks] - ref_stat) / np.maximum(ref_stat, 1e-9)))
    worst_hpl = float(np.max(np.abs(hpl[picks] - ref_hpl) / ref_hpl))
    iso_equal = bool(np.all(iso[picks] == ref_iso))
    assert worst_stat < 1e-6 and worst_hpl < 1e-6 and iso_equal, (worst_stat, worst_hpl, iso_equal)
    print(
        f"numpy loop: {numpy_epoch_us:.0f} us/epoch ({len(picks)} epochs in {numpy_s:.1f} s); agreement: "
        f"statistic {worst_stat:.1e}, HPL {worst_hpl:.1e} relative, isolated satellite equal",
        flush=True,
    )

    glp = None
    try:
        import gnss_lib_py
        from gnss_lib_py.algorithms.fde import solve_fde
    except ImportError:
        print("gnss-lib-py not installed: skipped (pip install gnss-lib-py)")
    else:
        gpicks = np.linspace(0, args.epochs - 1, args.glp_epochs).astype(int)
        nav = glp_navdata(times[gpicks], sat_tx[gpicks], clk[gpicks], rho[gpicks])
        median_dof = int(np.median(np.isfinite(rho).sum(1) - 4))
        t0 = time.perf_counter()
        result = solve_fde(
            nav, method="residual", threshold=SIGMA**2 * float(threshold[median_dof])
        )
        glp_s = time.perf_counter() - t0
        flags = np.asarray(result["fault_residual"])
        sv = np.asarray(result["sv_id"]) - 1
        millis = np.asarray(result["gps_millis"])
        epoch_of = {m: k for k, m in enumerate(np.unique(millis))}
        hit = np.zeros(len(gpicks), bool)
        for m, s, f in zip(millis, sv, flags):
            if f == 1 and faulted[gpicks][epoch_of[m]] == s:
                hit[epoch_of[m]] = True
        faulty_epochs = faulted[gpicks] >= 0
        glp = {
            "version": gnss_lib_py.__version__,
            "epochs": len(gpicks),
            "seconds": glp_s,
            "us_per_epoch": glp_s / len(gpicks) * 1e6,
            "faulted_epochs_flagging_the_faulty_satellite": float(hit[faulty_epochs].mean()),
            "jaxfdi_same_epochs_excluding_it": float(
                (excluded[gpicks] == faulted[gpicks])[faulty_epochs].mean()
            ),
        }
        print(
            f"gnss-lib-py {gnss_lib_py.__version__}: {glp['us_per_epoch']:.0f} us/epoch ({len(gpicks)} epochs in "
            f"{glp_s:.1f} s); faulty satellite flagged on {glp['faulted_epochs_flagging_the_faulty_satellite']:.1%} "
            f"of the faulted epochs (jaxfdi excludes it on {glp['jaxfdi_same_epochs_excluding_it']:.1%})",
            flush=True,
        )

    summary = {
        "epochs": args.epochs,
        "channels": args.channels,
        "batch": args.batch,
        "jax_compile_s": timing["compile_s"],
        "jax_run_s": timing["median_s"],
        "jax_us_per_epoch": jax_epoch_us,
        "numpy_us_per_epoch": numpy_epoch_us,
        "speedup_vs_numpy": numpy_epoch_us / jax_epoch_us,
        "speedup_vs_gnss_lib_py": None if glp is None else glp["us_per_epoch"] / jax_epoch_us,
        "gnss_lib_py": glp,
        "agreement": {
            "statistic_rel": worst_stat,
            "hpl_rel": worst_hpl,
            "isolated_equal": iso_equal,
        },
        "faulted_epochs_excluded_jax": float((excluded == faulted)[faulted >= 0].mean()),
        "fault_free_alarm_rate_jax": float(alarm[faulted < 0].mean()),
        "machine": {
            "cpu": cpu_model(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "date": datetime.date.today().isoformat(),
        },
    }
    print(
        f"speed-up: {summary['speedup_vs_numpy']:.0f}x the numpy loop"
        + ("" if glp is None else f", {summary['speedup_vs_gnss_lib_py']:.0f}x gnss-lib-py")
    )
    _io.write_json(args.out, summary)
    print(f"wrote {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_gnss_raim.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
