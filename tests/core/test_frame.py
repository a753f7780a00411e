"""Study results as data (``jaxfdi._studies.frame``): tidy rows, the rates' Clopper-Pearson
intervals against SciPy's exact binomial interval, and the HTML a notebook renders."""

import math

import pandas as pd
import pytest
from _frames import assert_table_is_the_json
from scipy import stats

from jaxfdi import results_frame, text_table
from jaxfdi._studies.frame import results_html

ROWS = [
    {
        "method": "MM",
        "fault": "P2",
        "runs": 20,
        "unhealthy_runs": 2,
        "detection_rate": 15 / 18,
        "isolation_rate": 0.5,
        "delay_median_s": 0.03,
        "shape": [1, 2],
        "noise": {"q": 1.0, "r": 2.0},
    },
    {
        "method": "MM",
        "fault": "none",
        "runs": 20,
        "unhealthy_runs": 0,
        "detection_rate": None,
        "false_alarm_rate": 0.05,
        "delay_median_s": None,
        "shape": [1, 2],
        "noise": {"q": 1.0, "r": 2.0},
    },
]


def test_rows_become_columns_with_their_intervals():
    frame = results_frame(ROWS)
    assert_table_is_the_json(frame, ROWS)
    assert list(frame.columns[4:7]) == [
        "detection_rate",
        "detection_rate_low",
        "detection_rate_high",
    ]
    assert "noise.q" in frame and frame["noise.r"].tolist() == [2.0, 2.0]
    # 15 of the 18 healthy runs: SciPy's exact (Clopper-Pearson) 95 % interval
    ci = stats.binomtest(15, 18).proportion_ci(0.95, method="exact")
    assert frame.loc[0, "detection_rate_low"] == pytest.approx(ci.low, rel=1e-12)
    assert frame.loc[0, "detection_rate_high"] == pytest.approx(ci.high, rel=1e-12)
    ci = stats.binomtest(9, 18).proportion_ci(0.95, method="exact")
    assert (
        frame.loc[0, "isolation_rate_low"],
        frame.loc[0, "isolation_rate_high"],
    ) == pytest.approx((ci.low, ci.high))
    ci = stats.binomtest(1, 20).proportion_ci(0.99, method="exact")
    assert results_frame(ROWS, level=0.99).loc[1, "false_alarm_rate_low"] == pytest.approx(
        ci.low, rel=1e-12
    )
    # no rate, no interval
    assert math.isnan(frame.loc[1, "detection_rate_low"]) and math.isnan(
        frame.loc[0, "false_alarm_rate_low"]
    )


def test_a_rate_over_another_denominator_gets_no_interval():
    frame = results_frame(
        [{"runs": 10, "detection_rate": 0.55}]
    )  # 5.5 of 10 runs: not a count of them
    assert math.isnan(frame.loc[0, "detection_rate_low"]) and math.isnan(
        frame.loc[0, "detection_rate_high"]
    )


def test_per_method_entries_become_rows():
    nested = [
        {
            "fault": "a1",
            "runs": 4,
            "methods": {"raw": {"detection_rate": 1.0}, "window": {"detection_rate": 0.75}},
        }
    ]
    frame = results_frame(nested)
    assert frame["method"].tolist() == ["raw", "window"] and frame["detection_rate"].tolist() == [
        1.0,
        0.75,
    ]
    assert_table_is_the_json(frame, nested)
    fields = [
        {
            "case": "stop w1",
            "runs": 4,
            "unhealthy_runs": 0,
            "fdp": {"rate": 1.0},
            "nis": {"rate": 0.5},
        }
    ]
    frame = results_frame(fields, methods=("fdp", "nis"))
    assert frame["method"].tolist() == ["fdp", "nis"] and frame["rate"].tolist() == [1.0, 0.5]
    assert_table_is_the_json(frame, fields, methods=("fdp", "nis"))
    with pytest.raises(ValueError, match="repeat the row's keys"):
        results_frame([{"runs": 4, "methods": {"raw": {"runs": 3}}}])


def test_html_is_one_table_per_section_with_its_own_columns():
    rows = [
        {"section": "trim", "cell": "thtl", "ours": 0.816},
        {"section": "tracking", "error": "q", "rms": 0.1},
    ]
    text = results_html(results_frame(rows), {"runs": 3, "seed": 7})
    assert (
        text.count("<table") == 2 and "<h4>trim</h4>" in text and "3 runs per case, seed 7" in text
    )
    trim = text.split("<h4>tracking</h4>")[0]
    assert "thtl" in trim and "rms" not in trim
    assert results_html(results_frame(ROWS)).count("<table") == 1


def test_html_keeps_within_pandas_display_limits():
    """A long section shows pandas' ``min_rows`` (first and last halves) past ``max_rows``, as a DataFrame does."""
    rows = [
        {"section": "long", "case": f"c{i}", **{f"x{j}": float(i + j) for j in range(30)}}
        for i in range(99)
    ]
    with pd.option_context("display.max_rows", 20, "display.min_rows", 6, "display.max_columns", 8):
        text = results_html(results_frame(rows))
    body = text.split("<tbody>")[1]
    assert body.count("<tr>") == 7  # 3 + the "..." row + 3
    assert (
        "c0<" in body and "c98<" in body and "c50<" not in body and "99 rows × 31 columns" in text
    )
    assert "x29" in text and "x15" not in text  # the first and last columns
    with pd.option_context("display.max_rows", None, "display.max_columns", None):
        assert results_html(results_frame(rows)).split("<tbody>")[1].count("<tr>") == 99


def test_text_table_is_the_frame_with_intervals_in_one_cell_and_wide_blocks_transposed():
    rows = [
        {
            "section": "faults",
            "fault": "P2",
            "runs": 20,
            "unhealthy_runs": 0,
            "detection_rate": 0.75,
        },
        {
            "section": "faults",
            "fault": "T4",
            "runs": 20,
            "unhealthy_runs": 0,
            "detection_rate": 0.0,
        },
        {"section": "station", "name": "0759", **{f"error_{j}_m": 0.25 * j for j in range(12)}},
    ]
    text = text_table(results_frame(rows), group="section")
    ci = stats.binomtest(15, 20).proportion_ci(0.95, method="exact")
    ci0 = stats.binomtest(0, 20).proportion_ci(0.95, method="exact")
    faults, station = text.split("\n\n")
    assert faults.splitlines() == [
        "faults",
        "fault  runs  unhealthy_runs     detection_rate",
        f"   P2    20               0  0.75 [{ci.low:.2f}, {ci.high:.2f}]",
        f"   T4    20               0     0 [{ci0.low:.2f}, {ci0.high:.2f}]",
    ]
    lines = (
        station.splitlines()
    )  # 13 columns of one row: wider than 110 characters, so a line per column
    assert (
        lines[:3] == ["station", "name        0759", "error_0_m      0"]
        and lines[-1] == "error_11_m  2.75"
    )
    assert "-" not in station  # the other section's columns are not this block's
    # a count in a column with gaps is a float column in pandas: still printed as the count
    counts = text_table(results_frame([{"epochs": 12345}, {"epochs": None, "x": 1.5}]))
    assert counts.splitlines()[1].split() == ["12345", "-"]
