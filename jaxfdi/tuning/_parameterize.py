"""Unconstrained parameterisations of the quantities a tuner may change.

These maps turn any point of R^d into a valid object and back (``inverse(forward(x)) = x`` up to round-off,
``forward(inverse(p)) = p`` for every valid ``p``):

* ``stochastic_rows(mask)``: row-stochastic ``pi_ij = exp(l_ij) / sum_k exp(l_ik)`` over allowed entries; structural
  zeros (static bool ``mask``) stay exactly 0 with zero gradient (log-space softmax, Bishop 2006 sec. 4.3.4);
* ``log_diagonal()``: ``diag(exp(d))``; ``cholesky_factor()``: ``L L^T``, ``L`` lower triangular with ``exp``
  diagonal (log-Cholesky, Pinheiro & Bates 1996);
* ``positive()``: ``softplus(x)`` (thresholds, noise levels of order one); ``log_scale()``: ``exp(x)`` (positive
  quantities spanning decades, e.g. inflation 1e4, bias walk 1e-12: a step is a relative change);
  ``unit_interval()``: ``sigmoid(x)`` (probability thresholds); ``identity()``: unconstrained reals.

A *parameterisation* is a dict ``name -> Transform``; ``constrain``/``unconstrain`` map whole parameter dicts,
``partition`` splits trainable from frozen entries (static mask). ``save_params`` records transform names and
options, so a file reads back into the same parameterisation.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg


class Transform(NamedTuple):
    """``forward: unconstrained -> constrained``, its ``inverse``, a name and static options (saved with params).

    Attributes:
      forward: ``forward(raw) -> value``, an unconstrained array to the valid parameter
      inverse: ``inverse(value) -> raw``, a valid parameter back to its unconstrained array
      name: str, the transform's key in ``TRANSFORMS`` (what ``save_params`` records)
      options: dict of the static keyword arguments that rebuild it (``TRANSFORMS[name](**options)``), JSON-able
    """

    forward: Callable[[Array], Array]
    inverse: Callable[[Array], Array]
    name: str
    options: dict


def identity() -> Transform:
    """The unconstrained parameterisation: the parameter is its own raw value."""
    return Transform(lambda x: x, lambda p: jnp.asarray(p), "identity", {})


def positive(floor: float = 0.0) -> Transform:
    """``p = floor + softplus(x)``; inverse ``x = log(expm1(p - floor))`` written stably; ``floor`` >= 0, finite.

    Returns:
      ``Transform`` named ``"positive"``, options ``{"floor": floor}``: ``forward`` maps any-shape arrays
      elementwise above ``floor``, ``inverse`` maps them back to raw reals of the same shape.
    """
    checks.check_scalar("floor", floor, 0.0, meaning="a lower bound >= 0")

    def forward(x):
        return floor + jax.nn.softplus(x)

    def inverse(p):
        excess = jnp.asarray(p) - floor
        # log(expm1(e)) = e + log(1 - exp(-e)), exact for large e, finite for small e > 0
        return excess + jnp.log(-jnp.expm1(-excess))

    return Transform(forward, inverse, "positive", {"floor": floor})


def log_scale() -> Transform:
    """``p = exp(x)`` elementwise, any shape; inverse ``log p``; a step ``eta`` scales ``p`` by ``exp(eta)``.

    Returns:
      ``Transform`` named ``"log_scale"`` (no options): ``forward`` maps any-shape arrays to positive ones of the
      same shape, ``inverse`` maps positive arrays back to their logs.
    """
    return Transform(jnp.exp, lambda p: jnp.log(jnp.asarray(p)), "log_scale", {})


def unit_interval() -> Transform:
    """``p = sigmoid(x)`` in (0, 1) (a probability threshold such as ``mu_T``); inverse logit.

    Returns:
      ``Transform`` named ``"unit_interval"`` (no options), elementwise on any shape.
    """

    def inverse(p):
        p = jnp.asarray(p)
        return jnp.log(p) - jnp.log1p(-p)

    return Transform(jax.nn.sigmoid, inverse, "unit_interval", {})


def _log_probability(p: Array) -> Array:
    """``log p``, and ``log(tiny)`` (about -708 in float64) where ``p == 0``: a finite logit softmax maps to ~0."""
    return jnp.where(p > 0, jnp.log(jnp.where(p > 0, p, 1.0)), jnp.log(jnp.finfo(p.dtype).tiny))


def simplex() -> Transform:
    """Probability vector ``p = softmax(x)`` (e.g. an IMM's initial mode probabilities); ``inverse`` returns
    ``log p`` (log-sum-exp 0), ``log(tiny)`` at a zero.

    Returns:
      ``Transform`` named ``"simplex"`` (no options): ``forward`` maps (M,) logits to an (M,) probability vector
      (positive, summing to 1), ``inverse`` the reverse.
    """

    def forward(logits):
        logits = jnp.asarray(logits)
        checks.check_shape("logits", logits, (None,), "(M,) logits of a probability vector")
        return jax.nn.softmax(logits)

    def inverse(p):
        return _log_probability(jnp.asarray(p))

    return Transform(forward, inverse, "simplex", {})


def stochastic_rows(mask: Any = None) -> Transform:
    """Row-stochastic (M, M) matrix from (M, M) logits; ``mask[i, j] = False`` fixes ``pi_ij = 0``; every row needs
    an allowed entry. Row logits are defined up to a constant; ``inverse`` returns ``log pi`` (row log-sum-exp 0), 0
    where the mask forbids, and ``log(tiny)`` (about -708 in float64) at an allowed zero, which ``forward`` maps to
    ~1e-308: it stays zero in training (its gradient vanishes with it); start it small positive to learn it.

    Returns:
      ``Transform`` named ``"stochastic_rows"``, options ``{"mask": mask as nested lists or None}``: ``forward`` maps
      (M, M) logits to a row-stochastic (M, M) matrix (an IMM's transition matrix with its structural zeros).
    """
    if mask is not None and checks.shape_of(mask) and np.asarray(mask).dtype != bool:
        raise TypeError(f"mask: expected a boolean (M, M) array, got {checks.received(mask)}")
    mask_np = None if mask is None else np.asarray(mask, bool)
    if mask_np is not None:
        if mask_np.ndim != 2 or mask_np.shape[0] != mask_np.shape[1]:
            raise ValueError(
                f"mask: expected a square (M, M) boolean array, got shape {mask_np.shape}"
            )
        if not np.all(mask_np.any(axis=1)):
            raise ValueError("mask: expected at least one allowed (True) entry in every row")

    def allowed(shape):
        return jnp.ones(shape, bool) if mask_np is None else jnp.asarray(mask_np)

    def forward(logits):
        logits = jnp.asarray(logits)
        checks.check_shape("logits", logits, (None, None), "square (M, M) transition logits")
        ok = allowed(logits.shape)
        if logits.shape != ok.shape:
            raise ValueError(f"logits: expected shape {ok.shape} (the mask's), got {logits.shape}")
        masked = jnp.where(ok, logits, -jnp.inf)
        return jnp.where(ok, jax.nn.softmax(masked, axis=1), 0.0)

    def inverse(pi):
        pi = jnp.asarray(pi)
        return jnp.where(allowed(pi.shape), _log_probability(pi), 0.0)

    return Transform(
        forward, inverse, "stochastic_rows", {"mask": None if mask_np is None else mask_np.tolist()}
    )


def log_diagonal() -> Transform:
    """Diagonal covariance ``diag(exp(d))`` from (n,) log-variances.

    Returns:
      ``Transform`` named ``"log_diagonal"`` (no options): ``forward`` maps (n,) to an (n, n) diagonal covariance,
      ``inverse`` an (n, n) covariance's diagonal to (n,) log-variances.
    """

    def forward(log_var):
        return jnp.diag(jnp.exp(jnp.asarray(log_var)))

    def inverse(cov):
        return jnp.log(jnp.diagonal(jnp.asarray(cov)))

    return Transform(forward, inverse, "log_diagonal", {})


def cholesky_factor() -> Transform:
    """Full covariance ``L L^T`` from an (n, n) array: strict lower triangle = ``L``'s off-diagonal, diagonal = log
    of ``L``'s diagonal (upper triangle ignored). SPD for every finite input.

    Returns:
      ``Transform`` named ``"cholesky_factor"`` (no options): ``forward`` maps (n, n) raw parameters to the (n, n)
      covariance, ``inverse`` an SPD (n, n) covariance to its log-Cholesky parameters (zero above the diagonal).
    """

    def forward(raw):
        raw = jnp.asarray(raw)
        checks.check_shape("raw", raw, (None, None), "square (n, n) log-Cholesky parameters")
        L = jnp.tril(raw, -1) + jnp.diag(jnp.exp(jnp.diagonal(raw)))
        return _linalg.symmetrize(L @ L.T)

    def inverse(cov):
        L = jnp.linalg.cholesky(jnp.asarray(cov))
        return jnp.tril(L, -1) + jnp.diag(jnp.log(jnp.diagonal(L)))

    return Transform(forward, inverse, "cholesky_factor", {})


TRANSFORMS = {
    "identity": identity,
    "positive": positive,
    "log_scale": log_scale,
    "unit_interval": unit_interval,
    "stochastic_rows": stochastic_rows,
    "simplex": simplex,
    "log_diagonal": log_diagonal,
    "cholesky_factor": cholesky_factor,
}


def from_record(name: str, options: dict) -> Transform:
    """The transform a saved file names (``Transform.name`` and ``.options``)."""
    if name not in TRANSFORMS:
        raise ValueError(
            f"name: expected a transform name, one of {sorted(TRANSFORMS)}, got {name!r}"
        )
    return TRANSFORMS[name](**options)


def constrain(parameterization: dict[str, Transform], raw: dict[str, Array]) -> dict[str, Array]:
    """Unconstrained -> constrained, entry by entry.

    Returns:
      dict with the keys of ``raw``: ``parameterization[name].forward(raw[name])`` (transforms without a raw value
      are left out).

    Raises:
      ValueError: a key of ``raw`` without a transform.
    """
    _check_keys(parameterization, raw, "raw")
    return {k: parameterization[k].forward(v) for k, v in raw.items()}


def unconstrain(parameterization: dict[str, Transform], params: dict[str, Any]) -> dict[str, Array]:
    """Constrained -> unconstrained, entry by entry: the raw start of ``fit`` from hand-set values.

    Returns:
      dict with the keys of ``params``: ``parameterization[name].inverse(params[name])``.

    Raises:
      ValueError: a key of ``params`` without a transform.
    """
    _check_keys(parameterization, params, "params")
    return {k: parameterization[k].inverse(v) for k, v in params.items()}


def partition(raw: dict[str, Array], trainable: set[str] | list[str]) -> tuple[dict, dict]:
    """``(trainable entries, frozen entries)``; ``merge`` puts them back together."""
    unknown = set(trainable) - set(raw)
    if unknown:
        raise ValueError(
            f"trainable: unknown names {sorted(unknown)}; expected names from {sorted(raw)}"
        )
    return {k: v for k, v in raw.items() if k in trainable}, {
        k: v for k, v in raw.items() if k not in trainable
    }


def merge(trained: dict, frozen: dict) -> dict:
    """Trained and frozen raw parameters in one dict (trained values win)."""
    return {**frozen, **trained}


def _check_keys(parameterization: dict, values: dict, name: str) -> None:
    missing = set(values) - set(parameterization)
    if missing:
        raise ValueError(
            f"{name}: no transform for {sorted(missing)}; the parameterisation has {sorted(parameterization)}"
        )
