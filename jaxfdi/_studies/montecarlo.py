"""Monte Carlo driver: vmap over runs, chunked to bound memory, sharded over devices and processes.

``run_one(key_i, per_run_i)`` runs for every ``i``: ``key_i = jax.random.split(key, num_runs)[i]``, ``per_run_i``
the i-th slice of any per-run pytree (faults, magnitudes, initial states, models), ``chunk_size`` runs at a time
by one ``jit(vmap(run_one))`` with the run axis sharded over devices
(``NamedSharding(Mesh(devices, ("runs",)), P("runs"))``). A run's randomness depends only on its index
(``run_keys``), so results do not depend on devices, processes or chunk size (up to rounding: XLA may vectorise
another batch width differently; same runs per device: bit for bit). Outputs come back as NumPy.

Several processes (``jaxfdi.distributed.initialize``; all call ``monte_carlo`` with the same arguments): the mesh
spans every device of every process, each computes its devices' runs, outputs are gathered once at the end, and
every process returns the whole result. With ``reduce`` (e.g. ``streaming.detection_reducer``) each chunk is folded
into a summary instead of kept, and the processes' summaries are merged at the end.

The device never waits for the host: chunk ``c + 1`` is dispatched before chunk ``c``'s outputs are read, outputs
stay on the device until one final transfer, and ``summary`` (anything additive: counts, sums, histograms) is summed
on the device in the chunk's program. Progress counts finished chunks; the first chunk's compilation is reported.
"""

from __future__ import annotations

import functools
import threading
import time
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxfdi import checks
from jaxfdi._io.progress import progress_bar, status
from jaxfdi.distributed import allgather

ProgressFn = Callable[[int, int, float], None]


def _num_runs_of(per_run: Any) -> set[int]:
    return {
        np.shape(leaf)[0] if np.ndim(leaf) else -1 for leaf in jax.tree_util.tree_leaves(per_run)
    }


def is_key(key: Any) -> bool:
    """True for a PRNG key: a typed key or a raw ``uint32[2]`` one."""
    return isinstance(key, jax.Array) and (
        jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
        or (key.dtype == jnp.uint32 and key.shape == (2,))
    )


def _split_is_foldlike(key: jax.Array) -> bool:
    """True when ``split(key, n)[i]`` is the threefry hash of the 64-bit index ``i`` alone (JAX's partitionable
    threefry, the default), so any run's key can be computed without the others."""
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    impl = str(jax.random.key_impl(key)) if typed else str(jax.config.jax_default_prng_impl)
    return bool(jax.config.jax_threefry_partitionable) and "threefry" in impl


@jax.jit
def _threefry_index_keys(key_data: jax.Array, high: jax.Array, low: jax.Array) -> jax.Array:
    from jax.extend.random import threefry2x32_p

    bits = threefry2x32_p.bind(key_data[0], key_data[1], high, low)
    return jnp.stack(bits, axis=-1)


def run_keys(key: jax.Array, index: np.ndarray, num_runs: int) -> jax.Array:
    """The keys of runs ``index`` of ``num_runs``: ``jax.random.split(key, num_runs)[index]``, computed directly
    with partitionable threefry (the default; a 10^8-run study never holds 10^8 keys), else from the whole split.
    """
    index = np.asarray(index)
    if not _split_is_foldlike(key):
        return jax.random.split(key, num_runs)[jnp.asarray(index)]
    typed = jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
    wide = index.astype(np.uint64)
    bits = _threefry_index_keys(
        jax.random.key_data(key) if typed else key,
        jnp.asarray((wide >> np.uint64(32)).astype(np.uint32)),
        jnp.asarray((wide & np.uint64(0xFFFFFFFF)).astype(np.uint32)),
    )
    return jax.random.wrap_key_data(bits, impl=jax.random.key_impl(key)) if typed else bits


#: runs per chunk by backend (``default_chunk_size``). CPU: 64, where a study's state stays in cache (wider chunks
#: slowed the engine's bias IMMs); each chunk costs a dispatch, so very cheap runs want a larger ``chunk_size``. An
#: accelerator wants wide batches (bounded by memory: outputs and scratch are per run).
CHUNK_BY_PLATFORM = {"cpu": 64, "gpu": 16384, "cuda": 16384, "rocm": 16384, "tpu": 16384}
#: the smallest default chunk per device: a smaller study is padded up to it, so its calibration, main runs and a
#: test's few runs share one program (on a CPU a closed loop's compilation costs far more than its padded runs)
MIN_CHUNK = 64


def default_chunk_size(devices: list | None = None) -> int:
    """Runs per chunk for the devices' backend (``CHUNK_BY_PLATFORM``), times their count."""
    devices = devices or jax.local_devices()
    return CHUNK_BY_PLATFORM.get(devices[0].platform, 1024) * len(devices)


