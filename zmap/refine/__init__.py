"""Precision refinements of a base z-map (paper 004, §3): EZ-maps and CZ-maps.

Submodules load on first use: ``zmap.refine.ez`` (:class:`EZMap`, :func:`build_ez`) and
``zmap.refine.cz`` (core z-maps).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["EZMap", "build_ez", "cz", "ez"]

_LAZY = {"EZMap": "ez", "build_ez": "ez"}


def __getattr__(name: str) -> Any:
    if name in ("ez", "cz"):
        return importlib.import_module(f".{name}", __name__)
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'zmap.refine' has no attribute {name!r}")
