"""Notebook 06 (seed 000: hybrid PSA + UKF on the closed-loop F-16) end to end in a fresh
kernel, one run per case (the programs of ``jaxfdi run f16 --runs 1``: 24 directions per
sensor plane, 400 optimiser steps; compilation dominates, so fewer would not be cheaper);
its Table 1 check, printed paper comparison and figures checked."""

import json

import pandas as pd
from _frames import assert_table_is_the_json
from _notebooks import images, run_clean, tables


def test_f16_hybrid_notebook(python3_kernel, monkeypatch, tmp_path):
    frame, rows = tmp_path / "frame.pkl", tmp_path / "rows.json"
    outputs, text = run_clean(
        "06_f16_hybrid_psa_ukf.ipynb",
        python3_kernel,
        monkeypatch,
        {"JAXFDI_NB_RUNS": "1", "JAXFDI_NB_OPT_STEPS": "400"},  # the CLI's 400 steps
        f"import json\nstudy.to_frame().to_pickle({str(frame)!r})\n"
        f"open({str(rows)!r}, 'w').write(json.dumps(study.rows))",
    )
    assert_table_is_the_json(
        pd.read_pickle(frame), json.loads(rows.read_text())
    )  # to_frame() is the rows
    assert "runs per case: 1, directions per sensor plane: 24, optimiser steps: 400" in text
    for kind in (1, 2, 3):
        assert f"type {kind}: sensors" in text
    assert "Headline case beside the paper's" in text
    assert "PSA suspects: ours [1, 3] | paper: [1, 3]" in text
    assert "isolated sensor: ours 1 | paper: 1" in text
    html = tables(outputs)  # the study as DataFrames, a table per section
    assert html.count("<table") == 9 and "<h4>table1</h4>" in html and "<h4>paper_case</h4>" in html
    assert len(images(outputs)) == 5, f"expected 5 figures, got {len(images(outputs))}"
