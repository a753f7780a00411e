"""Real receivers: epochs per second for positioning + RAIM + both protection levels on the
GEONET hour, jaxfdi beside RTKLIB, and on a smartphone trace, jaxfdi beside gnss_lib_py.

* jaxfdi: ``monitor_receiver`` (single-point fix with RTKLIB's model, parity test,
  slope HPL/VPL, exclusion by a 3-step re-solve) and ``solution_separation`` (ARAIM
  MHSS levels) vmapped over the epochs of station 0759's hour, tiled ``--copies`` (10) times
  (the same 120 epochs again: the cost per epoch does not depend on which epoch);
  compile apart from run (median of ``--repeats``).
* RTKLIB 2.4.3 (pyrtklib's ``postpos``, what ``rnx2rtkp`` runs) on the same hour:
  single-point positioning with the same models, with and without its RAIM FDE option;
  its time includes reading the RINEX files and writing the solution file (it has no
  call without them), so it is a per-epoch cost of the whole program, not of the fix alone.
* gnss_lib_py 1.1 on the same hour: ``solve_wls`` and ``solve_fde(method="residual",
  max_faults=1)`` on the satellites our fixes use, with our satellite positions at
  transmission and clock-corrected pseudoranges given (it computes no orbits there, no
  atmosphere and no protection level, so the ratio flatters it).

* Phones: the GSDC 2021 Pixel 4 XL trace (281 epochs, 48 signal slots, 5
  constellations). jaxfdi: ``monitor_receiver`` (a clock per constellation, parity test,
  slope levels, exclusion) and ``solution_separation``, the trace tiled ``--copies``
  times. gnss_lib_py 1.1: ``solve_wls`` and ``solve_fde(method="residual",
  max_faults=1)`` (its greedy residual FDE, which re-solves its WLS) on the trace's
  NavData; no protection level (it has none), so the ratio flatters gnss_lib_py.

Run:  python benchmarks/bench_gnss_real.py        (~2 minutes on 2 cores; writes benchmarks/gnss_real.json)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import tempfile
import time
import warnings
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

from jaxfdi.data import data_path
from jaxfdi.gnss import (
    monitor_receiver,
    read_observations,
    read_rinex_nav,
    receiver_epochs,
    select_orbits,
)
from jaxfdi.gnss._orbits import SPEED_OF_LIGHT
from jaxfdi.gnss._positioning import transmit_states
from jaxfdi.gnss._solution_separation import solution_separation
from jaxfdi.scenarios.gnss_real import _peer_navdata, load_phone

PHONE = "GSDC 2021 Pixel 4 XL"


def _timed(run, repeats: int) -> tuple[float, float]:
    """(first call [s], median of ``repeats`` later calls [s]) of ``run``, blocked until ready."""
    start = time.perf_counter()
    jax.block_until_ready(run())
    first = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run())
        times.append(time.perf_counter() - start)
    return first, float(np.median(times))


def phone_timing(copies: int, repeats: int) -> dict:
    phone = load_phone(PHONE)
    tiled = phone._replace(
        **{
            f: np.tile(getattr(phone, f), (copies,) + (1,) * (getattr(phone, f).ndim - 1))
            for f in ("pseudorange", "sigma", "satellite")
        }
    )
    separate = jax.jit(jax.vmap(solution_separation))

    def run():
        result = monitor_receiver(tiled)
        return result, separate(result.fix)

    first, median = _timed(run, repeats)
    count = copies * phone.gps_millis.size
    return {"epochs": count, "first_call_s": first, "run_s": median, "epochs_per_s": count / median}


def _gnss_lib_py_rate(make_nav, count: int, repeats: int) -> dict:
    """gnss_lib_py's ``solve_wls`` + ``solve_fde(method="residual", max_faults=1)`` on a fresh
    ``make_nav()`` each repeat (both write rows into it); ``count`` epochs."""
    from gnss_lib_py.algorithms.fde import solve_fde
    from gnss_lib_py.algorithms.snapshot import solve_wls

    times = []
    for _ in range(repeats):
        nav = make_nav()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = time.perf_counter()
            solve_wls(nav)
            solve_fde(nav, method="residual", threshold=3000.0, max_faults=1)
            times.append(time.perf_counter() - start)
    return {
        "epochs": count,
        "run_s": float(np.median(times)),
        "epochs_per_s": count / float(np.median(times)),
    }


def gnss_lib_py_timing(repeats: int) -> dict:
    phone = load_phone(PHONE)
    return _gnss_lib_py_rate(lambda: _peer_navdata(phone)[0], phone.gps_millis.size, repeats)


def gnss_lib_py_geonet_timing(repeats: int) -> dict:
    """gnss_lib_py's WLS + residual FDE on station 0759's hour (module doc)."""
    from gnss_lib_py.navdata.navdata import NavData

    epochs = receiver_epochs(
        read_observations(data_path("07590920.05o")), read_rinex_nav(data_path("07590920.05n"))
    )
    used = np.asarray(monitor_receiver(epochs).fix.used)

    def states(t, rho):
        orbit, _ = select_orbits(epochs.table, t)
        return transmit_states(orbit, t, rho)

    position, clock = (np.asarray(a) for a in jax.vmap(states)(epochs.times, epochs.pseudoranges))
    at, slot = np.nonzero(used)

    def make_nav():
        nav = NavData()
        nav["gps_millis"] = np.asarray(epochs.times)[at] * 1e3
        nav["corr_pr_m"] = (
            np.asarray(epochs.pseudoranges)[at, slot] + SPEED_OF_LIGHT * clock[at, slot]
        )
        for i, axis in enumerate("xyz"):
            nav[f"{axis}_sv_m"] = position[at, slot, i]
        nav["b_sv_m"] = np.zeros(at.size)
        return nav

    return _gnss_lib_py_rate(make_nav, int(np.any(used, axis=1).sum()), repeats)


def jaxfdi_timing(copies: int, repeats: int) -> dict:
    epochs = receiver_epochs(
        read_observations(data_path("07590920.05o")), read_rinex_nav(data_path("07590920.05n"))
    )
    tiled = epochs._replace(
        times=jnp.tile(epochs.times, copies),
        pseudoranges=jnp.tile(epochs.pseudoranges, (copies, 1)),
    )
    separate = jax.jit(jax.vmap(solution_separation))

    def run():
        result = monitor_receiver(tiled)
        return result, separate(result.fix)

    first, median = _timed(run, repeats)
    count = int(tiled.times.shape[0])
    return {"epochs": count, "first_call_s": first, "run_s": median, "epochs_per_s": count / median}


def rtklib_timing(raim: bool, repeats: int) -> dict:
    import pyrtklib as rtk

    files = [str(data_path("07590920.05o")), str(data_path("07590920.05n"))]
    times = []
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(repeats):
            rtk.resetsysopts()
            popt, sopt, fopt = rtk.prcopt_t(), rtk.solopt_t(), rtk.filopt_t()
            rtk.getsysopts(popt, sopt, fopt)
            popt.mode, popt.navsys, popt.elmin = rtk.PMODE_SINGLE, rtk.SYS_GPS, math.radians(15.0)
            popt.ionoopt, popt.tropopt, sopt.posf = rtk.IONOOPT_BRDC, rtk.TROPOPT_SAAS, rtk.SOLF_XYZ
            if raim:
                popt.posopt[4] = 1
            out = Path(folder) / "out.pos"
            name = rtk.Arr1Dchar(1024)
            for i, c in enumerate(str(out)):
                name[i] = c
            start = time.perf_counter()
            status = rtk.postpos(
                rtk.gtime_t(), rtk.gtime_t(), 0.0, 0.0, popt, sopt, fopt, files, 2, name, "", ""
            )
            times.append(time.perf_counter() - start)
            assert status == 0
            solved = sum(1 for line in out.read_text().splitlines() if not line.startswith("%"))
    return {
        "epochs": 120,
        "solved": solved,
        "run_s": float(np.median(times)),
        "epochs_per_s": 120 / float(np.median(times)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--copies", type=int, default=10, help="tiles of the 120-epoch hour for jaxfdi (default 10)"
    )
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--out", default="benchmarks/gnss_real.json", help="JSON results (written atomically)"
    )
    args = parser.parse_args()
    results = {
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(),
            "jax": jax.__version__,
            "device": str(jax.devices()[0]),
        },
        "copies": args.copies,
    }
    ours = jaxfdi_timing(args.copies, args.repeats)
    results["geonet"] = {"jaxfdi": ours}
    print(
        f"jaxfdi: {ours['epochs']} epochs, first call {ours['first_call_s']:.1f} s (compile), then "
        f"{ours['run_s'] * 1e3:.1f} ms: {ours['epochs_per_s']:.0f} epochs/s (fix, parity test, slope and "
        f"solution-separation PLs, exclusion)"
    )
    for raim in (False, True):
        peer = rtklib_timing(raim, args.repeats)
        results["geonet"]["rtklib_raim_fde" if raim else "rtklib"] = peer
        print(
            f"RTKLIB postpos{' with RAIM FDE' if raim else ''}: {peer['solved']} of 120 epochs solved in "
            f"{peer['run_s'] * 1e3:.1f} ms (reading and writing files included): {peer['epochs_per_s']:.0f} epochs/s; "
            f"jaxfdi/RTKLIB = {ours['epochs_per_s'] / peer['epochs_per_s']:.1f}x"
        )
    peer = gnss_lib_py_geonet_timing(args.repeats)
    results["geonet"]["gnss_lib_py"] = peer
    print(
        f"gnss_lib_py solve_wls + residual FDE on the same hour: {peer['epochs']} epochs in "
        f"{peer['run_s'] * 1e3:.0f} ms: {peer['epochs_per_s']:.0f} epochs/s (satellite states given, no protection "
        f"levels); jaxfdi/gnss_lib_py = {ours['epochs_per_s'] / peer['epochs_per_s']:.0f}x"
    )
    phone = phone_timing(args.copies, args.repeats)
    print(
        f"jaxfdi, {PHONE}: {phone['epochs']} epochs, first call {phone['first_call_s']:.1f} s (compile), then "
        f"{phone['run_s'] * 1e3:.1f} ms: {phone['epochs_per_s']:.0f} epochs/s (a clock per constellation, parity "
        "test, slope and solution-separation PLs, exclusion)"
    )
    peer = gnss_lib_py_timing(args.repeats)
    print(
        f"gnss_lib_py solve_wls + residual FDE, {PHONE}: {peer['epochs']} epochs in {peer['run_s'] * 1e3:.0f} ms: "
        f"{peer['epochs_per_s']:.0f} epochs/s (no protection levels); jaxfdi/gnss_lib_py = "
        f"{phone['epochs_per_s'] / peer['epochs_per_s']:.0f}x"
    )
    results["phone"] = {"trace": PHONE, "jaxfdi": phone, "gnss_lib_py": peer}
    tmp = f"{args.out}.tmp"
    with open(tmp, "w") as handle:
        json.dump(results, handle, indent=1)
    os.replace(tmp, args.out)
    print(f"wrote {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "gnss_real.json")


if __name__ == "__main__":
    main()
