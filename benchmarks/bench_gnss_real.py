"""Real receivers: epochs per second for positioning + RAIM + both protection levels on the
GEONET hour, jaxfdi beside RTKLIB.

* jaxfdi: ``monitor_receiver`` (single-point fix with RTKLIB's model, parity test,
  slope HPL/VPL, exclusion by a 3-step re-solve) and ``solution_separation`` (ARAIM
  MHSS levels) vmapped over the epochs of station 0759's hour, tiled ``--copies`` (10) times
  (the same 120 epochs again: the cost per epoch does not depend on which epoch);
  compile apart from run (median of ``--repeats``).
* RTKLIB 2.4.3 (pyrtklib's ``postpos``, what ``rnx2rtkp`` runs) on the same hour:
  single-point positioning with the same models, with and without its RAIM FDE option;
  its time includes reading the RINEX files and writing the solution file (it has no
  call without them), so it is a per-epoch cost of the whole program, not of the fix alone.

gnss-lib-py is not timed here: its FDE needs the satellite positions and clocks per
measurement in its NavData, which RINEX 2 files do not carry (the phone files do); its
timing on simulated epochs is in ``bench_gnss_raim.py``.

Run:  python benchmarks/bench_gnss_real.py        (~1 minute on 2 cores)
"""
from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxfdi.data import data_path  # noqa: E402
from jaxfdi.gnss._receiver import monitor_receiver, receiver_epochs  # noqa: E402
from jaxfdi.gnss._rinex import read_rinex_nav  # noqa: E402
from jaxfdi.gnss._rinex_obs import read_rinex_obs  # noqa: E402
from jaxfdi.gnss._solution_separation import solution_separation  # noqa: E402


def jaxfdi_timing(copies: int, repeats: int) -> dict:
    epochs = receiver_epochs(read_rinex_obs(data_path("07590920.05o")), read_rinex_nav(data_path("07590920.05n")))
    tiled = epochs._replace(times=jnp.tile(epochs.times, copies), pseudoranges=jnp.tile(epochs.pseudoranges, (copies, 1)))
    separate = jax.jit(jax.vmap(solution_separation))

    def run():
        result = monitor_receiver(tiled)
        return result, separate(result.fix)

    start = time.perf_counter()
    jax.block_until_ready(run())
    first = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run())
        times.append(time.perf_counter() - start)
    count = int(tiled.times.shape[0])
    return {"epochs": count, "first_call_s": first, "run_s": float(np.median(times)),
            "epochs_per_s": count / float(np.median(times))}


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
            status = rtk.postpos(rtk.gtime_t(), rtk.gtime_t(), 0.0, 0.0, popt, sopt, fopt, files, 2, name, "", "")
            times.append(time.perf_counter() - start)
            assert status == 0
            solved = sum(1 for line in out.read_text().splitlines() if not line.startswith("%"))
    return {"epochs": 120, "solved": solved, "run_s": float(np.median(times)), "epochs_per_s": 120 / float(np.median(times))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--copies", type=int, default=10, help="tiles of the 120-epoch hour for jaxfdi (default 10)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    ours = jaxfdi_timing(args.copies, args.repeats)
    print(f"jaxfdi: {ours['epochs']} epochs, first call {ours['first_call_s']:.1f} s (compile), then "
          f"{ours['run_s'] * 1e3:.1f} ms: {ours['epochs_per_s']:.0f} epochs/s (fix, parity test, slope and "
          f"solution-separation PLs, exclusion)")
    for raim in (False, True):
        peer = rtklib_timing(raim, args.repeats)
        print(f"RTKLIB postpos{' with RAIM FDE' if raim else ''}: {peer['solved']} of 120 epochs solved in "
              f"{peer['run_s'] * 1e3:.1f} ms (reading and writing files included): {peer['epochs_per_s']:.0f} epochs/s; "
              f"jaxfdi/RTKLIB = {ours['epochs_per_s'] / peer['epochs_per_s']:.1f}x")


if __name__ == "__main__":
    main()
