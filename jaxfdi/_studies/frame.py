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

from jaxfdi._studies.metrics import rate_bounds

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
    frame.attrs["row_columns"] = [tuple(r) for r in flat]  # each row's own order, for text_table
    if "runs" not in frame:
        return frame
    for rate in (r for r in RUN_RATES if r in frame and f"{r}_low" not in frame):  # not given
        bounds = []
        for row in flat:
            known = unhealthy in row or not any(k.startswith("unhealthy") for k in row)
            n = (
                row["runs"] - (row.get(unhealthy) or 0)
                if known and row.get("runs") is not None
                else None
            )
            bounds.append(rate_bounds(row.get(rate), n, level))
        at = frame.columns.get_loc(rate) + 1
        frame.insert(at, f"{rate}_low", [b[0] for b in bounds])
        frame.insert(at + 1, f"{rate}_high", [b[1] for b in bounds])
    return frame


def _display_limits(part) -> dict:
    """``to_html``'s row and column limits from pandas' ``display.max_rows``/``min_rows``/``max_columns``, as a
    notebook shows a long ``DataFrame`` (past ``max_rows`` rows, the first and last ``min_rows`` / 2)."""
    import pandas as pd

    max_rows, min_rows = pd.get_option("display.max_rows"), pd.get_option("display.min_rows")
    rows = None if not max_rows or len(part) <= max_rows else (min_rows or max_rows)
    return {"max_rows": rows, "max_cols": pd.get_option("display.max_columns") or None}


def results_html(frame, config: dict | None = None, group: str = "section") -> str:
    """The HTML a notebook renders for a study's frame: one table per value of the ``group`` column where the frame has
    one (only the columns each uses), numbers to four significant digits, ``-`` for none; each table within pandas'
    ``display.max_rows`` and ``display.max_columns``."""
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
        part = part.dropna(axis=1, how="all")
        limits = _display_limits(part)
        parts.append(
            part.to_html(
                index=False,
                na_rep="-",
                float_format="{:.4g}".format,
                show_dimensions=bool(
                    limits["max_rows"] or (limits["max_cols"] or 1e9) < part.shape[1]
                ),
                **limits,
            )
        )
    return "\n".join(parts)


def _text_cell(value, digits: int) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if isinstance(value, (float, np.floating)):
        # a count in a column with gaps (pandas makes it floats) prints as the count
        if float(value).is_integer() and abs(value) < 1e15:
            return str(int(value))
        return f"{value:.{digits}g}"
    return str(value)


def text_table(frame, group: str = "section", width: int = 110, digits: int = 4) -> str:
    """A study's frame as fixed-width text (what the CLI prints): a block per value of the ``group`` column (its name
    as a heading) with only the columns it uses; a rate and its interval as one cell ``r [low, high]``; numbers to
    ``digits`` significant digits, ``-`` for none. A block wider than ``width`` characters is printed transposed: a
    line per column, a column per row (headed by the block's first column).

    Returns:
      str, the blocks separated by blank lines.
    """
    group = group if group in frame else None
    parts = (
        [(None, frame)]
        if group is None
        else [
            (name, part.drop(columns=[group]))
            for name, part in frame.groupby(group, sort=False, dropna=False)
        ]
    )
    own = frame.attrs.get("row_columns")
    blocks = []
    for name, part in parts:
        part = part.dropna(axis=1, how="all")
        if own is not None and len(own) == len(frame):  # the rows' own column order
            seen = dict.fromkeys(k for i in part.index for k in own[frame.index.get_loc(i)])
            order = [k for k in seen if k in part]
            for k in [c for c in part.columns if c not in seen]:  # intervals: after their rate
                base = k.rsplit("_", 1)[0]
                order.insert(
                    order.index(base) + 1 + k.endswith("_high") if base in order else len(order), k
                )
            part = part[order]
        records = part.to_dict("records")
        columns = []  # (header, cells)
        for column in part.columns:
            if column.endswith(("_low", "_high")) and column.rsplit("_", 1)[0] in part:
                continue
            cells = [_text_cell(r[column], digits) for r in records]
            if f"{column}_low" in part and f"{column}_high" in part:
                rate = column.endswith("rate") or "_rate_" in column  # in [0, 1]: two decimals
                bound = (lambda v: f"{v:.2f}") if rate else (lambda v: _text_cell(v, digits))
                cells = [
                    c
                    if c == "-" or _text_cell(r[f"{column}_low"], 2) == "-"
                    else f"{c} [{bound(r[f'{column}_low'])}, {bound(r[f'{column}_high'])}]"
                    for c, r in zip(cells, records)
                ]
            columns.append((str(column), cells))
        lines = [] if name is None else [str(name)]
        widths = [max(len(h), *(len(c) for c in cells)) for h, cells in columns]
        if sum(widths) + 2 * len(widths) <= width or len(records) == 0:
            lines.append("  ".join(f"{h:>{w}}" for (h, _), w in zip(columns, widths)))
            lines += [
                "  ".join(f"{cells[i]:>{w}}" for (_, cells), w in zip(columns, widths))
                for i in range(len(records))
            ]
        else:  # transposed
            (first, heads), rest = columns[0], columns[1:]
            label = max(len(first), *(len(h) for h, _ in rest))
            widths = [
                max(len(heads[i]), *(len(cells[i]) for _, cells in rest))
                for i in range(len(records))
            ]
            lines.append(
                f"{first:<{label}}  " + "  ".join(f"{h:>{w}}" for h, w in zip(heads, widths))
            )
            lines += [
                f"{h:<{label}}  " + "  ".join(f"{c:>{w}}" for c, w in zip(cells, widths))
                for h, cells in rest
            ]
        blocks.append("\n".join(line.rstrip() for line in lines))
    return "\n\n".join(blocks)


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
