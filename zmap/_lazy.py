"""Lazy public names of a package (PEP 562): one mechanism for zmap's and cad_io's packages.

A package lists its public names with the submodule that holds each, and the submodules it
shows as attributes; :func:`attach` returns the module ``__getattr__`` and ``__dir__`` that
import a submodule the first time one of its names is asked for. ``import zmap.access`` thus
compiles no kernels and ``import cad_io`` loads no OCP until a function needs them.

Examples
--------
>>> import zmap.cam
>>> zmap.cam.drop_cutter.__module__
'zmap.cam.drop'
>>> "drop_cutter" in dir(zmap.cam)
True
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = ["attach"]


class _NamesOverSubmodules(types.ModuleType):
    """A package with a public name equal to the submodule that holds it (``zmap.mesh``'s
    function ``triangulate`` in module ``triangulate``): the import system binding the
    submodule on the package must not hide the function."""

    _lazy_shadowed: frozenset = frozenset()

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and name in self._lazy_shadowed:
            return
        super().__setattr__(name, value)


def attach(package: str, names: Mapping[str, str] | None = None,
           submodules: Iterable[str] = ()) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the package ``package`` (its ``__name__``).

    Parameters
    ----------
    package : str
        The package's module name; it must be imported (call this from its ``__init__``).
    names : mapping of str to str
        Public name -> submodule holding it (relative to the package). A name is looked up
        once and then kept on the package.
    submodules : iterable of str
        Submodules reachable as attributes (``zmap.sim``), imported on first use.

    Returns
    -------
    (callable, callable)
        The package's ``__getattr__`` and ``__dir__``.
    """
    names = dict(names or {})
    subs = frozenset(submodules)
    module = sys.modules[package]
    shadowed = frozenset(n for n, where in names.items() if where == n)
    if shadowed:
        module.__class__ = _NamesOverSubmodules
        module._lazy_shadowed = shadowed

    def __getattr__(name: str) -> Any:
        if name in names:
            value = getattr(importlib.import_module(f".{names[name]}", package), name)
            setattr(module, name, value)
            return value
        if name in subs:
            return importlib.import_module(f".{name}", package)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(vars(module)) | set(names) | subs)

    return __getattr__, __dir__
