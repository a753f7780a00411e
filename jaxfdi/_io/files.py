"""Results files: each written completely or not at all, a study's files published together.

Guarantees (POSIX, one file system):

- ``atomic_write`` / ``write_json``: written to a temporary name in the same folder, then ``os.replace``d onto the
  name (atomic): readers see the old or the new file, never a part. The temporary file is removed on any exception,
  ``KeyboardInterrupt`` included. Permissions of a new file, ``0o666 & ~umask`` (``mkstemp`` alone: 0600).
- ``study_output(out)``: a study writes into ``out/.jaxfdi-tmp-*``; on return every file is ``os.replace``d into
  ``out`` (same relative path), JSON last, SIGINT/SIGTERM/SIGHUP held back during the moves; on raise (error,
  Ctrl-C, SIGTERM turned into an exception by the caller) the temporary folder and any folder it created are
  removed: ``out`` is left as it was.

Not atomic: several files cannot be replaced in one step on POSIX (only a folder rename can; the layout is
``out/engine.json``, ``out/engine-*.png``). The moves take microseconds, but SIGKILL during them leaves some new
files beside old ones (never a partial file; the JSON, moved last, is new only if every other file is). A signal
during the moves acts after them (the study is then complete in ``out``). SIGKILL during the study leaves its
``.jaxfdi-tmp-*`` folder behind, never a file under a result name. Nothing is fsynced: no durability across a
power cut.

Provenance: every JSON object from ``write_json`` gets a ``"provenance"`` entry (``provenance()``); the CLI names
command line and seed with ``recording(argv, seed)``, and its ``.npz`` files carry the same record.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import math
import os
import secrets
import shlex
import shutil
import signal
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

from jaxfdi._version import __version__

#: prefix of a study's temporary folder inside its output folder
TEMP_PREFIX = ".jaxfdi-tmp-"
#: signals held back while files are published or a temporary folder is removed
_HELD = tuple(
    s for s in (getattr(signal, n, None) for n in ("SIGINT", "SIGTERM", "SIGHUP")) if s is not None
)


def current_umask() -> int:
    """The process umask (from ``/proc/self/status`` where there is one: read without changing it)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The permissions of a newly created file: ``0o666 & ~umask``."""
    return 0o666 & ~current_umask()


def save_figures(figures: Mapping[str, Any], folder: str | Path) -> list[Path]:
    """Write each figure of ``figures`` (file name -> ``matplotlib.figure.Figure``, e.g. a study's ``plot_*``
    captioned by ``plotting.caption_figure``) as a PNG at its own ``dpi`` into ``folder``, each atomically
    (``atomic_write``).

    Returns:
      The ``pathlib.Path`` s written, in order.
    """

    def png(fig):
        # savefig's default 'figure' resolution is the one the figure was created with, not fig.dpi
        return lambda tmp: fig.savefig(tmp, format="png", dpi=fig.dpi)

    return [atomic_write(Path(folder) / name, png(fig)) for name, fig in figures.items()]


def atomic_write(path: str | Path, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp_path)`` then rename onto ``path`` (same folder, so atomic)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _strict(value: Any) -> Any:
    """NaN/inf -> None (JSON null), recursively, so the file is standard JSON."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value


#: the command line and seed of the CLI command being run (``recording``); None outside it
_RECORDING: dict | None = None


@contextlib.contextmanager
def recording(argv: list[str] | None, seed: int | None) -> Iterator[None]:
    """Within this block ``provenance()`` names the command line ``jaxfdi <argv...>`` (``argv`` None:
    ``sys.argv[1:]``) and ``seed``; the CLI wraps each command in it."""
    global _RECORDING
    previous = _RECORDING
    _RECORDING = {"argv": ["jaxfdi", *(sys.argv[1:] if argv is None else argv)], "seed": seed}
    try:
        yield
    finally:
        _RECORDING = previous


