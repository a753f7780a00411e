"""The public API is explicit and documented: the package, each subpackage and the public
modules ``checks``, ``rotation``, ``plotting``, ``streaming`` and ``distributed`` define ``__all__`` (a name
is public when a study, a notebook or a user needs it: no cap); every function among them
documents its result (a ``Returns:`` section), every class its fields or members
(``Attributes:``) and every constant has a line in its package's docstring; and the API
pages, ``docs/api/<package>.md``, render each of these namespaces exactly once. Every other
module and name is implementation."""

import importlib
import inspect
import pkgutil
import re
import types
from pathlib import Path

import nbformat
import numpy as np
import pytest

import jaxfdi

PUBLIC_MODULES = [
    "jaxfdi.checks",
    "jaxfdi.rotation",
    "jaxfdi.plotting",
    "jaxfdi.streaming",
    "jaxfdi.distributed",
]
PACKAGES = (
    ["jaxfdi"]
    + sorted(
        m.name
        for m in pkgutil.walk_packages(jaxfdi.__path__, "jaxfdi.")
        if m.ispkg and not any(part.startswith("_") for part in m.name.split("."))
    )
    + PUBLIC_MODULES
)
API_PAGE = Path(__file__).resolve().parents[2] / "docs" / "api" / "index.md"


def public(package: str) -> dict:
    """``{name: object}`` of ``package.__all__`` (a submodule is imported if need be)."""
    module = importlib.import_module(package)
    names = getattr(module, "__all__", None)
    assert isinstance(names, (list, tuple)), f"{package} has no __all__"
    assert len(set(names)) == len(names), f"{package}.__all__ repeats a name"
    return {
        name: getattr(module, name)
        if hasattr(module, name)
        else importlib.import_module(f"{package}.{name}")
        for name in names
    }


def own_docstring(obj) -> str:
    doc = obj.__dict__.get("__doc__") if inspect.isclass(obj) else obj.__doc__
    if (
        inspect.isclass(obj)
        and doc
        and hasattr(obj, "_fields")
        and doc.startswith(f"{obj.__name__}(")
    ):
        return ""  # a NamedTuple's generated text
    return inspect.cleandoc(doc or "")


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_documents_its_result(package):
    missing = []
    for name, obj in public(package).items():
        doc = own_docstring(obj)
        if isinstance(obj, types.ModuleType):
            ok = bool(doc)
        elif isinstance(obj, (int, float, str, tuple, dict, np.ndarray)):
            # a constant (a number, a name, a table or an array): its package's docstring says what it is
            ok = f"``{name}``" in inspect.getdoc(importlib.import_module(package))
        elif inspect.isclass(obj):
            ok = "\nAttributes:\n" in doc
        else:
            ok = callable(obj) and "\nReturns:\n" in doc
        if not ok:
            missing.append(name)
    assert missing == [], f"{package}: no docstring, Returns: or Attributes: section for {missing}"


def test_the_api_pages_render_every_public_namespace_once_and_the_index_links_each_page():
    pages = sorted(p for p in API_PAGE.parent.glob("*.md") if p != API_PAGE)
    rendered = [n for p in pages for n in re.findall(r"^::: ([\w.]+)$", p.read_text(), flags=re.M)]
    assert sorted(rendered) == sorted(PACKAGES)
    linked = re.findall(r"\]\((\w+)\.md\)", API_PAGE.read_text())
    assert sorted(linked) == [p.stem for p in pages]


def test_all_is_what_star_import_gives():
    namespace = {}
    exec("from jaxfdi import *", namespace)
    assert set(jaxfdi.__all__) <= set(namespace)


@pytest.mark.parametrize("package", PACKAGES)
def test_every_field_of_a_public_named_tuple_is_a_documented_attribute(package):
    """The API reference shows a result's fields: each ``_fields`` entry has its own line
    (``name:`` or ``name (type):``) in the class's ``Attributes:`` section."""
    missing = []
    for name, obj in public(package).items():
        if inspect.isclass(obj) and hasattr(obj, "_fields"):
            section = own_docstring(obj).partition("\nAttributes:\n")[2]
            documented = set(re.findall(r"^ {2,4}(\w+)(?: \(.*?\))?:", section, flags=re.M))
            missing += [f"{name}.{field}" for field in obj._fields if field not in documented]
    assert missing == [], f"{package}: fields without an attribute line: {missing}"


