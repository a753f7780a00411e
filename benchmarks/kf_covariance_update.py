"""What the Joseph form costs one sequence: ``jit(run_filter)`` of the engine KF (T = 1000)
with the library's Joseph update, ``P+ = M diag(P, R) M^T`` with ``M = [I - K C, K]``,
against the same filter with the Joseph form as five products,
``(I - K C) P (I - K C)^T + K R K^T``, and with the standard form ``P+ = P - K C P``
patched in, and dynamax (its standard form), interleaved in one process (best of 40 runs,
3 rounds).

    python benchmarks/kf_covariance_update.py
"""

from __future__ import annotations

import os
import sys

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bench_filters as B

from jaxfdi import _linalg

BLOCK = _linalg.joseph_cov


def five_products(cov, gain, H, noise_cov):
    """The Joseph form as written: ``(I - K H) P (I - K H)^T + K R K^T``."""
    I_KH = jnp.eye(cov.shape[0], dtype=cov.dtype) - gain @ H
    return _linalg.symmetrize(I_KH @ cov @ I_KH.T + gain @ noise_cov @ gain.T)


def standard_cov(cov, gain, H, noise_cov):
    """``P - K H P``: equal to Joseph's for the optimal gain, without its PSD guarantee."""
    return _linalg.symmetrize(cov - gain @ (H @ cov))


def best_ms(fn, args, repeats: int = 40) -> float:
    timing, _ = B.compiled_timing(
        lambda *a: fn(*a), args, repeats
    )  # a fresh trace: the patch is seen
    return 1e3 * timing["run_min_s"]


def main() -> int:
    prob = B.engine_problem(1)
    args = (prob["model"], prob["m0"], prob["P0"], prob["ys"][0], prob["us"])
    for round_ in range(3):
        times = {}
        for name, update in (
            ("Joseph in one block", BLOCK),
            ("Joseph as five products", five_products),
            ("standard form", standard_cov),
        ):
            _linalg.joseph_cov = update
            times[name] = best_ms(B.jaxfdi_kf, args)
        _linalg.joseph_cov = BLOCK
        times["dynamax"] = best_ms(B.dynamax_kf, args)
        print(
            f"round {round_}: " + ", ".join(f"{k} {v:.2f} ms" for k, v in times.items()), flush=True
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
