"""Protection levels by the slope method and availability against alert limits
(Brown & Chin 1992; Yoo et al. 2010, eqs. 10-11, Table 1).

A bias ``b`` on satellite ``i`` moves the position by ``A[:, i] b``, ``A = (H^T W H)^{-1} H^T W``, and the
noncentrality by ``S_ii b^2 / sigma_i^2`` (``S = P^T P``, whitened). Slopes (eq. 10 times ``sigma``):

``SLOPE_H(i) = sqrt(A_N,i^2 + A_E,i^2) sigma_i / sqrt(S_ii)``, ``SLOPE_V`` with ``|A_D,i|``.

``lambda``: noncentrality missed with probability ``P_md`` at the threshold
(``noncentral_chi2.noncentrality_for_missed_detection``, ``n - u`` dof, ``u`` = 3 + a clock per constellation in view):

``HPL = max_i SLOPE_H(i) sqrt(lambda)``, ``VPL = max_i SLOPE_V(i) sqrt(lambda)`` (eq. 11:
``SLOPE_max sqrt(mu) sigma_pr``), ``MDB_i = sigma_i sqrt(lambda / S_ii)``.

Available when ``HPL <= HAL`` (and ``VPL <= VAL`` where a vertical limit applies); with ``u`` satellites
or fewer there is no test and the levels are infinite. ``ALERT_LIMITS`` (RTCA DO-229 / ICAO Annex 10):
non-precision approach HAL 556 m (the paper's Table 1, accuracy 220 m), terminal 1852 m, en route
3704 m, oceanic 7408 m, LNAV/VNAV 556 m / 50 m, LPV 40 m / 50 m.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._numerics import linalg as _linalg
from jaxfdi.gnss._least_squares import MaskedQR, masked_qr, parity_column_norms, thin_q
from jaxfdi.gnss._positioning import PositionFix
from jaxfdi.gnss._raim import RaimTables, check_tables, whitened

#: (horizontal, vertical) alert limits [m]; inf: no vertical requirement
ALERT_LIMITS = {
    "npa": (556.0, math.inf),
    "terminal": (1852.0, math.inf),
    "enroute": (3704.0, math.inf),
    "oceanic": (7408.0, math.inf),
    "lnav-vnav": (556.0, 50.0),
    "lpv": (40.0, 50.0),
}


class ProtectionLevels(NamedTuple):
    """Slope-method protection levels: slopes per satellite, HPL, VPL and minimum detectable biases.

    Attributes:
      slope_horizontal: (S,) m per sqrt(noncentrality), 0 at unused slots
      slope_vertical: (S,) vertical slope, m per sqrt(noncentrality)
      hpl: () m (inf without a test)
      vpl: () m (inf without a test)
      minimum_detectable_bias: (S,) m (inf at unused or unobservable slots)
      available: () bool: HPL <= HAL and VPL <= VAL
    """

    slope_horizontal: Array
    slope_vertical: Array
    hpl: Array
    vpl: Array
    minimum_detectable_bias: Array
    available: Array


def protection_levels(
    fix: PositionFix,
    tables: RaimTables,
    operation: str | tuple[float, float] = "npa",
    qr: MaskedQR | None = None,
) -> ProtectionLevels:
    """Slopes, HPL, VPL, minimum detectable biases and availability of one fix.

    Args:
      fix: the epoch's least-squares fix (NED geometry, sigmas, used slots).
      tables: ``raim.raim_tables`` (threshold and noncentrality per degrees of freedom).
      operation: a key of ``ALERT_LIMITS`` or ``(HAL, VAL)`` in metres.
      qr: the whitened geometry's ``masked_qr`` when already computed.

    Returns:
      ``ProtectionLevels``: slopes 0 at unused or unobservable slots; ``hpl``, ``vpl`` inf with
      ``n - u <= 0`` dof; ``minimum_detectable_bias`` inf at unused or unobservable slots or without a test.
    """
    if isinstance(operation, str):
        if operation not in ALERT_LIMITS:
            raise ValueError(
                f"operation: expected one of {sorted(ALERT_LIMITS)} or (HAL, VAL), got {operation!r}"
            )
        hal, val = ALERT_LIMITS[operation]
    else:
        limits = checks.concrete(operation)
        if (
            limits is None
            or limits.shape != (2,)
            or limits.dtype.kind not in "fiu"
            or not np.all(limits > 0)
        ):
            raise ValueError(
                f"operation: expected one of {sorted(ALERT_LIMITS)} or (HAL, VAL), two alert limits > 0 "
                f"[m] (inf: none), got {operation!r}"
            )
        hal, val = operation
    check_tables(tables, fix)
    h, _ = whitened(fix)
    qr = masked_qr(h, fix.used) if qr is None else qr
    q1 = thin_q(qr)
    gain = _linalg.solve_upper(qr.r, q1.T)  # (u, S) = (H_w^T H_w)^-1 H_w^T
    root, observable = parity_column_norms(q1, fix.used)  # sqrt(S_ii)
    slope_h = jnp.where(observable, jnp.hypot(gain[0], gain[1]) / root, 0.0)
    slope_v = jnp.where(observable, jnp.abs(gain[2]) / root, 0.0)
    dof = jnp.maximum(qr.num_used - qr.num_pivots, 0)
    lam = tables.noncentrality[jnp.minimum(dof, tables.noncentrality.shape[0] - 1)]
    scale = jnp.where(dof > 0, jnp.sqrt(lam), jnp.inf)
    hpl = jnp.where(dof > 0, jnp.max(slope_h) * scale, jnp.inf)
    vpl = jnp.where(dof > 0, jnp.max(slope_v) * scale, jnp.inf)
    mdb = jnp.where(observable & (dof > 0), fix.sigma * scale / root, jnp.inf)
    return ProtectionLevels(slope_h, slope_v, hpl, vpl, mdb, (hpl <= hal) & (vpl <= val))
