"""Notebook 01 (the engine Kalman filter and its chi-square Monte Carlo) end to end in a
fresh kernel, 5 runs per fault, and its printed results checked."""
from _notebooks import FAULT_NAMES, images, python3_kernel, run_clean  # noqa: F401 (python3_kernel: a fixture)


def test_kalman_monte_carlo_notebook(python3_kernel, monkeypatch, tmp_path):
    outputs, text = run_clean("01_kalman_monte_carlo.ipynb", python3_kernel, monkeypatch,
                              {"JAXFDI_NB_RUNS": "5"})
    stderr = "".join(o.text for o in outputs if o.output_type == "stream" and o.name == "stderr")
    assert "Traceback" not in stderr, stderr
    assert "runs per fault: 5" in text  # the kernel saw JAXFDI_NB_RUNS
    assert "spectral radius of Phi = 0.9858" in text

    # the Monte Carlo table: header, then one line per fault in the seed-003 order
    table_lines = text[text.index("fault      magnitude"):].splitlines()
    assert "det. rate" in table_lines[0] and "FA/step" in table_lines[0]
    rows = table_lines[2:2 + len(FAULT_NAMES)]
    assert [r.split()[0] for r in rows] == list(FAULT_NAMES)
    # each rate is followed by its interval "[low,high]" and preceded by the run count n
    rows = [" ".join(f for f in r.split() if not f.startswith("[")) for r in rows]
    rows = [" ".join(r.split()[:2] + r.split()[3:]) for r in rows]
    assert "clean" in table_lines[0] and "delay med [s]" in table_lines[0]
    for row in rows[:-1]:  # faulty rows: these faults are detected, within a fraction of a second
        # fault, magnitude, det. rate, FA rate (runs alarming before the onset), FA/step,
        # clean runs, then the delay's mean, median and p90 over the clean runs (issue 27)
        fields = row.split()
        det_rate, fa_rate, clean = float(fields[2]), float(fields[3]), int(fields[5])
        assert det_rate >= 0.8, row
        assert 0.0 <= fa_rate <= 1.0, row
        assert clean == round(5 * (1.0 - fa_rate)), row
        if clean:
            delay_mean, delay_median = float(fields[6]), float(fields[7])
            assert 0.0 <= delay_mean < 0.5 and 0.0 <= delay_median < 0.5, row
    assert rows[-1].split()[2] == "-"  # fault-free: no detection rate

    figures = images(outputs)
    assert len(figures) >= 2, f"expected the run figure and the Monte Carlo figure, got {len(figures)} PNG outputs"
