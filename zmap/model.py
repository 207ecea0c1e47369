"""The precision model: a base z-map refined by CZ-maps and an EZ-map (paper 004 §3).

``PrecisionModel.height(x, y)`` answers from the CZ-map whose domain holds the point (the
one in which it lies deepest, where domains overlap), else from the EZ-map's Coons patch
where the point's base cell has e-points, else from the base z-map's cubic Bezier patch.
The CZ lookup is a CSR list of CZ-maps per base cell; one numba kernel does the lookup and
the Bezier evaluation, the EZ cells go to :meth:`zmap.refine.ez.EZMap.evaluate` in one
vectorised call. The model saves to one ``.zpm`` file (npz + JSON header) and loads back
exactly.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .errors import OutOfDomainError, ZMapFileError
from .fmt import size
from .grid import ZMap

__all__ = ["PrecisionModel", "FORMAT_NAME", "FORMAT_VERSION", "SOURCES"]

FORMAT_NAME = "zmap.PrecisionModel"
FORMAT_VERSION = 1
#: codes of :meth:`PrecisionModel.source`
SOURCES = {"none": 0, "base": 1, "cz": 2, "ez": 3}
_TANGENT_CIRCLE = 0
_BOUNDARY_DUMMY = 0


def _cells_of(base: ZMap, cz: ZMap) -> np.ndarray:
    """Flat ids of the base cells that the CZ-map's rectangular domain meets (SAT test)."""
    corners_l = np.array([[cz.x0, cz.y0], [cz.x1, cz.y0], [cz.x1, cz.y1], [cz.x0, cz.y1]])
    wx, wy = cz.local_to_world(corners_l[:, 0], corners_l[:, 1])
    bx, by = base.world_to_local(wx, wy)  # rectangle corners in the base's local frame
    nx, ny = base.nx, base.ny
    i0 = max(0, int(math.floor((bx.min() - base.x0) / base.dx)))
    i1 = min(nx - 2, int(math.floor((bx.max() - base.x0) / base.dx)))
    j0 = max(0, int(math.floor((by.min() - base.y0) / base.dy)))
    j1 = min(ny - 2, int(math.floor((by.max() - base.y0) / base.dy)))
    if i1 < i0 or j1 < j0:
        return np.zeros(0, dtype=np.int64)
    I, J = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1), indexing="ij")
    I, J = I.ravel(), J.ravel()
    cx0 = base.x0 + I * base.dx
    cy0 = base.y0 + J * base.dy
    # separating axes of the rectangle (its own two axes in the base frame)
    rel = cz.angle - base.angle
    keep = np.ones(I.shape, dtype=bool)
    for ax in (np.array([math.cos(rel), math.sin(rel)]), np.array([-math.sin(rel), math.cos(rel)])):
        rp = bx * ax[0] + by * ax[1]
        cell = np.stack([cx0 * ax[0] + cy0 * ax[1], (cx0 + base.dx) * ax[0] + cy0 * ax[1],
                         cx0 * ax[0] + (cy0 + base.dy) * ax[1], (cx0 + base.dx) * ax[0] + (cy0 + base.dy) * ax[1]])
        keep &= (cell.max(axis=0) >= rp.min()) & (cell.min(axis=0) <= rp.max())
    return (I[keep] * (ny - 1) + J[keep]).astype(np.int64)


