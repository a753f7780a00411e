"""The package's layering, read from the source: every import of a jaxfdi module points down
the layers (or stays within its own layer), none hides inside a function, and no library module
imports another subpackage's private module (it imports the subpackage's public name).

Two imports happen at run time, by design, and only these (``importlib.import_module``): the
CLI imports the study of the command it runs (``jaxfdi.cli._study``, the module path its
registry names, a study below it), so that ``jaxfdi --help`` imports no study and no JAX; and
the package imports a top-level name or a submodule on first use (``jaxfdi.__getattr__``,
PEP 562), so that ``import jaxfdi`` imports no JAX either.

Layers, lowest first: numerics and I/O <- faults and the stage shapes <- models <- Riccati
and simulation <- filters <- metrics and Monte Carlo <- studies and streaming <- detection <- the
loop <- monitor, tracking, tuning <- GNSS, control <- INS <- plotting <- scenarios <- CLI and the
package's front door. The top level's shared modules live in four private rooms (``_numerics``,
``_io``, ``_simulation``, ``_studies``); a room spans layers, so each of its modules is a unit.
"""

import ast
import collections
import importlib.util
import pathlib

import pytest

import jaxfdi
from jaxfdi import cli

PACKAGE = pathlib.Path(jaxfdi.__file__).parent

#: the private rooms that group the top level's shared modules; each of their modules is a unit of
#: its own (a room spans layers: its modules sit between the subpackages), its ``__init__`` layer 0
ROOMS = ("_numerics", "_io", "_simulation", "_studies")

#: unit (a package, a top-level module or a room's module) -> layer; lower layers never import higher ones
LAYERS = {
    "checks": 0,
    "rotation": 0,
    "_numerics": 0,
    "_numerics.linalg": 0,
    "_io": 0,
    "_io.files": 0,
    "_io.progress": 0,
    "_version": 0,
    "data": 0,
    "distributed": 0,
    "_simulation": 0,
    "_simulation.faults": 1,
    "_simulation.stages": 1,
    "_numerics.levenberg_marquardt": 1,
    "models": 2,
    "_numerics.riccati": 3,
    "_simulation.simulate": 3,
    "filters": 4,
    "_studies": 0,
    "_studies.metrics": 5,
    "_studies.montecarlo": 5,
    "_studies.frame": 5,
    "_studies.study": 6,
    "streaming": 6,
    "detection": 7,
    "_simulation.loop": 8,
    "_simulation.monitor": 9,
    "_simulation.tracking": 9,
    "tuning": 9,
    "gnss": 10,
    "control": 10,
    "ins": 11,
    "plotting": 12,
    "scenarios": 13,
    "cli": 14,
    "__init__": 14,
    "__main__": 14,
}


def _unit(dotted: str) -> str:
    """``jaxfdi.filters._kalman`` -> ``filters``; ``jaxfdi._simulation.loop`` -> ``_simulation.loop``;
    ``jaxfdi`` -> ``__init__``; a top-level name, ``jaxfdi.run_loop``, -> the unit of the module the
    package imports it from on first use (``jaxfdi._WHERE``: ``_simulation.loop``)."""
    parts = dotted.split(".")
    if len(parts) > 2 and parts[1] in ROOMS:
        return f"{parts[1]}.{parts[2]}"
    if len(parts) == 2 and parts[1] in jaxfdi._WHERE:
        return _unit(jaxfdi._WHERE[parts[1]])
    if len(parts) == 1 or not (
        (PACKAGE / parts[1]).is_dir() or (PACKAGE / f"{parts[1]}.py").exists()
    ):
        return "__init__"  # the package itself, or a name its __init__ exports
    return parts[1]


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield ".".join(parts), path


def _is_module(dotted: str) -> bool:
    path = PACKAGE.parent.joinpath(*dotted.split("."))
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


