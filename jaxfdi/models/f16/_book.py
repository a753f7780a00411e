"""The book's trim tables beside ours: Stevens & Lewis (2003), Table 3.6-2 (level flight at sea level, 130-800 ft/s,
xcg = 0.35) and Table 3.6-3 (502 ft/s at sea level: level flight at xcg = 0.35, 0.30, 0.38 and a 0.3 rad/s coordinated
turn at xcg = 0.30), as transcribed in ``f16_stevens_lewis.json`` (``reference_trim_points``).

All twenty cases are trimmed in one vmapped solve (``trim_book_cases``). Printed precision
(``printed_decimals``): Table 3.6-2 three significant digits, at most three decimals (the data file drops
trailing zeros: 0.2 is 0.200, -0.09 is -0.090); Table 3.6-3 the data file's digits.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxfdi.models.f16._dynamics import F16Params
from jaxfdi.models.f16._tables import stevens_lewis_data
from jaxfdi.models.f16._trim import TrimResult, trim_batch, trim_condition

#: where each printed quantity is found: (``"state"`` or ``"control"``, index, to degrees)
QUANTITIES = {
    "thtl": ("control", 0, False),
    "el_deg": ("control", 1, False),
    "ail_deg": ("control", 2, False),
    "rdr_deg": ("control", 3, False),
    "alpha_deg": ("state", 1, True),
    "alpha_rad": ("state", 1, False),
    "beta_rad": ("state", 2, False),
    "phi_rad": ("state", 3, False),
    "theta_rad": ("state", 4, False),
    "P_rad_s": ("state", 6, False),
    "Q_rad_s": ("state", 7, False),
    "R_rad_s": ("state", 8, False),
}
#: the lateral cells of the level cases of Table 3.6-3, zero by symmetry (the book prints its
#: optimiser's residue, |value| < 5e-6)
SYMMETRIC_ZEROS = ("ail_deg", "rdr_deg", "beta_rad")


class BookCase(NamedTuple):
    """One row of Stevens & Lewis Tables 3.6-2/3.6-3: the flight condition and the book's trim.

    Attributes:
      table: "3.6-2" or "3.6-3"
      label: the row's case, as the book names it
      airspeed: ft/s
      turn_rate: rad/s
      xcg: c.g. position, fraction of cbar
      printed: quantity -> the book's value
    """

    table: str
    label: str
    airspeed: float
    turn_rate: float
    xcg: float
    printed: dict


def book_cases() -> list[BookCase]:
    """The 20 cases of the two tables, Table 3.6-2 first (in its row order).

    Returns:
      list of 20 ``BookCase``: 16 level-flight rows of Table 3.6-2, then the 4 rows of Table 3.6-3 (airspeeds in
      ft/s, turn rates in rad/s, the printed values by quantity name).
    """
    ref = stevens_lewis_data()["reference_trim_points"]
    cases = []
    for vt, thtl, alpha, el in ref["table_3_6_2_level_flight_sea_level_xcg_0_35"]["rows"]:
        cases.append(
            BookCase(
                "3.6-2",
                f"level {vt:g} ft/s",
                float(vt),
                0.0,
                0.35,
                {"thtl": thtl, "alpha_deg": alpha, "el_deg": el},
            )
        )
    for row in ref["table_3_6_3_VT_502_ft_s_sea_level"]:
        label = row["case"]
        xcg = float(label.split("xcg=")[1])
        turn = 0.3 if label.startswith("coordinated turn 0.3") else 0.0
        cases.append(
            BookCase(
                "3.6-3", label, 502.0, turn, xcg, {k: v for k, v in row.items() if k != "case"}
            )
        )
    return cases


def trim_book_cases(params: F16Params, cases: list[BookCase] | None = None) -> TrimResult:
    """Every case trimmed at once (``trim_batch``; sea level, no climb); a stacked ``TrimResult`` (N, ...).

    Returns:
      ``TrimResult`` with a leading case axis N = ``len(cases)`` (``state`` (N, 13), ``control`` (N, 4), ...), in
      ``params``' dtype, in the order of ``cases``.
    """
    cases = book_cases() if cases is None else cases
    dtype = params.mass.dtype
    conditions = trim_condition(
        np.array([c.airspeed for c in cases]),
        0.0,
        0.0,
        np.array([c.turn_rate for c in cases]),
        dtype=dtype,
    )
    return trim_batch(params, conditions, jnp.asarray([c.xcg for c in cases], dtype))


def printed_decimals(value: float, table: str) -> int:
    """Decimals the book prints ``value`` with (module doc)."""
    if table == "3.6-2":
        whole = abs(value)
        return 3 if whole < 1.0 else max(0, 3 - len(str(int(whole))))
    text = repr(float(value))
    if "e" in text:
        mantissa, exponent = text.split("e")
        return (len(mantissa.split(".")[1]) if "." in mantissa else 0) - int(exponent)
    return len(text.split(".")[1].rstrip("0")) if "." in text else 0


def ours(result: TrimResult, i: int, quantity: str) -> float:
    where, index, to_degrees = QUANTITIES[quantity]
    value = float((result.state if where == "state" else result.control)[i, index])
    return math.degrees(value) if to_degrees else value


def comparison_rows(result: TrimResult, cases: list[BookCase] | None = None) -> list[dict]:
    """A JSON-ready row per case: printed quantities beside ours, differences in half last printed digits
    (``half_units``), trim residual and flags.

    Returns:
      list of dicts, one per case: ``table``, ``case``, ``airspeed_ft_s``, ``xcg``, ``turn_rate_rad_s``, ``cells``
      (quantity -> ``ours``, ``book``, ``half_unit``, ``half_units``, ``symmetric_zero``), ``max_abs_residual``,
      ``converged``, ``within_limits``, ``steps`` (Python numbers and bools).
    """
    cases = book_cases() if cases is None else cases
    rows = []
    for i, case in enumerate(cases):
        cells = {}
        for quantity, book_value in case.printed.items():
            value = ours(result, i, quantity)
            half = 0.5 * 10.0 ** (-printed_decimals(book_value, case.table))
            symmetric = (
                case.table == "3.6-3" and case.turn_rate == 0.0 and quantity in SYMMETRIC_ZEROS
            )
            cells[quantity] = {
                "ours": value,
                "book": book_value,
                "half_unit": half,
                "half_units": abs(value - book_value) / half,
                "symmetric_zero": symmetric,
            }
        rows.append(
            {
                "table": case.table,
                "case": case.label,
                "airspeed_ft_s": case.airspeed,
                "xcg": case.xcg,
                "turn_rate_rad_s": case.turn_rate,
                "cells": cells,
                "max_abs_residual": float(np.max(np.abs(np.asarray(result.residual[i])))),
                "converged": bool(result.converged[i]),
                "within_limits": bool(result.within_limits[i]),
                "steps": int(result.steps[i]),
            }
        )
    return rows
