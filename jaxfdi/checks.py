"""The one validation layer: trace-time errors that name the argument, what was expected and what was received.

Every public constructor and function checks its arguments with these helpers, in Python while JAX traces, so a
wrong argument is reported once, before compilation, under the caller's name:

- ``TypeError`` for the wrong *kind* of value: a float for a count, a complex or string array for real numbers, a
  non-callable for a function;
- ``ValueError`` for a wrong value of the right kind: shape, non-finite entry, indefinite covariance, probability
  outside (0, 1), index out of range, unknown name.

Shape and dtype checks always run; value checks (finiteness, symmetry, definiteness, ranges) only on concrete arrays
(under ``jit``/``vmap`` filters report numerical trouble through ``healthy``).

Tolerances (``eps`` of the array's float dtype), relative so that a covariance of 1e-24 is as valid as one of 1e24:

- symmetry: ``max |X - X^T| <= 1e3 eps max |X|``;
- PSD: ``lambda_min >= -100 n eps lambda_max`` (eigenvalues of the symmetric part, in float64); positive definite:
  ``lambda_min > 100 n eps lambda_max`` and ``lambda_max > 0``.

A plant, detector or study of one's own checks its arguments with the same functions, so that its errors read alike.
Constants: ``MAX_SEED`` the largest seed a study or the CLI takes, 2**32 - 1 (its comment says why).
"""

from __future__ import annotations

__all__ = [
    "MAX_SEED",
    "received",
    "shape_of",
    "check_real",
    "check_finite",
    "check_shape",
    "check_matrix",
    "check_square",
    "check_covariance",
    "check_probability",
    "check_int",
    "check_int_array",
    "check_scalar",
    "check_positive",
    "check_angle",
    "check_index",
    "check_choice",
    "check_flag",
    "check_callable",
    "check_same_length",
]

import numbers
from typing import Any, Iterable

import jax
import jax.numpy as jnp
import numpy as np

#: how many entries of a received value an error message prints
_SHOWN = 6
#: the largest seed a study or the CLI takes: ``jax.random.key`` gives distinct keys for 0 .. 2**63 - 1 with float64
#: enabled, else takes seeds modulo 2**32; 0 .. 2**32 - 1 is the same key either way and leaves room for derived
#: seeds (seed + 1, + 2, + 1000, + 1_000_003).
MAX_SEED = 2**32 - 1


def concrete(x: Any) -> np.ndarray | None:
    """The value of ``x`` as NumPy if it is known at trace time, else ``None``."""
    if isinstance(x, jax.core.Tracer):
        return None
    try:
        return np.asarray(x)
    except Exception:  # pragma: no cover - defensive: unusual array-likes
        return None


def shape_of(x: Any) -> tuple[int, ...]:
    """The shape of any array-like (a Python scalar: ``()``).

    Returns:
      tuple of int, ``np.shape(x)``.
    """
    return tuple(np.shape(x))


def _fmt(shape: tuple) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def received(value: Any) -> str:
    """A short description of a received value for an error message.

    Returns:
      str: ``repr`` of a scalar, or the shape, dtype and first entries of an array (a traced one: its shape and dtype).
    """
    if isinstance(value, jax.core.Tracer):
        return f"a traced array of shape {_fmt(value.shape)} and dtype {value.dtype}"
    if isinstance(value, (str, bool, numbers.Number)) or value is None:
        return repr(value)
    try:
        array = np.asarray(value)
    except Exception:
        return f"a {type(value).__name__}"
    if array.dtype == object:
        return f"a {type(value).__name__}"
    if array.ndim == 0:
        return repr(array.item())
    flat = array.ravel()
    head = np.array2string(flat[:_SHOWN], precision=6, separator=", ")
    more = ", ..." if flat.size > _SHOWN else ""
    return f"shape {_fmt(array.shape)} {array.dtype} {head[:-1]}{more}]"


def _kind(x: Any) -> str:
    """The dtype kind of ``x`` ('f', 'i', 'u', 'b', 'c', 'U', 'O', ...)."""
    dtype = getattr(x, "dtype", None)
    if dtype is None:
        if isinstance(x, bool):
            return "b"
        if isinstance(x, numbers.Integral):
            return "i"
        if isinstance(x, numbers.Real):
            return "f"
        if isinstance(x, numbers.Complex):
            return "c"
        try:
            dtype = np.asarray(x).dtype
        except Exception:
            return "O"
    return np.dtype(dtype).kind


