"""Seed 004's two-stage architecture: the cost per step of the dual-filter detector (runs
always) against the hypothesis banks (run once a fault is detected, to isolate it).

Data (simulated once, float64): ``run_wheels(wheel_design(), key, stop of wheel 1 at
step 300, history=True)`` vmapped over ``--runs`` keys, T = 600 steps at 10 Hz: the
gyro measurements and the filters' input ``u = [Omega_cmd, Omega_cmd']`` with
``Omega_cmd'[k] = (Omega_cmd[k+1] - Omega_cmd[k]) / dt`` (the flight software's
integration of the commanded torques; 601 steps are simulated so the last step has one).
Every filter then runs standalone over the same 600 steps from the scenario's prior
(the closed loop's slaving of the banks to the nominal filter is not part of the cost):

  (a) detector: the nominal dual filter (EKF + prediction filter + ``F = |det A_PF -
      det A_EKF|``), the scenario's estimator noise; output ``F`` and ``x_EKF[k|k]``;
  (b) credit bank: 4 dual filters (one per stop hypothesis, ``stop_hypotheses(params)``)
      vmapped in one scan, the banks' EKF noise; output ``F_x`` (T, 4) and the credits;
  (c) likelihood bank: ``multiple_model`` over the nominal model + 4 stop hypotheses
      (``stop_hypotheses(params, include_nominal=True)``), 5 EKFs; output mode probabilities;
  (d) detector with the UKF estimator (alpha = 0.5, as in the scenario).

Each for one sequence (``jit``) and for the batch of ``--runs`` sequences (``jit(vmap)``).
Compile time (trace + lower + XLA compile) is reported apart from the run time (median of
``--repeats`` calls of the compiled executable, blocked until ready, after a warm-up).
Per-step cost = run time / (T x sequences).

Baseline: filterpy's ``ExtendedKalmanFilter`` running the same nominal dual filter in a
Python loop, one step at a time, for ``--filterpy-sequences`` sequences: ``update`` with
``H = I``, then ``predict`` with ``predict_x`` overridden to set ``x = f(x, u)`` and
``F = df/dx`` at the posterior (as jaxfdi's EKF), plus the prediction filter and ``F``.
Two versions of ``f`` and its Jacobian:
  * numpy: a pure-NumPy RK4 of the same rate model and the exact Jacobian of that RK4 step
    (the closed-form ``A = -I^-1([w]x I - [I w + h_w]x)`` chained through the four stages),
    ``det A`` by cofactors: no JAX in the loop;
  * jax-jit: jaxfdi's ``wheel_rate_transition`` and its ``jax.jacfwd`` in one jitted call
    per step, and one jitted call for the prediction filter and ``F``, wrapped in numpy.
Both are checked against jaxfdi's detector (filtered means and ``F``, relative 1e-8); the
speed-up is reported against the faster of the two.

Run:  python benchmarks/bench_reaction_wheels.py                 (1000 runs; ~1 minute on an idle 2-core VM)
      python benchmarks/bench_reaction_wheels.py --runs 100 --repeats 3 --filterpy-sequences 2   (quick)
Writes benchmarks/results_reaction_wheels.json.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_filters import compiled_timing, cpu_model, rel_diff, write_json_atomic

from jaxfdi._numerics import linalg as _linalg
from jaxfdi.detection import dual_filter, hypothesis_credits
from jaxfdi.filters import Filter, multiple_model, run_filter
from jaxfdi.models import body_rate_field, stop_hypotheses, wheel_rate_transition
from jaxfdi.scenarios.reaction_wheels import (
    estimation_filter,
    run_wheels,
    wheel_design,
    wheel_fault,
)

T = 600
FAULT_WHEEL, FAULT_STEP = 0, 300
TOL = 1e-8


# --------------------------------------------------------------------------- data
def wheel_data(design, runs: int, seed: int = 0, chunk: int = 100):
    """(runs, T, 3) gyro measurements and (runs, T, 2N) inputs from the closed loop, in
    chunks of ``chunk`` runs (one compiled program). On an idle 2-core VM 1000 runs at
    once take ~8 s; with other processes on the cores (load 4-7) one such call took 481 s
    while chunks of 100 stayed near 1 s each, hence the chunks."""
    f = wheel_fault("stop", FAULT_WHEEL, FAULT_STEP)
    sim = jax.jit(jax.vmap(lambda key: run_wheels(design, key, f, T + 1, history=True)[1]))
    keys = jax.random.split(jax.random.key(seed), runs)
    chunk = min(chunk, runs)
    pad = -runs % chunk
    keys = jnp.concatenate([keys, keys[:pad]]) if pad else keys
    parts = [sim(keys[i : i + chunk]) for i in range(0, runs + pad, chunk)]
    measurement = np.concatenate([np.asarray(h.measurement) for h in parts])[:runs]
    speeds = np.concatenate([np.asarray(h.commanded_speed) for h in parts])[:runs]
    ys = measurement[:, :T]
    accel = np.diff(speeds, axis=1) / float(design.params.dt)
    us = np.concatenate([speeds[:, :T], accel], axis=2)
    return ys, us


# --------------------------------------------------------------------------- jaxfdi
def prior(design):
    dtype = design.params.inertia.dtype
    return jnp.zeros(3, dtype), design.initial_sigma**2 * jnp.eye(3, dtype=dtype)


def detector_run(design, kind: str):
    """(a) / (d): the nominal dual filter; -> (F (T,), x_EKF[k|k] (T, 3))."""
    params = design.params
    filt = dual_filter(
        estimation_filter(params, design.estimator_q, design.gyro_sigma, kind),
        wheel_rate_transition,
        body_rate_field,
        params,
    )
    m0, P0 = prior(design)

    def run(ys, us):
        _, info = run_filter(filt, filt.init(m0, P0), ys, us)
        return info.detection_parameter, info.estimator.filtered_mean

    return run


def credit_bank_run(design):
    """(b): one dual filter per stop hypothesis, vmapped inside one scan;
    -> (F_x (T, 4), credits C_x (T, 4))."""
    hypotheses = stop_hypotheses(design.params)
    m0, P0 = prior(design)

    def member(p):
        return dual_filter(
            estimation_filter(p, design.bank_q, design.gyro_sigma, "ekf"),
            wheel_rate_transition,
            body_rate_field,
            p,
        )

    def init():
        return jax.vmap(lambda p: member(p).init(m0, P0))(hypotheses)

    def step(states, y, u):
        return jax.vmap(lambda p, s: member(p).step(s, y, u))(hypotheses, states)

    bank = Filter(init, step)

    def run(ys, us):
        _, info = run_filter(bank, bank.init(), ys, us)
        return info.detection_parameter, hypothesis_credits(info.detection_parameter)

    return run


def likelihood_bank_run(design):
    """(c): static MM over the nominal model + 4 stop hypotheses; -> mode probabilities (T, 5)."""
    modes = stop_hypotheses(design.params, include_nominal=True)
    M = modes.wheel_mask.shape[0]
    mm = multiple_model(
        lambda p: estimation_filter(p, design.bank_q, design.gyro_sigma, "ekf"),
        modes,
        design.mm_floor,
    )
    m0, P0 = prior(design)
    uniform = jnp.full((M,), 1.0 / M, m0.dtype)

    def run(ys, us):
        _, info = run_filter(mm, mm.init(m0, P0, uniform), ys, us)
        return info.mode_prob

    return run


# --------------------------------------------------------------------------- baseline
def numpy_model(design):
    """Pure-NumPy ``f`` (one RK4 step, as ``wheel_rate_transition``), its exact Jacobian,
    and ``det A`` of the continuous model (the closed form ``rate_jacobian``). Written for
    speed in NumPy: ``I^-1`` and ``I_w H^T`` precomputed, cross products and 3x3
    determinants by hand (``np.cross``, ``np.linalg.solve`` and ``det`` cost 5-20 us each
    on 3-vectors)."""
    p = design.params
    I = np.asarray(p.inertia)
    I_inv = np.linalg.inv(I)
    dt = float(p.dt)
    HwT = float(p.wheel_inertia) * np.asarray(p.wheel_axes).T  # (3, N): h_w = HwT @ Omega
    N = HwT.shape[1]
    eye = np.eye(3)

    def field_and_jacobian(w, speeds, accel):
        m = I @ w + HwT @ speeds
        cross = np.array(
            [w[1] * m[2] - w[2] * m[1], w[2] * m[0] - w[0] * m[2], w[0] * m[1] - w[1] * m[0]]
        )
        g = I_inv @ (-cross - HwT @ accel)
        wI = np.array(
            [w[1] * I[2] - w[2] * I[1], w[2] * I[0] - w[0] * I[2], w[0] * I[1] - w[1] * I[0]]
        )  # [w]x I
        skew_m = np.array([[0.0, -m[2], m[1]], [m[2], 0.0, -m[0]], [-m[1], m[0], 0.0]])
        return g, -I_inv @ (wI - skew_m)

    def transition_and_jacobian(x, u):
        speeds, accel = u[:N], u[N:]
        h = dt
        k1, J1 = field_and_jacobian(x, speeds, accel)
        k2, A2 = field_and_jacobian(x + 0.5 * h * k1, speeds + 0.5 * h * accel, accel)
        J2 = A2 @ (eye + 0.5 * h * J1)
        k3, A3 = field_and_jacobian(x + 0.5 * h * k2, speeds + 0.5 * h * accel, accel)
        J3 = A3 @ (eye + 0.5 * h * J2)
        k4, A4 = field_and_jacobian(x + h * k3, speeds + h * accel, accel)
        J4 = A4 @ (eye + h * J3)
        return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4), eye + h / 6.0 * (
            J1 + 2 * J2 + 2 * J3 + J4
        )

    def transition(x, u):
        """``f`` alone (the prediction filter needs no Jacobian)."""
        speeds, accel = u[:N], u[N:]
        h = dt

        def g(w, speeds):
            m = I @ w + HwT @ speeds
            cross = np.array(
                [w[1] * m[2] - w[2] * m[1], w[2] * m[0] - w[0] * m[2], w[0] * m[1] - w[1] * m[0]]
            )
            return I_inv @ (-cross - HwT @ accel)

        k1 = g(x, speeds)
        k2 = g(x + 0.5 * h * k1, speeds + 0.5 * h * accel)
        k3 = g(x + 0.5 * h * k2, speeds + 0.5 * h * accel)
        k4 = g(x + h * k3, speeds + h * accel)
        return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)

    def det3(a):
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = a.tolist()
        return (
            a00 * (a11 * a22 - a12 * a21)
            - a01 * (a10 * a22 - a12 * a20)
            + a02 * (a10 * a21 - a11 * a20)
        )

    zero = np.zeros(N)

    def dual_part(prediction, posterior, u):
        """-> (F, next prediction)."""
        det_p = det3(field_and_jacobian(prediction, u[:N], zero)[1])
        det_e = det3(field_and_jacobian(posterior, u[:N], zero)[1])
        return abs(det_p - det_e), transition(prediction, u)

    return transition_and_jacobian, dual_part


def jax_wrapped_model(design):
    """jaxfdi's transition with its ``jax.jacfwd`` Jacobian, and the prediction filter and
    ``F``, each one jitted call per step from Python (numpy in, numpy out)."""
    params = design.params
    f = lambda x, u: wheel_rate_transition(x, u, params)
    both = jax.jit(lambda x, u: (f(x, u), jax.jacfwd(f)(x, u)))

    def det_a(x, u):
        return _linalg.det(jax.jacfwd(body_rate_field)(x, u, params))

    dual = jax.jit(lambda pf, post, u: (jnp.abs(det_a(pf, u) - det_a(post, u)), f(pf, u)))

    def transition_and_jacobian(x, u):
        x1, F = both(x, u)
        return np.asarray(x1), np.asarray(F)

    def dual_part(prediction, posterior, u):
        F, nxt = dual(prediction, posterior, u)
        return float(F), np.asarray(nxt)

    return transition_and_jacobian, dual_part


class RateEKF(ExtendedKalmanFilter):
    """filterpy's EKF with ``x = f(x, u)`` and ``F = df/dx`` (at the posterior) in ``predict_x``."""

    def __init__(self, transition_and_jacobian, Q, R, x0, P0):
        super().__init__(dim_x=3, dim_z=3)
        self._f = transition_and_jacobian
        self.Q, self.R, self.x, self.P = Q.copy(), R.copy(), x0.copy(), P0.copy()

    def predict_x(self, u=0):
        self.x, self.F = self._f(self.x, u)


