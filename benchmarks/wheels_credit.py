"""Why the paper's credit isolator misses wheels (issue 27 items 4 and 8): per wheel, its
Monte Carlo isolation rate and the computation that explains each miss.

The reaction-wheel scenario's credit bank (``scenarios.reaction_wheels.wheel_fdi``) runs one
dual filter per stop hypothesis ``x`` (seed 004 Section III) and scores it by

    F_x = |det A_x(w_PF,x) - det A_x(w_EKF,x)| ~ |g_x . dw_x|,   g_x = grad_w det A_x,
    dw_x = w_PF,x - w_EKF,x (the prediction filter's drift from the measured rates),

so the credits see the rate discrepancy ``dw_x`` (a 3-vector: the information that tells
the hypotheses apart) only through its projection on ``g_x``. The script measures:

1. **Monte Carlo** (the scenario's closed loop, its noise, onsets uniform in 15-25 s):
   per stopped wheel, the runs in which the credit isolator names it (the scenario's
   record: first confirmed decision at or after the onset), the rate with its one-sided
   95 % Clopper-Pearson lower bound, which hypothesis was named, and the rates at which the
   largest credit is the right one 0.3, 1, 2 and 4 s after the banks engage. Done twice: with the
   scenario's default start of the prediction filters (``restart_prediction=True``: each
   starts from its own EKF's posterior at engagement) and with the former start (the
   nominal filter's predicted mean, which lags the stop's rate jump).
2. **Noise-free explanation** (the same closed loop with the plant's noises off, a stop at
   20 s): the bank re-run in NumPy on the recorded gyro readings and commands (an
   independent implementation: closed-form ``A``, finite-difference Jacobians; its
   ``F_x`` is checked against the scenario's), and per hypothesis ``F_x``, ``|dw_x|``,
   ``|g_x|`` and ``cos(g_x, dw_x)`` at 0.3 s (the decision: 3 confirming steps) and 4 s
   after the engagement. The right hypothesis has the smallest ``|dw_x|`` for every wheel;
   where its ``F`` is not clearly the smallest, the rival's drift is nearly orthogonal to
   its ``g`` (the scalar ``det A`` discards the direction of ``dw``).

Prints a per-wheel table and writes ``--out`` (JSON, completely or not at all).

    python benchmarks/wheels_credit.py --runs 100 --baseline-runs 50
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

from jaxfdi import _io, binomial_lower_bound, detection_scorer, monte_carlo, run_loop
from jaxfdi.control import wheel_attitude_controller, wheel_plant
from jaxfdi.models import WheelCommand, filter_input
from jaxfdi.scenarios import reaction_wheels as rw

#: steps after the engagement at which the credits are examined (0.3 s: the decision
#: after CONFIRM_STEPS; 1, 2 and 4 s)
LAGS = (3, 10, 20, 40)
#: the wheel across the pyramid from each wheel (its spin axis mirrored through body z)
OPPOSITE = (2, 3, 0, 1)


def run_once(design, f, key, noise_scale, steps, restart, history=False):
    """``run_wheels``' composition (plant, ``wheel_fdi``, controller, ``run_loop``) with the
    plant's noises scaled by ``noise_scale`` (0: noise-free truth; the filters keep their
    noise model) and the prediction start ``restart``. Returns the credit and MM records,
    the engagement step, the bank's ``F_x`` at ``LAGS`` after it (and the history)."""
    params = design.params
    N = params.wheel_axes.shape[0]
    fdi = rw.wheel_fdi(
        design, restart_prediction=restart, gyro_health=False
    )  # the credit bank alone
    plant = wheel_plant(
        params,
        f,
        noise_scale * design.gyro_sigma,
        noise_scale * design.disturbance_sigma,
        noise_scale * design.wheel_noise_sigma,
    )
    controller = wheel_attitude_controller(
        params, design.gains, design.profile, design.initial_speeds
    )
    x0 = jnp.concatenate([jnp.array([1.0, 0, 0, 0]), jnp.zeros(3), design.initial_speeds])
    u0 = WheelCommand(design.initial_speeds, jnp.zeros(N))
    scorer = detection_scorer(f.onset, lambda out: (out.decisions[2], out.decisions[3]))
    result = run_loop(
        plant, fdi, controller, x0, fdi.init(), key, steps, u0=u0, scorer=scorer, keep_history=True
    )
    out = result.history.output
    engaged = jnp.argmax(
        out.engaged
    )  # first step the banks ran on their own (the step after the alarm)
    at = jnp.clip(engaged - 1 + jnp.asarray(LAGS), 0, steps - 1)
    summary = dict(
        credit=result.score[0],
        likelihood=result.score[1],
        engaged_step=engaged,
        lagged_F=out.hypothesis_parameter[at],
        lag_valid=(engaged > 0) & (engaged - 1 + jnp.asarray(LAGS) < steps),
        healthy=jnp.all(out.healthy),
    )
    if history:
        h = result.history
        summary["history"] = dict(
            y=h.sensed.measurement.rate,
            u=jax.vmap(lambda c: filter_input(c, params))(h.control),
            engaged=out.engaged,
            F=out.hypothesis_parameter,
        )
    return summary


