"""Notebook 01 (the engine Kalman filter and its chi-square Monte Carlo) end to end in a
fresh kernel, 5 runs per fault, and its printed results checked."""

from _notebooks import FAULT_NAMES, cells_of_column, images, run_clean, tables


def test_kalman_monte_carlo_notebook(python3_kernel, monkeypatch, tmp_path):
    outputs, text = run_clean(
        "01_kalman_monte_carlo.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": "5"}
    )
    stderr = "".join(o.text for o in outputs if o.output_type == "stream" and o.name == "stderr")
    assert "Traceback" not in stderr, stderr
    assert "runs per fault: 5" in text  # the kernel saw JAXFDI_NB_RUNS
    assert "spectral radius of Phi = 0.9858" in text

    # the Monte Carlo table renders as a DataFrame: one row per fault in the seed-003 order,
    # every rate beside its interval (its numbers are the study's JSON: tests/scenarios/test_cli.py)
    html = tables(outputs)
    assert html.count("<table") == 1 and "detection_rate_low" in html and "delay_mean_s" in html
    order = [html.index(f"<td>{name}</td>") for name in FAULT_NAMES]
    assert order == sorted(order) and all(cells_of_column(html, name) == 1 for name in FAULT_NAMES)
    assert "7 rows; .to_frame() for the table" in text  # the result's text form is short

    figures = images(outputs)
    assert len(figures) >= 2, (
        f"expected the run figure and the Monte Carlo figure, got {len(figures)} PNG outputs"
    )
