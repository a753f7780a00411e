"""Study results as data: a tidy pandas DataFrame, and the HTML table a notebook shows.

pandas (imported on first use; the ``plots`` extra) is what notebook users already sort, filter, plot and join with.
A study's rows (``result.rows``, its file's JSON-ready dicts) become the frame's rows by two rules:

* a field holding a dict of dicts (``{"MM": {...}, "IMM": {...}}``) becomes one row per entry, its key in a column named
  by the field's singular (``methods`` -> ``method``); so do the fields a study names as ``methods`` (one dict per
  method), the field's name in the ``method`` column;
* any other dict flattens into ``field.key`` columns; a list stays one cell, NumPy scalars as Python numbers (a CSV cell
  reads ``[1.5, 0.0]``, as in the JSON).

Each run rate (``RUN_RATES``) of a row that counts its runs gets its two-sided 95 % Clopper-Pearson interval
(``rate_interval``) in ``<rate>_low``, ``<rate>_high`` over the healthy runs ``n = runs - unhealthy_runs`` (the study's
``unhealthy`` column); NaN where rate times ``n`` is not a count (another denominator), ``n`` is unknown, or no rate.
"""

from __future__ import annotations

import html
import math
from typing import Any

import numpy as np

from jaxfdi._studies.metrics import rate_interval

#: the per-run rates of ``fault_row`` whose intervals the frame adds
RUN_RATES = (
    "detection_rate",
    "missed_detection_rate",
    "isolation_rate",
    "false_alarm_rate",
    "pre_onset_alarm_rate",
)


def _plain(value: Any) -> Any:
    """``value`` with NumPy scalars as Python numbers, inside lists and tuples too."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def _flat(row: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in row.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = _plain(value)
    return out


def tidy_rows(rows: list[dict], methods: tuple[str, ...] = ()) -> list[dict]:
    """The study's rows as flat dicts, one per table row (module docstring). A key of an inner dict that is also a key
    of its row is a ``ValueError``: neither may be lost."""
    out = []
    for row in rows:
        per_method = {k: row[k] for k in methods if isinstance(row.get(k), dict)}
        if per_method:
            row = {**{k: v for k, v in row.items() if k not in per_method}, "methods": per_method}
        nested = next(
            (
                k
                for k, v in row.items()
                if isinstance(v, dict) and v and all(isinstance(x, dict) for x in v.values())
            ),
            None,
        )
        if nested is None:
            out.append(_flat(row))
            continue
        column = nested[:-1] if nested.endswith("s") else nested
        rest = {k: v for k, v in row.items() if k != nested}
        for name, inner in row[nested].items():
            clash = (set(inner) | {column}) & set(rest)
            if clash:
                raise ValueError(
                    f"rows: the entries of {nested!r} repeat the row's keys {sorted(clash)}"
                )
            out.extend(tidy_rows([{**rest, column: name, **inner}]))
    return out


def _interval(rate: Any, n: Any, level: float) -> tuple[float, float]:
    nan = float("nan")
    if (
        rate is None
        or n is None
        or isinstance(rate, (str, bool))
        or not math.isfinite(rate)
        or not n > 0
    ):
        return nan, nan
    count = rate * n
    if abs(count - round(count)) > 1e-6:
        return nan, nan
    return rate_interval(int(round(count)), int(n), level)


def results_frame(
    rows: list[dict],
    level: float = 0.95,
    methods: tuple[str, ...] = (),
    unhealthy: str = "unhealthy_runs",
):
    """A study's rows as a pandas DataFrame: one row per table row (``tidy_rows``), with the ``level`` Clopper-Pearson
    interval of each run rate beside it over ``runs`` less the ``unhealthy`` column (module docstring).

    Returns:
      ``pandas.DataFrame``; ``None`` fields are NaN, the columns in the order first seen.
    """
    import pandas as pd

    flat = tidy_rows(rows, methods)
    frame = pd.DataFrame.from_records(flat, columns=list(dict.fromkeys(k for r in flat for k in r)))
    if "runs" not in frame:
        return frame
    for rate in (r for r in RUN_RATES if r in frame):
        bounds = []
        for row in flat:
            known = unhealthy in row or not any(k.startswith("unhealthy") for k in row)
            n = (
                row["runs"] - (row.get(unhealthy) or 0)
                if known and row.get("runs") is not None
                else None
            )
            bounds.append(_interval(row.get(rate), n, level))
        at = frame.columns.get_loc(rate) + 1
        frame.insert(at, f"{rate}_low", [b[0] for b in bounds])
        frame.insert(at + 1, f"{rate}_high", [b[1] for b in bounds])
    return frame


def results_html(frame, config: dict | None = None, group: str = "section") -> str:
    """The HTML a notebook renders for a study's frame: one table per value of the ``group`` column where the frame has
    one (only the columns each uses), numbers to four significant digits, ``-`` for none."""
    group = group if group in frame else None
    parts = []
    if config:
        runs = config.get("runs", config.get("runs_per_fault", config.get("runs_per_case")))
        seed = config.get("seed")
        if runs is not None:
            parts.append(
                f"<p>{html.escape(str(runs))} runs per case, seed {html.escape(str(seed))}; "
                "rates with their 95 % Clopper-Pearson intervals (<code>_low</code>, <code>_high</code>)</p>"
            )
    groups = (
        [(None, frame)]
        if group is None
        else [(name, part) for name, part in frame.groupby(group, sort=False, dropna=False)]
    )
    for name, part in groups:
        if name is not None:
            parts.append(f"<h4>{html.escape(str(name))}</h4>")
            part = part.drop(columns=[group])
        parts.append(
            part.dropna(axis=1, how="all").to_html(
                index=False, na_rep="-", float_format="{:.4g}".format
            )
        )
    return "\n".join(parts)


def study_result(
    cls=None,
    *,
    group: str = "section",
    methods: tuple[str, ...] = (),
    unhealthy: str = "unhealthy_runs",
):
    """Class decorator for a study's result (a NamedTuple with ``config``, ``rows``): ``to_frame(level=0.95)``
    (``results_frame`` with the study's ``methods`` and ``unhealthy``); ``_repr_html_``, HTML tables per ``group``
    value; a one-line ``repr`` (the per-run arrays are too long to print).

    Returns:
      The class, with the three methods attached.
    """

    def attach(cls):
        def to_frame(self, level: float = 0.95):
            """The study's table as a pandas DataFrame: one row per method and case, every run rate beside its ``level``
            Clopper-Pearson interval (``_low``, ``_high``)."""
            return results_frame(self.rows, level, methods, unhealthy)

        def _repr_html_(self) -> str:
            return results_html(self.to_frame(), self.config, group)

        def __repr__(self) -> str:
            return f"{type(self).__name__}({len(self.rows)} rows; .to_frame() for the table, .table() for text)"

        cls.to_frame, cls._repr_html_, cls.__repr__ = to_frame, _repr_html_, __repr__
        return cls

    return attach if cls is None else attach(cls)