def monte_carlo_stops(design, runs, seed, steps, restart, chunk):
    faults = rw.case_faults([("stop", w) for w in range(4)], runs, jax.random.key(seed + 2))
    out = monte_carlo(
        lambda key, f: run_once(design, f, key, 1.0, steps, restart),
        jax.random.key(seed),
        4 * runs,
        faults,
        chunk_size=chunk,
    )
    return jax.tree_util.tree_map(np.asarray, out)


def per_wheel_rates(out, runs):
    wheel = np.repeat(np.arange(4), runs)
    rec = out["credit"]
    right = (rec.detection_step >= 0) & (rec.isolated == wheel + 1) & out["healthy"]
    opposite = (rec.detection_step >= 0) & (rec.isolated == np.take(OPPOSITE, wheel) + 1)
    mm = out["likelihood"]
    mm_right = (mm.detection_step >= 0) & (mm.isolated == wheel + 1)
    best = np.argmin(
        out["lagged_F"], axis=2
    )  # (runs, lags): the smallest F_x, i.e. the largest credit
    rows = []
    for w in range(4):
        sel = wheel == w
        n = int(np.sum(sel & out["healthy"]))
        k = int(np.sum(right[sel]))
        rows.append(
            {
                "wheel": w + 1,
                "runs": n,
                "unhealthy_runs": int(np.sum(sel & ~out["healthy"])),
                "isolated": k,
                "rate": k / n if n else float("nan"),
                "lower_95": binomial_lower_bound(k, n),
                "named_opposite": int(np.sum(opposite[sel])),
                "opposite_wheel": OPPOSITE[w] + 1,
                "named_counts": {
                    str(x): int(np.sum(rec.isolated[sel] == x))
                    for x in range(-1, 5)
                    if np.any(rec.isolated[sel] == x)
                },
                "decided": int(np.sum(rec.detection_step[sel] >= 0)),
                "largest_credit_right": {
                    f"{lag * 0.1:.1f}s": float(np.mean(best[sel & out["lag_valid"][:, i], i] == w))
                    for i, lag in enumerate(LAGS)
                },
                "mm_rate": float(np.mean(mm_right[sel])),
            }
        )
    return rows


# --- the NumPy reference of the credit bank (independent of the library) -------------

INERTIA = np.diag([3.118, 3.050, 4.055])
WHEEL_INERTIA = 0.000239


def pyramid_axes_np():
    s = c = np.sqrt(0.5)  # beta = sigma = 45 deg
    return np.array(
        [[s * c, s * c, c], [-s * c, s * c, c], [-s * c, -s * c, c], [s * c, -s * c, c]]
    )


