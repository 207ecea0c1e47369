"""A design, as the drop-cutter and the comparison see it: heights over a region.

Consumers (:mod:`zmap.cam`, :mod:`zmap.verify`) never ask what type a design is: they call
:func:`as_design` and get a :class:`Design` (heights at x, y with NaN where there is no
surface, the xy extent, the natural sample spacing, whether the heights are the shape itself,
and a fast grid sampler where the type has one). :class:`~zmap.ZMap`,
:class:`~zmap.tiled.TiledZMap`, :class:`~zmap.model.PrecisionModel` and ``heights(x, y)``
callables are built in. Packages
above zmap register their own types with :func:`register` and the files they read with
:func:`register_reader` (``cad_io`` registers its STEP ``Part`` and ``.step``/``.stp``); a
package that declares a ``zmap.designs`` entry point is imported the first time a file suffix
is not known, so zmap itself imports none of them.

Examples
--------
>>> import numpy as np
>>> from zmap import ZMap
>>> d = as_design(ZMap.from_function(lambda x, y: x + y, (0, 0, 4, 2), 0.5))
>>> d.kind, d.bounds, d.exact, float(d.heights(np.array([1.0]), np.array([1.0]))[0])
('zmap', (0.0, 0.0, 4.0, 2.0), True, 2.0)
>>> as_design(lambda x, y: 0 * x).kind
'callable'
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

__all__ = ["Design", "as_design", "read_design", "register", "register_reader"]


@dataclass(frozen=True)
class Design:
    """A design's heights and what a consumer needs to sample them.

    Attributes
    ----------
    heights : callable ``(x, y) -> z``
        Top-most heights in mm, NaN where there is no surface.
    bounds : (xmin, ymin, xmax, ymax) or None
        The xy extent (None: unbounded, a callable).
    pitch : float or None
        The design's natural spacing between samples, mm.
    kind : str
        "zmap", "precision model", "part", "callable", or a registered type's name.
    exact : bool
        The heights are the shape itself (a z-map's own surface, a part's B-rep), not a model within
        a tolerance of it.
    grid : callable ``(x0, y0, h, nx, ny) -> (nx, ny)`` or None
        Heights on a grid, where the type samples a grid faster than scattered points.
    drop_pitch, drop_check
        The drop-cutter's default sample spacing (mm) and fine samples per interval for a
        design that is not a z-map (None: the cutter radius / 8).
    source
        The object itself.
    """

    heights: Callable[[np.ndarray, np.ndarray], np.ndarray]
    bounds: tuple | None
    pitch: float | None
    kind: str
    exact: bool
    grid: Callable | None = None
    drop_pitch: float | None = None
    drop_check: int = 4
    source: Any = None

    def sample_grid(self, x0: float, y0: float, h: float, nx: int, ny: int) -> np.ndarray:
        """``(nx, ny)`` heights at ``(x0 + i h, y0 + j h)``."""
        if self.grid is not None:
            return self.grid(x0, y0, h, nx, ny)
        X, Y = np.meshgrid(x0 + h * np.arange(nx), y0 + h * np.arange(ny), indexing="ij")
        return np.asarray(self.heights(X.ravel(), Y.ravel()), dtype=np.float64).reshape(nx, ny)


_TYPES: list = []
_READERS: dict = {}
_PLUGINS = {"loaded": False}


def register(cls: type, adapter: Callable[[Any], Design]) -> None:
    """Make instances of ``cls`` designs: ``adapter(obj)`` gives their :class:`Design`."""
    _TYPES.append((cls, adapter))


def register_reader(suffixes: tuple, reader: Callable[[str], Any], what: str) -> None:
    """Read files ending in one of ``suffixes`` (lower case, with the dot) with ``reader(path)``;
    ``what`` names them in messages ("a STEP part")."""
    for s in suffixes:
        _READERS[s.lower()] = (reader, what)


def _load_plugins() -> bool:
    """Import the packages that declare a ``zmap.designs`` entry point (once); True if any."""
    if _PLUGINS["loaded"]:
        return False
    _PLUGINS["loaded"] = True
    from importlib.metadata import entry_points

    found = False
    for ep in entry_points(group="zmap.designs"):
        ep.load()
        found = True
    return found


def as_design(obj: Any) -> Design:
    """The :class:`Design` of a z-map, tiled z-map, precision model, registered type (a STEP
    part) or ``heights(x, y)`` callable; ValueError for anything else."""
    if isinstance(obj, Design):
        return obj
    from .grid import ZMap
    from .model import PrecisionModel

    if isinstance(obj, ZMap):
        from .interpolate import bezier

        return Design(lambda x, y: bezier(obj, x, y), tuple(float(v) for v in obj.bounds), min(obj.dx, obj.dy),
                      "zmap", True, source=obj)
    if isinstance(obj, PrecisionModel):
        p = min(obj.base.dx, obj.base.dy) / 4
        return Design(obj.height, tuple(float(v) for v in obj.base.bounds), p, "precision model", False,
                      drop_pitch=p, drop_check=4, source=obj)
    from .tiled.store import TiledZMap  # zarr and dask load only when the store is read

    if isinstance(obj, TiledZMap):
        from .tiled.store import bezier as tiled_bezier

        return Design(lambda x, y: tiled_bezier(obj, x, y), tuple(float(v) for v in obj.bounds),
                      min(obj.dx, obj.dy), "tiled zmap", True, source=obj)
    for cls, adapter in _TYPES:
        if isinstance(obj, cls):
            return adapter(obj)
    if callable(obj):
        return Design(obj, None, None, "callable", False, source=obj)
    raise ValueError("a design must be a ZMap, a TiledZMap, a PrecisionModel, a STEP part (cad_io.Part) or a "
                     f"heights(x, y) callable, got {type(obj).__name__}")


def read_design(path: str | os.PathLike) -> Any:
    """A design from a file: ``.zpm`` precision model, ``.zmap.npz`` z-map, ``.zarr`` tiled
    z-map (a folder), or a registered suffix (``.step``/``.stp`` through cad_io)."""
    from .errors import ZMapFileError

    p = os.fspath(path)
    if not os.path.exists(p):
        raise ZMapFileError(p, "no such file")
    low = p.lower().rstrip("/\\")
    if low.endswith(".zarr"):
        from .tiled.store import TiledZMap

        return TiledZMap.open(p)
    if low.endswith(".zpm"):
        from .model import PrecisionModel

        return PrecisionModel.load(p)
    if low.endswith(".npz"):
        from .grid import ZMap

        return ZMap.load(p)
    for attempt in (0, 1):
        for suffix, (reader, _what) in _READERS.items():
            if low.endswith(suffix):
                return reader(p)
        if attempt == 0 and not _load_plugins():
            break
    known = ", ".join(f"{s} ({w})" for s, (_r, w) in sorted(_READERS.items()))
    raise ValueError(f"design {p!r} is not a .zpm precision model, a .zmap.npz z-map or a .zarr tiled z-map"
                     + (f", nor one of {known}" if known else " (a .step part needs cad_io installed)"))
