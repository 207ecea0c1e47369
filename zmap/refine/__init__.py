"""Precision refinements of a base z-map (paper 004, §3): EZ-maps and CZ-maps.

Submodules load on first use: ``zmap.refine.ez`` (:class:`EZMap`, :func:`build_ez`) and
``zmap.refine.cz`` (core z-maps).
"""

from __future__ import annotations

from .._lazy import attach


__all__ = ["EZMap", "build_ez", "cz", "ez"]

_LAZY = {"EZMap": "ez", "build_ez": "ez"}


__getattr__, __dir__ = attach(__name__, _LAZY, submodules=("ez", "cz"))