AXES = pyramid_axes_np()


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _rate_derivative(w, speeds, accelerations, mask):
    h = WHEEL_INERTIA * (mask * speeds) @ AXES
    return np.linalg.solve(
        INERTIA, -np.cross(w, INERTIA @ w + h) - WHEEL_INERTIA * (mask * accelerations) @ AXES
    )


def _transition(w, u, mask, dt):
    speeds, acc = u[:4], u[4:]
    f = lambda x, t: _rate_derivative(x, speeds + t * acc, acc, mask)
    k1 = f(w, 0.0)
    k2 = f(w + dt / 2 * k1, dt / 2)
    k3 = f(w + dt / 2 * k2, dt / 2)
    k4 = f(w + dt * k3, dt)
    return w + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _jacobian(fun, w, eps=1e-7):
    return np.stack([(fun(w + eps * e) - fun(w - eps * e)) / (2 * eps) for e in np.eye(3)], axis=-1)


def system_matrix_np(w, u, mask):
    """Closed form ``A = -I^-1 ([w]x I - [I w + h_w]x)``."""
    h = WHEEL_INERTIA * (mask * u[:4]) @ AXES
    return -np.linalg.solve(INERTIA, _skew(w) @ INERTIA - _skew(INERTIA @ w + h))


def det_gradient_np(w, u, mask):
    return _jacobian(lambda x: np.atleast_1d(np.linalg.det(system_matrix_np(x, u, mask))), w)[0]


def credit_bank_np(y, u, engaged_before, u0, design, restart=True):
    """The credit bank on recorded readings ``y`` (T, 3), inputs ``u`` (T, 8) and the
    scenario's engagement flags: the nominal EKF (estimator noise), the hypotheses' EKFs
    re-slaved to its posterior (prior widened by ``engage_sigma``) until the engagement,
    Joseph updates, ``F_x`` with the closed-form ``A``. Returns ``F`` (T, 4), the
    predictions and the filtered means (T, 4, 3)."""
    dt = float(design.params.dt)
    R = float(design.gyro_sigma) ** 2 * np.eye(3)
    widen = float(design.engage_sigma) ** 2 * np.eye(3)
    masks = 1.0 - np.eye(4)

    def update(m, P, yk):
        K = P @ np.linalg.inv(P + R)
        IK = np.eye(3) - K
        return m + K @ (yk - m), IK @ P @ IK.T + K @ R @ K.T

    def predict(m, P, uk, mask, q):
        F = _jacobian(lambda x: _transition(x, uk, mask, dt), m)
        return _transition(m, uk, mask, dt), F @ P @ F.T + q**2 * np.eye(3)

    def slaved(m, P, uk):
        return [(*predict(m, P + widen, uk, mask, float(design.bank_q)),) for mask in masks]

    T = y.shape[0]
    first = int(np.argmax(engaged_before))  # the alarm is at first - 1: the bank runs from there
    P0 = float(design.initial_sigma) ** 2 * np.eye(3)
    nm, nP = np.zeros(3), P0
    bank = [(m, P, m) for m, P in slaved(np.zeros(3), P0, u0)]
    F, pred, filt = np.full((T, 4), np.nan), np.full((T, 4, 3), np.nan), np.full((T, 4, 3), np.nan)
    for k in range(T):
        nmf, nPf = update(nm, nP, y[k])
        nm, nP = predict(nmf, nPf, u[k], np.ones(4), float(design.estimator_q))
        if (
            k < first - 1
        ):  # until the alarm the bank is re-slaved every step: only its last start matters
            bank = [(m, P, m) for m, P in slaved(nmf, nPf, u[k])] if k == first - 2 else bank
            continue
        new = []
        for x, (m, P, p) in enumerate(bank):
            mf, Pf = update(m, P, y[k])
            F[k, x] = abs(
                np.linalg.det(system_matrix_np(p, u[k], masks[x]))
                - np.linalg.det(system_matrix_np(mf, u[k], masks[x]))
            )
            pred[k, x], filt[k, x] = p, mf
            start = mf if (restart and not engaged_before[k]) else p
            new.append(
                (
                    *predict(mf, Pf, u[k], masks[x], float(design.bank_q)),
                    _transition(start, u[k], masks[x], dt),
                )
            )
        engaged_next = engaged_before[k + 1] if k + 1 < T else True
        bank = new if engaged_next else [(m, P, m) for m, P in slaved(nmf, nPf, u[k])]
    return F, pred, filt


