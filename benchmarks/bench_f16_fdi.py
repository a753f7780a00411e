"""Seed 000's hybrid FDI in the closed loop (issue 24): flights per second of the full
FDI flight (F-16 plant, six rate channels with noise and a sensor fault, parity-space
detection and isolation, the UKF's bounded replay on demand, the controller flying on
the FDI-selected rates) with jaxfdi (vmapped, one compiled scan) against the same flight
as a NumPy loop, and the cost of the FDI relative to the bare flight of issue 23.

The flight: ``jaxfdi.scenarios.f16_fdi.run_fdi_flight`` (15 s, 1500 RK4 steps at 0.01 s,
the paper's climb and bank turn, 3 ft/s gusts, c.g. and initial-state dispersions), a bias
of fault-to-noise ratio 10 from 3 s on both axes of a random sensor in a random direction
of its plane (so the UKF runs in the flights whose parity falls near a singular
direction), float64.

- Baseline: ``fly_fdi`` below, ``f16_numpy_baseline.fly`` with the FDI written in NumPy
  (parity vector, FD, FI, the latched decision, a ring buffer of the last 3 steps, a
  scaled-UT UKF on the moment equations with the coefficient errors, restarted on demand,
  the exclusion estimators); one flight after another. Checked first against jaxfdi on
  the paper's case without noise (bias at 45 deg on sensor 1: both suspects, the UKF
  decides): every state within 1e-8 relative, the same decision, the UKF residuals within
  1e-6 of the largest. Timed on ``--numpy-flights`` noisy flights.
- jaxfdi: ``jit(vmap(run_fdi_flight, axis_name))`` (the replay condition reduced over the
  batch) over ``--flights`` flights, compile apart from run (median of ``--repeats``); the
  bare flight (``run_flights``, the rate pass-through) at the same sizes, same process.
  The first call after compilation is one of the timed calls.

Run:   python benchmarks/bench_f16_fdi.py                       (10^4 flights; minutes on 2 cores)
Quick: python benchmarks/bench_f16_fdi.py --flights 1 100 --numpy-flights 1 --repeats 1
Writes benchmarks/results_f16_fdi.json.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import statistics
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import f16_numpy_baseline as baseline
from bench_f16_flight import numpy_design

from jaxfdi._io import files as _io
from jaxfdi.data import data_path
from jaxfdi.detection import FOLLOW
from jaxfdi.scenarios import f16_fdi as sf
from jaxfdi.scenarios.f16_flight import (
    DT,
    GUST_SIGMA,
    dispersions,
    flight_setup,
    run_flight,
    run_flights,
)


def _parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--flights", type=int, nargs="+", default=[1, 100, 10000])
    parser.add_argument("--numpy-flights", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--out",
        default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results_f16_fdi.json"),
    )
    return parser.parse_args(argv)


# --- the FDI in NumPy ----------------------------------------------------------------


def numpy_fdi(setup, fdi) -> dict:
    """The FDI's arrays as NumPy (from jaxfdi's setup: thresholds, V, bases, estimators)."""
    h = fdi.hybrid
    return dict(
        V=np.asarray(h.space.V),
        bases=np.asarray(h.space.fault_bases),
        groups=np.asarray(h.space.groups),
        H=np.asarray(h.space.H),
        td=float(h.detection_threshold),
        ti=float(h.isolation_threshold),
        estimators=np.asarray(h.estimators),
        restart_cov=np.asarray(h.restart_cov),
        Q=np.asarray(fdi.process_cov),
        R=np.asarray(fdi.noise_cov),
        scale=np.asarray(fdi.rates.coefficient_scale),
        xcg=float(fdi.rates.aircraft.xcg),
        lag=sf.RESTART_LAG,
        ut=(sf.UKF_ALPHA, sf.UKF_BETA, sf.UKF_KAPPA),
    )


def rate_derivative(T, w, v, xcg, scale):
    """Seed 000 eqs. 34-36 (the book's moment equations) with Cl, Cm, Cn scaled, from the
    input ``v = [VT, alpha, beta, h, thtl, el, ail, rdr]`` (``f16_numpy_baseline``'s functions)."""
    vt, alpha, beta, alt = v[0], v[1] * baseline.RTOD, v[2] * baseline.RTOD, v[3]
    el, ail, rdr = v[5], v[6], v[7]
    p, q, r = w
    _, qbar = baseline.adc(vt, alt)
    dail, drdr = ail / 20.0, rdr / 30.0
    cyt = baseline.cy(beta, ail, rdr)
    czt = baseline.cz(T, alpha, beta, el)
    clt = (
        baseline._abs_beta_table(T.cl, alpha, beta)
        + baseline._beta_table(T.dlda, alpha, beta) * dail
        + baseline._beta_table(T.dldr, alpha, beta) * drdr
    )
    cmt = baseline.cm(T, alpha, el)
    cnt = (
        baseline._abs_beta_table(T.cn, alpha, beta)
        + baseline._beta_table(T.dnda, alpha, beta) * dail
        + baseline._beta_table(T.dndr, alpha, beta) * drdr
    )
    tvt = 0.5 / vt
    b2v = T.b * tvt
    cq = T.cbar * q * tvt
    d = baseline.damp(T, alpha)
    cyt += b2v * (d[1] * r + d[2] * p)
    czt += cq * d[3]
    clt += b2v * (d[4] * r + d[5] * p)
    cmt += cq * d[6] + czt * (T.xcgr - xcg)
    cnt += b2v * (d[7] * r + d[8] * p) - cyt * (T.xcgr - xcg) * T.cbar / T.b
    clt, cmt, cnt = clt * scale[0], cmt * scale[1], cnt * scale[2]
    qs = qbar * T.s
    qsb = qs * T.b
    gam = T.jxx * T.jzz - T.jxz**2
    xpq = T.jxz * (T.jxx - T.jyy + T.jzz)
    xqr = T.jzz * (T.jzz - T.jyy) + T.jxz**2
    zpq = (T.jxx - T.jyy) * T.jxx + T.jxz**2
    ypr = T.jzz - T.jxx
    roll, pitch, yaw = qsb * clt, qs * T.cbar * cmt, qsb * cnt
    pq, qr, qhx = p * q, q * r, q * T.hx
    return np.array(
        [
            (xpq * pq - xqr * qr + T.jzz * roll + T.jxz * (yaw + qhx)) / gam,
            (ypr * p * r - T.jxz * (p * p - r * r) + pitch - r * T.hx) / T.jyy,
            (zpq * pq - xpq * qr + T.jxz * roll + T.jxx * (yaw + qhx)) / gam,
        ]
    )


def rate_transition(T, w, v, F):
    f = lambda x: rate_derivative(T, x, v, F["xcg"], F["scale"])
    k1 = f(w)
    k2 = f(w + 0.5 * DT * k1)
    k3 = f(w + 0.5 * DT * k2)
    k4 = f(w + DT * k3)
    return w + DT / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def _sigma_points(m, P, F):
    alpha, beta, kappa = F["ut"]
    n = m.size
    lam = alpha**2 * (n + kappa) - n
    root = np.linalg.cholesky((n + lam) * P)
    points = np.vstack([m, m + root.T, m - root.T])
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = wm[0] + 1.0 - alpha**2 + beta
    return points, wm, wc


def ukf_update(m, P, y, trusted, F):
    if not trusted.any():
        return m, P
    X, wm, wc = _sigma_points(m, P, F)
    Ht = F["H"][trusted]
    Y = X @ Ht.T
    ym = wm @ Y
    dY, dX = Y - ym, X - m
    Pyy = (wc * dY.T) @ dY + F["R"][np.ix_(trusted, trusted)]
    Pxy = (wc * dX.T) @ dY
    K = np.linalg.solve(Pyy, Pxy.T).T
    return m + K @ (y[trusted] - ym), P - K @ Pyy @ K.T


def ukf_predict(T, m, P, v, F):
    X, wm, wc = _sigma_points(m, P, F)
    Xn = np.array([rate_transition(T, x, v, F) for x in X])
    mn = wm @ Xn
    d = Xn - mn
    return mn, (wc * d.T) @ d + F["Q"]


def fly_fdi(T, design: dict, F: dict, x0, xcg, rng, fault, noise=True):
    """One FDI flight; ``fault = (sensor, (2,) bias in rad/s, onset step)``. Returns the
    states (T, 13), the controls (T, 4) and the decision ``(detection step, decision step,
    PSA, hybrid, suspects, residual norms)``."""
    dt = design["dt"]
    H, V, bases, groups = F["H"], F["V"], F["bases"], F["groups"]
    G = groups.shape[0]
    channel_group = np.repeat(np.arange(G), groups.shape[1])
    K_lon, K_lat = design["K_lon"], design["K_lat"]
    lon_idx, lat_idx = [0, 1, 4, 7, 11, 12], [2, 3, 6, 8]
    lower, upper = design["lower"], design["upper"]
    sigma = design["sigma"] if noise else np.zeros_like(design["sigma"])
    gust_std = design["gust_std"] if noise else 0.0
    sensor, bias, onset = fault
    x = np.array(x0, float)
    gust = np.zeros(2)
    z_lon, z_lat = np.zeros(2), np.zeros(1)
    steps = design["x_ref"].shape[0]
    states, controls = np.empty((steps, 13)), np.empty((steps, 4))
    history = []  # the last `lag` (channels, filter input, LS estimate)
    detection, decision, psa, hybrid, suspects_at, norms_at = -1, -1, 0, 0, None, np.full(G, np.nan)
    for k in range(steps):
        y = np.concatenate(
            [x[[0, 1, 2, 3, 4, 5, 11, 12]], H @ x[6:9]]
        ) + sigma * rng.standard_normal(sigma.size)
        if k >= onset:
            y[8 + 2 * sensor : 10 + 2 * sensor] += bias
        m = y[8:]
        # FDI: parity, FD, FI, decision (latched), the UKF's replay when two suspects remain
        p = V @ m
        fd = p @ p
        size = math.sqrt(fd)
        fi = np.array(
            [1.0 - np.linalg.norm(p - Q @ (Q.T @ p)) / size if size > 0 else 0.0 for Q in bases]
        )
        alarm = fd > F["td"]
        suspects = fi > F["ti"]
        if detection < 0 and alarm:
            detection = k
        if decision < 0 and alarm and suspects.any():
            decision, suspects_at = k, suspects
            psa = int(np.argmax(np.where(suspects, fi, -np.inf))) + 1
            hybrid = psa
            if suspects.sum() >= 2:
                trusted = ~suspects[channel_group]
                mean, cov = history[0][2], F["restart_cov"]
                mean, cov = ukf_predict(T, mean, cov, history[0][1], F)
                for ch, v, _ in history[1:]:
                    mean, cov = ukf_update(mean, cov, ch, trusted, F)
                    mean, cov = ukf_predict(T, mean, cov, v, F)
                mean, cov = ukf_update(mean, cov, m, trusted, F)
                residual = m - H @ mean
                norms_at = np.linalg.norm(residual[groups], axis=1)
                hybrid = int(np.argmax(np.where(suspects, norms_at, -np.inf))) + 1
        excluded = hybrid if decision >= 0 else 0
        rates = F["estimators"][excluded] @ m
        x_lon = np.array([y[0], y[1], y[4], rates[1], y[6], y[7]])
        x_lat = np.array([y[2], y[3], rates[0], rates[2]])
        x_ref, u_ref = design["x_ref"][k], design["u_ref"][k]
        d_lon = x_lon - x_ref[lon_idx]
        d_lat = x_lat - x_ref[lat_idx]
        u_lon = u_ref[[0, 1]] - K_lon @ np.concatenate([d_lon, z_lon])
        u_lat = u_ref[[2, 3]] - K_lat @ np.concatenate([d_lat, z_lat])
        wanted = np.array([u_lon[0], u_lon[1], u_lat[0], u_lat[1]])
        u = np.clip(wanted, lower, upper)
        if wanted[0] == u[0] and wanted[1] == u[1]:
            z_lon = z_lon - dt * d_lon[[0, 4]]
        if wanted[2] == u[2] and wanted[3] == u[3]:
            z_lat = z_lat - dt * d_lat[[1]]
        history.append((m, np.concatenate([y[0:3], y[6:7], u]), F["estimators"][0] @ m))
        if len(history) > F["lag"]:
            history.pop(0)
        states[k], controls[k] = x, u
        x = baseline.rk4(T, x, u, xcg, gust / x[0], dt)
        gust = design["gust_decay"] * gust + gust_std * rng.standard_normal(2)
    return states, controls, (detection, decision, psa, hybrid, suspects_at, norms_at)


# --- jaxfdi --------------------------------------------------------------------------


def block(x):
    return jax.tree_util.tree_map(
        lambda a: a.block_until_ready() if hasattr(a, "block_until_ready") else a, x
    )


def timed(fn, repeats):
    """Median wall and process CPU time of ``repeats`` calls of ``fn`` (the first call after
    compilation included, so that ``--repeats 1`` runs a large batch once), and the last output."""
    walls, cpus = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return statistics.median(walls), statistics.median(cpus), out


def random_cases(n: int, seed: int, dtype):
    rng = np.random.default_rng(seed)
    draws = [
        (int(rng.integers(3)), float(rng.uniform(0, 360))) for _ in range(n)
    ]  # the same draws as before
    sensor, angle = (np.asarray(column) for column in zip(*draws))
    return sf.fault_case("bias", sensor, 10.0, angle, dtype=dtype)


def fdi_flights(setup, fdi, keys, disp, cases):
    follow = jnp.asarray(FOLLOW["hybrid"], jnp.int32)

    def one(k, d, c):
        out = sf.run_fdi_flight(setup, fdi, k, d, c, follow, batch_axis=sf.BATCH_AXIS)
        return out._replace(fdi=out.fdi.decision)

    return jax.vmap(one, axis_name=sf.BATCH_AXIS)(keys, disp, cases)


def check_agreement(setup, fdi, tables, design, F) -> dict:
    """The paper's case without noise or gusts, jaxfdi against NumPy."""
    zero = jax.tree_util.tree_map(lambda a: 0.0 * a, setup.sensors)._replace(
        rate_axes=setup.sensors.rate_axes
    )
    quiet = setup._replace(sensors=zero, gust_sigma=0.0 * setup.gust_sigma)
    case = sf.fault_case(dtype=setup.x0.dtype)
    fault = sf.sensor_fault(
        case, setup.sensors.rate_sigma
    )  # the bias of the noisy sensors (0.1 rad/s per axis)
    disp = jax.tree_util.tree_map(lambda a: a[0], dispersions(jax.random.key(0), setup, 1))
    disp = disp._replace(initial=0.0 * disp.initial, xcg=setup.params.xcg)
    out, hist = jax.jit(
        lambda s, f: run_flight(
            s,
            jax.random.key(0),
            disp,
            True,
            fdi=sf.f16_hybrid_fdi(f),
            fdi_state0=sf.fdi_state0(f),
            fault=fault,
        )
    )(quiet, fdi)
    ours = np.asarray(hist.state[:, :13])
    bias = np.asarray(fault.magnitude)
    ref, _, dec = fly_fdi(
        tables,
        design,
        F,
        np.asarray(setup.x0),
        float(setup.params.xcg),
        np.random.default_rng(0),
        (0, bias, int(case.onset)),
        noise=False,
    )
    d = out.fdi.decision
    norms = np.asarray(d.analytic_residuals)
    return {
        "state_max_relative": float(np.max(np.abs(ours - ref) / np.maximum(np.abs(ours), 1.0))),
        "decision_jaxfdi": [int(d.detection_step), int(d.decision_step), int(d.psa), int(d.hybrid)],
        "decision_numpy": [int(v) for v in dec[:4]],
        "suspects": [np.asarray(d.suspects).tolist(), np.asarray(dec[4]).tolist()],
        "residuals_jaxfdi": norms.tolist(),
        "residuals_numpy": np.asarray(dec[5]).tolist(),
        "residual_max_relative": float(np.max(np.abs(norms - dec[5])) / np.max(np.abs(dec[5]))),
    }


def time_numpy(setup, fdi, tables, design, F, flights: int) -> dict:
    disp = dispersions(jax.random.key(1), setup, max(flights, 2))
    cases = random_cases(max(flights, 2), 1, setup.x0.dtype)
    rng = np.random.default_rng(1)
    walls, cpus, used = [], [], 0
    for i in range(flights):
        case = jax.tree_util.tree_map(lambda a: a[i], cases)
        bias = np.asarray(sf.sensor_fault(case, setup.sensors.rate_sigma).magnitude)
        w, c = time.perf_counter(), time.process_time()
        _, _, dec = fly_fdi(
            tables,
            design,
            F,
            np.asarray(setup.x0 + disp.initial[i]),
            float(disp.xcg[i]),
            rng,
            (int(case.sensor), bias, int(case.onset)),
        )
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
        used += int(np.isfinite(dec[5]).all())
    return {
        "flights": flights,
        "per_flight_s": float(np.mean(walls)),
        "per_flight_cpu_s": float(np.mean(cpus)),
        "ukf_used": used,
    }


def time_jaxfdi(setup, fdi, flights: int, repeats: int) -> dict:
    keys = jax.random.split(jax.random.key(2), flights)
    disp = dispersions(jax.random.key(3), setup, flights)
    cases = random_cases(flights, 2, setup.x0.dtype)
    rows = {}
    for name, fn, args in (
        ("fdi", jax.jit(fdi_flights), (setup, fdi, keys, disp, cases)),
        ("bare", jax.jit(lambda s, k, d: run_flights(s, k, d)), (setup, keys, disp)),
    ):
        t0 = time.perf_counter()
        compiled = fn.lower(*args).compile()
        compile_s = time.perf_counter() - t0
        run_s, cpu_s, out = timed(lambda: block(compiled(*args)), repeats)
        row = {
            "compile_s": compile_s,
            "run_s": run_s,
            "run_cpu_s": cpu_s,
            "per_flight_s": run_s / flights,
            "flights_per_s": flights / run_s,
            "healthy": int(np.sum(np.asarray(out.healthy))),
        }
        if name == "fdi":
            d = out.fdi
            row.update(
                ukf_used=int(np.sum(np.asarray(d.filter_used))),
                isolated=int(np.sum(np.asarray(d.hybrid) == np.asarray(cases.sensor) + 1)),
                psa_isolated=int(np.sum(np.asarray(d.psa) == np.asarray(cases.sensor) + 1)),
            )
        rows[name] = row
    return {
        "flights": flights,
        **rows,
        "fdi_over_bare": rows["fdi"]["run_s"] / rows["bare"]["run_s"],
    }


def main() -> int:
    args = _parse() if __name__ == "__main__" else _parse([])
    print(
        f"jax {jax.__version__} on {jax.default_backend()}: {[d.device_kind for d in jax.devices()]}",
        flush=True,
    )
    setup, _ = flight_setup(gust_sigma=GUST_SIGMA)
    fdi, _ = sf.fdi_setup(setup)
    tables = baseline.Tables(data_path("f16_stevens_lewis.json"))
    design = numpy_design(setup)
    F = numpy_fdi(setup, fdi)
    agreement = check_agreement(setup, fdi, tables, design, F)
    print(
        f"paper's case without noise, jaxfdi vs NumPy: states within {agreement['state_max_relative']:.1e} "
        f"relative; decision (detection, decision step, PSA, hybrid) {agreement['decision_jaxfdi']} vs "
        f"{agreement['decision_numpy']}; UKF residuals {np.round(agreement['residuals_jaxfdi'], 6).tolist()} vs "
        f"{np.round(agreement['residuals_numpy'], 6).tolist()} (largest difference "
        f"{agreement['residual_max_relative']:.1e} of the largest)",
        flush=True,
    )
    if not (
        agreement["state_max_relative"] < 1e-8
        and agreement["decision_jaxfdi"] == agreement["decision_numpy"]
        and agreement["residual_max_relative"] < 1e-6
    ):
        print("the two implementations disagree: no timing", file=sys.stderr)
        return 1
    numpy_row = time_numpy(setup, fdi, tables, design, F, args.numpy_flights)
    print(
        f"numpy FDI loop: {numpy_row['per_flight_s']:.3f} s per flight (mean of {args.numpy_flights}; CPU "
        f"{numpy_row['per_flight_cpu_s']:.3f} s; UKF used in {numpy_row['ukf_used']})",
        flush=True,
    )
    rows = []
    for n in args.flights:
        row = time_jaxfdi(setup, fdi, n, args.repeats)
        f, b = row["fdi"], row["bare"]
        row.update(
            ratio_vs_numpy=numpy_row["per_flight_s"] / f["per_flight_s"],
            ratio_vs_numpy_cpu=numpy_row["per_flight_cpu_s"] / (f["run_cpu_s"] / n),
        )
        rows.append(row)
        print(
            f"jaxfdi {n:>6} flights: FDI flight compile {f['compile_s']:.1f} s, run {f['run_s']:.3f} s (CPU "
            f"{f['run_cpu_s']:.3f} s), {f['per_flight_s'] * 1e3:.3f} ms per flight, {f['flights_per_s']:.0f} "
            f"flights/s, {row['ratio_vs_numpy']:.0f}x numpy (CPU {row['ratio_vs_numpy_cpu']:.0f}x); UKF used in "
            f"{f['ukf_used']}, hybrid isolated {f['isolated']} (PSA alone {f['psa_isolated']}); bare flight "
            f"{b['per_flight_s'] * 1e3:.3f} ms per flight: FDI costs {row['fdi_over_bare']:.2f}x the bare flight",
            flush=True,
        )
    _io.write_json(
        args.out,
        {
            "date": datetime.datetime.now().isoformat(timespec="seconds"),
            "command": " ".join(sys.argv),
            "machine": {
                "cpu_count": os.cpu_count(),
                "platform": platform.platform(),
                "jax": jax.__version__,
                "backend": jax.default_backend(),
                "devices": [d.device_kind for d in jax.devices()],
                "load_average": list(os.getloadavg()),
            },
            "agreement": agreement,
            "numpy": numpy_row,
            "jaxfdi": rows,
        },
    )
    print(f"wrote {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_f16_fdi.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
