"""Gradient cost for tuning: the engine KF's total log-likelihood and its gradient with
respect to log-diagonal Q and R (jaxfdi, jaxfdi with rematerialised steps, dynamax), and
the engine IMM tuning loss (mode cross-entropy) forward vs gradient. Compile time apart;
XLA's temporary-buffer size (``compiled.memory_analysis()``) as the peak-memory figure.

Run:  python benchmarks/bench_tuning.py [--sequences 100] [--imm-sequences 14] [--repeats 5]
Writes benchmarks/results_tuning.json.
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_filters import compiled_timing, cpu_model, dynamax_kf, write_json_atomic
from bench_imm import engine_data

import jaxfdi
from jaxfdi import tuning
from jaxfdi.scenarios import engine_tuning as et


def kf_rows(args, log):
    model, ys, us = engine_data(args.sequences)
    ys, us = jnp.asarray(ys), jnp.asarray(us)
    m0, P0 = jnp.zeros(7), model.Q
    theta = (jnp.log(jnp.diag(model.Q) + 1e-12), jnp.log(jnp.diag(model.R)))

    def with_noise(t):
        return model._replace(Q=jnp.diag(jnp.exp(t[0])), R=jnp.diag(jnp.exp(t[1])))

    def jaxfdi_total(t, remat=False, unroll=True):
        kf = jaxfdi.filters.kalman_filter(with_noise(t), unroll_factorizations=unroll)
        kf = jaxfdi.tuning._train.checkpointed(kf) if remat else kf
        return jnp.sum(
            jax.vmap(
                lambda y: jaxfdi.filters.run_filter(kf, kf.init(m0, P0), y, us)[
                    1
                ].log_likelihood.sum()
            )(ys)
        )

    def dynamax_total(t):
        return jnp.sum(jax.vmap(lambda y: dynamax_kf(with_noise(t), m0, P0, y, us)[2])(ys))

    rows = []
    impls = {
        "jaxfdi": jaxfdi_total,
        "jaxfdi remat": lambda t: jaxfdi_total(t, True),
        "jaxfdi lapack": lambda t: jaxfdi_total(t, unroll=False),
        "jaxfdi lapack remat": lambda t: jaxfdi_total(t, True, False),
        "dynamax": dynamax_total,
    }
    values = {}
    for name, total in impls.items():
        fwd, v = compiled_timing(total, (theta,), args.repeats)
        grad, g = compiled_timing(jax.grad(total), (theta,), args.repeats)
        values[name] = (float(v), np.concatenate([np.asarray(x) for x in g]))
        rows.append(
            {
                "implementation": name,
                "forward_s": fwd["run_s"],
                "grad_s": grad["run_s"],
                "grad_over_forward": grad["run_s"] / fwd["run_s"],
                "forward_compile_s": fwd["compile_s"],
                "grad_compile_s": grad["compile_s"],
                "grad_temp_bytes": grad["temp_bytes"],
            }
        )
        log(
            f"KF {name}: forward {fwd['run_s'] * 1e3:.1f} ms, gradient {grad['run_s'] * 1e3:.1f} ms "
            f"({grad['run_s'] / fwd['run_s']:.1f}x forward), compile {fwd['compile_s']:.2f} / "
            f"{grad['compile_s']:.2f} s, "
            f"gradient temp memory {grad['temp_bytes'] / 2**20:.1f} MiB"
        )
    ref_v, ref_g = values["jaxfdi"]
    for name, (v, g) in values.items():
        log(
            f"  {name}: loglik rel diff {abs(v - ref_v) / abs(ref_v):.1e}, "
            f"gradient rel diff {np.max(np.abs(g - ref_g)) / np.max(np.abs(ref_g)):.1e} (vs jaxfdi)"
        )
    return rows


def imm_rows(args, log):
    runs = max(1, args.imm_sequences // 7)
    data = et.labelled_runs(runs, seed=0)
    design = et.imm_design("zhang-li")
    raw = jaxfdi.tuning._parameterize.unconstrain(design.parameterization, design.hand())
    rows = []
    for remat in (False, True):

        def loss(r, remat=remat):
            return et.imm_loss(
                design, tuning.constrain(design.parameterization, r), data, remat=remat
            )[0]

        fwd, _ = compiled_timing(loss, (raw,), args.repeats)
        grad, _ = compiled_timing(jax.grad(loss), (raw,), args.repeats)
        rows.append(
            {
                "remat": remat,
                "runs": 7 * runs,
                "steps": int(data.ys.shape[1]),
                "forward_s": fwd["run_s"],
                "grad_s": grad["run_s"],
                "grad_over_forward": grad["run_s"] / fwd["run_s"],
                "forward_compile_s": fwd["compile_s"],
                "grad_compile_s": grad["compile_s"],
                "grad_temp_bytes": grad["temp_bytes"],
            }
        )
        log(
            f"IMM tuning loss, {7 * runs} runs x {data.ys.shape[1]} steps, remat={remat}: forward "
            f"{fwd['run_s'] * 1e3:.0f} ms, gradient {grad['run_s'] * 1e3:.0f} ms "
            f"({grad['run_s'] / fwd['run_s']:.1f}x), "
            f"compile {fwd['compile_s']:.1f} / {grad['compile_s']:.1f} s, gradient temp memory "
            f"{grad['temp_bytes'] / 2**20:.1f} MiB"
        )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sequences", type=int, default=100)
    parser.add_argument("--imm-sequences", type=int, default=14)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--out",
        default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results_tuning.json"),
    )
    args = parser.parse_args(argv)
    log = lambda msg: print(msg, flush=True)
    log(
        f"jax {jax.__version__} on {jax.devices()[0].device_kind} ({cpu_model()}, {os.cpu_count()} cores)"
    )
    result = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "jax": jax.__version__,
        "device": jax.devices()[0].device_kind,
        "cpu": cpu_model(),
        "command": " ".join(["python", *sys.argv]),
        "kf": kf_rows(args, log),
        "imm": imm_rows(args, log),
    }
    write_json_atomic(args.out, result)
    log(f"wrote {args.out}")
    from report import refresh  # RESULTS.md again, only if the JSON went to its default path

    refresh(args.out, "results_tuning.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