def explain(design, restart, onset=200, steps=300):
    """Noise-free stop of each wheel: the NumPy bank and, per hypothesis, ``F``, ``|dw|``,
    ``|g|`` and ``cos(g, dw)`` at each of ``LAGS`` after the engagement."""
    faults = jax.tree_util.tree_map(
        lambda *x: jnp.stack(x), *[rw.wheel_fault("stop", w, onset) for w in range(4)]
    )
    run = jax.jit(
        jax.vmap(
            lambda f: run_once(design, f, jax.random.key(0), 0.0, steps, restart, history=True)
        )
    )
    out = jax.tree_util.tree_map(np.asarray, run(faults))
    u0 = np.concatenate([np.asarray(design.initial_speeds), np.zeros(4)])
    rows = []
    for w in range(4):
        h = {k: v[w] for k, v in out["history"].items()}
        F, pred, filt = credit_bank_np(h["y"], h["u"], h["engaged"], u0, design, restart)
        alarm = int(np.argmax(h["engaged"])) - 1
        after = slice(alarm, steps)
        rel = float(np.max(np.abs(F[after] - h["F"][after]) / np.abs(h["F"][after])))
        lags = []
        for lag in LAGS:
            k = alarm + lag
            dw = pred[k] - filt[k]
            g = np.array(
                [det_gradient_np(filt[k, x], h["u"][k], 1.0 - np.eye(4)[x]) for x in range(4)]
            )
            cos = np.sum(g * dw, axis=1) / (np.linalg.norm(g, axis=1) * np.linalg.norm(dw, axis=1))
            credit = np.maximum(F[k].mean() - F[k], 0.0) / F[k].mean()
            lags.append(
                {
                    "lag_s": lag * float(design.params.dt),
                    "F": F[k].tolist(),
                    "dw_norm": np.linalg.norm(dw, axis=1).tolist(),
                    "g_norm": np.linalg.norm(g, axis=1).tolist(),
                    "cos": cos.tolist(),
                    "relative_credit": credit.tolist(),
                    "winner": int(np.argmin(F[k])) + 1,
                    "smallest_dw": int(np.argmin(np.linalg.norm(dw, axis=1))) + 1,
                }
            )
        rows.append(
            {"wheel": w + 1, "alarm_step": alarm, "numpy_vs_jax_F_max_rel_error": rel, "lags": lags}
        )
    return rows


