"""A bounded history of a filter's inputs and its replay: a fixed-size ring buffer of the last ``L`` steps in a scan
carry, and a fixed-length scan re-running a filter over it (for detectors restarting their estimator a few steps
before a detection, e.g. Park et al. 2004's hybrid parity-space FDI). Bounded: ``jit``/``vmap`` friendly.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from jaxfdi import checks


class RingBuffer(NamedTuple):
    """The last ``L`` entries of a stream, fixed-size (a pytree: lives in a scan carry); built by
    ``ring_buffer``, appended to by ``push`` and read oldest first by ``ordered``.

    Attributes:
      data: pytree, leaves (L, ...)
      count: () int, entries pushed so far
    """

    data: Any
    count: Array

    @property
    def length(self) -> int:
        return jax.tree_util.tree_leaves(self.data)[0].shape[0]

    def push(self, entry: Any) -> RingBuffer:
        """Append ``entry``, overwriting the oldest once full; returns the new buffer."""
        slot = self.count % self.length
        data = jax.tree_util.tree_map(
            lambda store, leaf: store.at[slot].set(leaf), self.data, entry
        )
        return RingBuffer(data, self.count + 1)

    def ordered(self) -> tuple[Any, Array]:
        """``(entries, valid)``: stored entries oldest first (L, ...) and which slots hold one ((L,)
        bool; fewer than L before the buffer first fills)."""
        L = self.length
        start = jnp.where(self.count >= L, self.count % L, 0)
        index = (start + jnp.arange(L)) % L
        entries = jax.tree_util.tree_map(lambda store: store[index], self.data)
        return entries, jnp.arange(L) < jnp.minimum(self.count, L)


def ring_buffer(length: int, example: Any) -> RingBuffer:
    """An empty buffer of ``length`` entries shaped like ``example``.

    Returns:
      a ``RingBuffer`` of zeros, ``count`` 0.
    """
    length = checks.check_int("length", length, 1, meaning="a positive number of entries")
    data = jax.tree_util.tree_map(
        lambda leaf: jnp.zeros((int(length),) + jnp.shape(leaf), jnp.result_type(leaf)), example
    )
    return RingBuffer(data, jnp.zeros((), jnp.int32))


def replay_filter(
    filt, state: Any, ys: Array, us: Array, valid: Array | None = None
) -> tuple[Any, Any]:
    """Re-run ``filt`` from ``state`` (prior of the first entry) over (L, ...) stored ``ys``, ``us``;
    ``valid == False`` steps keep the state (a fixed-length scan).

    Returns:
      ``(final_state, infos)``: the state after the last entry and the (L, ...) step infos.
    """
    ys, us = jnp.asarray(ys), jnp.asarray(us)
    checks.check_same_length(("ys", "us"), ys, us)
    valid = jnp.ones((ys.shape[0],), bool) if valid is None else jnp.asarray(valid, bool)
    checks.check_shape("valid", valid, (ys.shape[0],), "one flag per stored step")

    def body(s, entry):
        y, u, ok = entry
        new, info = filt.step(s, y, u)
        return jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, s), info

    return jax.lax.scan(body, state, (ys, us, valid))
