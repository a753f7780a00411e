"""The documentation stays buildable and true (issue 28), without building it (CI runs
``mkdocs build --strict`` itself, in .ci/run): every page in the nav exists, every
notebook has an executed copy with its figures and no error, the README states the one
build command and CI runs it, and the concept pages' code runs. (The getting-started
page's code, the README's engine example plus a monitor Monte Carlo, is not run here: it
costs minutes of compilation on two loaded cores.)"""
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def nav_pages():
    """The page paths named in mkdocs.yml's nav (``- title: path.md`` or ``- path.md``)."""
    text = (ROOT / "mkdocs.yml").read_text().split("\nnav:", 1)[1]
    return re.findall(r"-\s+(?:[^:\n]+:\s+)?([\w./-]+\.(?:md|ipynb))\s*$", text, re.M)


def test_every_nav_page_exists_and_every_notebook_is_in_the_docs():
    pages = nav_pages()
    assert len(pages) > 20
    assert [p for p in pages if not (DOCS / p).is_file()] == []
    notebooks = sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb"))
    assert sorted(Path(p).name for p in pages if p.startswith("examples/") and p.endswith(".ipynb")) == notebooks


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb")))
def test_executed_copy_has_outputs_figures_and_no_error(name):
    copy = json.loads((DOCS / "examples" / name).read_text())
    outputs = [o for c in copy["cells"] if c["cell_type"] == "code" for o in c.get("outputs", [])]
    assert all(c.get("execution_count") for c in copy["cells"] if c["cell_type"] == "code" and c["source"])
    assert not [o for o in outputs if o["output_type"] == "error"]
    assert not [o for o in outputs if o["output_type"] == "stream" and "Traceback" in "".join(o["text"])]
    assert any("image/png" in o.get("data", {}) for o in outputs), f"{name}: no figure"
    meta = copy["metadata"]["jaxfdi_docs"]
    assert meta["source"] == f"notebooks/{name}" and len(meta["source_sha256"]) == 64


def test_readme_states_the_docs_command_and_ci_runs_it():
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Documentation", 1)[1].split("\n## ", 1)[0]
    commands = re.findall(r"```bash\n(.*?)\n```", section, re.S)
    assert commands == ['pip install -e ".[docs]" && mkdocs build --strict']
    ci = (ROOT / ".ci" / "run").read_text()
    assert re.search(r'^pip install -e "\.\[docs\]" && .*mkdocs build --strict', ci, re.M)


def test_concept_pages_code_runs():
    """The concept pages' Python blocks, in order in one namespace."""
    namespace = {}
    ran = 0
    for page in ("faults", "filters", "monte-carlo", "detectors", "control"):
        for block in re.findall(r"```python\n(.*?)```", (DOCS / "concepts" / f"{page}.md").read_text(), re.S):
            if "class Filter(NamedTuple)" in block:  # the shape of a Filter, not runnable code
                continue
            exec(block.replace("1000, jnp.ones(1000)", "16, jnp.ones(16)"), namespace)
            ran += 1
    assert ran == 6
    assert namespace["info"].nis.shape == (50,) and namespace["out"].shape == (16,)
    truth = namespace["truth"]                # faults.md: the bias enters sensor 1 from step 20
    assert truth.measurement.shape == (50, 2) and float(truth.sensor_fault[19, 1]) == 0.0
    assert float(truth.sensor_fault[20, 1]) == 0.5 and float(truth.sensor_fault[20, 0]) == 0.0
    assert abs(float(namespace["threshold"]) - 39.9968) < 1e-3          # scipy.stats.chi2.isf(0.005, 20)
    assert bool(namespace["converged"])
