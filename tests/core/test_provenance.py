"""Every results file the CLI writes records how it was made (issue 28), ``jaxfdi
--version``, and module names that no function shadows.

The scenarios are not run (each costs a minute or more): a fake runner goes through the
same writers (``cli._write_study``, ``_io.write_json``, ``tuning.save_params`` with the
CLI's meta), and every real runner is checked to write its JSON through them only."""

import ast
import inspect
import json
import subprocess
import sys
import textwrap
import types

import jax
import jaxlib
import numpy as np
import pytest

import jaxfdi
from jaxfdi import cli
from jaxfdi._io import files as _io

FIELDS = {
    "jaxfdi",
    "jax",
    "jaxlib",
    "numpy",
    "python",
    "backend",
    "device_kind",
    "device_count",
    "x64",
    "command",
    "seed",
    "created",
}


def check_provenance(record, argv, seed):
    assert set(record) == FIELDS
    assert record["jaxfdi"] == jaxfdi.__version__ and record["jax"] == jax.__version__
    assert record["jaxlib"] == jaxlib.__version__ and record["numpy"] == np.__version__
    assert record["backend"] == jax.default_backend()
    assert record["device_kind"] == jax.local_devices()[0].device_kind
    assert record["x64"] is True  # main turns float64 on
    assert record["command"] == "jaxfdi " + " ".join(argv) and record["seed"] == seed


def fake_study(args, folder):
    """A study written the way the scenario runners write theirs."""
    rows = [{"rate": 1.0}]
    study = types.SimpleNamespace(
        config={"runs": args.runs, "seed": args.seed},
        rows=rows,
        to_frame=lambda: __import__("pandas").DataFrame(rows),
    )
    return cli._write_study(study, args, folder, "fake.json", {}, 0.5)


def test_study_json_written_by_the_cli_carries_provenance(monkeypatch, tmp_path):
    monkeypatch.setitem(cli.RUNNERS, "fake", cli.Runner(fake_study, "fake"))
    argv = ["run", "fake", "--runs", "3", "--seed", "17", "--quiet", "--out", str(tmp_path / "out")]
    assert cli.main(argv) == 0
    data = json.loads((tmp_path / "out" / "fake.json").read_text())
    assert data["config"] == {"runs": 3, "seed": 17} and data["rows"] == [{"rate": 1.0}]
    assert (tmp_path / "out" / "fake.csv").read_text().splitlines() == [
        "rate",
        "1.0",
    ]  # the table beside it
    check_provenance(data["provenance"], argv, 17)


def test_tuned_parameters_npz_and_json_carry_provenance(monkeypatch, tmp_path):
    """The tuners' meta holds ``_io.provenance()``, written into the .npz by save_params."""
    from jaxfdi.tuning import load_params, positive, save_params

    def fake_tune(args, folder):
        save_params(
            folder / "fake-tuned.npz",
            {"q": np.zeros(2)},
            {"q": positive()},
            {"seed": args.seed, "provenance": _io.provenance()},
        )
        _io.write_json(folder / "fake-tuning.json", {"config": {"seed": args.seed}})
        return "wrote"

    monkeypatch.setitem(cli.TUNERS, "fake", cli.Runner(fake_tune, "fake"))
    argv = ["tune", "fake", "--seed", "5", "--quiet", "--out", str(tmp_path / "out")]
    assert cli.main(argv) == 0
    _, _, meta = load_params(tmp_path / "out" / "fake-tuned.npz")
    check_provenance(meta["provenance"], argv, 5)
    check_provenance(
        json.loads((tmp_path / "out" / "fake-tuning.json").read_text())["provenance"], argv, 5
    )


