"""Masked Householder QR of a tall geometry matrix, with a fixed number of rows.

One row per satellite *slot* (S, e.g. 32 PRNs), of which the ``n`` used count: unused rows are zeroed;
the ``m`` Householder reflections (Golub & Van Loan 2013, alg. 5.1.1) pivot on the first ``m`` used rows
and act on used rows only (the textbook algorithm on the used rows moved to the top, masks instead of a
permutation). For every ``n >= m``, same shapes:

- ``Q1`` (S, m), zero rows at unused slots, ``R`` (m, m): ``H = Q1 R`` on the used rows;
- columns ``m..n-1`` of ``Q`` span the parity space (Brown & Chin 1992): ``P`` (S, S), ``n - m`` valid rows,
  ``P H = 0``, ``P P^T = I``, zero columns at unused slots.

A column zero on every used row (a clock with no satellite in view) takes no pivot: unit row of ``R`` (solution entry
0), zero column of ``Q1``; ``num_pivots`` counts the others, the parity space has ``n - num_pivots`` dimensions.
Element-wise code over the S rows (no LAPACK call per epoch), vectorised by XLA under vmap.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array


class MaskedQR(NamedTuple):
    """Householder factorisation of the used rows of an (S, m) matrix.

    Attributes:
      reflectors: (m, S) unit Householder vectors (zero at unused slots)
      r: (m, m) upper triangular factor
      rank: (S,) int: position of each used slot among the used ones (-1: unused)
      num_used: () int, number of used rows
      pivot: (m,) int: the rank of each column's pivot row (-1: a column zero on the used rows)
      num_pivots: () int, columns with a pivot (the unknowns the used rows carry)
    """

    reflectors: Array
    r: Array
    rank: Array
    num_used: Array
    pivot: Array
    num_pivots: Array


def masked_qr(matrix: Array, used: Array) -> MaskedQR:
    """Householder QR of the rows of ``matrix`` (S, m) where ``used`` (S,) is true.

    Reflection ``j`` pivots on the ``j``-th used slot (module doc). A column zero below its pivot gives an identity
    reflection; with fewer than ``num_pivots`` used rows ``R`` is singular (callers check ``num_used``).
    """
    matrix = jnp.asarray(matrix)
    used = jnp.asarray(used, bool)
    num_cols = matrix.shape[1]
    rank = jnp.where(used, jnp.cumsum(used) - 1, -1)
    work = jnp.where(used[:, None], matrix, 0.0)
    carried = jnp.any(work != 0.0, axis=0)  # (m,) exact: reflections keep a zero column zero
    pivot_of = jnp.cumsum(carried) - 1
    reflectors, rows = [], []
    for j in range(num_cols):
        pivot = carried[j] & (rank == pivot_of[j])
        x = jnp.where(carried[j] & (rank >= pivot_of[j]), work[:, j], 0.0)
        x_pivot = jnp.sum(jnp.where(pivot, x, 0.0))
        alpha = -jnp.where(x_pivot >= 0, 1.0, -1.0) * jnp.linalg.norm(x)
        v = x - jnp.where(pivot, alpha, 0.0)
        v_norm = jnp.linalg.norm(v)
        v = jnp.where(v_norm > 0, v / jnp.where(v_norm > 0, v_norm, 1.0), 0.0)
        work = work - 2.0 * v[:, None] * (v @ work)[None, :]
        reflectors.append(v)
        unit = (jnp.arange(num_cols) == j).astype(work.dtype)
        rows.append(
            jnp.where(carried[j], jnp.sum(jnp.where(pivot[:, None], work, 0.0), axis=0), unit)
        )
    r = jnp.triu(jnp.stack(rows))
    pivots = jnp.where(carried, pivot_of, -1)
    return MaskedQR(jnp.stack(reflectors), r, rank, jnp.sum(used), pivots, jnp.sum(carried))


def _apply_q(qr: MaskedQR, columns: Array) -> Array:
    """``Q @ columns`` for (S, k) columns: the reflections in reverse order."""
    for v in qr.reflectors[::-1]:
        columns = columns - 2.0 * v[:, None] * (v @ columns)[None, :]
    return columns


def apply_qt(qr: MaskedQR, vector: Array) -> Array:
    """``Q^T y`` for (S,) ``y`` in slot order: ``Q1^T y`` at the m pivot slots (``leading``), the parity
    vector at the other used slots, zero at unused ones."""
    work = jnp.where(qr.rank >= 0, jnp.asarray(vector), 0.0)
    for v in qr.reflectors:
        work = work - 2.0 * v * (v @ work)
    return work


def leading(qr: MaskedQR, rotated: Array) -> Array:
    """(m,) the pivot slots' entries of ``apply_qt``'s result (``Q1^T y``), in column order
    (0 for a column without a pivot)."""
    return jnp.sum(jnp.where(_pivot_units(qr), rotated[:, None], 0.0), axis=0)


def _pivot_units(qr: MaskedQR) -> Array:
    """(S, m) bool: slot ``s`` is column ``j``'s pivot."""
    return (qr.rank[:, None] == qr.pivot[None, :]) & (qr.pivot[None, :] >= 0)


def thin_q(qr: MaskedQR) -> Array:
    """(S, m) ``Q1`` (zero rows at unused slots, a zero column for a column without a
    pivot): ``Q`` applied to the pivots' unit vectors."""
    return _apply_q(qr, _pivot_units(qr).astype(qr.r.dtype))


def parity_rows(qr: MaskedQR) -> tuple[Array, Array]:
    """``(P, valid)``: P (S, S), the orthonormal parity matrix of the used rows in its
    ``n - num_pivots`` rows ``valid`` ((S,) bool); the other rows are zero."""
    index = jnp.arange(qr.reflectors.shape[1])
    units = (qr.rank[:, None] == index[None, :]).astype(qr.r.dtype)  # (S, S)
    complement = _apply_q(qr, units).T
    valid = (index >= qr.num_pivots) & (index < qr.num_used)
    return jnp.where(valid[:, None], complement, 0.0), valid


def parity_column_norms(q1: Array, used: Array) -> tuple[Array, Array]:
    """``(norm, observable)``: ``||P[:, j]|| = sqrt(S_jj)``, ``S = P^T P = I - Q1 Q1^T`` (from ``thin_q``);
    ``observable``: used slots with ``S_jj > 1e-9`` (a satellite alone on its clock has 0); ``norm`` is 1
    elsewhere (safe divisor)."""
    diag = jnp.where(used, 1.0 - jnp.sum(q1**2, axis=1), 0.0)
    observable = used & (diag > 1e-9)
    return jnp.sqrt(jnp.where(observable, diag, 1.0)), observable
