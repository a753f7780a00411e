"""Seed 000's closed-loop F-16 flight (issue 23): flights per second of jaxfdi (vmapped,
one compiled scan) against the same flight as a straightforward NumPy loop, and the
gradient of a flight's tracking cost with respect to the LQR weights.

The flight: ``jaxfdi.scenarios.f16_flight.run_flight`` (climb at 120 ft/s for 0-5 s, then
altitude hold and a 30 deg bank turn to 15 s; 1500 steps of RK4 at 0.01 s; sensor noise,
3 ft/s gusts, c.g. and initial-state dispersions), float64.

- Baseline: ``f16_numpy_baseline.fly`` (the book's Fortran functions ported one by one,
  NumPy state, explicit RK4, a Python loop over time; one flight after another). First
  checked against jaxfdi on the noise-free nominal flight (every state, relative 1e-8),
  then timed on ``--numpy-flights`` noisy flights; its time per flight is the mean.
- jaxfdi: ``jit(vmap(run_flight))`` over 1, 100 and 10^4 flights (``--flights``), compile
  time (trace + lower + XLA compile) apart from run time (median of ``--repeats`` runs of
  the compiled executable); per flight = run time / flights. The ratio is the NumPy time
  per flight over jaxfdi's, wall clock, same process. ``--dtype float32`` adds the same
  flights in float32 (the float64 design cast). ``--host-devices 2`` (set before JAX
  starts) splits the flights over two CPU devices (``jax.sharding``), i.e. both cores.
- Gradient: ``J(log w) = mean over --gradient-flights flights of the mean squared altitude
  error (ft^2) + mean squared bank error (deg^2)``, the LQR weights ``w = exp(log w)`` (17
  numbers) going through the design (c2d, the DARE, implicitly differentiated) into the
  flight; ``jit(J)`` against ``jit(grad(J))``, compile apart; checked against a central
  difference along a random direction.

Run:   python benchmarks/bench_f16_flight.py                       (about 8 minutes on 2 cores)
Quick: python benchmarks/bench_f16_flight.py --flights 1 100 --numpy-flights 1 --repeats 2
Writes benchmarks/results_f16_flight.json.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import sys
import time


def _parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--flights", type=int, nargs="+", default=[1, 100, 10000])
    parser.add_argument("--numpy-flights", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--dtype", choices=["float64", "float32", "both"], default="float64")
    parser.add_argument(
        "--host-devices", type=int, default=1, help="CPU devices for the jaxfdi runs (XLA flag)"
    )
    parser.add_argument("--gradient-flights", type=int, default=4, help="0: skip the gradient")
    parser.add_argument(
        "--out",
        default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results_f16_flight.json"),
    )
    return parser.parse_args(argv)


ARGS = _parse() if __name__ == "__main__" else None
if ARGS is not None and ARGS.host_devices > 1:
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "")
        + f" --xla_force_host_platform_device_count={ARGS.host_devices}"
    ).strip()

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import f16_numpy_baseline as baseline

from jaxfdi._io import files as _io
from jaxfdi.control import FlightWeights, design_flight_control
from jaxfdi.data import data_path
from jaxfdi.models.f16 import measurement_cov
from jaxfdi.scenarios.f16_flight import (
    DT,
    ERRORS,
    GUST_SIGMA,
    cast_setup,
    dispersions,
    flight_setup,
    nominal_dispersion,
    run_flight,
    run_flights,
)


def block(x):
    return jax.tree_util.tree_map(
        lambda a: a.block_until_ready() if hasattr(a, "block_until_ready") else a, x
    )


def timed(fn, repeats):
    """Median wall time and median process CPU time of ``fn()`` over ``repeats`` calls."""
    walls, cpus = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return statistics.median(walls), statistics.median(cpus)


def numpy_design(setup) -> dict:
    decay = float(np.exp(-502.0 * DT / 1750.0))
    return dict(
        dt=DT,
        H=np.asarray(setup.sensors.rate_axes),
        K_lon=np.asarray(setup.gains.longitudinal),
        K_lat=np.asarray(setup.gains.lateral),
        x_ref=np.asarray(setup.reference.state),
        u_ref=np.asarray(setup.reference.control),
        lower=np.asarray(setup.params.control_lower),
        upper=np.asarray(setup.params.control_upper),
        sigma=np.sqrt(np.diag(np.asarray(measurement_cov(setup.sensors)))),
        gust_decay=decay,
        gust_std=float(setup.gust_sigma) * np.sqrt(1.0 - decay**2),
    )


def check_agreement(setup, tables, design) -> float:
    """Max relative difference of the noise-free nominal flight's states, jaxfdi vs NumPy."""
    zero = jax.tree_util.tree_map(lambda a: 0.0 * a, setup.sensors)._replace(
        rate_axes=setup.sensors.rate_axes
    )
    quiet = setup._replace(sensors=zero, gust_sigma=0.0 * setup.gust_sigma)
    _, hist = jax.jit(lambda s, k, d: run_flights(s, k, d, True))(
        quiet, jax.random.split(jax.random.key(0), 1), nominal_dispersion(quiet)
    )
    ours = np.asarray(hist.state[0, :, :13])
    ref, _ = baseline.fly(
        tables,
        design,
        np.asarray(setup.x0),
        float(setup.params.xcg),
        np.random.default_rng(0),
        noise=False,
    )
    return float(np.max(np.abs(ours - ref) / np.maximum(np.abs(ours), 1.0)))


