"""Notebook 04 (Lee & Lyou's VTOL: robust TSKF bank, wavelet-denoised tests, FTC) end to end
in a fresh kernel, 5 runs per fault, and its printed results checked."""

from _notebooks import images, run_clean, tables


def test_vtol_notebook(python3_kernel, monkeypatch, tmp_path):
    outputs, text = run_clean(
        "04_vtol_tskf_ftc.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": "5"}
    )
    assert "runs per fault: 5" in text
    assert (
        "nominal closed-loop spectral radius: 1.000000" in text
    )  # the paper's q tracking: eigenvalue 1
    assert "statistic dof: 3" in text
    html = tables(outputs)  # the study as a DataFrame: a row per fault and method|thresholds
    assert html.count("<table") == 1 and "detection_rate_low" in html
    for name in ("a2 effectiveness 0.5", "s3 step 0.7", "none"):
        assert html.count(f"<td>{name}</td>") == 10, name  # 5 methods x 2 threshold sets
    assert "Headline cases beside Lee & Lyou" in text
    assert "online isolation of the a2 fault (location + 1): 2" in text
    assert len(images(outputs)) == 2, f"expected Fig. 3 and Figs. 4-5, got {len(images(outputs))}"