def _public_objects() -> dict:
    return {name: obj for package in PACKAGES for name, obj in public(package).items()}


def _library_classes(annotation, namespace: dict) -> list[type]:
    """The jaxfdi classes an annotation string names (``Orbit``, ``dict[str, Transform]``, ``A | B``)."""
    found = []
    for word in re.findall(r"(?<![\w.])([A-Z]\w*)\b", str(annotation)):
        obj = namespace.get(word)
        if inspect.isclass(obj) and obj.__module__.startswith("jaxfdi"):
            found.append(obj)
    return found


def _globals(fn) -> dict:
    """The module namespace of a function, through ``jax.jit``'s wrapper."""
    return inspect.unwrap(fn).__globals__


def test_every_required_argument_of_a_public_function_is_built_by_the_public_api():
    """A user calls a public function without a private import: each jaxfdi type that a required argument's annotation
    names (one of them, for a union) is public, or a public function returns it (its return annotation or its
    ``Returns:`` section names it), or it is a field of such a result (one level down)."""
    objects = _public_objects()
    functions = [
        (name, obj) for name, obj in objects.items() if callable(obj) and not inspect.isclass(obj)
    ]
    built = {obj for obj in objects.values() if inspect.isclass(obj)}
    for _, fn in functions:
        built.update(_library_classes(inspect.signature(fn).return_annotation, _globals(fn)))
        built.update(_library_classes(own_docstring(fn).partition("\nReturns:\n")[2], _globals(fn)))
    for cls in list(built):
        module = vars(importlib.import_module(cls.__module__))
        for annotation in getattr(cls, "__annotations__", {}).values():
            built.update(_library_classes(annotation, module))
    unbuildable = []
    for name, fn in functions:
        for parameter in inspect.signature(fn).parameters.values():
            if parameter.default is not inspect.Parameter.empty:
                continue
            needed = _library_classes(parameter.annotation, _globals(fn))
            if needed and not any(cls in built for cls in needed):
                unbuildable.append(f"{name}({parameter.name}: {parameter.annotation})")
    assert unbuildable == [], f"arguments only private code can build: {unbuildable}"


DOC_PAGES = [p for p in (API_PAGE.parents[1]).rglob("*.md") if "api" not in p.parts] + [
    API_PAGE.parents[2] / "README.md"
]
NOTEBOOKS = sorted((API_PAGE.parents[2] / "notebooks").glob("*.ipynb"))


def _private_definitions() -> dict[str, str]:
    """``{name: module}`` of the top-level functions and classes of jaxfdi's modules outside ``scenarios`` (a public
    module each: its names are reachable as ``jaxfdi.scenarios.<study>.<name>``)."""
    found = {}
    for info in pkgutil.walk_packages(jaxfdi.__path__, "jaxfdi."):
        if ".scenarios" in info.name or info.ispkg or info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (
                not name.startswith("_")
                and (inspect.isfunction(obj) or inspect.isclass(obj))
                and obj.__module__ == info.name
            ):
                found.setdefault(name, info.name)
    return found


def test_the_docs_and_notebooks_name_only_the_public_api():
    """The pages, the README and the notebooks' text tell a user to call only what ``__all__`` exports: a backticked
    name of a private module's function or class fails, unless it is written with its private path (a ``_`` segment:
    an implementation note) or is also a field of a public result (``Plant.measure``)."""
    objects = _public_objects()
    fields = {
        field
        for obj in objects.values()
        if inspect.isclass(obj)
        for field in getattr(obj, "_fields", ())
    }
    private = {
        name: module
        for name, module in _private_definitions().items()
        if name not in objects and name not in fields
    }
    texts = [(str(p.relative_to(API_PAGE.parents[2])), p.read_text()) for p in DOC_PAGES]
    for path in NOTEBOOKS:
        cells = nbformat.read(path, as_version=4).cells
        texts += [
            (f"notebooks/{path.name}", cell.source)
            for cell in cells
            if cell.cell_type == "markdown"
        ]
    named = []
    for where, text in texts:
        for reference in re.findall(r"`([A-Za-z_][\w.]*)(?:\(|`)", text):
            name = reference.split(".")[-1]
            if name in private and not any(
                part.startswith("_") for part in reference.split(".")[:-1]
            ):
                named.append(f"{where}: `{reference}` ({private[name]})")
    assert named == [], "private names in the user's docs:\n" + "\n".join(sorted(set(named)))
