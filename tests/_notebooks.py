"""Execute the example notebooks end to end with nbclient (helpers for the notebook tests).

A notebook runs in a fresh ``python3`` Jupyter kernel with ``notebooks/`` as its working
directory and the environment given by its test (``JAXFDI_NB_*`` sizes, and
``JAXFDI_CACHE_DIR``: the notebooks call ``jaxfdi.enable_compilation_cache()``). If no
usable ``python3`` kernelspec exists (a fresh CI machine after ``pip install -e
".[dev]"``), one for the current interpreter is installed first.

Each notebook's test lives beside the tests of the same scenario (one file per scenario,
so that ``pytest-xdist --dist loadfile`` can spread them over the workers) and, where
the notebook computes what a CLI test of that file computes at the same size, shares
that test's XLA compilation cache: the programs are compiled once in the file.
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
_PYTHON_ALIASES = {
    "python",
    f"python{sys.version_info[0]}",
    "python{}.{}".format(*sys.version_info[:2]),
}


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
        monkeypatch.setenv(
            "JUPYTER_PATH",
            os.pathsep.join(filter(None, [str(data_dir), os.environ.get("JUPYTER_PATH")])),
        )
    assert _usable_kernel(), "could not provide a python3 Jupyter kernel for this interpreter"
    return KERNEL


def _execute(name: str, kernel: str, epilogue: str = "") -> nbformat.NotebookNode:
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    if epilogue:
        nb.cells.append(nbformat.v4.new_code_cell(epilogue))
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


def run_clean(name: str, kernel: str, monkeypatch, env: dict[str, str], epilogue: str = ""):
    """Execute a stored notebook (kept without outputs) with ``env`` in the kernel's
    environment, and then the code ``epilogue`` (a test's look at the notebook's variables);
    check it wrote nothing into the repo and raised no error. Returns ``(outputs, text)``."""
    stored = nbformat.read(NOTEBOOKS / name, as_version=4)
    assert all(not c.get("outputs") for c in stored.cells if c.cell_type == "code")
    for var, value in env.items():
        monkeypatch.setenv(var, value)  # inherited by the kernel process
    before = sorted(p.relative_to(NOTEBOOKS) for p in NOTEBOOKS.rglob("*"))
    nb = _execute(name, kernel, epilogue)
    after = sorted(p.relative_to(NOTEBOOKS) for p in NOTEBOOKS.rglob("*"))
    assert after == before, (
        f"the notebook wrote files into the repo: {sorted(set(after) - set(before))}"
    )
    outputs = list(_outputs(nb))
    errors = [o for o in outputs if o.output_type == "error"]
    assert not errors, f"{errors[0].ename}: {errors[0].evalue}"
    return outputs, "\n".join(_text(o) for o in outputs)


#: an epilogue for ``run_clean``: the notebook's ``study`` table without pandas' display limits, printed on one
#: line after ``FULL `` (what a notebook shows is cut to ``display.max_rows``)
FULL_TABLE = """
import pandas as pd
with pd.option_context("display.max_rows", None, "display.max_columns", None):
    print("FULL " + " ".join(study._repr_html_().splitlines()))
"""


def tables(outputs) -> str:
    """The HTML of the notebook's DataFrame tables (a study result or a DataFrame as a
    cell's value renders as ``<table class="dataframe">``), joined."""
    return "\n".join(
        o["data"]["text/html"]
        for o in outputs
        if 'class="dataframe"' in o.get("data", {}).get("text/html", "")
    )


def cells_of_column(html: str, value: str) -> int:
    """How many table cells hold exactly ``value``."""
    return html.count(f"<td>{value}</td>")


def images(outputs) -> list:
    """The PNG outputs (figures) of a notebook's cells."""
    return [o for o in outputs if "image/png" in o.get("data", {})]
