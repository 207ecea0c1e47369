"""The z-map grid: heights on a regular xy grid (paper 004, Eq. 2).

``z[i, j]`` is the height at ``x = x0 + i*dx``, ``y = y0 + j*dy``; NaN marks a grid point
with no surface. A map may carry a local frame (rotation angle and origin) so that the
rotated core maps (CZ-maps) of the refinement step are the same type: ``x0, y0, dx, dy``
are then measured in the local frame, and ``world = origin + R(angle) @ local``.
"""

from __future__ import annotations

import copy
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ._npzfile import atomic_write, atomic_write_text, read_npz, write_npz
from .errors import ZMapFileError
from .gridspec import GridSpec, OnGrid

__all__ = ["ZMap", "FORMAT_NAME", "FORMAT_VERSION", "atomic_write", "atomic_write_text"]

FORMAT_NAME = "zmap.ZMap"
FORMAT_VERSION = 1
_LAYER_PREFIX = "layer__"


def _finite_float(name: str, value: Any) -> float:
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(f):
        raise ValueError(f"{name} must be finite, got {f!r}")
    return f


def _positive_float(name: str, value: Any) -> float:
    f = _finite_float(name, value)
    if f <= 0.0:
        raise ValueError(f"{name} must be positive, got {f!r}")
    return f