def provenance(seed: int | None = None) -> dict:
    """How a result was made: a JSON-ready dict with ``jaxfdi``, ``jax``, ``jaxlib``, ``numpy`` and ``python``
    versions, ``backend`` (``jax.default_backend()``), ``device_kind`` and ``device_count`` (local), ``x64``
    (``jax_enable_x64``), ``command`` (shell-quoted), ``seed`` (the argument, else ``recording``'s, else None) and
    ``created`` (UTC, ISO 8601)."""
    import jax
    import jaxlib
    import numpy

    active = _RECORDING or {"argv": list(sys.argv), "seed": None}
    devices = jax.local_devices()
    return {
        "jaxfdi": __version__,
        "jax": jax.__version__,
        "jaxlib": getattr(jaxlib, "__version__", None) or jaxlib.version.__version__,
        "numpy": numpy.__version__,
        "python": sys.version.split()[0],
        "backend": jax.default_backend(),
        "device_kind": devices[0].device_kind if devices else None,
        "device_count": len(devices),
        "x64": bool(jax.config.jax_enable_x64),
        "command": shlex.join(str(a) for a in active["argv"]),
        "seed": active["seed"] if seed is None else seed,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def with_provenance(data: Any) -> Any:
    """``data`` (a dict) with a ``"provenance"`` entry added (kept if present); anything else unchanged."""
    if isinstance(data, dict) and "provenance" not in data:
        return {**data, "provenance": provenance()}
    return data


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as strict JSON (NaN and other undefined numbers become null); a dict gets its
    ``"provenance"`` entry (``with_provenance``)."""
    data = with_provenance(data)

    def write(tmp: str) -> None:
        with open(tmp, "w") as fh:
            json.dump(_strict(data), fh, indent=2, allow_nan=False)
            fh.write("\n")

    return atomic_write(path, write)


def check_output_dir(out: str | Path, name: str = "out") -> None:
    """Raise ``ValueError`` (``"<name>: expected ..., got ..."``) unless ``out`` can be a study's output folder: a
    writable folder, or a missing path below one (``study_output`` creates it). Writability is tested with a probe
    file (``os.access`` says yes to root whatever the permissions); nothing else is created."""
    out = Path(out)
    base = out
    while not base.exists():
        if base.is_symlink():
            raise ValueError(
                f"{name}: expected a folder, got {str(out)!r} ({str(base)!r} is a broken link)"
            )
        if base.parent == base:
            break
        base = base.parent
    if not base.is_dir():
        where = "a file" if base == out else f"below the file {str(base)!r}"
        raise ValueError(f"{name}: expected a folder, got {str(out)!r}, which is {where}")
    try:
        fd, probe = tempfile.mkstemp(prefix=".jaxfdi-probe-", dir=base)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        where = "" if base == out else f" (to be created in {str(base)!r})"
        raise ValueError(
            f"{name}: expected a writable folder, got {str(out)!r}{where}: {e.strerror or e}"
        ) from None


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold SIGINT/SIGTERM/SIGHUP (delivered on exit) in the main thread, so nothing is cut in half; else a no-op."""
    if not _HELD or threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _publish(tmp: Path, out: Path) -> list[Path]:
    """Move every file under ``tmp`` to its place under ``out``, JSON last; a folder target fails before any move."""
    files = sorted(
        (p for p in tmp.rglob("*") if not p.is_dir()), key=lambda p: (p.suffix == ".json", str(p))
    )
    targets = [out / p.relative_to(tmp) for p in files]
    clash = [str(t) for t in targets if t.is_dir() and not t.is_symlink()]
    if clash:
        raise IsADirectoryError(f"cannot write the study's files: {clash} are folders")
    mode = file_mode()
    for source, target in zip(files, targets):
        os.chmod(source, mode)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(source, target)
    return targets


@contextlib.contextmanager
def study_output(out: str | Path) -> Iterator[Path]:
    """A temporary folder inside ``out`` for a study's files, published together (module docstring).

    ``with study_output("results") as folder:`` write into ``folder``; on normal exit the files move into
    ``results`` (created if needed; JSON last, signals held back); on an exception (``KeyboardInterrupt`` included)
    nothing moves and the temporary folder and folders this call created are removed: ``out`` is as it was.
    """
    out = Path(out)
    created = []
    missing = out
    while not missing.exists():
        created.append(missing)
        missing = missing.parent
    tmp = None
    try:
        with _signals_held():
            out.mkdir(parents=True, exist_ok=True)
            # named before it exists: the OS mask holds signals back in this thread only; one delivered to another
            # thread (XLA's) still raises at the next bytecode, which could fall between mkdtemp's mkdir and the
            # assignment and leave the folder unknown to the clean-up
            tmp = out / f"{TEMP_PREFIX}{secrets.token_hex(8)}"
            tmp.mkdir(mode=0o700)
        yield tmp
    except BaseException:
        with _signals_held():
            _remove(tmp, created)
        raise
    with _signals_held():
        try:
            _publish(tmp, out)
        except BaseException:
            _remove(tmp, created)  # a folder that received a file before the failure stays
            raise
        shutil.rmtree(tmp, ignore_errors=True)


def _remove(tmp: Path | None, created: list[Path]) -> None:
    """The temporary folder, and the folders ``study_output`` created if still empty. A Python-level interrupt on
    its way (``cli._signals_raise`` re-delivers a dropped one 10 ms later; ``_signals_held`` blocks only OS
    signals) landing mid-removal is held until the removal is done, then raised: the folder never stays behind."""
    interrupted = None
    for _ in range(3):
        try:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            for folder in created:  # innermost first
                with contextlib.suppress(OSError):
                    folder.rmdir()
            break
        except BaseException as error:  # re-raised below, once the folders are gone
            interrupted = error
    if interrupted is not None:
        raise interrupted
