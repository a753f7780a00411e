"""Reaction wheels (Choi & Park 2009) end to end: `jaxfdi run reaction-wheels --runs 2`
(table, JSON equal to the one written before the scenario moved onto `jaxfdi._simulation.loop`,
figures) and notebook 05.

At 2 runs per case the notebook's study and examples are the CLI's (``wheel_study(runs=2,
seed=0, calibration_runs=20)``, ``wheel_examples(..., seed=0)``): both run on the run's
shared XLA compilation cache (conftest), so the closed loops are compiled once."""

import json

import pytest
from _notebooks import FULL_TABLE, images, run_clean, tables
from test_cli import assert_csv_is_the_json, assert_same_as_before, run_cli

from jaxfdi.scenarios.reaction_wheels import METHODS

RUNS = 2
WHEEL_CASES = ["none"] + [
    f"{kind} w{w}" for kind in ("stop", "stuck", "bias", "gain") for w in range(1, 5)
]
CASES = WHEEL_CASES + [
    "dead g1",
    "frozen g1",
]  # issue 37: the x gyro dead and frozen, after the wheel cases


@pytest.fixture(scope="module")
def shared(tmp_path_factory):
    """The CLI run's folder (its output is ``shared / "out"``)."""
    return tmp_path_factory.mktemp("wheels")


def test_reaction_wheels_prints_every_case_and_writes_figures(shared):
    proc = run_cli(shared, "reaction-wheels", "--runs", str(RUNS))
    assert proc.returncode == 0, proc.stderr
    data = json.loads((shared / "out" / "reaction-wheels.json").read_text())
    # the file predates the gyro cases (issue 37): appended after the wheel cases, they leave
    # those runs as they were (run keys and onsets are prefixes of the study's draws)
    assert_same_as_before("reaction-wheels", {**data, "rows": data["rows"][: len(WHEEL_CASES)]})
    assert "WARNING" not in proc.stdout and all(row["unhealthy_runs"] == 0 for row in data["rows"])
    assert [row["case"] for row in data["rows"]] == CASES
    for case in CASES:
        for method in (
            "dual filter F (paper)",
            "NIS chi-square",
            "credit isolator (paper)",
            "MM likelihood",
        ):
            assert f"\n{case:<10} {method}" in proc.stdout
    for case in ("none", "dead g1", "frozen g1"):
        assert f"\n{case:<10} gyro health test" in proc.stdout
    assert "Wheel stops (Choi & Park 2009 report" in proc.stdout
    assert data["config"]["runs"] == RUNS and data["config"]["calibration_runs"] == 20
    assert data["config"]["fdp_threshold"] > 0
    assert sorted(p.name for p in (shared / "out").iterdir()) == [
        "reaction-wheels-fig3-5-attitude.png",
        "reaction-wheels-fig4-6-detection.png",
        "reaction-wheels-fig8-9-isolation.png",
        "reaction-wheels.csv",
        "reaction-wheels.json",
    ]
    assert_csv_is_the_json(shared / "out" / "reaction-wheels.csv", data["rows"], METHODS)


def test_reaction_wheels_notebook(shared, python3_kernel, monkeypatch):
    outputs, text = run_clean(
        "05_reaction_wheels.ipynb",
        python3_kernel,
        monkeypatch,
        {"JAXFDI_NB_RUNS": str(RUNS)},
        epilogue=FULL_TABLE,
    )
    assert f"runs per case: {RUNS}" in text
    difference = float(text.split("AD vs closed-form Jacobian, largest difference: ")[1].split()[0])
    assert difference < 1e-15
    zero_total_det = float(text.split("zero total momentum")[1].split("det A = ")[1].split()[0])
    bias_det = float(text.split("wheels at bias speed:")[1].split("det A = ")[1].split()[0])
    assert abs(zero_total_det) < 1e-6 * abs(bias_det)
    # the study as a DataFrame, cut to pandas' display limits with its size; in full, a row per case and method
    # (the header's <tr> has a style; "none" is also the fault-free row's kind)
    rows = len(CASES) * len(METHODS)
    shown = tables(outputs)
    assert shown.count("<table") == 1 and f"<p>{rows} rows × " in shown
    html = text.split("FULL ", 1)[1]
    assert html.count("<tr>") == rows
    for case in CASES:
        assert html.count(f"<td>{case}</td>") >= len(METHODS), case
    assert "Wheel stops (Choi & Park 2009 report" in text
    assert len(images(outputs)) == 3, f"expected Figs. 3/5, 4/6 and 8/9, got {len(images(outputs))}"
