"""Counting XLA compilations (the backend compile events of ``jax.monitoring``)."""

import contextlib

import jax

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


@contextlib.contextmanager
def counting_compiles():
    """Yields a list that gets one entry per XLA backend compilation inside the block
    (a program loaded from the persistent cache is not compiled and does not count)."""
    compiles = []

    def listener(event, duration, **_):
        if event == COMPILE_EVENT:
            compiles.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield compiles
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
