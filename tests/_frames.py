"""A study's table (``to_frame()`` or the CSV the CLI writes) holds the same numbers as its
JSON rows: walked row by row, without the library's flattening code."""

import ast
import math

import numpy as np


def _same(table_value, json_value, where):
    if json_value is None or (isinstance(json_value, float) and math.isnan(json_value)):
        assert table_value is None or (
            isinstance(table_value, float) and math.isnan(table_value)
        ), where
    elif isinstance(json_value, list):
        parsed = (
            ast.literal_eval(table_value.replace("nan", "None"))
            if isinstance(table_value, str)
            else table_value
        )
        try:
            numbers = np.asarray(json_value, float), np.asarray(parsed, float)
        except (TypeError, ValueError):
            assert parsed == json_value, where
        else:
            assert np.array_equal(*numbers, equal_nan=True), where
    elif isinstance(json_value, bool):
        assert table_value in (json_value, str(json_value)), where
    elif isinstance(json_value, (int, float)):
        assert float(table_value) == float(json_value), (
            f"{where}: {table_value!r} in the table, {json_value!r} in JSON"
        )
    else:
        assert str(table_value) == str(json_value), where


def _cells(row: dict) -> dict:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}``, by pandas' own flattening (not the library's)."""
    import pandas as pd

    flat = pd.json_normalize(row, sep=".").iloc[0].items() if row else []
    return {key: value.item() if isinstance(value, np.generic) else value for key, value in flat}


def assert_table_is_the_json(frame, rows: list[dict], methods: tuple[str, ...] = ()) -> None:
    """Each JSON row is one table row, or one per entry where a field is a dict of dicts
    (``methods: {name: {...}}``, the name in column ``method``) or per method where the row
    has the fields ``methods`` names, in order; every
    scalar and list of the row (and of its method entry) is in that table row, with equal
    value; the table's other columns are the rates' intervals (``*_low``, ``*_high``) or
    empty."""
    records = frame.to_dict("records")
    at = 0
    for i, row in enumerate(rows):
        per_method = {k: row[k] for k in methods if isinstance(row.get(k), dict)}
        nested = next(
            (
                k
                for k, v in row.items()
                if isinstance(v, dict) and v and all(isinstance(x, dict) for x in v.values())
            ),
            None,
        )
        key = "method"
        if not per_method and nested:
            per_method, key = row[nested], nested[:-1] if nested.endswith("s") else nested
        common = _cells({k: v for k, v in row.items() if k not in per_method and k != nested})
        entries = list(per_method.items()) or [(None, {})]
        for name, inner in entries:
            record, at = records[at], at + 1
            expected = {**common, **_cells(inner)}
            for column, value in expected.items():
                assert column in record, f"row {i} ({name}): no column {column!r}"
                _same(record[column], value, f"row {i} ({name}) {column}")
            if name is not None:
                got = record[key]
                assert str(got) == str(name) or (
                    isinstance(got, float) and str(name).isdigit() and got == int(name)
                ), (
                    f"row {i}: {key} {got!r}, expected {name!r}"
                )  # a CSV reads the key 30 back as 30.0
            extra = set(record) - set(expected) - {key}
            for column in extra:
                value = record[column]
                empty = value is None or (isinstance(value, float) and math.isnan(value))
                assert empty or column.endswith(("_low", "_high")), (
                    f"row {i} ({name}): unexpected {column} = {value!r}"
                )
    assert at == len(records), f"{len(records) - at} table rows beyond the JSON's"