def _fmt_named(counts):
    return " ".join(f"{'none' if k == '-1' else 'H' + k}:{v}" for k, v in counts.items())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--runs",
        type=int,
        default=100,
        help="Monte Carlo stops per wheel, default start (default 100)",
    )
    parser.add_argument(
        "--baseline-runs",
        type=int,
        default=50,
        help="stops per wheel with the former prediction start (default 50; 0 skips)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--steps", type=int, default=300, help="steps per run (onsets at 150-250; default 300)"
    )
    parser.add_argument("--chunk", type=int, default=100, help="runs per compiled call")
    parser.add_argument(
        "--out",
        default=os.path.join(
            os.path.dirname(os.path.abspath(__file__)), "results_wheels_credit.json"
        ),
    )
    args = parser.parse_args(argv)
    rw.require_x64("wheels_credit")
    design = rw.wheel_design()
    report = {
        "config": {
            "runs": args.runs,
            "baseline_runs": args.baseline_runs,
            "seed": args.seed,
            "steps": args.steps,
            "lags_steps": list(LAGS),
            "credit_threshold": float(design.credit_threshold),
            "confirm_steps": rw.CONFIRM_STEPS,
            "momentum": "net",
            "opposite_wheel": [o + 1 for o in OPPOSITE],
        },
        "monte_carlo": {},
        "noise_free": {},
    }
    modes = [("restart", True, args.runs)] + (
        [("former", False, args.baseline_runs)] if args.baseline_runs > 0 else []
    )
    for name, restart, runs in modes:
        t0 = time.time()
        report["noise_free"][name] = explain(design, restart)
        t1 = time.time()
        report["monte_carlo"][name] = per_wheel_rates(
            monte_carlo_stops(design, runs, args.seed, args.steps, restart, args.chunk), runs
        )
        print(
            f"[{name}: noise-free explanation {t1 - t0:.0f} s, Monte Carlo {4 * runs} runs {time.time() - t1:.0f} s]",
            file=sys.stderr,
            flush=True,
        )
    for name, restart, runs in modes:
        title = (
            "prediction filters start from each hypothesis's EKF posterior at engagement (scenario default)"
            if restart
            else "former start: the nominal filter's predicted mean (lags the stop's rate jump)"
        )
        print(f"\nCredit isolator, wheel stops, {title}")
        print(
            f"{'wheel':>5} {'runs':>5} {'isol':>5} {'rate':>5} {'CP95lo':>6} {'opp':>4} "
            f"{'top@ 0.3s  1s  2s  4s':>21} {'MM':>5}  "
            f"{'named':<26} | noise-free @0.3s: {'win':>3} {'F_riv/F_j':>9} {'|dw|riv/j':>9} "
            f"{'cos riv':>7} | @4s: win F_riv/F_j"
        )
        for mc, nf in zip(report["monte_carlo"][name], report["noise_free"][name]):
            w = mc["wheel"] - 1
            cells = []
            for lag in (nf["lags"][0], nf["lags"][-1]):
                F = np.asarray(lag["F"])
                rival = int(np.argmin(np.where(np.arange(4) == w, np.inf, F)))
                cells.append(
                    (
                        lag["winner"],
                        F[rival] / F[w],
                        lag["dw_norm"][rival] / lag["dw_norm"][w],
                        lag["cos"][rival],
                        rival + 1,
                    )
                )
            (win0, f0, d0, c0, r0), (win4, f4, _, _, _) = cells
            print(
                f"{mc['wheel']:>5} {mc['runs']:>5} {mc['isolated']:>5} {mc['rate']:>5.2f} {mc['lower_95']:>6.3f} "
                f"{mc['named_opposite']:>4} "
                f"{' '.join(f'{v:.2f}' for v in mc['largest_credit_right'].values()):>21} {mc['mm_rate']:>5.2f}  "
                f"{_fmt_named(mc['named_counts']):<26} |  H{win0} {f0:>9.2f} {d0:>9.1f} "
                f"{c0:>7.2f} (H{r0}) | H{win4} {f4:>8.2f}"
            )
        err = max(nf["numpy_vs_jax_F_max_rel_error"] for nf in report["noise_free"][name])
        print(
            f"  (NumPy bank vs the scenario's F_x after the alarm, noise-free: largest relative difference {err:.1e})"
        )
    print(
        "\ncolumns: isol = runs the credit isolator named the stopped wheel (first confirmed decision), CP95lo = "
        "one-sided 95 % Clopper-Pearson lower bound, opp = runs it named the opposite wheel, top@ = the largest "
        "credit is the right one 0.3, 1, 2 and 4 s after engagement, MM = the likelihood bank's "
        "rate; noise-free: win = hypothesis "
        "with the smallest F, riv = the wrong hypothesis with the smallest F, |dw| = |w_PF - w_EKF| of the "
        "hypothesis's dual filter, cos = cos(grad det A, dw)"
    )
    _io.write_json(args.out, report)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
