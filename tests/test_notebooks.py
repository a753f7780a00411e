"""Execute the example notebooks end to end with nbclient and check their outputs.

The notebook runs in a fresh ``python3`` Jupyter kernel with ``notebooks/`` as its
working directory and ``JAXFDI_NB_RUNS=5`` (a small Monte Carlo). If no usable
``python3`` kernelspec exists (a fresh CI machine after ``pip install -e ".[dev]"``), one
for the current interpreter is installed first.
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import nbformat
import pytest
from jupyter_client.kernelspec import KernelSpecManager, NoSuchKernel
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
KERNEL = "python3"
CELL_TIMEOUT_S = 300
FAULT_NAMES = ("actuator", "RPM", "P2", "T2", "P4", "T4", "none")
# jupyter_client replaces these argv[0] values by sys.executable when it starts a kernel
_PYTHON_ALIASES = {"python", f"python{sys.version_info[0]}", "python{}.{}".format(*sys.version_info[:2])}


def _runs_this_interpreter(argv: list[str]) -> bool:
    if not argv:
        return False
    if argv[0] in _PYTHON_ALIASES:
        return True
    exe = shutil.which(argv[0]) or argv[0]
    try:
        return os.path.samefile(exe, sys.executable)
    except OSError:
        return False


def _usable_kernel() -> bool:
    try:
        spec = KernelSpecManager().get_kernel_spec(KERNEL)
    except NoSuchKernel:
        return False
    return _runs_this_interpreter(spec.argv)


@pytest.fixture
def python3_kernel(tmp_path_factory, monkeypatch) -> str:
    """Make sure the ``python3`` kernelspec starts *this* interpreter (with jaxfdi)."""
    if _usable_kernel():
        return KERNEL
    from ipykernel import kernelspec

    try:
        KernelSpecManager().get_kernel_spec(KERNEL)
        missing = False
    except NoSuchKernel:
        missing = True
    if missing:
        try:  # the usual fix on a fresh machine: a user-level kernelspec
            kernelspec.install(user=True, kernel_name=KERNEL)
        except Exception:  # e.g. read-only home: fall through to a private one
            pass
    if not _usable_kernel():
        # Missing and not installable, or a python3 spec of another interpreter: install
        # a private one for sys.executable and put it first on JUPYTER_PATH (this test only).
        prefix = tmp_path_factory.mktemp("jupyter-prefix")
        kernelspec.install(prefix=str(prefix), kernel_name=KERNEL)
        data_dir = prefix / "share" / "jupyter"
        monkeypatch.setenv("JUPYTER_PATH", os.pathsep.join(filter(None, [str(data_dir), os.environ.get("JUPYTER_PATH")])))
    assert _usable_kernel(), "could not provide a python3 Jupyter kernel for this interpreter"
    return KERNEL


def _execute(name: str, kernel: str) -> nbformat.NotebookNode:
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    client = NotebookClient(
        nb,
        timeout=CELL_TIMEOUT_S,
        kernel_name=kernel,
        resources={"metadata": {"path": str(NOTEBOOKS)}},  # cells run with notebooks/ as cwd
    )
    client.execute()
    return nb


def _outputs(nb: nbformat.NotebookNode):
    for cell in nb.cells:
        if cell.cell_type == "code":
            yield from cell.get("outputs", [])


def _text(output) -> str:
    if output.output_type == "stream":
        return output.text
    return output.get("data", {}).get("text/plain", "")


def _run_clean(name: str, kernel: str, monkeypatch, env: dict[str, str]):
    """Execute a stored notebook (kept without outputs) with ``env`` in the kernel's
    environment; check it wrote nothing into the repo and raised no error. Returns
    ``(outputs, text)``."""
    stored = nbformat.read(NOTEBOOKS / name, as_version=4)
    assert all(not c.get("outputs") for c in stored.cells if c.cell_type == "code")
    for var, value in env.items():
        monkeypatch.setenv(var, value)  # inherited by the kernel process
    before = sorted(p.relative_to(NOTEBOOKS) for p in NOTEBOOKS.rglob("*"))
    nb = _execute(name, kernel)
    after = sorted(p.relative_to(NOTEBOOKS) for p in NOTEBOOKS.rglob("*"))
    assert after == before, f"the notebook wrote files into the repo: {sorted(set(after) - set(before))}"
    outputs = list(_outputs(nb))
    errors = [o for o in outputs if o.output_type == "error"]
    assert not errors, f"{errors[0].ename}: {errors[0].evalue}"
    return outputs, "\n".join(_text(o) for o in outputs)


def test_kalman_monte_carlo_notebook(python3_kernel, monkeypatch):
    outputs, text = _run_clean("01_kalman_monte_carlo.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": "5"})
    stderr = "".join(o.text for o in outputs if o.output_type == "stream" and o.name == "stderr")
    assert "Traceback" not in stderr, stderr
    assert "runs per fault: 5" in text  # the kernel saw JAXFDI_NB_RUNS
    assert "spectral radius of Phi = 0.9858" in text

    # the Monte Carlo table: header, then one line per fault in the seed-003 order
    table_lines = text[text.index("fault      magnitude"):].splitlines()
    assert "det. rate" in table_lines[0] and "FA/step" in table_lines[0]
    rows = table_lines[2:2 + len(FAULT_NAMES)]
    assert [r.split()[0] for r in rows] == list(FAULT_NAMES)
    for row in rows[:-1]:  # faulty rows: these faults are detected, within a fraction of a second
        fields = row.split()
        det_rate, fa_rate, delay_median = float(fields[2]), float(fields[3]), float(fields[5])
        assert det_rate >= 0.8, row
        assert 0.0 <= fa_rate <= 1.0, row
        assert 0.0 <= delay_median < 0.5, row
    assert rows[-1].split()[2] == "-"  # fault-free: no detection rate

    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 2, f"expected the run figure and the Monte Carlo figure, got {len(images)} PNG outputs"


def test_engine_imm_glrt_notebook(python3_kernel, monkeypatch):
    outputs, text = _run_clean("02_engine_imm_glrt.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": "5"})
    assert "runs per fault: 5" in text
    assert "paper pi: stationary P(normal)" in text
    assert "theoretical threshold chi2.isf(0.005, 60) = 91.95" in text
    overview = text[text.index("method  "):].splitlines()
    methods = [line.split("  ")[0] for line in overview[2:13]]
    assert methods[:3] == ["MM", "IMM", "IMM hand-pi"] and methods[-1].startswith("GLRT")
    for fault in FAULT_NAMES:
        assert f"\n{fault} " in text
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 3, f"expected the three study figures, got {len(images)}"


def test_tuning_notebook(python3_kernel, monkeypatch):
    # the sizes of test_engine_tuning's CLI run, so that its compiled programs are reused
    env = {"JAXFDI_NB_STEPS": "20", "JAXFDI_NB_TRAIN_RUNS": "2", "JAXFDI_NB_RUNS": "10", "JAXFDI_NB_SELECTION_RUNS": "4"}
    outputs, text = _run_clean("03_tuning.ipynb", python3_kernel, monkeypatch, env)
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
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 2, f"expected the loss curves and the transition matrices, got {len(images)}"


def test_vtol_notebook(python3_kernel, monkeypatch):
    outputs, text = _run_clean("04_vtol_tskf_ftc.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": "5"})
    assert "runs per fault: 5" in text
    assert "nominal closed-loop spectral radius: 1.000000" in text   # the paper's q tracking: eigenvalue 1
    assert "statistic dof: 3" in text
    for name in ("a2 effectiveness 0.5 from k = 100", "s3 step 0.7 from k = 120", "none (fault-free)"):
        assert name in text
    assert "Headline cases beside seed 001" in text
    assert "online isolation of the a2 fault (location + 1): 2" in text
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 2, f"expected Fig. 3 and Figs. 4-5, got {len(images)}"


def test_reaction_wheels_notebook(python3_kernel, monkeypatch):
    outputs, text = _run_clean("05_reaction_wheels.ipynb", python3_kernel, monkeypatch, {"JAXFDI_NB_RUNS": "5"})
    assert "runs per case: 5" in text
    difference = float(text.split("AD vs closed-form Jacobian, largest difference: ")[1].split()[0])
    assert difference < 1e-15
    zero_total_det = float(text.split("zero total momentum")[1].split("det A = ")[1].split()[0])
    bias_det = float(text.split("wheels at bias speed:")[1].split("det A = ")[1].split()[0])
    assert abs(zero_total_det) < 1e-6 * abs(bias_det)
    for case in ["none"] + [f"{kind} w{w}" for kind in ("stop", "stuck", "bias", "gain") for w in range(1, 5)]:
        assert f"\n{case:<10} MM likelihood" in text
    assert "Wheel stops (seed 004 reports" in text
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 3, f"expected Figs. 3/5, 4/6 and 8/9, got {len(images)}"
