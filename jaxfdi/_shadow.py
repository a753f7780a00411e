"""Modules named like the function they define (``jaxfdi.monitor``, ``jaxfdi.simulate``,
``jaxfdi.filters.time_varying``, ...): the package attribute is the module, so that
``import jaxfdi.monitor as m`` gives the module, and the function lives at
``jaxfdi.monitor.monitor`` (``from jaxfdi.monitor import monitor``). Calling the module
itself, the old spelling ``jaxfdi.monitor(...)``, still works: it calls the function and
warns once per call site with a ``DeprecationWarning`` naming the new path.
"""
from __future__ import annotations

import sys
import types
import warnings


class CallableModule(types.ModuleType):
    """A module whose call forwards to its function of the same name (deprecated)."""

    def __call__(self, *args, **kwargs):
        short = self.__name__.rpartition(".")[2]
        warnings.warn(f"calling the module {self.__name__} is deprecated: call {self.__name__}.{short} "
                      f"(from {self.__name__} import {short})", DeprecationWarning, stacklevel=2)
        return getattr(self, short)(*args, **kwargs)


def unshadow(package: str, *names: str) -> None:
    """Make ``package.<name>`` the submodule ``package.<name>`` (callable, deprecated)
    for each name, replacing a function of the same name imported over it."""
    parent = sys.modules[package]
    for name in names:
        module = sys.modules[f"{package}.{name}"]
        if not isinstance(module, CallableModule):
            module.__class__ = CallableModule
        setattr(parent, name, module)