def check_real(name: str, x: Any, meaning: str = "real numbers") -> None:
    """Raise ``TypeError`` unless ``x`` holds real numbers (float, int or bool).

    Returns:
      None; raises ``TypeError`` naming ``name``, ``meaning`` and what was received.
    """
    kind = _kind(x)
    if kind not in "fiub":
        raise TypeError(f"{name}: expected {meaning}, got {received(x)} (dtype kind {kind!r})")


def check_finite(name: str, x: Any, meaning: str = "") -> None:
    """Raise ``ValueError`` if concrete ``x`` has a NaN or infinite entry.

    Returns:
      None; raises ``ValueError`` naming ``name`` and the first non-finite index (traced ``x`` passes).
    """
    value = concrete(x)
    if value is None or value.dtype.kind not in "fc":
        return
    if not np.all(np.isfinite(value)):
        where = tuple(int(i) for i in np.argwhere(~np.isfinite(value))[0]) if value.ndim else ()
        at = f" at index {where}" if where else ""
        extra = f" ({meaning})" if meaning else ""
        raise ValueError(
            f"{name}: expected finite values{extra}, got {received(value)} (non-finite{at})"
        )


def check_inputs(us: Any) -> jax.Array:
    """``us`` as a (T, nu) array of real inputs, finite when concrete (trace time)."""
    check_real("us", us, "real inputs of shape (T, nu)")
    check_finite("us", us, "inputs")
    us = jnp.asarray(us)
    if us.ndim != 2:
        raise ValueError(f"us: expected shape (T, nu), got {tuple(us.shape)}")
    return us


def float_dtype(*arrays: Any):
    """The float dtype of a result: the promoted dtype of the float arguments, or JAX's default float when all are
    integers (an integer initial mean must not make the covariance integer)."""
    floats = [a for a in arrays if _kind(a) == "f"]
    if not floats:
        return jnp.result_type(float)
    return jnp.result_type(*floats)


def check_shape(name: str, x: Any, expected: tuple, meaning: str = "") -> None:
    """Raise if ``x`` does not have shape ``expected`` (``None`` entries match anything).

    Returns:
      None; raises ``ValueError`` naming ``name``, the expected shape (``*`` for ``None``) and the received one.
    """
    shape = shape_of(x)
    ok = len(shape) == len(expected) and all(e is None or e == s for e, s in zip(expected, shape))
    if not ok:
        exp = _fmt(tuple("*" if e is None else e for e in expected))
        extra = f" ({meaning})" if meaning else ""
        raise ValueError(f"{name}: expected shape {exp}{extra}, got {_fmt(shape)}")


def check_matrix(name: str, x: Any, expected: tuple, meaning: str = "") -> None:
    """A real, finite (when concrete) array of shape ``expected``.

    Returns:
      None; raises ``TypeError`` (not real) or ``ValueError`` (shape, non-finite entry).
    """
    check_real(name, x, f"a real matrix{f' ({meaning})' if meaning else ''}")
    check_shape(name, x, expected, meaning)
    check_finite(name, x, meaning)


def check_square(name: str, x: Any, size: int | None = None, meaning: str = "") -> int:
    """A real, finite (when concrete) square matrix, of ``size`` rows when given.

    Returns:
      int, its size ``n``; raises ``TypeError`` or ``ValueError`` otherwise.
    """
    shape = shape_of(x)
    check_real(name, x, f"a real square matrix{f' ({meaning})' if meaning else ''}")
    if len(shape) != 2 or shape[0] != shape[1] or (size is not None and shape[0] != size):
        n = size if size is not None else "n"
        extra = f" ({meaning})" if meaning else ""
        raise ValueError(
            f"{name}: expected a square matrix of shape ({n}, {n}){extra}, got {_fmt(shape)}"
        )
    check_finite(name, x, meaning)
    return shape[0]


def _eps(value: np.ndarray) -> float:
    return float(np.finfo(value.dtype if value.dtype.kind == "f" else np.float64).eps)


