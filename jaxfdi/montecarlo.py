"""Monte Carlo driver: vmap over runs, chunked to bound memory, sharded over devices and
processes.

``monte_carlo(run_one, key, num_runs, per_run)`` calls ``run_one(key_i, per_run_i)``
for every run, where ``key_i`` is the i-th of ``jax.random.split(key, num_runs)`` and
``per_run_i`` the i-th slice of any pytree of per-run data (faults, magnitudes, initial
states, models). Runs are evaluated ``chunk_size`` at a time by one compiled
``jit(vmap(run_one))``; each chunk's run axis is sharded over the devices with
``jax.sharding`` (``NamedSharding(Mesh(devices, ("runs",)), P("runs"))``). Each run's
randomness depends only on its own key, which depends only on its index (``run_keys``),
so results do not depend on the number of devices, processes or the chunk size (up to
floating-point rounding: XLA may vectorise a batch of different width differently;
with the same number of runs per device they are bit for bit the same). Outputs come
back as NumPy.

Several processes (``jaxfdi.distributed.initialize``; every process calls
``monte_carlo`` with the same arguments): the mesh spans every device of every process,
each process computes the runs its devices hold, and the outputs are gathered once at
the end, so every process returns the whole result. With ``reduce`` (e.g.
``streaming.detection_reducer``), each chunk's outputs are folded into a summary
instead of kept, and the processes' summaries are merged at the end.
"""
from __future__ import annotations

import functools
import sys
import time
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxfdi import _checks
from jaxfdi.progress import progress_bar

ProgressFn = Callable[[int, int, float], None]


def print_progress(done: int, total: int, elapsed: float) -> None:
    """Default progress display: one updating line on stderr."""
    rate = done / elapsed if elapsed > 0 else float("nan")
    end = "\n" if done >= total else ""
    print(f"\rmonte carlo: {done}/{total} runs, {elapsed:.1f} s, {rate:.0f} runs/s", end=end, file=sys.stderr, flush=True)


def _num_runs_of(per_run: Any) -> set[int]:
    return {np.shape(leaf)[0] if np.ndim(leaf) else -1 for leaf in jax.tree_util.tree_leaves(per_run)}


def _is_key(key: Any) -> bool:
    return isinstance(key, jax.Array) and (jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
                                           or (key.dtype == jnp.uint32 and key.shape == (2,)))


def _split_is_foldlike(key: jax.Array) -> bool:
    """True when ``split(key, n)[i]`` is the threefry hash of the 64-bit index ``i``
    alone (JAX's partitionable threefry, the default), so any run's key can be computed
    without the others."""
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    impl = str(jax.random.key_impl(key)) if typed else str(jax.config.jax_default_prng_impl)
    return bool(jax.config.jax_threefry_partitionable) and "threefry" in impl


@jax.jit
def _threefry_index_keys(key_data: jax.Array, high: jax.Array, low: jax.Array) -> jax.Array:
    from jax.extend.random import threefry2x32_p

    bits = threefry2x32_p.bind(key_data[0], key_data[1], high, low)
    return jnp.stack(bits, axis=-1)


def run_keys(key: jax.Array, index: np.ndarray, num_runs: int) -> jax.Array:
    """The keys of runs ``index`` of ``num_runs``: ``jax.random.split(key, num_runs)[index]``.

    With JAX's partitionable threefry (the default) key ``i`` depends on ``i`` alone and
    is computed directly (a 10^8-run study never holds 10^8 keys); otherwise the whole
    split is formed.
    """
    index = np.asarray(index)
    if not _split_is_foldlike(key):
        return jax.random.split(key, num_runs)[jnp.asarray(index)]
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    wide = index.astype(np.uint64)
    bits = _threefry_index_keys(jax.random.key_data(key) if typed else key,
                                jnp.asarray((wide >> np.uint64(32)).astype(np.uint32)),
                                jnp.asarray((wide & np.uint64(0xFFFFFFFF)).astype(np.uint32)))
    return jax.random.wrap_key_data(bits, impl=jax.random.key_impl(key)) if typed else bits


