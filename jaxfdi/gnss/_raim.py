"""Parity-space RAIM: detection, isolation (Brown & Chin 1992; Yoo et al. 2010, eqs. 5-9).

Linearised at the least-squares fix, ``y = H x + eps`` (``H`` n x u: position and ``u - 3`` clocks, one per
constellation with a used satellite; ``u = 4`` for GPS). Whitened QR ``W^(1/2) H = Q R`` (``W = diag(1/sigma_i^2)``);
the last ``n - u`` columns of ``Q`` give ``P`` ((n - u) x n): ``P H_w = 0``, ``P P^T = I``, ``p = P y_w = P eps_w``.
Fault-free ``p ~ N(0, I)``: ``TS_D = p^T p`` is chi-square with ``n - u`` dof (weighted SSE, Walter & Enge 1995; equal
sigmas: the paper's ``||p||^2 / sigma^2``); the sensors' parity space (``detection.parity``, ``parity_statistic``) on
the used slots. A second clock costs a dof (higher threshold and protection level) wherever it has a satellite.

- **Threshold** ``chi2_threshold(n - 4, P_fa)`` (``rule="chi2"``); ``rule="paper"``: eq. 8 of Yoo et al.
  (2010), ``sqrt(2 ln(1/r) sigma^2 / (n - 4))``, a bound on the RMS parity ``sqrt(p^T p / (n - 4))`` (units
  agree): on ``TS_D`` ``2 ln(1/P_fa)`` for any ``n``, exact for 2 dof only, conservative for 1, above
  ``P_fa`` from 3 (``paper_threshold``; tested).
- **Isolation** (eq. 9): ``TS_j = p . P[:, j] / ||P[:, j]||``, the largest ``|TS_j|`` faulty; ``P^T p = S y_w``,
  ``S = P^T P = I - Q1 Q1^T``: from the thin ``Q1`` without ``P`` (``parity_matrix`` forms it for the paper's equations
  and tests). Needs ``n >= u + 2`` (with ``u + 1`` every column of ``P`` is parallel to ``p``).
- **Exclusion**: re-solve without the isolated satellite (``integrity.monitor_epoch``).

One entry per satellite slot (S); unused slots masked, never dropped: one program for any number visible.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi.detection import chi2_threshold, noncentrality_for_missed_detection, parity_statistic
from jaxfdi.gnss._least_squares import (
    MaskedQR,
    apply_qt,
    masked_qr,
    parity_column_norms,
    parity_rows,
    thin_q,
)
from jaxfdi.gnss._positioning import PositionFix

#: Brown & Chin (1992), RTCA DO-208 for non-precision approach: P_fa = 1/15000 per test
DEFAULT_PFA = 1.0 / 15000.0
#: missed-detection probability of the protection level (Brown & Chin 1992)
DEFAULT_PMD = 1e-3
RULES = ("chi2", "paper")


class RaimTables(NamedTuple):
    """Per degrees of freedom ``k = 0..S-4``: the threshold on ``TS_D`` and the
    noncentrality ``lambda`` missed with probability ``P_md`` (entry 0: no test).

    Attributes:
      threshold: (S - 3,) threshold on TS_D per degrees of freedom
      noncentrality: (S - 3,) noncentrality missed with probability P_md, per degrees of freedom
    """

    threshold: Array
    noncentrality: Array


class ParityCheck(NamedTuple):
    """Detection and isolation of one epoch.

    Attributes:
      statistic: () TS_D = p^T p (whitened), 0 with fewer than u + 1 satellites
      dof: () int, n - u (0: no test)
      threshold: () on TS_D (inf when dof == 0)
      alarm: () bool, TS_D above the threshold
      isolation: (S,) TS_j (0 at unused slots)
      isolated: () int, slot with the largest |TS_j| (-1: none; needs n >= 6)
      healthy: () bool: finite statistic
    """

    statistic: Array
    dof: Array
    threshold: Array
    alarm: Array
    isolation: Array
    isolated: Array
    healthy: Array


def paper_threshold(num_visible, pfa, sigma) -> Array:
    """Eq. 8 of Yoo et al. (2010): ``sqrt(2 ln(1/pfa) sigma^2 / (n - 4))`` [m], a bound on the RMS
    parity ``sqrt(p^T p / (n - 4))`` (NaN for ``n <= 4``)."""
    checks.check_probability("pfa", pfa)
    checks.check_real("sigma", sigma, "a pseudorange standard deviation [m]")
    value = checks.concrete(sigma)
    if value is not None and not np.all(value > 0):
        raise ValueError(
            f"sigma: expected a standard deviation > 0 [m], got {checks.received(value)}"
        )
    dof = jnp.asarray(num_visible) - 4.0
    return jnp.where(
        dof > 0,
        jnp.sqrt(
            2.0
            * jnp.log(1.0 / jnp.asarray(pfa))
            * jnp.asarray(sigma) ** 2
            / jnp.where(dof > 0, dof, 1.0)
        ),
        jnp.nan,
    )


def raim_tables(
    num_slots: int,
    pfa: float = DEFAULT_PFA,
    pmd: float = DEFAULT_PMD,
    rule: str = "chi2",
    dtype=None,
) -> RaimTables:
    """Thresholds on ``TS_D`` and protection-level noncentralities for ``k = 0..S-4``.

    Args:
      num_slots: S, the number of satellite slots.
      pfa: false-alarm probability per test; pmd: missed-detection probability.
      rule: "chi2" (``chi2_threshold(k, pfa)``) or "paper" (eq. 8: ``2 ln(1/pfa)``).

    Returns:
      ``RaimTables``: (S - 3,) ``threshold`` and ``noncentrality`` per degrees of freedom (entry 0: no test), what
      ``parity_check``, ``protection_levels`` and ``monitor_epochs`` take as ``tables``.
    """
    if rule not in RULES:
        raise ValueError(f"rule: expected one of {list(RULES)}, got {rule!r}")
    num_slots = checks.check_int(
        "num_slots", num_slots, 5, meaning="a number of satellite slots (at least 5)"
    )
    checks.check_probability("pfa", pfa)
    checks.check_probability("pmd", pmd)
    dtype = dtype or jnp.result_type(float)
    # computed for a multiple of 32 slots and cut: every receiver of up to 32 (64, ...) slots
    # shares one compiled program of the special functions (entries are elementwise)
    dof = jnp.arange(1, -(-int(num_slots) // 32) * 32 - 3, dtype=dtype)
    if rule == "chi2":
        threshold = chi2_threshold(dof, jnp.asarray(pfa, dtype))
    else:
        threshold = jnp.full(dof.shape, 2.0 * np.log(1.0 / pfa), dtype)
    lam = noncentrality_for_missed_detection(threshold, dof, jnp.asarray(pmd, dtype))
    inf = jnp.full((1,), jnp.inf, dtype)
    keep = int(num_slots) - 4
    return RaimTables(
        jnp.concatenate([inf, threshold[:keep]]),
        jnp.concatenate([jnp.full((1,), jnp.nan, dtype), lam[:keep]]),
    )


def unknowns(fix: PositionFix) -> int:
    """The fix's geometry columns: 3 position, then one per clock (trace time; >= 4). An epoch's ``u``
    counts only clocks with a used satellite (``MaskedQR.num_pivots``)."""
    shape = checks.shape_of(fix.geometry)
    if len(shape) != 2 or shape[1] < 4:
        raise ValueError(
            f"fix.geometry: expected (S, 3 + clocks) with at least one clock column, got shape {shape}"
        )
    return shape[1]


def check_tables(tables: RaimTables, fix: PositionFix) -> None:
    """Trace time: ``tables`` must cover every dof (``raim_tables`` of >= S slots); a smaller one would
    silently clamp ``n - u``, giving too small a threshold and protection level."""
    slots = checks.shape_of(fix.used)[0]
    size = checks.shape_of(tables.threshold)[0]
    unknowns(fix)
    most = slots - 4  # every used satellite on one clock
    if size < most + 1:
        raise ValueError(
            f"tables: built for {size + 3} satellite slots (raim_tables({size + 3})), but the fix has "
            f"{slots}: up to {most} degrees of freedom need raim_tables({most + 4}) or more"
        )


def whitened(fix: PositionFix) -> tuple[Array, Array]:
    """``(H_w, y_w)``: geometry and residuals divided by sigma, zero at unused slots."""
    h = jnp.where(fix.used[:, None], fix.geometry / fix.sigma[:, None], 0.0)
    return h, jnp.where(fix.used, fix.residuals / fix.sigma, 0.0)


def parity_matrix(fix: PositionFix) -> tuple[Array, Array]:
    """``(P, valid)``: explicit parity matrix ((S - u), S) from the whitened QR (``valid``: the ``n - u`` rows)."""
    h, _ = whitened(fix)
    return parity_rows(masked_qr(h, fix.used))


def parity_check(fix: PositionFix, tables: RaimTables, qr: MaskedQR | None = None) -> ParityCheck:
    """Detection statistic, threshold and isolation statistics of one fix (module doc).

    Returns:
      ``ParityCheck``: ``TS_D`` (0 when ``n <= u``), dof ``n - u`` (clipped at 0), threshold ``tables.threshold[dof]``,
      ``alarm = TS_D > threshold``, (S,) ``TS_j``, int32 ``isolated`` (-1 when ``n < u + 2``), ``healthy``.
    """
    check_tables(tables, fix)
    h, y = whitened(fix)
    qr = masked_qr(h, fix.used) if qr is None else qr
    q1 = thin_q(qr)
    rotated = apply_qt(qr, y)  # parity vector at used non-pivot slots
    num, u = qr.num_used, qr.num_pivots
    dof = jnp.maximum(num - u, 0)
    statistic = jnp.where(dof > 0, parity_statistic(rotated, qr.rank >= u), 0.0)
    projected = y - q1 @ (q1.T @ y)  # S y_w = P^T p
    norm, observable = parity_column_norms(q1, fix.used)  # ||P[:, j]||
    isolation = jnp.where(observable, projected / norm, 0.0)
    threshold = tables.threshold[jnp.minimum(dof, tables.threshold.shape[0] - 1)]
    isolated = jnp.where(num >= u + 2, jnp.argmax(jnp.abs(isolation)), -1).astype(jnp.int32)
    return ParityCheck(
        statistic,
        dof.astype(jnp.int32),
        threshold,
        statistic > threshold,
        isolation,
        isolated,
        jnp.isfinite(statistic),
    )
