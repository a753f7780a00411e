"""Can the VTOL bank tell an additive fault from a multiplicative one at the isolated
location? (issue 27, item 7)

At a location the bank has two TSKFs: multiplicative (actuator effectiveness
``-B e_i u_i``, sensor scaling ``e_j (C x)_j``) and additive (``-B e_i``, ``e_j``). Their
fault directions are the *same vector* scaled by ``u_i(k)`` or ``(C x)_j(k)``; with the
bias a random walk (``BIAS_WALK = 0.2^2`` a step), the multiplicative filter explains an
additive fault ``delta`` by ``b_k = delta / u_i(k)`` and vice versa. The kind is
identifiable only through the variation of that scaling signal over the window.

For every fault case (FTC off, ``--runs`` runs, seed 0) this prints:

* ``cv``: the coefficient of variation (std / |mean|) of the scaling signal (``u_i`` or
  ``(C x)_j`` of the true plant) over the ``W`` steps after the onset;
* ``right kind``: the share of runs in which the filter of the fault's own kind has the
  smaller windowed log-likelihood deficit, i.e. the smaller sum of its statistic
  ``lambda`` (its NIS: ``-2 log L`` up to the log-determinant, equal for both filters to
  within their bias covariance) over ``W`` steps after the onset, for W = 4 (the
  closed loop's one-block rule), 20 and 60;
* ``margin``: the median of ``sum lambda_other - sum lambda_own`` over those runs (> 0:
  the right kind wins), and its interquartile range;
* the same after subtracting each filter's fault-free mean statistic at each step (the
  fault-free case's runs): the disturbance ``3 sin 10t`` leaks into the filters unequally
  (fault-free means up to 8.6 for a chi2(3) statistic), which biases the raw comparison.

    python benchmarks/vtol_fault_kind.py [--runs 20]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxfdi
from jaxfdi import stack_faults
from jaxfdi.scenarios import vtol as sv
from jaxfdi.scenarios.vtol_loop import is_multiplicative, run_closed_loop

WINDOWS = (4, 20, 60)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument(
        "--json",
        default=os.path.join(
            os.path.dirname(os.path.abspath(__file__)), "results_vtol_fault_kind.json"
        ),
    )
    args = parser.parse_args()
    jaxfdi.enable_x64()
    design = sv.vtol_design()
    cases = sv.vtol_faults()  # the fault-free case last: each filter's baseline
    faults = stack_faults([f for _, f in cases])
    keys = jax.random.split(jax.random.PRNGKey(0), args.runs)
    start = time.time()
    run = jax.jit(
        jax.vmap(
            jax.vmap(
                lambda f, key: run_closed_loop(design, key, f, jnp.asarray(False), sv.STEPS),
                in_axes=(None, 0),
            ),
            in_axes=(0, None),
        )
    )
    history = jax.tree_util.tree_map(np.asarray, run(faults, keys))  # leaves (cases, runs, T, ...)
    C = np.asarray(design.model.C)
    baseline = history.fdi.statistic[-1].mean(axis=0)  # (T, F) fault-free mean per step
    rows = []
    for c, (name, f) in enumerate(cases[:-1]):
        if name in sv.HEALTH_CASES:  # a dead or frozen sensor has no additive/multiplicative kind
            continue
        onset = int(f.onset)
        location = int(f.component) + (
            0 if int(f.target) == int(jaxfdi._faults.Target.ACTUATOR) else 2
        )
        mult = bool(is_multiplicative(f))
        own = location + (0 if mult else 6)
        other = location + (6 if mult else 0)
        stat = history.fdi.statistic[c]  # (R, T, F)
        if location < 2:
            signal = history.control[c][:, :, location]  # u_i
        else:
            signal = history.state[c] @ C[location - 2]  # (C x)_j, the model's output
        row = {"fault": name, "multiplicative": mult}
        for W in WINDOWS:
            window = slice(onset, onset + W)
            s = signal[:, window]
            cv = np.std(s, axis=1) / np.maximum(np.abs(np.mean(s, axis=1)), 1e-12)
            margin = stat[:, window, other].sum(1) - stat[:, window, own].sum(1)
            excess = stat[:, window] - baseline[None, window]  # over each filter's fault-free mean
            corrected = excess[:, :, other].sum(1) - excess[:, :, own].sum(1)
            row[f"W{W}"] = {
                "cv_median": float(np.median(cv)),
                "right_kind": float(np.mean(margin > 0)),
                "margin_median": float(np.median(margin)),
                "margin_iqr": [float(v) for v in np.percentile(margin, [25, 75])],
                "right_kind_corrected": float(np.mean(corrected > 0)),
                "corrected_median": float(np.median(corrected)),
                "corrected_iqr": [float(v) for v in np.percentile(corrected, [25, 75])],
            }
        rows.append(row)
    seconds = time.time() - start
    print(
        f"VTOL fault kind by windowed likelihood ({args.runs} runs per case, FTC off, seed 0; {seconds:.0f} s)"
    )
    print(
        f"{'fault':<22} {'kind':<6} "
        + " ".join(f"{'W=' + str(W) + ' cv':>9} {'right':>6} {'margin (IQR)':>24}" for W in WINDOWS)
    )
    for row in rows:
        cells = []
        for W in WINDOWS:
            r = row[f"W{W}"]
            cells.append(
                f"{r['cv_median']:>9.3f} {r['right_kind']:>6.2f} "
                f"{r['margin_median']:>8.2f} ({r['margin_iqr'][0]:>6.1f},{r['margin_iqr'][1]:>6.1f})"
            )
        print(
            f"{row['fault']:<22} {'mult' if row['multiplicative'] else 'add':<6} " + " ".join(cells)
        )
    print(
        "the same with each filter's fault-free mean statistic (per step, from the fault-free runs) subtracted:"
    )
    for row in rows:
        cells = []
        for W in WINDOWS:
            r = row[f"W{W}"]
            cells.append(
                f"{'':>9} {r['right_kind_corrected']:>6.2f} {r['corrected_median']:>8.2f} "
                f"({r['corrected_iqr'][0]:>6.1f},{r['corrected_iqr'][1]:>6.1f})"
            )
        print(
            f"{row['fault']:<22} {'mult' if row['multiplicative'] else 'add':<6} " + " ".join(cells)
        )
    with open(args.json, "w") as fh:
        json.dump(
            {"runs": args.runs, "seed": 0, "windows": WINDOWS, "rows": rows, "seconds": seconds},
            fh,
            indent=1,
        )


if __name__ == "__main__":
    main()