def time_numpy(setup, tables, design, flights: int) -> dict:
    disp = dispersions(jax.random.key(1), setup, max(flights, 2))
    rng = np.random.default_rng(1)
    walls, cpus = [], []
    for i in range(flights):
        x0 = np.asarray(setup.x0 + disp.initial[i])
        w, c = time.perf_counter(), time.process_time()
        baseline.fly(tables, design, x0, float(disp.xcg[i]), rng)
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return {
        "flights": flights,
        "per_flight_s": float(np.mean(walls)),
        "per_flight_cpu_s": float(np.mean(cpus)),
    }


def time_jaxfdi(setup, flights: int, repeats: int) -> dict:
    keys = jax.random.split(jax.random.key(2), flights)
    disp = dispersions(jax.random.key(3), setup, flights)
    devices = jax.local_devices()
    fn = jax.jit(lambda s, k, d: run_flights(s, k, d))
    if len(devices) > 1 and flights % len(devices) == 0:
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        sharding = NamedSharding(Mesh(np.array(devices), ("flights",)), PartitionSpec("flights"))
        keys, disp = jax.device_put((keys, disp), sharding)
    t0 = time.perf_counter()
    compiled = fn.lower(setup, keys, disp).compile()
    compile_s = time.perf_counter() - t0
    out = block(compiled(setup, keys, disp))
    run_s, cpu_s = timed(lambda: block(compiled(setup, keys, disp)), repeats)
    return {
        "flights": flights,
        "compile_s": compile_s,
        "run_s": run_s,
        "run_cpu_s": cpu_s,
        "per_flight_s": run_s / flights,
        "flights_per_s": flights / run_s,
        "devices": len(devices) if flights % len(devices) == 0 else 1,
        "healthy": bool(np.all(np.asarray(out.healthy))),
        "altitude_error_max_ft_median": float(np.median(np.asarray(out.tracking.max_abs)[:, 0])),
    }


def gradient_benchmark(setup, design, flights: int, repeats: int) -> dict:
    """Tracking cost of ``flights`` flights as a function of the log LQR weights."""
    keys = jax.random.split(jax.random.key(4), flights)
    disp = dispersions(jax.random.key(5), setup, flights)
    linear = design.linear
    index = {name: i for i, name in enumerate(ERRORS)}

    def cost(log_w: FlightWeights):
        weights = jax.tree_util.tree_map(jnp.exp, log_w)
        gains = design_flight_control(linear, DT, weights).gains
        s = setup._replace(gains=gains)
        out = jax.vmap(lambda k, d: run_flight(s, k, d))(keys, disp)
        score = out.tracking
        per_flight = (
            score.sum_sq[:, index["altitude_ft"]] / score.count[:, index["altitude_ft"]]
            + score.sum_sq[:, index["bank_deg"]] / score.count[:, index["bank_deg"]]
        )
        return jnp.mean(per_flight)

    log_w = jax.tree_util.tree_map(jnp.log, design.weights)
    forward, gradient = jax.jit(cost), jax.jit(jax.grad(cost))
    t0 = time.perf_counter()
    forward_c = forward.lower(log_w).compile()
    forward_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    gradient_c = gradient.lower(log_w).compile()
    gradient_compile = time.perf_counter() - t0
    value = float(forward_c(log_w))
    grad = block(gradient_c(log_w))
    forward_s, _ = timed(lambda: block(forward_c(log_w)), repeats)
    gradient_s, _ = timed(lambda: block(gradient_c(log_w)), repeats)
    # directional derivative against a central difference
    leaves, tree = jax.tree_util.tree_flatten(log_w)
    rng = np.random.default_rng(6)
    direction = [rng.standard_normal(np.shape(leaf)) for leaf in leaves]
    norm = np.sqrt(sum(np.sum(d**2) for d in direction))
    direction = jax.tree_util.tree_unflatten(tree, [jnp.asarray(d / norm) for d in direction])
    step = 1e-4
    shifted = lambda sign: jax.tree_util.tree_map(
        lambda a, d: a + sign * step * d, log_w, direction
    )
    fd = (float(forward_c(shifted(1.0))) - float(forward_c(shifted(-1.0)))) / (2 * step)
    analytic = float(
        sum(
            jnp.sum(g * d)
            for g, d in zip(jax.tree_util.tree_leaves(grad), jax.tree_util.tree_leaves(direction))
        )
    )
    return {
        "flights": flights,
        "cost": value,
        "forward_s": forward_s,
        "gradient_s": gradient_s,
        "gradient_over_forward": gradient_s / forward_s,
        "forward_compile_s": forward_compile,
        "gradient_compile_s": gradient_compile,
        "weights": int(sum(np.size(leaf) for leaf in leaves)),
        "directional_derivative": analytic,
        "central_difference": fd,
        "relative_difference": abs(analytic - fd) / max(abs(fd), 1e-300),
    }