class PrecisionModel:
    """Base z-map + CZ-maps + EZ-map, queried as one height field.

    Parameters
    ----------
    base : ZMap
        The master z-map.
    cz : sequence of ZMap
        CZ-maps (each with its local frame), from :func:`zmap.refine.cz.build_cz`.
    ez : zmap.refine.ez.EZMap, optional
        E-map of ``base``, from :func:`zmap.refine.ez.build_ez`.
    meta : dict, optional
        JSON-serialisable metadata (source, tolerance, method, counts).

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> f = lambda x, y: np.where(x < 1.02, 0.0, 3.0)
    >>> base = ZMap.from_function(f, (0, 0, 2, 2), 0.5)
    >>> core = ZMap.from_function(f, (0.8, 0, 1.3, 2), 0.01, 0.03)
    >>> m = PrecisionModel(base, [core])
    >>> m.height([1.0, 1.04, 0.25], [1.0, 1.0, 1.0]).tolist()
    [0.0, 3.0, 0.0]
    """

    def __init__(self, base: ZMap, cz: Sequence[ZMap] = (), ez: Any = None, meta: dict | None = None):
        if not isinstance(base, ZMap):
            raise TypeError(f"base must be a zmap.ZMap, got {type(base).__name__}")
        cz = list(cz)
        for k, m in enumerate(cz):
            if not isinstance(m, ZMap):
                raise TypeError(f"cz[{k}] must be a zmap.ZMap, got {type(m).__name__}")
        if ez is not None:
            if (ez.nx, ez.ny) != base.shape or not np.allclose((ez.x0, ez.y0, ez.dx, ez.dy),
                                                               (base.x0, base.y0, base.dx, base.dy), rtol=0, atol=1e-12):
                raise ValueError(f"the EZ-map's grid ({ez.nx} x {ez.ny}, x0={ez.x0}, y0={ez.y0}, dx={ez.dx}, "
                                 f"dy={ez.dy}) is not the base's {base!r}")
        self.base = base
        self.cz = cz
        self.ez = ez
        self.meta = dict(meta or {})
        self._pack()

    # ---- packing ------------------------------------------------------------------------

    def _pack(self) -> None:
        base = self.base
        m = len(self.cz)
        sizes = np.array([c.z.size for c in self.cz], dtype=np.int64)
        self._cz_off = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self._cz_z = (np.concatenate([c.z.ravel() for c in self.cz]) if m else np.zeros(0))
        self._cz_shape = np.array([c.shape for c in self.cz], dtype=np.int64).reshape(m, 2)
        self._cz_par = np.array([[c.x0, c.y0, c.dx, c.dy, math.cos(c.angle), math.sin(c.angle),
                                  c.origin[0], c.origin[1]] for c in self.cz], dtype=np.float64).reshape(m, 8)
        ncell = (base.nx - 1) * (base.ny - 1)
        cells = [_cells_of(base, c) for c in self.cz]
        counts = np.zeros(ncell, dtype=np.int64)
        for cl in cells:
            np.add.at(counts, cl, 1)
        self._cell_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self._cell_cz = np.zeros(int(self._cell_ptr[-1]), dtype=np.int64)
        fill = self._cell_ptr[:-1].copy()
        for k, cl in enumerate(cells):
            self._cell_cz[fill[cl]] = k
            fill[cl] += 1
        self._ez_cell = (np.ascontiguousarray(self.ez.cell_mask().ravel()) if self.ez is not None
                         else np.zeros(ncell, dtype=np.bool_))

    # ---- queries ------------------------------------------------------------------------

    def _query(self, x, y) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple]:
        from . import _model_kernels as _k

        xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        shape = xb.shape
        xs = np.ascontiguousarray(xb).ravel()
        ys = np.ascontiguousarray(yb).ravel()
        out = np.empty(xs.shape[0])
        src = np.empty(xs.shape[0], dtype=np.int8)
        b = self.base
        _k.model_heights(b.z, b.x0, b.y0, b.dx, b.dy, math.cos(b.angle), math.sin(b.angle), b.origin[0],
                         b.origin[1], self._cz_z, self._cz_off, self._cz_shape, self._cz_par, self._cell_ptr,
                         self._cell_cz, self._ez_cell, xs, ys, _TANGENT_CIRCLE, _BOUNDARY_DUMMY, out, src)
        e = np.flatnonzero(src == 3)
        if e.size:
            he = np.asarray(self.ez.evaluate(b, xs[e], ys[e]), dtype=np.float64).ravel()
            ok = ~np.isnan(he)
            out[e[ok]] = he[ok]
            fall = e[~ok]
            src[fall] = np.where(np.isnan(out[fall]), 0, 1)
        return out, src, xs, ys, shape

    def height(self, x, y, *, strict: bool = False):
        """Heights of the model at world xy.

        Parameters
        ----------
        x, y : array_like of float, broadcastable
            World coordinates in mm.
        strict : bool
            Raise :class:`zmap.errors.OutOfDomainError` naming the first point without a
            height instead of returning NaN there.

        Returns
        -------
        ndarray of float64 (broadcast shape), or float for scalar input
            Heights in mm; NaN outside the base map or where no map has a height.
        """
        out, _src, xs, ys, shape = self._query(x, y)
        if strict:
            bad = np.flatnonzero(np.isnan(out))
            if bad.size:
                k = int(bad[0])
                raise OutOfDomainError(f"no height at point {k} (x={float(xs[k])!r}, y={float(ys[k])!r}); "
                                       f"{bad.size} of {out.size} points have none")
        out = out.reshape(shape)
        return out[()] if out.ndim == 0 else out

    def source(self, x, y) -> np.ndarray:
        """Which map answers at each point: int8 codes of :data:`SOURCES` (0 none, 1 base, 2 CZ, 3 EZ)."""
        _out, src, _xs, _ys, shape = self._query(x, y)
        return src.reshape(shape)

    # ---- figures ------------------------------------------------------------------------

    @property
    def nbytes(self) -> dict:
        """Memory in bytes: ``base`` (heights), ``cz`` (heights, grids and the per-cell
        lookup), ``ez`` (edge ids, offsets, heights) and ``total``."""
        base = int(self.base.z.nbytes)
        cz = int(self._cz_z.nbytes + self._cz_off.nbytes + self._cz_shape.nbytes + self._cz_par.nbytes
                 + (self._cell_ptr.nbytes + self._cell_cz.nbytes if self.cz else 0))
        ez = int(self.ez.nbytes) if self.ez is not None else 0
        return {"base": base, "cz": cz, "ez": ez, "total": base + cz + ez}

    def __repr__(self) -> str:
        nb = self.nbytes
        return (f"PrecisionModel(base {self.base.nx}x{self.base.ny} dx={self.base.dx:g}, {len(self.cz)} CZ-maps, "
                f"ez={'yes' if self.ez is not None else 'no'}, {size(nb['total'])})")

    # ---- persistence --------------------------------------------------------------------

    def save(self, path: str | os.PathLike) -> Path:
        """Write the model to one ``.zpm`` file (npz with a JSON header), atomically.

        Examples
        --------
        >>> import os, tempfile, numpy as np
        >>> from zmap import ZMap
        >>> m = PrecisionModel(ZMap(0, 0, 1, 1, np.arange(9.0).reshape(3, 3)))
        >>> p = m.save(os.path.join(tempfile.mkdtemp(), "a.zpm"))
        >>> float(PrecisionModel.load(p).base.z.sum())
        36.0
        """
        from ._npzfile import write_npz

        arrays: dict[str, np.ndarray] = {"base__z": self.base.z}
        for name, a in self.base.layers.items():
            arrays[f"base__layer__{name}"] = a
        for k, c in enumerate(self.cz):
            arrays[f"cz{k}__z"] = c.z
        if self.ez is not None:
            for name, a in self.ez.to_arrays().items():
                arrays[f"ez__{name}"] = np.asarray(a)
        header = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "base": self.base.header(),
                  "cz": [c.header() for c in self.cz], "ez": self.ez is not None, "meta": self.meta}
        return write_npz(path, header, arrays, compress=True)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "PrecisionModel":
        """Read a model written by :meth:`save`; a foreign or corrupt file raises ZMapFileError."""
        from ._npzfile import read_npz

        where = str(path)
        header, arrays = read_npz(path, FORMAT_NAME, FORMAT_VERSION, what="precision model")
        try:
            layers = {n[len("base__layer__"):]: a for n, a in arrays.items() if n.startswith("base__layer__")}
            base = ZMap._from_header(where, header["base"], arrays["base__z"], layers)
            cz = [ZMap._from_header(where, h, arrays[f"cz{k}__z"], {}) for k, h in enumerate(header["cz"])]
            ez = None
            if header["ez"]:
                from .refine.ez import EZMap

                ez = EZMap.from_arrays({n[4:]: a for n, a in arrays.items() if n.startswith("ez__")})
            return cls(base, cz, ez, meta=header.get("meta", {}))
        except KeyError as exc:
            raise ZMapFileError(where, f"precision model lacks {exc}") from None
        except (TypeError, ValueError) as exc:
            raise ZMapFileError(where, f"invalid content: {exc}") from None