def monte_carlo(
    run_one: Callable[[jax.Array, Any], Any],
    key: jax.Array,
    num_runs: int,
    per_run: Any = None,
    *,
    chunk_size: int | None = None,
    devices: list | None = None,
    progress: bool | ProgressFn = False,
    batched: bool = False,
    reduce: Any = None,
    summary: Callable[[Any, jax.Array], Any] | None = None,
    shared: Any = None,
    label: str = "monte carlo",
) -> Any:
    """Evaluate ``run_one`` over ``num_runs`` runs; return outputs stacked over runs.

    Args:
      run_one: pure function ``(key, per_run_slice) -> pytree``; keep its output small (metrics, not histories).
      key: PRNG key; run i gets ``jax.random.split(key, num_runs)[i]``.
      num_runs: number of runs.
      per_run: pytree whose leaves have leading axis ``num_runs`` (or ``None``); the same on every process.
      chunk_size: runs per compiled call (memory bound), rounded up to a multiple of the device count. ``None``:
        ``default_chunk_size(devices)``, or for a smaller study the next power of two, at least ``MIN_CHUNK`` per
        device (few program shapes whatever ``num_runs``; on a CPU one, compiling costs more than padded runs).
      devices: devices to shard the run axis over (default: all devices of all processes after
        ``jaxfdi.distributed.initialize``, else the local ones).
      progress: ``True`` for a line on stderr, or a callable ``(done, total, seconds)``.
      batched: ``run_one`` takes a whole chunk, ``(keys (B,), per_run (B, ...)) -> outputs (B, ...)`` (e.g.
        ``run_filter`` of a ``kalman_filter`` with a model per run, the batch kernel), instead of ``vmap``.
      reduce: a ``streaming.Reducer``: fold each chunk's outputs into its state on the host and return the state
        (merged across processes) instead of the stacked outputs.
      summary: ``(outputs (B, ...), weight (B,)) -> (kept, totals)``: ``kept`` the per-run outputs to return (e.g.
        less the histories summed), ``totals`` additive over runs (``weight`` 1 for a run, 0 for the last chunk's
        padding); computed on the device in the chunk's program, summed over chunks (and processes).
      shared: pytree every run reads whole (``run_one(key, per_run_slice, shared)``): program arguments, not
        constants, so studies differing only in these numbers (thresholds, transition matrices) share one program.
      label: what the progress display and the compilation message call this study.

    Returns:
      ``run_one``'s output pytree with NumPy leaves stacked along a leading run axis ``(num_runs, ...)``, in run
      order; with ``summary``, ``(kept, totals)`` (``kept`` stacked likewise, ``totals`` summed over runs, NumPy);
      with ``reduce``, the reducer's final state (merged across processes) instead.
    """
    checks.check_callable("run_one", run_one, "a function (key, per_run_slice) -> outputs")
    num_runs = checks.check_int("num_runs", num_runs, 1, meaning="a positive number of runs")
    if chunk_size is not None:
        chunk_size = checks.check_int(
            "chunk_size", chunk_size, 1, meaning="a positive number of runs per call"
        )
    if not is_key(key):
        raise TypeError(
            f"key: expected a PRNG key (jax.random.key(seed)), got {checks.received(key)}"
        )
    if not (progress is None or isinstance(progress, bool) or callable(progress)):
        raise TypeError(
            f"progress: expected True/False or a callable (done, total, seconds), got "
            f"{checks.received(progress)}"
        )
    if reduce is not None and not all(
        callable(getattr(reduce, name, None)) for name in ("init", "update", "merge")
    ):
        raise TypeError(
            f"reduce: expected a Reducer(init, update, merge) such as streaming.detection_reducer(...), "
            f"got {checks.received(reduce)}"
        )
    if summary is not None:
        checks.check_callable("summary", summary, "a function (outputs, weight) -> additive pytree")
        if reduce is not None:
            raise ValueError("summary: expected None with reduce (one way to fold the outputs)")
    sizes = _num_runs_of(per_run)
    if sizes and sizes != {num_runs}:
        raise ValueError(
            f"per_run: every leaf needs leading axis num_runs = {num_runs}, got leading sizes {sorted(sizes)}"
        )
    devices, multiprocess, chunk, sharding, compiled, shared = _plan(
        run_one, num_runs, chunk_size, devices, batched, summary, shared
    )
    report = (
        progress_bar(label, "runs") if progress is True else (progress or None)
    )  # a tqdm bar or log lines
    rows = _local_rows(devices, chunk) if multiprocess else slice(0, chunk)

    state = reduce.init() if reduce is not None else None
    outputs, total, pending = [], None, None
    start_time = time.perf_counter()
    done = [0]  # runs reported finished
    running = None  # after the first dispatch: a long chunk is reported while it runs

    def finish(chunk_result):
        """Wait for a dispatched chunk, fold it in, report it (the pipeline's tail)."""
        nonlocal state, total
        result, part, valid, stop = chunk_result
        if reduce is not None:
            host = jax.tree_util.tree_map(_to_host if multiprocess else np.asarray, result)
            state = reduce.update(state, jax.tree_util.tree_map(lambda leaf: leaf[valid], host))
        else:
            jax.block_until_ready(result)
            outputs.append(result)
        if part is not None:
            total = part if total is None else jax.tree_util.tree_map(jnp.add, total, part)
        if report:
            report(stop, num_runs, time.perf_counter() - start_time)
            done[0] = stop
            if running is not None:
                running.touch()

    try:
        for start in range(0, num_runs, chunk):
            stop = min(start + chunk, num_runs)
            index = np.minimum(
                np.arange(start, start + chunk), num_runs - 1
            )  # pad by repeating the last run
            valid = np.arange(start, start + chunk)[rows] < stop
            weight = np.arange(start, start + chunk) < stop
            first = start == 0
            heartbeat = None
            if first and progress:
                programs = _cache_size(compiled)
                if programs == 0:
                    status(f"{label}: compiling")
                    heartbeat = _Heartbeat(f"{label}: still compiling", start_time)
            try:
                if multiprocess:
                    result = _chunk_multiprocess(
                        compiled,
                        sharding,
                        key,
                        index[rows],
                        num_runs,
                        per_run,
                        chunk,
                        valid,
                        shared,
                    )
                else:  # dispatched: the device works on
                    result = compiled(
                        *_chunk_args(key, index, num_runs, per_run, weight, sharding), *shared
                    )
            finally:
                if heartbeat is not None:
                    heartbeat.stop()
            if first and progress and _cache_size(compiled) > programs:
                status(f"{label}: compiled in {time.perf_counter() - start_time:.1f} s")
            if first and report:
                running = _Heartbeat(
                    lambda: f"{label}: running, {done[0]}/{num_runs} runs done", start_time
                )
            result, part = result if summary is not None else (result, None)
            if pending is not None:
                finish(pending)  # the previous chunk, while this one runs
            pending = (result, part, valid, stop)
        finish(pending)
    finally:
        if running is not None:
            running.stop()
    if total is not None:  # the program summed over the global chunk: replicated on every process
        total = jax.tree_util.tree_map(lambda leaf: np.asarray(leaf.addressable_data(0)), total)
    if reduce is not None:
        if multiprocess:
            state = reduce.merge(allgather(state))
        return state
    if multiprocess:
        stacked = _gather_runs([jax.tree_util.tree_map(_to_host, o) for o in outputs], num_runs)
    elif len(outputs) == 1:
        stacked = jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[:num_runs], outputs[0])
    else:  # one transfer of every chunk, joined on the host (no program per number of chunks)
        stacked = jax.tree_util.tree_map(
            lambda *parts: np.concatenate(parts, axis=0)[:num_runs], *jax.device_get(outputs)
        )
    return (stacked, total) if summary is not None else stacked


