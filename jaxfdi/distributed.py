"""Multi-host Monte Carlo on JAX's multi-controller runtime.

Every process runs the same program (SPMD). ``initialize`` connects it to the others (``jax.distributed.initialize``;
gloo collectives on CPU); then ``jax.devices()`` lists every process's devices and ``monte_carlo`` shards each chunk
of runs over all of them (1-D mesh, processes in order), computes on each process only its devices' runs, and
gathers the outputs (or streaming summary) once at the end. Run keys depend only on the global index
(``run_keys``): bit for bit the results of one process with the same runs per device.

Launching: on a cluster, one process per host::

    jaxfdi run STUDY ... --num-processes N --process-id I --coordinator HOST:PORT

or the environment variables ``JAX_COORDINATOR_ADDRESS`` (JAX's own), ``JAXFDI_NUM_PROCESSES``,
``JAXFDI_PROCESS_ID`` (or a SLURM / Open MPI allocation, which ``jax.distributed`` detects). On one machine, N
local processes simulate a cluster::

    python -m jaxfdi.distributed --num-processes 2 -- python my_study.py

starts N copies of the command with those variables set (a free port on 127.0.0.1) and stops all if one fails.
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time
from typing import Any, NamedTuple, Sequence

import numpy as np

__all__ = ["initialize"]

ENV_NUM_PROCESSES = "JAXFDI_NUM_PROCESSES"
ENV_PROCESS_ID = "JAXFDI_PROCESS_ID"
ENV_COORDINATOR = "JAX_COORDINATOR_ADDRESS"


class ProcessInfo(NamedTuple):
    process_id: int
    num_processes: int
    local_devices: int
    global_devices: int


def check_options(
    num_processes: Any = None, process_id: Any = None, coordinator: Any = None
) -> tuple:
    """Check the launcher options (``None``: not given); return ``(num_processes, process_id, coordinator)`` with
    ints; ``ValueError`` naming the option. ``num_processes > 1`` needs all three (options or environment, module
    doc) unless a cluster manager provides them."""

    def as_int(name, value, minimum):
        if value is None:
            return None
        if isinstance(value, bool):
            raise ValueError(f"{name}: expected an integer, got {value!r}")
        try:
            number = int(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected an integer, got {value!r}") from None
        if str(value).strip() != str(number) and not isinstance(value, (int, np.integer)):
            raise ValueError(f"{name}: expected an integer, got {value!r}")
        if number < minimum:
            raise ValueError(f"{name}: expected an integer >= {minimum}, got {number}")
        return number

    num_processes = as_int("--num-processes", num_processes, 1)
    process_id = as_int("--process-id", process_id, 0)
    if num_processes is not None and process_id is not None and process_id >= num_processes:
        raise ValueError(
            f"--process-id: expected an integer in [0, {num_processes - 1}] for --num-processes "
            f"{num_processes}, got {process_id}"
        )
    if coordinator is not None:
        host, _, port = str(coordinator).rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(
                f"--coordinator: expected HOST:PORT (e.g. 10.0.0.1:8476), got {coordinator!r}"
            )
    if (
        num_processes is not None
        and num_processes > 1
        and (process_id is None or coordinator is None)
    ):
        missing = [
            name
            for name, value in (("--process-id", process_id), ("--coordinator", coordinator))
            if value is None
        ]
        raise ValueError(f"--num-processes {num_processes}: also needs {' and '.join(missing)}")
    if num_processes is None and (process_id is not None or coordinator is not None):
        raise ValueError("--process-id / --coordinator: also need --num-processes")
    return num_processes, process_id, coordinator


def resolve_options(num_processes=None, process_id=None, coordinator=None) -> tuple:
    """The options, each taken from the environment when not given (module doc), checked."""
    env = os.environ
    return check_options(
        num_processes if num_processes is not None else env.get(ENV_NUM_PROCESSES),
        process_id if process_id is not None else env.get(ENV_PROCESS_ID),
        coordinator if coordinator is not None else env.get(ENV_COORDINATOR),
    )


def initialize(
    num_processes: int | None = None,
    process_id: int | None = None,
    coordinator: str | None = None,
    timeout_s: int = 300,
) -> ProcessInfo:
    """Join the other processes of a multi-process study; a no-op for one process.

    Call before any other JAX work. Values not given come from the environment (``JAXFDI_NUM_PROCESSES``,
    ``JAXFDI_PROCESS_ID``, ``JAX_COORDINATOR_ADDRESS``); with none, one process. CPU-only hosts use gloo.

    Returns:
      ``ProcessInfo(process_id, num_processes, local_devices, global_devices)``: ``jax.process_index()``,
      ``jax.process_count()`` and the device counts (this process's, all processes'); ``(0, 1, n, n)`` for one.
    """
    import jax

    num_processes, process_id, coordinator = resolve_options(num_processes, process_id, coordinator)
    if num_processes is not None and num_processes > 1:
        _checks_timeout(timeout_s)
        if (
            jax.config.jax_cpu_collectives_implementation != "mpi"
        ):  # CPU collectives across processes
            jax.config.update("jax_cpu_collectives_implementation", "gloo")
        try:
            jax.distributed.initialize(
                coordinator_address=coordinator,
                num_processes=num_processes,
                process_id=process_id,
                initialization_timeout=int(timeout_s),
            )
        except RuntimeError as error:
            raise RuntimeError(
                f"jaxfdi.distributed.initialize: {error} (call it before any other JAX work)"
            ) from None
    return ProcessInfo(
        jax.process_index(), jax.process_count(), jax.local_device_count(), jax.device_count()
    )


def _checks_timeout(timeout_s) -> None:
    if not isinstance(timeout_s, (int, np.integer)) or timeout_s < 1:
        raise ValueError(f"timeout_s: expected a positive integer (seconds), got {timeout_s!r}")


def allgather(tree: Any) -> list:
    """Every process's ``tree`` (NumPy leaves, same shapes everywhere), as a list over processes; integer leaves
    travel as two 32-bit words, so int64 counts survive without ``jax_enable_x64``."""
    import jax
    from jax.experimental import multihost_utils

    leaves, treedef = jax.tree.flatten(tree)
    barrier("allgather")  # gloo gives a late process 30 s; the coordination service waits longer
    packed = []
    for leaf in leaves:
        leaf = np.asarray(leaf)
        if leaf.dtype.kind in "iub":
            wide = leaf.astype(np.int64).view(np.uint64)
            packed.append(
                np.stack(
                    [
                        (wide >> np.uint64(32)).astype(np.uint32),
                        (wide & np.uint64(0xFFFFFFFF)).astype(np.uint32),
                    ]
                )
            )
        else:
            packed.append(leaf)
    gathered = multihost_utils.process_allgather(packed, tiled=False)
    per_process = []
    for p in range(jax.process_count()):
        out = []
        for leaf, got in zip(leaves, gathered):
            got = np.asarray(got)[p]
            if np.asarray(leaf).dtype.kind in "iub":
                wide = (got[0].astype(np.uint64) << np.uint64(32)) | got[1].astype(np.uint64)
                got = wide.view(np.int64).astype(np.asarray(leaf).dtype)
            out.append(got)
        per_process.append(jax.tree.unflatten(treedef, out))
    return per_process


_BARRIERS = [0]


def barrier(name: str, timeout_s: int = 3600) -> None:
    """Wait until every process gets here (coordination-service barrier, up to ``timeout_s``); no-op for one
    process. Called before each cross-process gather: a process still compiling (loaded host) would otherwise make
    gloo's set-up (30 s allowed) fail on the others."""
    import jax

    if jax.process_count() == 1:
        return
    _BARRIERS[0] += 1
    try:
        from jax._src.distributed import global_state

        client = global_state.client
    except ImportError:  # another JAX layout: no barrier, gloo's own wait only
        return
    if client is not None:
        client.wait_at_barrier(f"jaxfdi_{name}_{_BARRIERS[0]}", int(timeout_s * 1000))


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def launch_local(
    command: Sequence[str],
    num_processes: int,
    timeout_s: float = 600.0,
    port: int | None = None,
    env: dict | None = None,
) -> list[subprocess.CompletedProcess]:
    """Run ``num_processes`` copies of ``command`` here as one multi-process study (simulated cluster), each with
    ``JAX_COORDINATOR_ADDRESS=127.0.0.1:PORT``, ``JAXFDI_NUM_PROCESSES`` and its ``JAXFDI_PROCESS_ID``. Waits for
    all; if one fails or ``timeout_s`` passes the others are stopped. Returns the completed processes (output
    captured); raises ``RuntimeError`` with the failing output."""
    num_processes, _, _ = check_options(num_processes, 0, "127.0.0.1:1")
    port = free_port() if port is None else port
    base = dict(os.environ if env is None else env)
    procs = []
    for rank in range(num_processes):
        child_env = dict(
            base,
            **{
                ENV_COORDINATOR: f"127.0.0.1:{port}",
                ENV_NUM_PROCESSES: str(num_processes),
                ENV_PROCESS_ID: str(rank),
            },
        )
        procs.append(
            subprocess.Popen(
                list(command),
                env=child_env,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
        )
    deadline = time.monotonic() + timeout_s
    outputs: dict[int, tuple[str, str]] = {}
    failed = None
    try:
        while len(outputs) < num_processes:
            for rank, proc in enumerate(procs):
                if rank in outputs or proc.poll() is None:
                    continue
                outputs[rank] = proc.communicate()
                if proc.returncode != 0 and failed is None:
                    failed = rank
            if failed is not None or time.monotonic() > deadline:
                break
            time.sleep(0.05)
    finally:
        for rank, proc in enumerate(procs):
            if proc.poll() is None:
                proc.terminate()
                try:
                    outputs[rank] = proc.communicate(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    outputs[rank] = proc.communicate()
    if failed is not None or len(outputs) < num_processes or any(p.returncode != 0 for p in procs):
        rank = (
            failed
            if failed is not None
            else next((r for r, p in enumerate(procs) if p.returncode != 0), 0)
        )
        reason = (
            f"process {rank} exited with {procs[rank].returncode}"
            if failed is not None
            else f"timed out after {timeout_s:.0f} s"
        )
        raise RuntimeError(
            f"launch_local: {reason}; its stderr:\n{outputs.get(rank, ('', ''))[1][-4000:]}"
        )
    return [
        subprocess.CompletedProcess(list(command), p.returncode, *outputs[r])
        for r, p in enumerate(procs)
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m jaxfdi.distributed --num-processes N [--timeout S] -- COMMAND ...``"""
    parser = argparse.ArgumentParser(
        prog="python -m jaxfdi.distributed",
        description="Run N local copies of COMMAND as one multi-process JAX study.",
    )
    parser.add_argument("--num-processes", "-n", type=int, required=True)
    parser.add_argument(
        "--timeout", type=float, default=3600.0, help="seconds before all are stopped"
    )
    parser.add_argument("command", nargs=argparse.REMAINDER, help="the command, after --")
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("expected a command after --")
    try:
        done = launch_local(command, args.num_processes, args.timeout)
    except (RuntimeError, ValueError) as error:
        print(error, file=sys.stderr)
        return 1
    for rank, proc in enumerate(done):
        for line in proc.stdout.splitlines():
            print(f"[{rank}] {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
