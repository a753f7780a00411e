"""A small engine Monte Carlo study run by ``tests/core/test_multiprocess.py`` in one process
and, as a script, in several processes (``python -m jaxfdi.distributed``)."""

from __future__ import annotations

import sys

import jax
import jax.numpy as jnp
import numpy as np

import jaxfdi
from jaxfdi import streaming

NUM_RUNS, T, ONSET, WINDOW = 22, 50, 25, 3


def run_one(key, size):
    """Constant-velocity target, position and velocity sensors, KF + 3-step chi-square
    test; a sensor-0 bias of ``size`` from step ONSET (fault-free when 0)."""
    model = jaxfdi.models.linear_gaussian_model(
        jnp.array([[1.0, 0.1], [0.0, 1.0]]),
        jnp.eye(2),
        jnp.diag(jnp.array([1e-3, 1e-2])),
        jnp.diag(jnp.array([0.05, 0.02])),
    )
    onset = jnp.where(size > 0, ONSET, jaxfdi._simulation.faults.NEVER)
    sim = jaxfdi.linear_simulator(model, jaxfdi.fault("bias", "sensor", 0, onset, size))
    kf = jaxfdi.filters.kalman_filter(
        model, unroll_factorizations=False
    )  # LAPACK calls: compiles faster
    detector = jaxfdi.detection.chi2_detector(
        jaxfdi.detection.chi2_threshold(WINDOW * 2, 1e-3), WINDOW
    )
    return jaxfdi.monitor(
        sim,
        kf,
        detector,
        jnp.zeros(2),
        kf.init(jnp.zeros(2), jnp.eye(2)),
        jnp.zeros((T, 0)),
        key,
        onset,
    ).record


def study(chunk_size: int, reduce: bool = False):
    """Half of the runs fault-free, half with a bias of a per-run size. Returns the stacked
    records, or the streaming counts with ``reduce``."""
    sizes = np.where(np.arange(NUM_RUNS) % 2 == 0, 0.0, np.linspace(0.2, 1.5, NUM_RUNS))
    reducer = streaming.detection_reducer(T, bin_width=4) if reduce else None
    return jaxfdi.monte_carlo(
        run_one, jax.random.key(7), NUM_RUNS, sizes, chunk_size=chunk_size, reduce=reducer
    )


if __name__ == "__main__":  # python _multiprocess_study.py OUT_PREFIX CHUNK_SIZE
    jax.config.update("jax_enable_x64", True)
    from jaxfdi import distributed

    info = distributed.initialize(timeout_s=120)
    chunk = int(sys.argv[2])
    records = study(chunk)
    counts = study(chunk, reduce=True)
    np.savez(
        f"{sys.argv[1]}{info.process_id}.npz",
        process_count=info.num_processes,
        **{f"record_{k}": np.asarray(v) for k, v in records._asdict().items()},
        **{f"counts_{k}": np.asarray(v) for k, v in counts._asdict().items()},
    )
