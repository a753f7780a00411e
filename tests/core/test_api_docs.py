"""The public API is explicit and documented (issue 28): the package and every subpackage
define ``__all__``, every name in it exists, and every one has a docstring (100 %):
modules, classes (a NamedTuple's generated ``X(a, b)`` text does not count), functions;
constants carry a ``#:`` comment on the line above their assignment."""
import ast
import functools
import importlib
import inspect
import pkgutil
import types
from pathlib import Path

import pytest

import jaxfdi

PACKAGES = ["jaxfdi"] + sorted(m.name for m in pkgutil.walk_packages(jaxfdi.__path__, "jaxfdi.") if m.ispkg)
ROOT = Path(jaxfdi.__file__).parent


@functools.lru_cache(maxsize=1)
def documented_constants() -> frozenset[str]:
    """Names assigned at module level under jaxfdi with a ``#:`` comment right above or a
    string literal right after."""
    names = set()
    for path in ROOT.rglob("*.py"):
        source = path.read_text()
        lines = source.splitlines()
        body = ast.parse(source).body
        for i, node in enumerate(body):
            if isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                above = lines[node.lineno - 2].lstrip() if node.lineno >= 2 else ""
                after = body[i + 1] if i + 1 < len(body) else None
                string_after = (isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                                and isinstance(after.value.value, str))
                if above.startswith("#:") or string_after:
                    names |= {t.id for t in targets if isinstance(t, ast.Name)}
    return frozenset(names)


def has_docstring(obj) -> bool:
    doc = obj.__doc__ if isinstance(obj, types.ModuleType) else inspect.getdoc(obj)
    if inspect.isclass(obj):
        doc = obj.__dict__.get("__doc__")  # its own, not inherited
        if doc and hasattr(obj, "_fields") and doc.startswith(f"{obj.__name__}("):  # NamedTuple's generated one
            doc = None
    return bool(doc and doc.strip())


@pytest.mark.parametrize("package", PACKAGES)
def test_every_name_in_all_exists_and_has_a_docstring(package):
    module = importlib.import_module(package)
    assert isinstance(getattr(module, "__all__", None), (list, tuple)), f"{package} has no __all__"
    assert len(set(module.__all__)) == len(module.__all__), f"{package}.__all__ repeats a name"
    constants = None
    missing = []
    for name in module.__all__:
        if not hasattr(module, name):  # a submodule not imported yet (what ``import *`` would import)
            importlib.import_module(f"{package}.{name}")
        obj = getattr(module, name)
        if isinstance(obj, types.ModuleType) or inspect.isclass(obj) or inspect.isroutine(obj) or callable(obj):
            if not has_docstring(obj):
                missing.append(name)
        else:
            constants = documented_constants() if constants is None else constants
            if name not in constants:
                missing.append(name)
    assert missing == [], f"{package}: undocumented public names {missing}"


def test_all_is_what_star_import_gives():
    namespace = {}
    exec("from jaxfdi import *", namespace)
    assert set(jaxfdi.__all__) <= set(namespace)
