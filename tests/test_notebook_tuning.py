"""Notebook 03 (tuning the engine IMM by gradient) end to end in a fresh kernel at a
reduced size (20 Adam steps, 2 training runs per fault, 10 held-out and 4 selection runs
per fault: the sizes of test_engine_tuning's CLI run), and its printed results checked."""
from _notebooks import FAULT_NAMES, images, python3_kernel, run_clean  # noqa: F401 (python3_kernel: a fixture)


def test_tuning_notebook(python3_kernel, monkeypatch, tmp_path):
    env = {"JAXFDI_NB_STEPS": "20", "JAXFDI_NB_TRAIN_RUNS": "2", "JAXFDI_NB_RUNS": "10", "JAXFDI_NB_SELECTION_RUNS": "4"}
    outputs, text = run_clean("03_tuning.ipynb", python3_kernel, monkeypatch, env)
    assert "Adam steps: 20, training runs per fault: 2, held-out runs per fault: 10" in text
    assert "rows sum to one: True | structural zeros kept: True" in text
    table = text[text.index("fault     "):].splitlines()
    assert [line.split()[:2] for line in table[2:16]] == [[f, label] for f in FAULT_NAMES for label in ("paper", "tuned")]
    ce_line = next(line for line in table if line.startswith("mean per-step mode cross-entropy"))
    paper_ce, tuned_ce = (float(part.split()[-1].rstrip(",")) for part in ce_line.split(":")[1].split("(")[0].split(","))
    assert tuned_ce < paper_ce, ce_line
    # the per-mode thresholds: seven values in (0, 1), chosen to shrink the shortfall on the selection runs
    line = next(line for line in text.splitlines() if line.startswith("mu_T per mode:"))
    assert [k for k in FAULT_NAMES[:-1] if f"'{k}':" in line] == list(FAULT_NAMES[:-1]), line
    shortfall = next(line for line in text.splitlines() if line.startswith("shortfall against the paper's"))
    trained, selected = (float(part.split()[0]) for part in shortfall.split(": ")[1].split("->"))
    assert selected <= trained, shortfall
    assert text.count("mean per-step mode cross-entropy") == 2 and "worse than the paper's (per-mode mu_T):" in text
    figures = images(outputs)
    assert len(figures) == 2, f"expected the loss curves and the transition matrices, got {len(figures)}"