def main() -> int:
    args = ARGS or _parse([])
    print(
        f"jax {jax.__version__} on {jax.default_backend()}: {[d.device_kind for d in jax.devices()]}",
        flush=True,
    )
    setup, design = flight_setup(gust_sigma=GUST_SIGMA)
    tables = baseline.Tables(data_path("f16_stevens_lewis.json"))
    np_design = numpy_design(setup)
    agreement = check_agreement(setup, tables, np_design)
    print(
        f"noise-free nominal flight, jaxfdi vs NumPy: max relative state difference {agreement:.1e}",
        flush=True,
    )
    if not agreement < 1e-8:
        print("the two implementations disagree: no timing", file=sys.stderr)
        return 1
    numpy_row = time_numpy(setup, tables, np_design, args.numpy_flights)
    print(
        f"numpy loop: {numpy_row['per_flight_s']:.3f} s per flight (mean of {args.numpy_flights}; CPU "
        f"{numpy_row['per_flight_cpu_s']:.3f} s)",
        flush=True,
    )
    rows = []
    dtypes = ["float64", "float32"] if args.dtype == "both" else [args.dtype]
    for dtype in dtypes:
        s = setup if dtype == "float64" else cast_setup(setup, jnp.float32)
        for n in args.flights:
            row = time_jaxfdi(s, n, args.repeats)
            row.update(
                dtype=dtype,
                ratio_vs_numpy=numpy_row["per_flight_s"] / row["per_flight_s"],
                ratio_vs_numpy_cpu=numpy_row["per_flight_cpu_s"] / (row["run_cpu_s"] / n),
            )
            rows.append(row)
            print(
                f"jaxfdi {dtype} {n:>6} flights ({row['devices']} device(s)): compile {row['compile_s']:.1f} s, "
                f"run {row['run_s']:.3f} s (CPU {row['run_cpu_s']:.3f} s), "
                f"{row['per_flight_s'] * 1e3:.3f} ms per flight, {row['flights_per_s']:.0f} flights/s, "
                f"{row['ratio_vs_numpy']:.0f}x numpy (CPU time: {row['ratio_vs_numpy_cpu']:.0f}x)",
                flush=True,
            )
    grad_row = None
    if args.gradient_flights > 0:
        grad_row = gradient_benchmark(setup, design, args.gradient_flights, args.repeats)
        print(
            f"gradient of the tracking cost over {grad_row['flights']} flights w.r.t. {grad_row['weights']} LQR "
            f"weights: forward {grad_row['forward_s']:.3f} s, gradient {grad_row['gradient_s']:.3f} s "
            f"({grad_row['gradient_over_forward']:.1f}x), compile {grad_row['forward_compile_s']:.1f} / "
            f"{grad_row['gradient_compile_s']:.1f} s; directional derivative "
            f"{grad_row['directional_derivative']:.6g} vs central difference {grad_row['central_difference']:.6g} "
            f"(rel. {grad_row['relative_difference']:.1e})",
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
            "agreement_max_relative": agreement,
            "numpy": numpy_row,
            "jaxfdi": rows,
            "gradient": grad_row,
        },
    )
    print(f"wrote {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_f16_flight.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
