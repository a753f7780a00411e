"""The documentation stays buildable and true (issue 28), without building it (CI runs
``mkdocs build --strict`` itself, in .ci/run): every page in the nav exists, every
notebook has an executed copy with its figures and no error, the README states the one
build command and CI runs it, and the concept pages' code runs. (The getting-started
page's code, the README's engine example plus a monitor Monte Carlo, is not run here: it
costs minutes of compilation on two loaded cores.)"""

import json
import re
from pathlib import Path

import numpy as np
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
    assert (
        sorted(Path(p).name for p in pages if p.startswith("examples/") and p.endswith(".ipynb"))
        == notebooks
    )


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb")))
def test_executed_copy_has_outputs_figures_and_no_error(name):
    copy = json.loads((DOCS / "examples" / name).read_text())
    outputs = [o for c in copy["cells"] if c["cell_type"] == "code" for o in c.get("outputs", [])]
    assert all(
        c.get("execution_count") for c in copy["cells"] if c["cell_type"] == "code" and c["source"]
    )
    assert not [o for o in outputs if o["output_type"] == "error"]
    assert not [
        o for o in outputs if o["output_type"] == "stream" and "Traceback" in "".join(o["text"])
    ]
    warned = [
        o for o in outputs if o["output_type"] == "stream" and "Warning" in "".join(o["text"])
    ]
    assert not warned, f"{name}: {''.join(warned[0]['text'])[:300]}"
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


def test_concept_pages_code_runs(tmp_path, monkeypatch):
    """The concept pages' Python blocks, in order in one namespace (in a temporary folder: they write files)."""
    monkeypatch.chdir(tmp_path)
    namespace = {}
    ran = 0
    for page in ("faults", "filters", "monte-carlo", "detectors", "control", "studies", "tuning"):
        for block in re.findall(
            r"```python\n(.*?)```", (DOCS / "concepts" / f"{page}.md").read_text(), re.S
        ):
            if "class Filter(NamedTuple)" in block:  # the shape of a Filter, not runnable code
                continue
            exec(block.replace("1000, jnp.ones(1000)", "16, jnp.ones(16)"), namespace)
            ran += 1
    assert ran == 9
    # tuning.md: the tuned matrix moved from the start towards the generating one; the held-out interval brackets
    pi = np.asarray(namespace["params"]["transition"])
    assert abs(pi[0, 1] - 0.04) < abs(0.2 - 0.04) and abs(pi[1, 0] - 0.12) < abs(0.3 - 0.12)
    scores = namespace["scores"]
    assert scores["nll_low"] <= scores["nll"] <= scores["nll_high"]
    assert namespace["info"].nis.shape == (50,) and namespace["out"].shape == (16,)
    truth = namespace["truth"]  # faults.md: the bias enters sensor 1 from step 20
    assert truth.measurement.shape == (50, 2) and float(truth.sensor_fault[19, 1]) == 0.0
    assert float(truth.sensor_fault[20, 1]) == 0.5 and float(truth.sensor_fault[20, 0]) == 0.0
    assert abs(float(namespace["threshold"]) - 39.9968) < 1e-3  # scipy.stats.chi2.isf(0.005, 20)
    assert bool(namespace["converged"])
    # studies.md: the closed loop holds the open-loop unstable plant near 0 from x0 = (1, 0) ...
    states = np.asarray(namespace["true_states"])
    assert states.shape == (200, 2) and np.max(np.abs(states[-50:])) < 0.1
    # ... and on the same runs a lower threshold detects at least as often (an alarm at 13.8 is one at 9.2)
    detected = namespace["detected"].to_dict()
    assert detected["R x1, 9.2"] >= detected["R x1, 13.8"] and set(detected) == {
        "R x1, 9.2",
        "R x1, 13.8",
        "R x1.5, 13.8",
    }


def _hooks():
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    return hooks