@dataclass(eq=False)
class ZMap(OnGrid):
    """Heights on a regular grid, NaN where there is no surface.

    Parameters
    ----------
    x0, y0 : float
        Grid origin in mm (in the local frame when ``angle`` or ``origin`` is set).
    dx, dy : float
        Grid intervals in mm, positive; they may differ.
    z : ndarray of shape (nx, ny), float64
        Heights in mm, ``z[i, j]`` at ``(x0 + i*dx, y0 + j*dy)``; NaN = no surface.
    angle : float
        Rotation of the local frame about +z, radians (0 for a plain map).
    origin : tuple of float
        World position of the local frame's origin (``(0, 0)`` for a plain map).
    meta : dict
        JSON-serialisable metadata: ``units``, ``source``, ``method`` and anything else.
    layers : dict of str to ndarray of shape (nx, ny)
        Side arrays saved with the map, e.g. which face and which method gave each height.

    Examples
    --------
    >>> import numpy as np
    >>> zm = ZMap(0.0, 0.0, 1.0, 1.0, np.zeros((3, 4)))
    >>> zm.shape, zm.bounds
    ((3, 4), (0.0, 0.0, 2.0, 3.0))
    """

    x0: float
    y0: float
    dx: float
    dy: float
    z: np.ndarray
    angle: float = 0.0
    origin: tuple[float, float] = (0.0, 0.0)
    meta: dict = field(default_factory=dict)
    layers: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.x0 = _finite_float("x0", self.x0)
        self.y0 = _finite_float("y0", self.y0)
        self.dx = _positive_float("dx", self.dx)
        self.dy = _positive_float("dy", self.dy)
        self.angle = _finite_float("angle", self.angle)
        if np.shape(self.origin) != (2,):
            raise ValueError(f"origin must be a pair (ox, oy), got {np.asarray(self.origin).tolist()!r}")
        self.origin = (_finite_float("origin[0]", self.origin[0]), _finite_float("origin[1]", self.origin[1]))
        z = np.asarray(self.z)
        if z.ndim != 2:
            raise ValueError(f"z must be a 2D array of shape (nx, ny), got shape {z.shape}")
        if z.shape[0] < 2 or z.shape[1] < 2:
            raise ValueError(f"z must have at least 2 grid points along each axis, got shape {z.shape}")
        if not np.issubdtype(z.dtype, np.number) or np.iscomplexobj(z):
            raise ValueError(f"z must hold real numbers, got dtype {z.dtype}")
        if np.isinf(z).any():
            raise ValueError("z holds infinite heights; use NaN to mark 'no surface'")
        self.z = np.ascontiguousarray(z, dtype=np.float64)
        self.meta = dict(self.meta)
        self.meta.setdefault("units", "mm")
        layers = {}
        for name, arr in dict(self.layers).items():
            arr = np.asarray(arr)
            if arr.shape != self.z.shape:
                raise ValueError(f"layer {name!r} must have the shape of z {self.z.shape}, got {arr.shape}")
            layers[str(name)] = arr
        self.layers = layers

    # ---- construction -------------------------------------------------------------------

    @classmethod
    def from_function(
        cls,
        f: Callable[[np.ndarray, np.ndarray], np.ndarray],
        bounds: tuple[float, float, float, float],
        dx: float,
        dy: float | None = None,
        **kwargs: Any,
    ) -> "ZMap":
        """Sample ``z = f(x, y)`` on the grid covering ``bounds = (x0, y0, x1, y1)``.

        The lines start on ``x0``, ``y0``; the last is the first one at or beyond ``x1``
        (``y1``), within 1e-9 of an interval (:meth:`zmap.gridspec.GridSpec.covering`, the
        rule every map made over a domain follows).

        Examples
        --------
        >>> ZMap.from_function(lambda x, y: x + 2 * y, (0, 0, 10, 5), 1.0).shape
        (11, 6)
        >>> ZMap.from_function(lambda x, y: x + 2 * y, (0, 0, 10.2, 5), 1.0).shape
        (12, 6)
        """
        dy = dx if dy is None else dy
        x0, y0, x1, y1 = (_finite_float(n, v) for n, v in zip(("x0", "y0", "x1", "y1"), bounds))
        spec = GridSpec.covering((x0, y0, x1, y1), _positive_float("dx", dx), _positive_float("dy", dy))
        X, Y = np.meshgrid(spec.x, spec.y, indexing="ij")
        z = np.asarray(f(X, Y), dtype=np.float64)
        return cls(spec.x0, spec.y0, spec.dx, spec.dy, z, **kwargs)

    # ---- geometry -----------------------------------------------------------------------

    @property
    def spec(self) -> GridSpec:
        """The grid's lines (local frame) as a :class:`zmap.gridspec.GridSpec`."""
        return GridSpec(self.x0, self.y0, self.dx, self.dy, self.nx, self.ny)

    @property
    def nx(self) -> int:
        return int(self.z.shape[0])

    @property
    def ny(self) -> int:
        return int(self.z.shape[1])

    @property
    def shape(self) -> tuple[int, int]:
        return (self.nx, self.ny)

    @property
    def nbytes(self) -> int:
        """Bytes held by the heights and side layers."""
        return int(self.z.nbytes + sum(a.nbytes for a in self.layers.values()))

    def copy(self) -> "ZMap":
        return ZMap(self.x0, self.y0, self.dx, self.dy, self.z.copy(), self.angle, self.origin,
                    copy.deepcopy(self.meta), {k: v.copy() for k, v in self.layers.items()})

    def __repr__(self) -> str:
        frame = f", angle={self.angle:.6g}, origin={self.origin}" if self.has_frame else ""
        return (f"ZMap(nx={self.nx}, ny={self.ny}, x0={self.x0:g}, y0={self.y0:g}, dx={self.dx:g}, "
                f"dy={self.dy:g}{frame}, empty={int(np.isnan(self.z).sum())}, layers={list(self.layers)})")

    # ---- persistence --------------------------------------------------------------------

    def header(self) -> dict:
        """The JSON metadata stored with the map."""
        return {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "x0": self.x0, "y0": self.y0, "dx": self.dx, "dy": self.dy,
            "nx": self.nx, "ny": self.ny,
            "angle": self.angle, "origin": list(self.origin),
            "layers": sorted(self.layers),
            "meta": self.meta,
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write the map to one ``.npz`` file (atomic: no half-written file on failure).

        Examples
        --------
        >>> import tempfile, os, numpy as np
        >>> zm = ZMap(0, 0, 0.5, 0.5, np.ones((3, 3)), meta={"source": "doc"})
        >>> p = zm.save(os.path.join(tempfile.mkdtemp(), "a.zmap.npz"))
        >>> float(ZMap.load(p).z.sum())
        9.0
        """
        arrays = {"z": self.z} | {_LAYER_PREFIX + name: arr for name, arr in self.layers.items()}
        return write_npz(path, self.header(), arrays, compress=True)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ZMap":
        """Read a map written by :meth:`save`; a foreign or corrupt file raises ZMapFileError."""
        header, arrays = read_npz(path, FORMAT_NAME, FORMAT_VERSION, what="zmap")
        if "z" not in arrays:
            raise ZMapFileError(str(path), f"not a zmap file (arrays {sorted(arrays)}, no 'z')")
        layers = {n[len(_LAYER_PREFIX):]: a for n, a in arrays.items() if n.startswith(_LAYER_PREFIX)}
        return cls._from_header(str(path), header, arrays["z"], layers)

    @classmethod
    def _from_header(cls, where: str, header: Any, z: np.ndarray, layers: dict) -> "ZMap":
        try:
            if tuple(z.shape) != (header["nx"], header["ny"]):
                raise ZMapFileError(where, f"z has shape {z.shape}, header says ({header['nx']}, {header['ny']})")
            return cls(header["x0"], header["y0"], header["dx"], header["dy"], z,
                       angle=header.get("angle", 0.0), origin=tuple(header.get("origin", (0.0, 0.0))),
                       meta=header.get("meta", {}), layers=layers)
        except KeyError as exc:
            raise ZMapFileError(where, f"header lacks field {exc}") from None
        except ValueError as exc:
            raise ZMapFileError(where, f"invalid content: {exc}") from None