def _calls(function):
    """Names of the functions called in ``function``'s source (``a.b.c(...)`` -> ``c``)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            names.add(f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None))
    return names, tree


@pytest.mark.parametrize(
    "kind,name",
    [("run", n) for n in sorted(cli.RUNNERS)] + [("tune", n) for n in sorted(cli.TUNERS)],
)
def test_every_cli_command_writes_json_through_the_provenance_writer(kind, name):
    """Each runner writes its JSON with ``_io.write_json`` (directly or by
    ``_write_study``), never ``json.dump``; a tuner's ``save_params`` meta names
    ``provenance``."""
    runner = (cli.RUNNERS if kind == "run" else cli.TUNERS)[name]
    calls, tree = _calls(runner.run)
    assert calls & {"write_json", "_write_study"}, (
        f"{kind} {name} writes no JSON through _io.write_json"
    )
    assert not calls & {"dump", "dumps", "savez", "savez_compressed", "save"}, (
        f"{kind} {name} writes files itself"
    )
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "save_params":
            meta = node.args[3] if len(node.args) > 3 else None
            assert isinstance(meta, ast.Dict) and "provenance" in [
                getattr(k, "value", None) for k in meta.keys
            ]


def test_write_json_keeps_an_existing_provenance_and_leaves_non_dicts_alone(tmp_path):
    mine = {"jaxfdi": "x"}
    _io.write_json(tmp_path / "a.json", {"provenance": mine})
    assert json.loads((tmp_path / "a.json").read_text()) == {"provenance": mine}
    _io.write_json(tmp_path / "b.json", [1, 2])
    assert json.loads((tmp_path / "b.json").read_text()) == [1, 2]


def test_version_option():
    proc = subprocess.run(
        [sys.executable, "-m", "jaxfdi", "--version"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0 and proc.stdout.strip() == f"jaxfdi {jaxfdi.__version__}"


# --- a function and its module never share a name ------------------------------------------

#: (public package, the private module defining the function, the function's name)
FUNCTIONS = [
    ("jaxfdi", "jaxfdi._simulation.monitor", "monitor"),
    ("jaxfdi", "jaxfdi._simulation.simulate", "simulate"),
    ("jaxfdi.filters", "jaxfdi.filters._time_varying", "time_varying"),
    ("jaxfdi.detection", "jaxfdi.detection._dual_filter", "dual_filter"),
    ("jaxfdi.models.f16", "jaxfdi.models.f16._linearize", "linearize"),
    ("jaxfdi.models.f16", "jaxfdi.models.f16._trim", "trim"),
]


@pytest.mark.parametrize("package,module_name,name", FUNCTIONS, ids=[f[2] for f in FUNCTIONS])
def test_the_package_attribute_is_the_function_and_its_module_is_private(
    package, module_name, name
):
    """``jaxfdi.monitor`` is the function; its module is ``jaxfdi._simulation.monitor``, so no module
    is shadowed by a function of its name and nothing needs a callable module (a function
    that is not public, ``time_varying``, is its private module's only)."""
    import importlib

    module = importlib.import_module(module_name)
    function = getattr(module, name)
    assert inspect.isfunction(function) and function.__module__ == module_name
    assert type(module) is types.ModuleType
    public = importlib.import_module(package)
    assert getattr(public, name, function) is function and (name in public.__all__) == hasattr(
        public, name
    )
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(f"{package}.{name}")


def test_no_module_of_the_package_is_callable():
    import importlib
    import pkgutil

    modules = [
        importlib.import_module(info.name)
        for info in pkgutil.walk_packages(jaxfdi.__path__, "jaxfdi.")
        if not info.name.endswith("__main__")
    ]
    assert [m.__name__ for m in modules if type(m) is not types.ModuleType or callable(m)] == []


def test_no_module_is_shadowed_by_a_name_of_its_package():
    """Every submodule of jaxfdi is what its package's attribute of that name holds."""
    import importlib
    import pkgutil

    shadowed = []
    for info in pkgutil.walk_packages(jaxfdi.__path__, "jaxfdi."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        package, _, short = info.name.rpartition(".")
        if getattr(importlib.import_module(package), short, module) is not module:
            shadowed.append(info.name)
    assert shadowed == []
