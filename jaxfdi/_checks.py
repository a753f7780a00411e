"""Trace-time validation: clear ``ValueError``s that name the argument and the shape.

These run in Python while JAX traces, so a wrong shape is reported once, before any
compilation, with the name the caller used. Value checks (symmetry, ranges) run only on
concrete arrays: under ``jit``/``vmap`` the values are unknown at trace time and the
filters report numerical trouble through their ``healthy`` flag instead.
"""
from __future__ import annotations

from typing import Any

import jax
import numpy as np


def concrete(x: Any) -> np.ndarray | None:
    """The value of ``x`` as NumPy if it is known at trace time, else ``None``."""
    if isinstance(x, jax.core.Tracer):
        return None
    try:
        return np.asarray(x)
    except Exception:  # pragma: no cover - defensive: unusual array-likes
        return None


def shape_of(x: Any) -> tuple[int, ...]:
    return tuple(np.shape(x))


def _fmt(shape: tuple) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def check_shape(name: str, x: Any, expected: tuple, meaning: str = "") -> None:
    """Raise if ``x`` does not have shape ``expected`` (``None`` entries match anything)."""
    shape = shape_of(x)
    ok = len(shape) == len(expected) and all(
        e is None or e == s for e, s in zip(expected, shape)
    )
    if not ok:
        exp = _fmt(tuple("*" if e is None else e for e in expected))
        extra = f" ({meaning})" if meaning else ""
        raise ValueError(f"{name}: expected shape {exp}{extra}, got {_fmt(shape)}")


def check_square(name: str, x: Any, size: int | None = None, meaning: str = "") -> int:
    shape = shape_of(x)
    if len(shape) != 2 or shape[0] != shape[1] or (size is not None and shape[0] != size):
        n = size if size is not None else "n"
        extra = f" ({meaning})" if meaning else ""
        raise ValueError(f"{name}: expected a square matrix of shape ({n}, {n}){extra}, got {_fmt(shape)}")
    return shape[0]


def check_covariance(name: str, x: Any, size: int | None = None) -> int:
    """Square, and (when concrete) symmetric with no negative diagonal."""
    n = check_square(name, x, size, "a covariance")
    value = concrete(x)
    if value is not None:
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{name}: covariance of shape ({n}, {n}) has non-finite entries")
        scale = max(float(np.max(np.abs(value))), np.finfo(value.dtype if value.dtype.kind == "f" else np.float64).tiny)
        tol = 1e3 * np.finfo(value.dtype if value.dtype.kind == "f" else np.float64).eps * scale
        if np.max(np.abs(value - value.T)) > tol:
            raise ValueError(f"{name}: covariance of shape ({n}, {n}) must be symmetric")
        if np.any(np.diagonal(value) < 0):
            raise ValueError(f"{name}: covariance of shape ({n}, {n}) has a negative variance on its diagonal")
    return n


def check_probability(name: str, p: Any, open_interval: bool = True) -> None:
    value = concrete(p)
    if value is None:
        return
    bad = (value <= 0) | (value >= 1) if open_interval else (value < 0) | (value > 1)
    if np.any(bad) or not np.all(np.isfinite(value)):
        rng = "(0, 1)" if open_interval else "[0, 1]"
        raise ValueError(f"{name}: expected a probability in {rng}, got {value}")


def check_same_length(names: tuple[str, str], a: Any, b: Any) -> None:
    la, lb = shape_of(a)[:1], shape_of(b)[:1]
    if la != lb:
        raise ValueError(
            f"{names[0]} and {names[1]}: expected the same number of time steps T along axis 0, "
            f"got {la[0] if la else 'a scalar'} and {lb[0] if lb else 'a scalar'}"
        )
