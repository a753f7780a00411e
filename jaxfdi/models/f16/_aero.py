"""The Stevens & Lewis F-16 aerodynamic model from its tables (Stevens & Lewis 2003,
sec. 3.4 and the Fortran of App. A; data after Nguyen et al. 1979, NASA TP-1538).

Coefficients about the reference centre of gravity ``xcg_ref = 0.35 cbar`` (the shift to
the actual c.g. is applied in ``dynamics``), angles in degrees, rates in rad/s::

    CX = CX(alpha, el) + CXq cq               cq  = cbar q / (2 V)
    CY = -0.02 beta + 0.021 ail/20 + 0.086 rdr/30 + b2v (CYr r + CYp p)
    CZ = CZ(alpha) (1 - (beta/57.3)^2) - 0.19 el/25 + CZq cq
    Cl = CL(alpha, |beta|) sgn(beta) + DLDA(alpha, beta) ail/20 + DLDR(alpha, beta) rdr/30 + b2v (Clr r + Clp p)
    Cm = CM(alpha, el) + Cmq cq
    Cn = CN(alpha, |beta|) sgn(beta) + DNDA(alpha, beta) ail/20 + DNDR(alpha, beta) rdr/30 + b2v (Cnr r + Cnp p)

with ``b2v = b / (2 V)`` and the damping derivatives ``CXq ... Cnp`` from ``DAMP(alpha)``. ``sgn(beta)`` is the Fortran
``SIGN(1.0, BETA)`` (+1 at 0), and ``|beta|`` is taken on the same branch, so the derivative at ``beta = 0`` is the
table's slope (``jnp.sign`` would give 0 there and break the linearisation of every symmetric trim).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi.models.f16._tables import AeroTables, interpolate1, interpolate2, segment


class AeroCoefficients(NamedTuple):
    """Body-axis force and moment coefficients (moments about ``xcg_ref``)."""

    CX: Array
    CY: Array
    CZ: Array
    Cl: Array
    Cm: Array
    Cn: Array


def table_coefficients(
    tables: AeroTables,
    alpha_deg: Array,
    beta_deg: Array,
    el: Array,
    ail: Array,
    rdr: Array,
    p: Array,
    q: Array,
    r: Array,
    vt: Array,
    span: Array,
    chord: Array,
) -> AeroCoefficients:
    """Total coefficients of the table model, damping included (module doc)."""
    positive = beta_deg >= 0
    sign = jnp.where(positive, 1.0, -1.0)
    abs_beta = jnp.where(positive, beta_deg, -beta_deg)
    a = segment(alpha_deg, tables.alpha_deg)  # shared by every table
    e = segment(el, tables.elevator_deg)
    b_abs = segment(abs_beta, tables.beta_abs_deg)
    b = segment(beta_deg, tables.beta_deg)
    damp = interpolate1(tables.DAMP, *a)  # (9,)
    dail = ail / tables.ail_norm
    drdr = rdr / tables.rdr_norm
    half_over_v = 0.5 / vt
    b2v = span * half_over_v
    cq = chord * q * half_over_v
    CX = interpolate2(tables.CX, *e, *a) + cq * damp[0]
    CY = (
        tables.cy_beta * beta_deg
        + tables.cy_ail * dail
        + tables.cy_rdr * drdr
        + b2v * (damp[1] * r + damp[2] * p)
    )
    CZ = (
        interpolate1(tables.CZ, *a) * (1.0 - (beta_deg / tables.cz_beta_factor) ** 2)
        + tables.cz_el * el / tables.el_norm
        + cq * damp[3]
    )
    Cl = (
        sign * interpolate2(tables.CL, *b_abs, *a)
        + interpolate2(tables.DLDA, *b, *a) * dail
        + interpolate2(tables.DLDR, *b, *a) * drdr
        + b2v * (damp[4] * r + damp[5] * p)
    )
    Cm = interpolate2(tables.CM, *e, *a) + cq * damp[6]
    Cn = (
        sign * interpolate2(tables.CN, *b_abs, *a)
        + interpolate2(tables.DNDA, *b, *a) * dail
        + interpolate2(tables.DNDR, *b, *a) * drdr
        + b2v * (damp[7] * r + damp[8] * p)
    )
    return AeroCoefficients(CX, CY, CZ, Cl, Cm, Cn)
