"""Noncentral chi-square in JAX: CDF, quantile and the noncentrality for a missed-detection probability.

A fault shifts a chi-square statistic of ``k`` dof to the noncentral chi-square with noncentrality ``lambda`` (the
squared shift of the whitened residual), a Poisson mixture of central CDFs (Johnson, Kotz & Balakrishnan 1995,
ch. 29):

``F(x; k, lambda) = sum_j exp(-lambda/2) (lambda/2)^j / j! P(k/2 + j, x/2)``

``P`` the regularised lower incomplete gamma, evaluated once at the window's top and carried down by
``P(a, y) = P(a + 1, y) + y^a e^-y / Gamma(a + 1)`` (positive terms: no cancellation). A fixed window of
``NUM_TERMS`` terms centred on the Poisson mode (jits, vmaps) holds all but a negligible mass (over 9 standard
deviations each side) for ``lambda <= 400``, beyond the protection-level range (``lambda`` < 200 for
``P_fa, P_md >= 1e-9``, up to 30 dof).

RAIM's protection level (Brown & Chin 1992): ``noncentrality_for_missed_detection(threshold, k, p_md)`` solves
``F(threshold; k, lambda) = p_md`` (the bias the test at ``threshold`` misses with probability ``p_md``);
``ncx2_quantile`` inverts in ``x``. Both by fixed-count bisection (the CDF is monotone in each argument).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array
from jax.scipy.special import gammainc, gammaln, ndtri

from jaxfdi import checks

#: terms of the Poisson mixture summed (a window around the mode)
NUM_TERMS = 256
#: bisection steps of the inversions (the bracket shrinks by 2^-ITERATIONS)
ITERATIONS = 80


def _dtype(*values):
    """The arguments' floating dtype (Python numbers are weak: they follow the arrays)."""
    dtype = jnp.result_type(*values)
    return dtype if jnp.issubdtype(dtype, jnp.floating) else jnp.result_type(float)


def ncx2_cdf(x, dof, noncentrality) -> Array:
    """``P(X <= x)`` for ``X ~ ncx2(dof, noncentrality)``; broadcasts its arguments.

    Args:
      x: point(s), >= 0 (negative gives 0).
      dof: degrees of freedom, > 0.
      noncentrality: ``lambda >= 0`` (0 gives the central chi-square).
    """
    dtype = _dtype(x, dof, noncentrality)
    return _cdf(*(jnp.asarray(v, dtype) for v in (x, dof, noncentrality)))


@jax.jit
def _cdf(x, dof, lam):
    dtype = x.dtype
    half = 0.5 * lam
    first = jnp.maximum(jnp.floor(half) - NUM_TERMS // 2, 0.0)
    j = first[..., None] + jnp.arange(NUM_TERMS, dtype=dtype)
    safe_half = jnp.where(half > 0, half, 1.0)[..., None]
    log_weight = jnp.where(j > 0, j * jnp.log(safe_half), 0.0) - half[..., None] - gammaln(j + 1.0)
    log_weight = jnp.where((half[..., None] == 0) & (j > 0), -jnp.inf, log_weight)
    # P(a + j, y) for the window's j from one incomplete gamma at its top, adding the positive terms
    # y^(a+i) e^-y / Gamma(a+i+1) downwards (stable, no cancellation)
    a = 0.5 * dof[..., None] + j
    y = 0.5 * jnp.maximum(x, jnp.finfo(dtype).tiny)[..., None]
    top = gammainc(a[..., -1:], y)
    log_step = a[..., :-1] * jnp.log(y) - y - gammaln(a[..., :-1] + 1.0)
    below_top = jnp.flip(jnp.cumsum(jnp.flip(jnp.exp(log_step), -1), -1), -1)
    lower_gamma = jnp.concatenate([below_top + top, top], axis=-1)
    terms = jnp.exp(log_weight) * lower_gamma
    return jnp.where(x > 0, jnp.sum(terms, axis=-1), 0.0)


def _bisect(increasing, target, low, high):
    """Root of ``increasing(v) = target`` in ``[low, high]`` by ``ITERATIONS`` bisections."""

    def body(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        below = increasing(mid) < target
        return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

    lo, hi = jax.lax.fori_loop(0, ITERATIONS, body, (low, high))
    return 0.5 * (lo + hi)


def ncx2_quantile(p, dof, noncentrality) -> Array:
    """``x`` with ``P(X <= x) = p`` for ``X ~ ncx2(dof, noncentrality)`` (scipy's ``ppf``)."""
    checks.check_probability("p", p)
    dtype = _dtype(p, dof, noncentrality)
    return _quantile(
        *jnp.broadcast_arrays(*(jnp.asarray(v, dtype) for v in (p, dof, noncentrality)))
    )


@jax.jit
def _quantile(p, dof, lam):
    spread = jnp.sqrt(2.0 * (dof + 2.0 * lam))
    z = jnp.abs(ndtri(jnp.minimum(p, 1.0 - p)))
    high = dof + lam + (z + 10.0) * spread + 50.0
    return _bisect(lambda v: _cdf(v, dof, lam), p, jnp.zeros_like(high), high)


def noncentrality_for_missed_detection(threshold, dof, p_md) -> Array:
    """``lambda`` with ``P(ncx2(dof, lambda) <= threshold) = p_md``; 0 when even the central distribution stays
    below ``threshold`` with probability less than ``p_md``. A test at ``threshold`` on a ``dof``-dof chi-square
    misses a fault of noncentrality ``>= lambda`` with probability ``<= p_md`` (Brown & Chin 1992:
    ``p_bias = sigma sqrt(lambda)``).

    Returns:
      ``lambda`` (broadcast over the arguments' shapes).
    """
    checks.check_probability("p_md", p_md)
    dtype = _dtype(threshold, dof, p_md)
    return _noncentrality(
        *jnp.broadcast_arrays(*(jnp.asarray(v, dtype) for v in (threshold, dof, p_md)))
    )


@jax.jit
def _noncentrality(threshold, dof, p_md):
    # F decreases in lambda; bisect on s = sqrt(lambda) with -F increasing
    z = jnp.abs(ndtri(p_md))
    high = jnp.sqrt(jnp.maximum(threshold, 0.0)) + z + 3.0 + jnp.sqrt(dof)
    root = _bisect(lambda s: -_cdf(threshold, dof, s**2), -p_md, jnp.zeros_like(high), high)
    return jnp.where(_cdf(threshold, dof, jnp.zeros_like(threshold)) <= p_md, 0.0, root**2)
