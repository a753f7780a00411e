"""Progress displays and log messages.

``progress_bar`` makes a progress hook: a tqdm bar when tqdm is installed (``tqdm.auto``'s widget in a notebook that
has ``ipywidgets``, else a text line: ``tqdm.auto`` without ipywidgets warns), else INFO lines. Messages use the
``logging`` logger ``"jaxfdi"`` (silence: ``logging.getLogger("jaxfdi").setLevel(logging.WARNING)``); the CLI installs a
stderr handler (``configure_logging``) and ``--quiet`` turns bars and INFO messages off.
"""

from __future__ import annotations

import logging
import sys
import time
from typing import Callable

__all__ = ["ProgressFn", "configure_logging", "logger", "progress_bar", "status", "tqdm_available"]

#: a progress hook: ``(done, total, seconds)``
ProgressFn = Callable[[int, int, float], None]

#: the library's logger (messages and, without tqdm, progress lines)
logger = logging.getLogger("jaxfdi")


def tqdm_available() -> bool:
    """Whether tqdm is installed (importing ``tqdm.auto`` here would warn in a notebook without ipywidgets)."""
    try:
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True


def _tqdm_class():
    """``tqdm.auto.tqdm`` where ipywidgets is installed (a notebook gets a widget), else ``tqdm.std.tqdm``."""
    try:
        import ipywidgets  # noqa: F401
    except ImportError:
        from tqdm.std import tqdm
    else:
        from tqdm.auto import tqdm
    return tqdm


class _Bar:
    """A progress hook on a ``tqdm.auto`` bar, created on the first call and closed when ``done >= total``."""

    def __init__(self, description: str, unit: str, **tqdm_options) -> None:
        self.description, self.unit, self.options = description, unit, tqdm_options
        self.bar, self.done = None, 0

    def __call__(
        self, done: int, total: int, seconds: float = 0.0, postfix: str | None = None
    ) -> None:
        if self.bar is None:
            self.bar = _tqdm_class()(
                total=total, desc=self.description, unit=f" {self.unit}", leave=True, **self.options
            )
        if postfix is not None:
            self.bar.set_postfix_str(postfix, refresh=False)
        self.bar.update(max(done - self.done, 0))
        self.done = done
        if done >= total:
            self.close()

    def close(self) -> None:
        """Close the bar (idempotent)."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class _LogLines:
    """A progress hook that logs ``description: done/total unit, seconds`` at INFO at most every ``interval`` seconds,
    and always at the end."""

    def __init__(self, description: str, unit: str, interval: float) -> None:
        self.description, self.unit, self.interval = description, unit, interval
        self.last = -float("inf")

    def __call__(
        self, done: int, total: int, seconds: float = 0.0, postfix: str | None = None
    ) -> None:
        now = time.monotonic()
        if done < total and now - self.last < self.interval:
            return
        self.last = now
        rate = f", {done / seconds:.0f} {self.unit}/s" if seconds > 0 else ""
        extra = f", {postfix}" if postfix else ""
        status(f"{self.description}: {done}/{total} {self.unit}, {seconds:.1f} s{rate}{extra}")

    def close(self) -> None:
        """Nothing to close."""


def status(message: str) -> None:
    """A progress message (what is compiling, what ran): INFO on the ``"jaxfdi"`` logger when it has a handler that
    takes INFO, else (a plain script, a notebook, or ``logging.basicConfig()`` at its default WARNING) one line on
    stderr: a long run is never silent.

    Returns:
      None; it logs or prints ``message``.
    """
    if logger.hasHandlers() and logger.isEnabledFor(logging.INFO):
        logger.info(message)
    else:
        print(message, file=sys.stderr, flush=True)


def progress_bar(
    description: str = "monte carlo",
    unit: str = "runs",
    *,
    interval: float = 5.0,
    use_tqdm: bool | None = None,
    **tqdm_options,
) -> ProgressFn:
    """A progress hook ``(done, total, seconds[, postfix])``.

    Args:
      description: the bar's label.
      unit: what is counted (``"runs"``, ``"steps"``).
      interval: without tqdm, the least time between two log lines [s].
      use_tqdm: ``None`` uses tqdm when installed; ``False`` logs lines instead.
      **tqdm_options: passed to the tqdm bar (e.g. ``file=``, ``disable=``).

    Returns:
      A callable for ``monte_carlo(..., progress=...)``; it has ``close()``.
    """
    if use_tqdm is None:
        use_tqdm = tqdm_available()
    return (
        _Bar(description, unit, **tqdm_options)
        if use_tqdm
        else _LogLines(description, unit, interval)
    )


class _CurrentStderr(logging.StreamHandler):
    """A handler that writes to whatever ``sys.stderr`` is when a message is emitted (a notebook's or a test's capture
    may replace it after the handler is made)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def configure_logging(quiet: bool = False, stream=None) -> logging.Handler:
    """Send the ``"jaxfdi"`` logger's messages to ``stream`` (default stderr) as plain lines; level INFO, or WARNING
    with ``quiet``. Replaces a handler installed by an earlier call; returns the handler."""
    for handler in list(logger.handlers):
        if getattr(handler, "_jaxfdi_cli", False):
            logger.removeHandler(handler)
    handler = logging.StreamHandler(stream) if stream is not None else _CurrentStderr()
    handler.setFormatter(logging.Formatter("%(message)s"))
    handler._jaxfdi_cli = True
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING if quiet else logging.INFO)
    return handler