def check_covariance(name: str, x: Any, size: int | None = None, definite: bool = False) -> int:
    """A covariance: real, square, finite, symmetric, PSD (``definite``: positive definite) by the eigenvalue test
    with the module doc's tolerances.

    Returns:
      int, its size ``n``; raises ``ValueError`` naming the failed property (value checks only when concrete).
    """
    n = check_square(name, x, size, "a covariance")
    value = concrete(x)
    if value is None or n == 0:
        return n
    eps = _eps(value)
    scale = float(np.max(np.abs(value)))
    if np.max(np.abs(value - value.T)) > 1e3 * eps * scale:
        raise ValueError(
            f"{name}: covariance of shape ({n}, {n}) must be symmetric, got {received(value)} "
            f"(max |X - X^T| = {np.max(np.abs(value - value.T)):.3g})"
        )
    if np.any(np.diagonal(value) < 0):
        raise ValueError(
            f"{name}: covariance of shape ({n}, {n}) has a negative variance on its diagonal, got "
            f"{received(np.diagonal(value))}"
        )
    eig = np.linalg.eigvalsh(0.5 * (value + value.T).astype(np.float64))
    top = max(float(eig[-1]), 0.0)
    tol = 100.0 * n * eps * top
    if definite and not (eig[0] > tol and top > 0):
        raise ValueError(
            f"{name}: expected a positive definite covariance of shape ({n}, {n}), got smallest "
            f"eigenvalue {eig[0]:.3g} (largest {eig[-1]:.3g}; tolerance {tol:.3g})"
        )
    if eig[0] < -tol:
        raise ValueError(
            f"{name}: expected a positive semi-definite covariance of shape ({n}, {n}), got smallest "
            f"eigenvalue {eig[0]:.3g} (largest {eig[-1]:.3g}; tolerance {tol:.3g})"
        )
    return n


def check_probability(name: str, p: Any, open_interval: bool = True) -> None:
    """A real probability (scalar or array) in (0, 1) (``open_interval``) or [0, 1].

    Returns:
      None; raises ``TypeError`` or ``ValueError`` naming the interval (traced ``p`` passes the value check).
    """
    check_real(name, p, "a probability")
    value = concrete(p)
    if value is None:
        return
    bad = (value <= 0) | (value >= 1) if open_interval else (value < 0) | (value > 1)
    if np.any(bad) or not np.all(np.isfinite(value)):
        rng = "(0, 1)" if open_interval else "[0, 1]"
        raise ValueError(f"{name}: expected a probability in {rng}, got {received(value)}")


def check_int(
    name: str,
    value: Any,
    minimum: int | None = None,
    maximum: int | None = None,
    meaning: str = "an integer",
) -> int:
    """A concrete integer count or index (Python/NumPy integer or 0-d integer array; not a bool, not an integral
    float) in ``[minimum, maximum]``.

    Returns:
      int, the value; raises ``TypeError`` (not a concrete integer) or ``ValueError`` (out of range).
    """
    kind = _kind(value)
    if isinstance(value, jax.core.Tracer):
        raise TypeError(
            f"{name}: expected {meaning} known at trace time (a Python int), got {received(value)}"
        )
    if kind not in "iu" or np.ndim(value) != 0:
        raise TypeError(f"{name}: expected {meaning} (a Python int), got {received(value)}")
    number = int(value)
    if (minimum is not None and number < minimum) or (maximum is not None and number > maximum):
        low = "-inf" if minimum is None else minimum
        high = "inf" if maximum is None else maximum
        raise ValueError(f"{name}: expected {meaning} in [{low}, {high}], got {number}")
    return number


def check_int_array(
    name: str,
    value: Any,
    minimum: int | None = None,
    maximum: int | None = None,
    meaning: str = "integers",
) -> None:
    """Integer entries (any shape; floats refused), within ``[minimum, maximum]`` when concrete (traced integer
    arrays pass: checked by whoever made them).

    Returns:
      None; raises ``TypeError`` (not integers) or ``ValueError`` (an entry out of range).
    """
    kind = _kind(value)
    if kind not in "iu":
        raise TypeError(f"{name}: expected {meaning}, got {received(value)}")
    array = concrete(value)
    if array is None or array.size == 0:
        return
    if (minimum is not None and array.min() < minimum) or (
        maximum is not None and array.max() > maximum
    ):
        low = "-inf" if minimum is None else minimum
        high = "inf" if maximum is None else maximum
        raise ValueError(f"{name}: expected {meaning} in [{low}, {high}], got {received(array)}")