def monte_carlo(
    run_one: Callable[[jax.Array, Any], Any],
    key: jax.Array,
    num_runs: int,
    per_run: Any = None,
    *,
    chunk_size: int = 8192,
    devices: list | None = None,
    progress: bool | ProgressFn = False,
    batched: bool = False,
    reduce: Any = None,
) -> Any:
    """Evaluate ``run_one`` over ``num_runs`` runs; return outputs stacked over runs.

    Args:
      run_one: pure function ``(key, per_run_slice) -> pytree``; keep its output small
        (metrics, not histories) for large ``num_runs``.
      key: PRNG key; run i gets ``jax.random.split(key, num_runs)[i]``.
      num_runs: number of runs.
      per_run: pytree whose leaves have leading axis ``num_runs`` (or ``None``); with
        several processes, the same on every process.
      chunk_size: runs per compiled call (memory bound); rounded up to a multiple of the
        number of devices.
      devices: devices to shard the run axis over (default: all devices of all
        processes after ``jaxfdi.distributed.initialize``, else the local ones).
      progress: ``True`` for a line on stderr, or a callable ``(done, total, seconds)``.
      batched: ``run_one`` takes a whole chunk, ``(keys (B,), per_run (B, ...)) ->
        outputs (B, ...)`` (e.g. to run a batch kernel such as ``run_kalman_batch``
        over runs that differ in their model), instead of one run under ``vmap``.
      reduce: a ``streaming.Reducer``: fold each chunk's outputs into its state and
        return the state (merged across processes) instead of the stacked outputs.
    """
    _checks.check_callable("run_one", run_one, "a function (key, per_run_slice) -> outputs")
    num_runs = _checks.check_int("num_runs", num_runs, 1, meaning="a positive number of runs")
    chunk_size = _checks.check_int("chunk_size", chunk_size, 1, meaning="a positive number of runs per call")
    if not _is_key(key):
        raise TypeError(f"key: expected a PRNG key (jax.random.key(seed)), got {_checks.received(key)}")
    if not (progress is None or isinstance(progress, bool) or callable(progress)):
        raise TypeError(f"progress: expected True/False or a callable (done, total, seconds), got "
                        f"{_checks.received(progress)}")
    if reduce is not None and not all(callable(getattr(reduce, name, None)) for name in ("init", "update", "merge")):
        raise TypeError(f"reduce: expected a Reducer(init, update, merge) such as streaming.detection_reducer(...), "
                        f"got {_checks.received(reduce)}")
    sizes = _num_runs_of(per_run)
    if sizes and sizes != {num_runs}:
        raise ValueError(f"per_run: every leaf needs leading axis num_runs = {num_runs}, got leading sizes {sorted(sizes)}")
    devices = list(devices or (jax.devices() if jax.process_count() > 1 else jax.local_devices()))
    multiprocess = len({d.process_index for d in devices}) > 1
    if multiprocess:
        devices = sorted(devices, key=lambda d: (d.process_index, d.id))
        per_process = {p: sum(d.process_index == p for d in devices) for p in {d.process_index for d in devices}}
        if len(set(per_process.values())) != 1:
            raise ValueError(f"devices: every process needs the same number of devices, got {per_process}")
    n_dev = len(devices)
    chunk = min(int(chunk_size), int(num_runs))
    chunk = -(-chunk // n_dev) * n_dev
    sharding = NamedSharding(Mesh(np.array(devices), ("runs",)), PartitionSpec("runs"))
    try:
        compiled = _compiled(run_one, bool(batched))
    except TypeError:  # an unhashable callable object
        compiled = jax.jit(run_one if batched else jax.vmap(run_one))
    report = progress_bar("monte carlo", "runs") if progress is True else (progress or None)  # tqdm.auto or log lines
    rows = _local_rows(devices, chunk) if multiprocess else slice(0, chunk)

    state = reduce.init() if reduce is not None else None
    outputs = []
    start_time = time.perf_counter()
    for start in range(0, num_runs, chunk):
        stop = min(start + chunk, num_runs)
        index = np.minimum(np.arange(start, start + chunk), num_runs - 1)  # pad by repeating the last run
        if multiprocess:
            result = _chunk_multiprocess(compiled, sharding, key, index[rows], num_runs, per_run, chunk)
        else:
            chunk_keys = run_keys(key, index, num_runs)
            chunk_data = jax.tree_util.tree_map(lambda leaf: jnp.asarray(leaf)[index], per_run)
            chunk_keys, chunk_data = jax.device_put((chunk_keys, chunk_data), sharding)
            result = jax.tree_util.tree_map(np.asarray, compiled(chunk_keys, chunk_data))
        valid = np.arange(start, start + chunk)[rows] < stop
        if reduce is not None:
            state = reduce.update(state, jax.tree_util.tree_map(lambda leaf: leaf[valid], result))
        else:
            outputs.append(result)
        if report:
            report(stop, num_runs, time.perf_counter() - start_time)
    if reduce is not None:
        if multiprocess:
            from jaxfdi.distributed import allgather

            state = reduce.merge(allgather(state))
        return state
    if multiprocess:
        return _gather_runs(outputs, num_runs)
    return jax.tree_util.tree_map(lambda *parts: np.concatenate(parts, axis=0)[:num_runs], *outputs)


@functools.lru_cache(maxsize=8)
def _compiled(run_one: Callable, batched: bool) -> Callable:
    """``jit(vmap(run_one))``, one per ``run_one``: a second study with the same function
    (e.g. its streaming summary after its records) reuses the compiled executables."""
    return jax.jit(run_one if batched else jax.vmap(run_one))


def _local_rows(devices: list, chunk: int) -> slice:
    """The rows of a chunk held by this process's devices (contiguous: the mesh lists
    the devices process by process)."""
    per_device = chunk // len(devices)
    mine = [i for i, d in enumerate(devices) if d.process_index == jax.process_index()]
    if not mine or mine != list(range(mine[0], mine[-1] + 1)):
        raise ValueError("devices: every process needs at least one device in the list")
    return slice(mine[0] * per_device, (mine[-1] + 1) * per_device)


def _chunk_multiprocess(compiled, sharding, key, local_index, num_runs, per_run, chunk):
    """One chunk over the global mesh: this process builds its rows only, every process
    runs the same program, and the rows its devices computed come back as NumPy."""
    local_keys = run_keys(key, local_index, num_runs)
    local_data = jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[local_index], per_run)

    def global_array(local):
        return jax.make_array_from_process_local_data(sharding, local, (chunk,) + tuple(np.shape(local)[1:]))

    result = compiled(global_array(local_keys), jax.tree_util.tree_map(global_array, local_data))
    return jax.tree_util.tree_map(_local_part, result)


def _local_part(array: jax.Array) -> np.ndarray:
    shards = sorted(array.addressable_shards, key=lambda shard: shard.index[0].start or 0)
    return np.concatenate([np.asarray(shard.data) for shard in shards], axis=0)


def _gather_runs(outputs: list, num_runs: int) -> Any:
    """One all-gather of every process's rows of every chunk, put back in run order."""
    from jaxfdi.distributed import allgather

    local = jax.tree_util.tree_map(lambda *parts: np.stack(parts), *outputs)   # (chunks, local rows, ...)
    everyone = allgather(local)                                                 # [process](chunks, rows, ...)

    def order(*per_process):
        stacked = np.stack(per_process, axis=1)                                 # (chunks, processes, rows, ...)
        return stacked.reshape((-1,) + stacked.shape[3:])[:num_runs]

    return jax.tree_util.tree_map(order, *everyone)

