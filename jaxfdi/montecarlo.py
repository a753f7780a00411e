"""Monte Carlo driver: vmap over runs, chunked to bound memory, sharded over devices.

``monte_carlo(run_one, key, num_runs, per_run)`` calls ``run_one(key_i, per_run_i)``
for every run, where ``key_i`` is the i-th of ``jax.random.split(key, num_runs)`` and
``per_run_i`` the i-th slice of any pytree of per-run data (faults, magnitudes, initial
states, models). Runs are evaluated ``chunk_size`` at a time by one compiled
``jit(vmap(run_one))``; each chunk's run axis is sharded over all local devices with
``jax.sharding`` (``NamedSharding(Mesh(devices, ("runs",)), P("runs"))``). Each run's
randomness depends only on its own key, so results do not depend on the number of
devices or the chunk size (up to floating-point rounding: XLA may vectorise a batch of
different width differently). Outputs come back as NumPy.
"""
from __future__ import annotations

import sys
import time
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxfdi import _checks

ProgressFn = Callable[[int, int, float], None]


def print_progress(done: int, total: int, elapsed: float) -> None:
    """Default progress display: one updating line on stderr."""
    rate = done / elapsed if elapsed > 0 else float("nan")
    end = "\n" if done >= total else ""
    print(f"\rmonte carlo: {done}/{total} runs, {elapsed:.1f} s, {rate:.0f} runs/s", end=end, file=sys.stderr, flush=True)


def _num_runs_of(per_run: Any) -> set[int]:
    return {np.shape(leaf)[0] if np.ndim(leaf) else -1 for leaf in jax.tree_util.tree_leaves(per_run)}


def monte_carlo(
    run_one: Callable[[jax.Array, Any], Any],
    key: jax.Array,
    num_runs: int,
    per_run: Any = None,
    *,
    chunk_size: int = 8192,
    devices: list | None = None,
    progress: bool | ProgressFn = False,
) -> Any:
    """Evaluate ``run_one`` over ``num_runs`` runs; return outputs stacked over runs.

    Args:
      run_one: pure function ``(key, per_run_slice) -> pytree``; keep its output small
        (metrics, not histories) for large ``num_runs``.
      key: PRNG key; run i gets ``jax.random.split(key, num_runs)[i]``.
      num_runs: number of runs.
      per_run: pytree whose leaves have leading axis ``num_runs`` (or ``None``).
      chunk_size: runs per compiled call (memory bound); rounded to the device count.
      devices: devices to shard the run axis over (default: all local devices).
      progress: ``True`` for a line on stderr, or a callable ``(done, total, seconds)``.
    """
    _checks.check_callable("run_one", run_one, "a function (key, per_run_slice) -> outputs")
    num_runs = _checks.check_int("num_runs", num_runs, 1, meaning="a positive number of runs")
    chunk_size = _checks.check_int("chunk_size", chunk_size, 1, meaning="a positive number of runs per call")
    if not (isinstance(key, jax.Array) and (jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
                                             or (key.dtype == jnp.uint32 and key.shape == (2,)))):
        raise TypeError(f"key: expected a PRNG key (jax.random.key(seed)), got {_checks.received(key)}")
    if not (progress is None or isinstance(progress, bool) or callable(progress)):
        raise TypeError(f"progress: expected True/False or a callable (done, total, seconds), got "
                        f"{_checks.received(progress)}")
    sizes = _num_runs_of(per_run)
    if sizes and sizes != {num_runs}:
        raise ValueError(f"per_run: every leaf needs leading axis num_runs = {num_runs}, got leading sizes {sorted(sizes)}")
    devices = list(devices or jax.local_devices())
    n_dev = len(devices)
    chunk = min(int(chunk_size), int(num_runs))
    chunk = -(-chunk // n_dev) * n_dev
    sharding = NamedSharding(Mesh(np.array(devices), ("runs",)), PartitionSpec("runs"))
    batched = jax.jit(jax.vmap(run_one))
    keys = jax.random.split(key, num_runs)
    report = print_progress if progress is True else (progress or None)

    outputs = []
    start_time = time.perf_counter()
    for start in range(0, num_runs, chunk):
        stop = min(start + chunk, num_runs)
        index = np.minimum(np.arange(start, start + chunk), num_runs - 1)  # pad by repeating the last run
        chunk_keys, chunk_data = jax.tree_util.tree_map(lambda leaf: jnp.asarray(leaf)[index], (keys, per_run))
        chunk_keys, chunk_data = jax.device_put((chunk_keys, chunk_data), sharding)
        result = batched(chunk_keys, chunk_data)
        outputs.append(jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[: stop - start], result))
        if report:
            report(stop, num_runs, time.perf_counter() - start_time)
    return jax.tree_util.tree_map(lambda *parts: np.concatenate(parts, axis=0), *outputs)