def check_scalar(
    name: str,
    value: Any,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    meaning: str = "a real scalar",
) -> None:
    """A real finite scalar in ``low .. high`` (open or closed ends) when concrete; a traced scalar passes.

    Returns:
      None; raises ``TypeError`` (not real) or ``ValueError`` (not a scalar, not finite, outside the interval).
    """
    check_real(name, value, meaning)
    if np.ndim(value) != 0:
        raise ValueError(
            f"{name}: expected {meaning} (shape ()), got shape {_fmt(shape_of(value))}"
        )
    array = concrete(value)
    if array is None:
        return
    number = float(array)
    below = low is not None and (number <= low if low_open else number < low)
    above = high is not None and (number >= high if high_open else number > high)
    if not np.isfinite(number) or below or above:
        left = "(" if low_open else "["
        right = ")" if high_open else "]"
        interval = (
            f"{left}{'-inf' if low is None else low}, {'inf' if high is None else high}{right}"
        )
        raise ValueError(
            f"{name}: expected {meaning}, finite, in {interval}, got {received(value)}"
        )


def check_angle(name: str, value: Any, low: float, high: float, meaning: str = "an angle") -> None:
    """Real angles in radians within ``[low, high]`` when concrete (a traced value passes); the error says the unit and,
    for a value that reads as degrees, what it is in radians (a 5 deg mask passed as 5, a latitude of 37.57).

    Returns:
      None; raises ``TypeError`` (not real) or ``ValueError`` (not finite, or outside the interval).
    """
    check_real(name, value, meaning)
    array = concrete(value)
    if array is None or array.size == 0:
        return
    array = np.asarray(array, float)
    bad = ~np.isfinite(array) | (array < low) | (array > high)
    if np.any(bad):
        first = float(array[bad].flat[0])
        hint = (
            f" ({first:g} deg would be {np.deg2rad(first):.4g} rad)"
            if np.isfinite(first) and np.abs(np.deg2rad(first)) <= max(abs(low), abs(high))
            else ""
        )
        raise ValueError(
            f"{name}: expected {meaning} in radians, in [{low:.4g}, {high:.4g}], got {received(value)}{hint}"
        )


def check_positive(name: str, value: Any, meaning: str = "a positive real scalar") -> None:
    """``check_scalar`` on ``(0, inf]`` (finite): a positive real scalar.

    Returns:
      None; raises as ``check_scalar``.
    """
    check_scalar(name, value, 0.0, low_open=True, meaning=meaning)


def check_index(name: str, value: Any, size: int, meaning: str = "an index") -> None:
    """Integer index (or array of them) in ``[0, size)`` when concrete.

    Returns:
      None; raises as ``check_int_array``.
    """
    check_int_array(name, value, 0, size - 1, f"{meaning} in range for size {size}")


def check_choice(name: str, value: Any, options: Iterable[Any]) -> None:
    """``value`` is one of ``options`` (listed in the message).

    Returns:
      None; raises ``ValueError`` listing ``options``.
    """
    options = list(options)
    try:
        ok = value in options
    except Exception:
        ok = False
    if not ok:
        raise ValueError(f"{name}: expected one of {options}, got {value!r}")


def check_flag(name: str, value: Any) -> None:
    """``value`` is a Python ``bool`` (a switch between algorithms, decided at trace time).

    Returns:
      None; raises ``TypeError``.
    """
    if not isinstance(value, bool):
        raise TypeError(f"{name}: expected True or False, got {received(value)}")


def check_callable(name: str, value: Any, meaning: str = "a function") -> None:
    """``value`` is callable.

    Returns:
      None; raises ``TypeError`` naming ``meaning``.
    """
    if not callable(value):
        raise TypeError(f"{name}: expected {meaning}, got {received(value)}")


def check_same_length(names: tuple[str, str], a: Any, b: Any) -> None:
    """``a`` and ``b`` have the same leading (time) length ``T``.

    Returns:
      None; raises ``ValueError`` naming both arguments and their lengths.
    """
    la, lb = shape_of(a)[:1], shape_of(b)[:1]
    if la != lb:
        raise ValueError(
            f"{names[0]} and {names[1]}: expected the same number of time steps T along axis 0, "
            f"got {la[0] if la else 'a scalar'} and {lb[0] if lb else 'a scalar'}"
        )