class _Heartbeat:
    """Logs ``message`` (string or callable) with the seconds since ``start`` from a daemon thread whenever
    ``interval`` s pass without a beat or ``touch()``, until ``stop()``: a long compilation or chunk is never
    silent."""

    def __init__(self, message, start: float, interval: float = 5.0) -> None:
        self._done = threading.Event()
        self._last = time.perf_counter()
        self._thread = threading.Thread(
            target=self._beat, args=(message, start, interval), daemon=True
        )
        self._thread.start()

    def _beat(self, message, start: float, interval: float) -> None:
        while not self._done.wait(min(1.0, interval)):
            now = time.perf_counter()
            if now - self._last >= interval:
                self._last = now
                status(f"{message() if callable(message) else message} ({now - start:.0f} s)")

    def touch(self) -> None:
        self._last = time.perf_counter()

    def stop(self) -> None:
        self._done.set()


def _plan(run_one, num_runs, chunk_size, devices, batched, summary, shared):
    """Devices (multi-process or not), chunk, sharding, compiled chunk program, ``shared`` args of ``monte_carlo``."""
    devices = list(devices or (jax.devices() if jax.process_count() > 1 else jax.local_devices()))
    multiprocess = len({d.process_index for d in devices}) > 1
    if multiprocess:
        devices = sorted(devices, key=lambda d: (d.process_index, d.id))
        per_process = {
            p: sum(d.process_index == p for d in devices)
            for p in {d.process_index for d in devices}
        }
        if len(set(per_process.values())) != 1:
            raise ValueError(
                f"devices: every process needs the same number of devices, got {per_process}"
            )
    n_dev = len(devices)
    if chunk_size is None:
        smallest = max(MIN_CHUNK * n_dev, 1 << max(int(num_runs) - 1, 0).bit_length())
        chunk = min(default_chunk_size(devices), smallest)
    else:
        chunk = min(int(chunk_size), int(num_runs))
    chunk = -(-chunk // n_dev) * n_dev
    sharding = NamedSharding(Mesh(np.array(devices), ("runs",)), PartitionSpec("runs"))
    try:
        compiled = _compiled(run_one, bool(batched), summary, shared is not None)
    except TypeError:  # an unhashable callable object
        compiled = _chunk_program(run_one, bool(batched), summary, shared is not None)
    shared = () if shared is None else (jax.tree_util.tree_map(jnp.asarray, shared),)
    return devices, multiprocess, chunk, sharding, compiled, shared


def _chunk_args(
    key, index: np.ndarray, num_runs: int, per_run: Any, weight: np.ndarray, sharding
) -> tuple:
    """A chunk's keys, per-run data and weights, on the devices (one process)."""
    chunk_keys = run_keys(key, index, num_runs)
    chunk_data = jax.tree_util.tree_map(lambda leaf: _take(leaf, index), per_run)
    return jax.device_put((chunk_keys, chunk_data, weight), sharding)


def _take(leaf: Any, index: np.ndarray) -> Any:
    """Rows ``index`` of a per-run leaf: NumPy stays on host (no program per shape), device data gathered in place."""
    return leaf[index] if isinstance(leaf, jax.Array) else np.asarray(leaf)[index]


def _cache_size(compiled) -> int:
    """How many programs a ``jax.jit`` function holds (0 when it cannot tell)."""
    try:
        return int(compiled._cache_size())
    except (AttributeError, TypeError):
        return 0


def _chunk_program(
    run_one: Callable, batched: bool, summary: Callable | None, with_shared: bool
) -> Callable:
    """``jit`` of one chunk: ``(keys, per_run, weight[, shared]) -> outputs``, or with ``summary``
    ``summary(outputs, weight) = (kept, totals)``."""
    runs = (
        run_one if batched else jax.vmap(run_one, in_axes=(0, 0, None) if with_shared else (0, 0))
    )

    def chunk(keys, data, weight, *shared):
        out = runs(keys, data, *shared)
        return out if summary is None else summary(out, weight)

    return jax.jit(chunk)


@functools.lru_cache(maxsize=64)
def _compiled(
    run_one: Callable, batched: bool, summary: Callable | None, with_shared: bool
) -> Callable:
    """``_chunk_program``, one per ``run_one``: another study with the same function (e.g. its streaming summary
    after its records) reuses the compiled executables."""
    return _chunk_program(run_one, batched, summary, with_shared)


def _local_rows(devices: list, chunk: int) -> slice:
    """The chunk rows held by this process's devices (contiguous: the mesh lists devices process by process)."""
    per_device = chunk // len(devices)
    mine = [i for i, d in enumerate(devices) if d.process_index == jax.process_index()]
    if not mine or mine != list(range(mine[0], mine[-1] + 1)):
        raise ValueError("devices: every process needs at least one device in the list")
    return slice(mine[0] * per_device, (mine[-1] + 1) * per_device)


def _chunk_multiprocess(
    compiled, sharding, key, local_index, num_runs, per_run, chunk, local_valid, shared
):
    """One chunk over the global mesh: this process builds only its rows, every process runs the same program
    (dispatched; ``_to_host`` takes this process's rows)."""
    local_keys = run_keys(key, local_index, num_runs)
    local_data = jax.tree_util.tree_map(lambda leaf: np.asarray(leaf)[local_index], per_run)

    def global_array(local):
        return jax.make_array_from_process_local_data(
            sharding, local, (chunk,) + tuple(np.shape(local)[1:])
        )

    return compiled(
        global_array(local_keys),
        jax.tree_util.tree_map(global_array, local_data),
        global_array(np.asarray(local_valid)),
        *shared,
    )


def _to_host(array: jax.Array) -> np.ndarray:
    """This process's rows of a global array, as NumPy."""
    shards = sorted(array.addressable_shards, key=lambda shard: shard.index[0].start or 0)
    return np.concatenate([np.asarray(shard.data) for shard in shards], axis=0)


def _gather_runs(outputs: list, num_runs: int) -> Any:
    """One all-gather of every process's rows of every chunk, put back in run order."""
    local = jax.tree_util.tree_map(
        lambda *parts: np.stack(parts), *outputs
    )  # (chunks, local rows, ...)
    everyone = allgather(local)  # [process](chunks, rows, ...)

    def order(*per_process):
        stacked = np.stack(per_process, axis=1)  # (chunks, processes, rows, ...)
        return stacked.reshape((-1,) + stacked.shape[3:])[:num_runs]

    return jax.tree_util.tree_map(order, *everyone)