def _imports(path: pathlib.Path):
    """(line, imported module, inside a function) for every import of a jaxfdi module."""
    tree = ast.parse(path.read_text())
    functions = [
        node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
    ]
    inside = {id(n) for f in functions for n in ast.walk(f) if n is not f}
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.ImportFrom)
            and node.level == 0
            and node.module
            and node.module.split(".")[0] == "jaxfdi"
        ):
            # ``from jaxfdi._studies import metrics`` imports the module ``jaxfdi._studies.metrics``
            targets = [
                f"{node.module}.{a.name}" if _is_module(f"{node.module}.{a.name}") else node.module
                for a in node.names
            ]
            if node.module == "jaxfdi":
                targets = [f"jaxfdi.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            targets = [a.name for a in node.names if a.name.split(".")[0] == "jaxfdi"]
        else:
            continue
        for target in targets:
            yield node.lineno, target, id(node) in inside


def test_every_unit_has_a_layer():
    units = {_unit(name) for name, _ in _modules()}
    assert units - set(LAYERS) == set(), "give these modules a layer in LAYERS"


@pytest.mark.parametrize("name,path", list(_modules()), ids=[name for name, _ in _modules()])
def test_imports_point_down_the_layers(name, path):
    source = _unit(name)
    bad = []
    for line, target, in_function in _imports(path):
        unit = _unit(target)
        if in_function:
            bad.append(f"line {line}: {target} imported inside a function")
        elif LAYERS[unit] > LAYERS[source]:
            bad.append(f"line {line}: {target} (layer {LAYERS[unit]}) from layer {LAYERS[source]}")
    assert bad == []


def _run_time_imports(path: pathlib.Path):
    """The innermost function (None: the module's own code) around each ``importlib.import_module``
    or ``__import__`` call."""
    found = []

    def visit(node, function):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Call):
                func = child.func
                called = getattr(func, "attr", None) or getattr(func, "id", None)
                if called in ("import_module", "__import__"):
                    found.append(function)
            inner = (
                child.name
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
                else function
            )
            visit(child, inner)

    visit(ast.parse(path.read_text()), None)
    return found


#: (module, function) -> how many run-time imports it makes: the CLI's study import, the
#: package's two in ``__getattr__`` (a top-level name's module, a submodule)
RUN_TIME_IMPORTS = {("jaxfdi.cli", "_study"): 1, ("jaxfdi", "__getattr__"): 2}


def test_the_only_run_time_imports_are_the_clis_study_and_the_packages_names():
    found = collections.Counter(
        (name, function) for name, path in _modules() for function in _run_time_imports(path)
    )
    assert found == collections.Counter(RUN_TIME_IMPORTS)


def test_the_cli_registry_names_existing_studies_below_it():
    """What ``jaxfdi.cli._study`` imports: each registry entry's module, a study of
    ``jaxfdi.scenarios`` (a layer below the CLI)."""
    modules = [runner.module for registry in cli.REGISTRY.values() for runner in registry.values()]
    assert cli.REGISTRY == {"run": cli.RUNNERS, "tune": cli.TUNERS}
    for module in modules:
        assert module.startswith("jaxfdi.scenarios."), module
        assert importlib.util.find_spec(module) is not None, module
        assert LAYERS[_unit(module)] < LAYERS["cli"], module


SUBPACKAGES = sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists())


def _private_module_of_another_subpackage(importer: str, target: str) -> bool:
    """``jaxfdi.<sub>._<module>`` (any depth) imported from outside ``<sub>``."""
    parts = target.split(".")
    if len(parts) < 3 or parts[1] not in SUBPACKAGES:
        return False
    own = importer.split(".")[1] if importer.count(".") >= 1 else None
    return parts[1] != own and any(part.startswith("_") for part in parts[2:])


def _targets(path: pathlib.Path):
    """(line, module) for every jaxfdi module an import names, ``from jaxfdi.x import _y`` as ``jaxfdi.x._y``."""
    for node in ast.walk(ast.parse(path.read_text())):
        if (
            isinstance(node, ast.ImportFrom)
            and node.level == 0
            and (node.module or "").startswith("jaxfdi")
        ):
            yield node.lineno, node.module
            yield from (
                (node.lineno, f"{node.module}.{a.name}")
                for a in node.names
                if a.name.startswith("_")
            )
        elif isinstance(node, ast.Import):
            yield from ((node.lineno, a.name) for a in node.names if a.name.startswith("jaxfdi"))


#: the library and the CLI (the studies are held to more: ``test_a_study_imports_only_the_public_api``)
LIBRARY = [(n, p) for n, p in _modules() if not n.startswith("jaxfdi.scenarios")]
STUDIES = [(n, p) for n, p in _modules() if n.startswith("jaxfdi.scenarios")]


@pytest.mark.parametrize("name,path", LIBRARY, ids=[name for name, _ in LIBRARY])
def test_no_library_module_imports_another_subpackages_private_module(name, path):
    bad = [
        f"line {line}: {target}"
        for line, target in _targets(path)
        if _private_module_of_another_subpackage(name, target)
    ]
    assert bad == []


def _private(target: str) -> bool:
    return any(part.startswith("_") for part in target.split(".")[1:])


@pytest.mark.parametrize("name,path", STUDIES, ids=[name for name, _ in STUDIES])
def test_a_study_imports_only_the_public_api(name, path):
    """The papers' studies are users of the library: from it they import public modules and
    public names only (``jaxfdi``, ``jaxfdi.filters``, ``jaxfdi.models.f16``, ...), never
    ``jaxfdi.x._y`` or ``from jaxfdi.x import _y``; among themselves they may share helpers."""
    bad = [
        f"line {line}: {target}"
        for line, target in _targets(path)
        if not target.startswith("jaxfdi.scenarios") and _private(target)
    ]
    assert bad == []