def filterpy_dual(design, model, ys, us):
    """The nominal dual filter in a Python loop: (S, T) F and (S, T, 3) posteriors."""
    S, T = ys.shape[:2]
    transition_and_jacobian, dual_part = model
    Q = float(design.estimator_q) ** 2 * np.eye(3)
    R = float(design.gyro_sigma) ** 2 * np.eye(3)
    m0, P0 = (np.asarray(a) for a in prior(design))
    eye = np.eye(3)
    jac_h = lambda x: eye
    h = lambda x: x
    F_all, x_all = np.empty((S, T)), np.empty((S, T, 3))
    for s in range(S):
        ekf = RateEKF(transition_and_jacobian, Q, R, m0, P0)
        prediction = m0.copy()
        for k in range(T):
            u = us[s, k]
            ekf.update(ys[s, k], jac_h, h)
            x_all[s, k] = ekf.x
            F_all[s, k], prediction = dual_part(prediction, ekf.x, u)
            ekf.predict(u)
    return F_all, x_all


# --------------------------------------------------------------------------- main
CASES = [
    ("a", "detector: dual filter (EKF)", "1 dual filter"),
    ("b", "credit bank: 4 dual filters", "4 dual filters"),
    ("c", "likelihood bank: MM, 5 EKFs", "5 EKFs + mode update"),
    ("d", "detector: dual filter (UKF)", "1 dual filter"),
]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000, help="sequences in the vmapped batch")
    parser.add_argument(
        "--repeats", type=int, default=5, help="timed calls per measurement (median reported)"
    )
    parser.add_argument(
        "--budget",
        type=float,
        default=15.0,
        help="seconds after which a measurement stops repeating (at least 3 calls)",
    )
    parser.add_argument(
        "--filterpy-sequences", type=int, default=3, help="sequences the filterpy loops run"
    )
    parser.add_argument(
        "--sim-chunk", type=int, default=100, help="runs per call of the data simulation"
    )
    parser.add_argument(
        "--out",
        default=os.path.join(
            os.path.dirname(os.path.abspath(__file__)), "results_reaction_wheels.json"
        ),
    )
    args = parser.parse_args(argv)
    log = lambda *a: print(*a, file=sys.stderr, flush=True)
    t_start = time.perf_counter()
    load_start = os.getloadavg()

    design = wheel_design()
    t0 = time.perf_counter()
    ys, us = wheel_data(design, args.runs, chunk=args.sim_chunk)
    sim_s = time.perf_counter() - t0
    log(
        f"data: {args.runs} runs x {T} steps (wheel {FAULT_WHEEL + 1} stops at step {FAULT_STEP}) simulated in "
        f"{sim_s:.1f} s; jax {jax.__version__} on {jax.devices()[0].device_kind}, {os.cpu_count()} cores"
    )
    ys_j, us_j = jnp.asarray(ys), jnp.asarray(us)

    runs = {
        "a": detector_run(design, "ekf"),
        "b": credit_bank_run(design),
        "c": likelihood_bank_run(design),
        "d": detector_run(design, "ukf"),
    }
    timings, outputs = {}, {}
    for key, name, _ in CASES:
        one, _ = compiled_timing(runs[key], (ys_j[0], us_j[0]), args.repeats, args.budget)
        many, out = compiled_timing(jax.vmap(runs[key]), (ys_j, us_j), args.repeats, args.budget)
        finite = all(
            bool(np.all(np.isfinite(np.asarray(leaf)))) for leaf in jax.tree_util.tree_leaves(out)
        )
        if not finite:
            raise SystemExit(f"({key}) {name}: non-finite outputs")
        for t, n in ((one, 1), (many, args.runs)):
            t["per_step_per_sequence_us"] = t["run_s"] / (T * n) * 1e6
        timings[key] = {"one": one, "batch": many}
        outputs[key] = out
        log(
            f"({key}) {name}: 1 seq {one['run_s'] * 1e3:.2f} ms (compile {one['compile_s']:.2f} s); "
            f"{args.runs} seq {many['run_s'] * 1e3:.0f} ms (compile {many['compile_s']:.2f} s), "
            f"{many['per_step_per_sequence_us']:.3f} us/step/seq"
        )

    # a light sanity reading of the banks on the same data (they run standalone from step 0)
    mode_prob = np.asarray(outputs["c"])  # (runs, T, 5)
    mm_isolated = float(np.mean(np.argmax(mode_prob[:, -1], axis=-1) == FAULT_WHEEL + 1))
    mm_nominal_before = float(np.mean(np.argmax(mode_prob[:, FAULT_STEP - 1], axis=-1) == 0))
    fdp = np.asarray(outputs["a"][0])
    before = np.max(fdp[:, :FAULT_STEP], axis=1)
    fdp_jump_2s = float(np.median(np.max(fdp[:, FAULT_STEP : FAULT_STEP + 20], axis=1) / before))
    fdp_jump = float(np.median(np.max(fdp[:, FAULT_STEP:], axis=1) / before))

    # filterpy baselines, checked against jaxfdi's detector (a)
    S = min(args.filterpy_sequences, args.runs)
    ref_F, ref_x = np.asarray(outputs["a"][0])[:S], np.asarray(outputs["a"][1])[:S]
    baselines = {}
    for label, model in (("numpy", numpy_model(design)), ("jax-jit", jax_wrapped_model(design))):
        filterpy_dual(design, model, ys[:1, :5], us[:1, :5])  # warm-up (jit compiles for jax-jit)
        t0 = time.perf_counter()
        F_fp, x_fp = filterpy_dual(design, model, ys[:S], us[:S])
        per_seq = (time.perf_counter() - t0) / S
        agree = {
            "detection_parameter": rel_diff(F_fp, ref_F),
            "filtered_mean": rel_diff(x_fp, ref_x),
        }
        if max(agree.values()) > TOL:
            raise SystemExit(f"filterpy ({label}) and jaxfdi's dual filter disagree: {agree}")
        baselines[label] = {
            "per_sequence_s": per_seq,
            "sequences_timed": S,
            "per_step_per_sequence_us": per_seq / T * 1e6,
            "agreement": agree,
        }
        log(
            f"filterpy dual filter ({label}): {per_seq * 1e3:.0f} ms per sequence ({S} timed), "
            f"agreement F {agree['detection_parameter']:.1e}, mean {agree['filtered_mean']:.1e}"
        )

    a = timings["a"]
    ratios = {}
    for key in ("b", "c", "d"):
        ratios[f"{key}/a"] = {
            scope: timings[key][scope]["run_s"] / a[scope]["run_s"] for scope in ("one", "batch")
        }
    best = min(baselines, key=lambda k: baselines[k]["per_step_per_sequence_us"])
    fp_us = baselines[best]["per_step_per_sequence_us"]
    speedup = {scope: fp_us / a[scope]["per_step_per_sequence_us"] for scope in ("one", "batch")}
    speedup_all = {
        label: {
            scope: b["per_step_per_sequence_us"] / a[scope]["per_step_per_sequence_us"]
            for scope in ("one", "batch")
        }
        for label, b in baselines.items()
    }

    result = {
        "date": datetime.date.today().isoformat(),
        "command": " ".join(["python", *sys.argv]),
        "machine": cpu_model(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "device": jax.devices()[0].device_kind,
        "load_average_1_5_15": {"start": load_start, "end": os.getloadavg()},
        "dtype": "float64",
        "steps": T,
        "runs": args.runs,
        "repeats": args.repeats,
        "data": {
            "fault": f"stop of wheel {FAULT_WHEEL + 1} at step {FAULT_STEP}",
            "simulation_s": sim_s,
        },
        "cases": {
            key: {"name": name, "filters": what, **timings[key]} for key, name, what in CASES
        },
        "ratios_vs_detector": ratios,
        "filterpy": baselines,
        "filterpy_reported": best,
        "speedup_dual_filter_vs_filterpy": speedup,
        "speedup_by_baseline": speedup_all,
        "sanity": {
            "mm_final_mode_is_stopped_wheel": mm_isolated,
            "mm_nominal_before_fault": mm_nominal_before,
            "median_F_max_2s_after_over_before": fdp_jump_2s,
            "median_F_max_after_over_before": fdp_jump,
        },
    }
    write_json_atomic(args.out, result)

    n = args.runs
    print(
        f"Reaction wheels (seed 004), T = {T}, float64, {jax.devices()[0].device_kind} "
        f"({result['machine']}, {result['cores']} cores); same gyro data for every filter"
    )
    head = (
        f"{'case':<34} {'compile 1 [s]':>13} {'run 1 [ms]':>10} {'us/step':>8}   "
        f"{'compile N [s]':>13} {'run N [ms]':>10} {'us/step/seq':>11}  {'x (a) 1/N':>12}"
    )
    print(head)
    print("-" * len(head))
    for key, name, _ in CASES:
        one, many = timings[key]["one"], timings[key]["batch"]
        ratio = (
            ""
            if key == "a"
            else f"{ratios[f'{key}/a']['one']:5.2f}/{ratios[f'{key}/a']['batch']:5.2f}"
        )
        print(
            f"({key}) {name:<30} {one['compile_s']:>13.2f} {one['run_s'] * 1e3:>10.2f} "
            f"{one['per_step_per_sequence_us']:>8.2f}   {many['compile_s']:>13.2f} {many['run_s'] * 1e3:>10.0f} "
            f"{many['per_step_per_sequence_us']:>11.3f}  {ratio:>12}"
        )
    for label, b in baselines.items():
        print(
            f"filterpy EKF dual filter ({label:<7})  {'-':>13} {b['per_sequence_s'] * 1e3:>10.1f} "
            f"{b['per_step_per_sequence_us']:>8.1f}   Python loop, {b['sequences_timed']} sequences timed"
        )
    print(f"N = {n}; 'x (a)' = run time / detector (a) run time, 1 sequence / N sequences.")
    print(
        f"jaxfdi dual filter vs filterpy ({best}, the faster baseline), per sequence-step: "
        f"{speedup['one']:.0f}x (1 sequence), {speedup['batch']:.0f}x ({n} sequences); "
        f"vs filterpy (jax-jit): {speedup_all['jax-jit']['one']:.0f}x / {speedup_all['jax-jit']['batch']:.0f}x"
    )
    agree = max(max(b["agreement"].values()) for b in baselines.values())
    print(
        f"agreement filterpy vs jaxfdi (F and x_EKF): {agree:.1e}; MM picks the stopped wheel at the last step in "
        f"{mm_isolated:.2f} of runs (nominal before the stop {mm_nominal_before:.2f}); median F "
        "max after/before the stop "
        f"{fdp_jump_2s:.1f}x within 2 s, {fdp_jump:.0f}x over steps {FAULT_STEP}-{T - 1}"
    )
    print(
        f"load average (1 min) {load_start[0]:.1f} at start, {os.getloadavg()[0]:.1f} at end on {os.cpu_count()} cores "
        f"(> cores: other processes shared the CPU)"
    )
    print(f"wrote {args.out} ({time.perf_counter() - t_start:.0f} s in all)")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_reaction_wheels.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
