"""The public API is small, explicit and documented: the package, each subpackage and the
public modules ``plotting``, ``streaming`` and ``distributed`` define ``__all__``, which
together hold at most 150 names; every function among them documents its result (a
``Returns:`` section) and every class its fields or members (``Attributes:``); and the
one API page, ``docs/api/index.md``, renders exactly these namespaces. Every other module
and name is implementation."""
import importlib
import inspect
import pkgutil
import re
import types
from pathlib import Path

import pytest

import jaxfdi

PUBLIC_MODULES = ["jaxfdi.plotting", "jaxfdi.streaming", "jaxfdi.distributed"]
PACKAGES = (["jaxfdi"] + sorted(m.name for m in pkgutil.walk_packages(jaxfdi.__path__, "jaxfdi.") if m.ispkg)
            + PUBLIC_MODULES)
MAX_PUBLIC_NAMES = 150
API_PAGE = Path(__file__).resolve().parents[2] / "docs" / "api" / "index.md"


def public(package: str) -> dict:
    """``{name: object}`` of ``package.__all__`` (a submodule is imported if need be)."""
    module = importlib.import_module(package)
    names = getattr(module, "__all__", None)
    assert isinstance(names, (list, tuple)), f"{package} has no __all__"
    assert len(set(names)) == len(names), f"{package}.__all__ repeats a name"
    return {name: getattr(module, name) if hasattr(module, name) else importlib.import_module(f"{package}.{name}")
            for name in names}


def own_docstring(obj) -> str:
    doc = obj.__dict__.get("__doc__") if inspect.isclass(obj) else obj.__doc__
    if inspect.isclass(obj) and doc and hasattr(obj, "_fields") and doc.startswith(f"{obj.__name__}("):
        return ""  # a NamedTuple's generated text
    return inspect.cleandoc(doc or "")


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_documents_its_result(package):
    missing = []
    for name, obj in public(package).items():
        doc = own_docstring(obj)
        if isinstance(obj, types.ModuleType):
            ok = bool(doc)
        elif inspect.isclass(obj):
            ok = "\nAttributes:\n" in doc
        else:
            ok = callable(obj) and "\nReturns:\n" in doc
        if not ok:
            missing.append(name)
    assert missing == [], f"{package}: no docstring, Returns: or Attributes: section for {missing}"


def test_the_public_api_has_at_most_150_names():
    count = sum(len(public(package)) for package in PACKAGES)
    assert count <= MAX_PUBLIC_NAMES, f"{count} public names"


def test_the_one_api_page_renders_every_public_namespace():
    rendered = re.findall(r"^::: ([\w.]+)$", API_PAGE.read_text(), flags=re.M)
    assert sorted(rendered) == sorted(PACKAGES)
    assert [p.name for p in API_PAGE.parent.iterdir()] == ["index.md"]


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