def test_the_build_finds_stale_copies_and_regenerates_them(tmp_path, monkeypatch, caplog):
    """mkdocs' hook on a copy of the tree: a changed notebook text makes its copy stale (a
    warning, an error under --strict), ``JAXFDI_EXECUTE_NOTEBOOKS=1`` brings it up to date
    with its outputs kept; a notebook without a copy is stale too. (A changed code cell is
    executed again: ``execute_notebooks.execute``, what the notebook tests run.)"""
    import shutil

    (tmp_path / "notebooks").mkdir()
    (tmp_path / "docs" / "examples").mkdir(parents=True)
    shutil.copy(DOCS / "execute_notebooks.py", tmp_path / "docs")
    name = "01_kalman_monte_carlo.ipynb"
    shutil.copy(ROOT / "notebooks" / name, tmp_path / "notebooks")
    shutil.copy(DOCS / "examples" / name, tmp_path / "docs" / "examples")
    hooks = _hooks()
    monkeypatch.setattr(hooks, "ROOT", tmp_path)
    assert hooks.stale_copies(tmp_path) == []

    source = json.loads((tmp_path / "notebooks" / name).read_text())
    first_text = next(c for c in source["cells"] if c["cell_type"] == "markdown")
    first_text["source"] = ["# A new title\n"] + first_text["source"][1:]
    (tmp_path / "notebooks" / name).write_text(json.dumps(source))
    monkeypatch.delenv(hooks.REGENERATE, raising=False)
    with caplog.at_level("WARNING", logger="mkdocs.hooks.examples"):
        hooks.on_pre_build(config=None)
    assert [r.getMessage().split(" is missing")[0] for r in caplog.records] == [
        f"examples: docs/examples/{name}"
    ]

    caplog.clear()
    monkeypatch.setenv(hooks.REGENERATE, "1")
    with caplog.at_level("WARNING", logger="mkdocs.hooks.examples"):
        hooks.on_pre_build(config=None)
    assert caplog.records == [] and hooks.stale_copies(tmp_path) == []
    copy = json.loads((tmp_path / "docs" / "examples" / name).read_text())
    assert "".join(
        next(c for c in copy["cells"] if c["cell_type"] == "markdown")["source"]
    ).startswith("# A new title")
    executed = json.loads((DOCS / "examples" / name).read_text())
    assert [c["outputs"] for c in copy["cells"] if c["cell_type"] == "code"] == [
        c["outputs"] for c in executed["cells"] if c["cell_type"] == "code"
    ]

    shutil.copy(ROOT / "notebooks" / "02_engine_imm_glrt.ipynb", tmp_path / "notebooks")
    assert hooks.stale_copies(tmp_path) == ["02_engine_imm_glrt.ipynb"]


def test_ci_tries_the_wheel_on_every_python_the_package_claims():
    """The classifiers name the Pythons the wheel is known to install and run on: the floor
    (``requires-python``, CI's own interpreter, which runs the suite) and each newer one that
    ``.ci/run`` installs the wheel into and runs the README's example with."""
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    version = lambda v: tuple(map(int, v.split(".")))
    claimed = sorted(
        (
            c.rsplit(":: ", 1)[1]
            for c in project["classifiers"]
            if re.fullmatch(r"Programming Language :: Python :: 3\.\d+", c)
        ),
        key=version,
    )
    floor = project["requires-python"].removeprefix(">=")
    ci = (ROOT / ".ci" / "run").read_text()
    newer = re.search(r"^for minor in ([\d. ]+); do$", ci, re.M).group(1).split()
    assert claimed == sorted([floor, *newer], key=version)


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb")))
def test_notebooks_use_only_the_public_api(name):
    """A notebook is what users copy: it imports jaxfdi's public namespaces and the studies
    (``jaxfdi.scenarios.<study>``), never an implementation module (``jaxfdi.<...>._name``)."""
    import ast

    cells = json.loads((ROOT / "notebooks" / name).read_text())["cells"]
    code = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
    code = re.sub(r"^\s*[%!].*$", "", code, flags=re.M)  # IPython magics and shell lines
    private = []
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("jaxfdi"):
            private += [
                f"{node.module}.{a.name}"
                for a in node.names
                if any(part.startswith("_") for part in [*node.module.split("."), a.name])
            ]
        elif isinstance(node, ast.Import):
            private += [
                a.name
                for a in node.names
                if a.name.startswith("jaxfdi") and any(p.startswith("_") for p in a.name.split("."))
            ]
        elif (
            isinstance(node, ast.Attribute)
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            root = node.value
            while isinstance(root, ast.Attribute):
                root = root.value
            if isinstance(root, ast.Name) and root.id == "jaxfdi":
                private.append(ast.unparse(node))
    assert private == [], f"{name} reaches into {private}"


def test_citation_names_this_version_and_only_what_exists():
    """CITATION.cff: the package's version and a release date, and every command and module its notes
    name is one the package has (``jaxfdi list``; an importable attribute)."""
    import importlib

    import jaxfdi
    from jaxfdi import cli

    text = (Path(__file__).resolve().parents[2] / "CITATION.cff").read_text()
    assert re.search(r'^version: "(.*)"$', text, re.M).group(1) == jaxfdi.__version__
    assert re.search(r'^date-released: "\d{4}-\d\d-\d\d"$', text, re.M)
    commands = re.findall(r"jaxfdi run ([a-z0-9-]+)", text)
    assert commands and set(commands) <= set(cli.RUNNERS)
    for dotted in re.findall(r"\bjaxfdi(?:\.[a-z_0-9]+)+", text):
        module, _, name = dotted.rpartition(".")
        try:
            importlib.import_module(dotted)
        except ModuleNotFoundError:
            assert hasattr(importlib.import_module(module), name), dotted
    assert (
        "Seed 00" not in text
    )  # the papers are named by their authors, not by our folder's numbers
