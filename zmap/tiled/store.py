"""Tiled z-maps: the :class:`zmap.ZMap` grid contract on a chunked zarr store.

A store is a zarr group (a folder) holding the heights ``z`` (float64, NaN = no surface)
and any side layers as arrays chunked in square tiles of ``tile`` x ``tile`` nodes, the
map's JSON header in the group's attributes (key ``zmap``), and two kinds of completion
markers written after the data they vouch for, each by an atomic rename:

* ``zmap_tiles/I_J`` for each tile (I, J) whose chunks are all written;
* ``zmap_complete.json`` once every tile is, with the header again.

:meth:`TiledZMap.open` refuses a store without the final marker (an interrupted
conversion), unless asked for an incomplete one, so a half-written store is never taken
for a finished one; a conversion that starts again skips the tiles that have their marker.

Height queries (:func:`bezier`, :func:`bilinear`) read, per tile holding query points, that
tile's window plus the 2-node stencil halo, and give the in-memory map's results to the
last bit.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from ..errors import ZMapFileError
from ..fmt import count, size
from ..gridspec import GridSpec, OnGrid
from ..memory import check_room

__all__ = ["TiledZMap", "FORMAT_NAME", "FORMAT_VERSION", "HALO", "bezier", "bilinear", "is_tiled_store",
           "remove_store", "tile_grid", "check_tile"]

FORMAT_NAME = "zmap.TiledZMap"
FORMAT_VERSION = 1
#: nodes around a cell that the widest stencil (the quartic tangent) reads on each side
HALO = 2
_ATTR = "zmap"
_COMPLETE = "zmap_complete.json"
_TILES = "zmap_tiles"
_LAYER_PREFIX = "layer__"


def check_tile(tile: Any) -> int:
    """``tile`` as a whole number of grid nodes, ValueError unless it is one and at least :data:`HALO`."""
    try:
        t = int(tile)
    except (TypeError, ValueError):
        raise ValueError(f"tile must be a whole number of grid nodes, got {tile!r}") from None
    if t != tile or t < HALO:
        raise ValueError(f"tile={tile!r} nodes is below the {HALO}-node stencil halo of the Bezier "
                         f"queries; use tiles of at least {HALO} nodes (thousands for speed)")
    return t


def tile_grid(nx: int, ny: int, tile: int) -> tuple[int, int]:
    """Number of tiles ``(ntx, nty)`` covering an ``nx`` x ``ny`` grid in ``tile``-node squares.

    Examples
    --------
    >>> tile_grid(10, 7, 4)
    (3, 2)
    """
    t = check_tile(tile)
    return -(-int(nx) // t), -(-int(ny) // t)


def _atomic_text(path: Path, text: str, sync: bool = False) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "w") as fh:
        fh.write(text)
        if sync:
            fh.flush()
            os.fsync(fh.fileno())
    os.replace(tmp, path)


def _read_header(path: Path) -> dict:
    """The ``zmap`` attributes of the zarr group at ``path``; ZMapFileError when not ours."""
    if not path.exists():
        raise ZMapFileError(str(path), "no such tiled store")
    if not path.is_dir():
        raise ZMapFileError(str(path), "not a tiled z-map store (a file, not a zarr folder)")
    if not (path / "zarr.json").exists() and not (path / ".zgroup").exists():
        raise ZMapFileError(str(path), "is a directory but not a tiled z-map store (no zarr group metadata in it)")
    import zarr

    try:
        group = zarr.open_group(str(path), mode="r")
        attrs = dict(group.attrs)
    except Exception as exc:  # zarr raises several types for a foreign or broken folder
        raise ZMapFileError(str(path), f"not a readable zarr group ({type(exc).__name__}: {exc})") from None
    head = attrs.get(_ATTR)
    if not isinstance(head, dict) or head.get("format") != FORMAT_NAME:
        raise ZMapFileError(str(path), f"a zarr group but not a tiled z-map store (no '{_ATTR}' attributes "
                                       f"of format {FORMAT_NAME!r}; attributes {sorted(attrs)})")
    if head.get("version") != FORMAT_VERSION:
        raise ZMapFileError(str(path), f"tiled store version {head.get('version')!r}, this zmap reads "
                                       f"version {FORMAT_VERSION}")
    return head


def is_tiled_store(path: str | os.PathLike) -> bool:
    """True when ``path`` is a folder holding a zarr group (ours or not: :meth:`TiledZMap.open` checks)."""
    p = Path(path)
    return p.is_dir() and ((p / "zarr.json").exists() or (p / ".zgroup").exists())


class TiledZMap(OnGrid):
    """A z-map in a zarr store, chunked in square tiles: the :class:`zmap.ZMap` grid contract.

    ``z[i, j]`` is the height at local ``(x0 + i*dx, y0 + j*dy)``, NaN where there is no
    surface, in the local frame ``(angle, origin)`` as for a ZMap. Make one with
    :meth:`create` (then :meth:`write_tile` and :meth:`finish`) or :meth:`from_zmap`; read
    one with :meth:`open`. The object holds only the path and the header, so it pickles
    cheaply into Dask tasks.

    Examples
    --------
    >>> import tempfile, os, numpy as np
    >>> from zmap import ZMap
    >>> zm = ZMap.from_function(lambda x, y: x * y, (0, 0, 9, 9), 1.0)
    >>> tz = TiledZMap.from_zmap(zm, os.path.join(tempfile.mkdtemp(), "a.zarr"), tile=4)
    >>> tz.shape, tz.tiles_shape, float(tz.bezier(2.5, 3.5))
    ((10, 10), (3, 3), 8.75)
    """

    def __init__(self, path: str | os.PathLike, header: dict):
        self.path = Path(path)
        self._head = dict(header)
        self.x0 = float(header["x0"])
        self.y0 = float(header["y0"])
        self.dx = float(header["dx"])
        self.dy = float(header["dy"])
        self.nx = int(header["nx"])
        self.ny = int(header["ny"])
        self.tile = int(header["tile"])
        self.angle = float(header.get("angle", 0.0))
        self.origin = tuple(float(v) for v in header.get("origin", (0.0, 0.0)))
        self.meta = dict(header.get("meta", {}))
        self.layers = {str(k): str(v) for k, v in dict(header.get("layers", {})).items()}
        #: windows ``(i0, i1, j0, j1)`` read by the queries (for tests and benches)
        self.reads: list[tuple[int, int, int, int]] = []
        self._arrays: dict[str, Any] = {}

    def __getstate__(self):
        return {"path": str(self.path), "header": self._head}

    def __setstate__(self, state):
        self.__init__(state["path"], state["header"])

    # ---- creation -----------------------------------------------------------------------

    @classmethod
    def create(cls, path: str | os.PathLike, *, x0: float, y0: float, dx: float, dy: float, nx: int, ny: int,
               tile: int, angle: float = 0.0, origin: Sequence[float] = (0.0, 0.0), meta: dict | None = None,
               layers: dict[str, str] | None = None, resume: bool = False) -> "TiledZMap":
        """An empty store (every height NaN, no tile done), or the unfinished one already there.

        Parameters
        ----------
        path : str or PathLike
            Folder of the zarr group (``*.zarr`` by convention).
        x0, y0, dx, dy, nx, ny, angle, origin
            The grid, as for :class:`zmap.ZMap`.
        tile : int
            Tile (chunk) side in grid nodes, at least :data:`HALO`.
        meta : dict, optional
            JSON-serialisable metadata.
        layers : dict of str to dtype name, optional
            Side layers to hold, e.g. ``{"face": "int32", "method": "int8"}``.
        resume : bool
            When ``path`` holds a store of the same grid, tile and layers, keep it and its
            finished tiles (an interrupted conversion going on); when it holds another grid,
            raise. Without ``resume`` an existing path raises.

        Raises
        ------
        ValueError
            A tile below the halo or a bad grid.
        zmap.errors.ZMapFileError
            ``path`` exists and is not ours, or holds another grid.
        """
        from ..grid import ZMap

        tile = check_tile(tile)
        nx, ny = int(nx), int(ny)
        # the grid contract is ZMap's: let it check the numbers on a 2 x 2 stand-in
        probe = ZMap(x0, y0, dx, dy, np.zeros((2, 2)), angle=angle, origin=tuple(origin))
        if nx < 2 or ny < 2:
            raise ValueError(f"a tiled map needs at least 2 grid points along each axis, got {nx} x {ny}")
        layers = {str(k): np.dtype(v).name for k, v in dict(layers or {}).items()}
        head = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "x0": probe.x0, "y0": probe.y0,
                "dx": probe.dx, "dy": probe.dy, "nx": nx, "ny": ny, "tile": tile, "angle": probe.angle,
                "origin": list(probe.origin), "layers": layers, "meta": dict(meta or {})}
        json.dumps(head)  # metadata must be JSON: fail before anything is written
        p = Path(path)
        if p.exists():
            if not resume:
                raise ZMapFileError(str(p), "already exists; remove it, choose another name, or resume it")
            old = _read_header(p)
            keys = ("x0", "y0", "dx", "dy", "nx", "ny", "tile", "angle", "origin", "layers")
            diff = [k for k in keys if old.get(k) != head[k]]
            if diff:
                raise ZMapFileError(str(p), "holds another tiled map (" + ", ".join(
                    f"{k} {old.get(k)!r} != {head[k]!r}" for k in diff) + "); remove it or choose another name")
            return cls(p, old)
        import zarr

        group = zarr.open_group(str(p), mode="w-")
        t = (tile, tile)
        group.create_array("z", shape=(nx, ny), chunks=t, dtype="float64", fill_value=np.nan)
        for name, dt in layers.items():
            fill = -1 if name == "face" else 0
            group.create_array(_LAYER_PREFIX + name, shape=(nx, ny), chunks=t, dtype=dt, fill_value=fill)
        (p / _TILES).mkdir()
        # the attributes last: a folder without them is not taken for a store, not even an unfinished one
        group.attrs[_ATTR] = head
        return cls(p, head)

    @classmethod
    def from_zmap(cls, zm: Any, path: str | os.PathLike, *, tile: int = 4096) -> "TiledZMap":
        """Write an in-memory :class:`zmap.ZMap` (heights and layers) as a finished tiled store.

        Examples
        --------
        >>> import tempfile, os, numpy as np
        >>> from zmap import ZMap
        >>> zm = ZMap(0, 0, 1, 1, np.arange(12.0).reshape(3, 4))
        >>> tz = TiledZMap.from_zmap(zm, os.path.join(tempfile.mkdtemp(), "b.zarr"), tile=2)
        >>> bool((tz.to_zmap().z == zm.z).all())
        True
        """
        tz = cls.create(path, x0=zm.x0, y0=zm.y0, dx=zm.dx, dy=zm.dy, nx=zm.nx, ny=zm.ny, tile=tile,
                        angle=zm.angle, origin=zm.origin, meta=zm.meta,
                        layers={k: v.dtype.name for k, v in zm.layers.items()})
        for ti, tj in tz.tiles():
            si, sj = tz.tile_slices(ti, tj)
            tz.write_tile(ti, tj, zm.z[si, sj], {k: v[si, sj] for k, v in zm.layers.items()})
        return tz.finish()

    @classmethod
    def open(cls, path: str | os.PathLike, *, incomplete: bool = False) -> "TiledZMap":
        """Open a store; one without its completion marker raises unless ``incomplete=True``.

        Raises
        ------
        zmap.errors.ZMapFileError
            Missing, not a zarr group, a zarr group that is not ours, or unfinished.
        """
        p = Path(path)
        head = _read_header(p)
        tz = cls(p, head)
        if not incomplete and not tz.is_complete:
            done, total = len(tz.done_tiles()), tz.n_tiles
            raise ZMapFileError(str(p), f"unfinished tiled store: {done} of {total} tiles written and no "
                                        f"completion marker (an interrupted conversion: run it again to resume)")
        return tz

    # ---- geometry -----------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int]:
        return (self.nx, self.ny)

    @property
    def spec(self) -> GridSpec:
        """The grid's lines (local frame) as a :class:`zmap.gridspec.GridSpec`."""
        return GridSpec(self.x0, self.y0, self.dx, self.dy, self.nx, self.ny)

    @property
    def tiles_shape(self) -> tuple[int, int]:
        return tile_grid(self.nx, self.ny, self.tile)

    @property
    def n_tiles(self) -> int:
        a, b = self.tiles_shape
        return a * b

    @property
    def nbytes(self) -> int:
        """Bytes of the heights and layers once loaded in memory (not on disk)."""
        n = self.nx * self.ny
        return int(n * 8 + sum(n * np.dtype(d).itemsize for d in self.layers.values()))

    def disk_bytes(self) -> int:
        """Bytes the store takes on disk (compressed chunks and metadata)."""
        return int(sum(f.stat().st_size for f in self.path.rglob("*") if f.is_file()))

    def header(self) -> dict:
        return dict(self._head)

    def tiles(self) -> list[tuple[int, int]]:
        """Every tile ``(ti, tj)``, row by row."""
        a, b = self.tiles_shape
        return [(i, j) for i in range(a) for j in range(b)]

    def tile_slices(self, ti: int, tj: int) -> tuple[slice, slice]:
        """Node ranges of tile ``(ti, tj)``."""
        t = self.tile
        return slice(ti * t, min((ti + 1) * t, self.nx)), slice(tj * t, min((tj + 1) * t, self.ny))

    def tile_bounds(self, ti: int, tj: int) -> tuple[float, float, float, float]:
        """Local ``(x0, y0, x1, y1)`` of the tile's first and last nodes, mm."""
        si, sj = self.tile_slices(ti, tj)
        return (self.x0 + si.start * self.dx, self.y0 + sj.start * self.dy,
                self.x0 + (si.stop - 1) * self.dx, self.y0 + (sj.stop - 1) * self.dy)

    # ---- completion markers -----------------------------------------------------------------

    def _marker(self, ti: int, tj: int) -> Path:
        return self.path / _TILES / f"{int(ti)}_{int(tj)}"

    def tile_done(self, ti: int, tj: int) -> bool:
        return self._marker(ti, tj).exists()

    def done_tiles(self) -> list[tuple[int, int]]:
        d = self.path / _TILES
        if not d.is_dir():
            return []
        out = []
        for f in d.iterdir():
            parts = f.name.split("_")
            if len(parts) == 2 and all(p.isdigit() for p in parts):
                out.append((int(parts[0]), int(parts[1])))
        return sorted(out)

    @property
    def is_complete(self) -> bool:
        return (self.path / _COMPLETE).exists()

    def _array(self, name: str, mode: str = "r"):
        key = (name, mode)
        if key not in self._arrays:
            import zarr

            self._arrays[key] = zarr.open_array(str(self.path / name), mode=mode)
        return self._arrays[key]

    def write_tile(self, ti: int, tj: int, z: np.ndarray, layers: dict | None = None) -> None:
        """Write the heights (and layers) of one tile, then its completion marker."""
        si, sj = self.tile_slices(ti, tj)
        want = (si.stop - si.start, sj.stop - sj.start)
        z = np.asarray(z, dtype=np.float64)
        if z.shape != want:
            raise ValueError(f"tile ({ti}, {tj}) holds {want[0]} x {want[1]} nodes, got heights of shape {z.shape}")
        layers = dict(layers or {})
        if set(layers) != set(self.layers):
            raise ValueError(f"tile ({ti}, {tj}): layers {sorted(layers)} given, the store holds {sorted(self.layers)}")
        self._array("z", "r+")[si, sj] = z
        for name, arr in layers.items():
            self._array(_LAYER_PREFIX + name, "r+")[si, sj] = np.asarray(arr).astype(self.layers[name], copy=False)
        filled = np.isfinite(z)
        nf = int(filled.sum())
        stats = {"filled": nf, "zmin": float(z[filled].min()) if nf else None,
                 "zmax": float(z[filled].max()) if nf else None}
        _atomic_text(self._marker(ti, tj), json.dumps(stats))

    def tile_stats(self) -> dict:
        """Heights over the finished tiles from their markers (no chunk is read).

        Returns
        -------
        dict
            ``tiles_done``, ``filled`` (nodes with a height), ``zmin``, ``zmax`` (None when
            no height).
        """
        done = self.done_tiles()
        filled, lo, hi = 0, math.inf, -math.inf
        for ti, tj in done:
            try:
                st = json.loads(self._marker(ti, tj).read_text() or "{}")
            except (OSError, ValueError):
                continue
            filled += int(st.get("filled", 0))
            if st.get("zmin") is not None:
                lo = min(lo, float(st["zmin"]))
                hi = max(hi, float(st["zmax"]))
        return {"tiles_done": len(done), "filled": filled, "zmin": lo if filled else None,
                "zmax": hi if filled else None}

    def describe(self) -> list[str]:
        """Lines of ``zmap info`` for this store (read from the metadata and markers only)."""
        st = self.tile_stats()
        n = self.nx * self.ny
        state = "complete" if self.is_complete else (
            f"UNFINISHED: {st['tiles_done']} of {self.n_tiles} tiles written (run the conversion again to resume)")
        frame = f" (local frame: angle {self.angle:g} rad, origin {self.origin})" if self.has_frame else ""
        lines = [f"store    {self.path} (tiled zarr z-map, {state})",
                 f"grid     {self.nx:,} x {self.ny:,} = {count(n)} points, dx={self.dx:g} dy={self.dy:g} mm",
                 f"domain   x {self.x0:g} .. {self.x1:g}, y {self.y0:g} .. {self.y1:g} mm{frame}",
                 f"tiles    {self.tiles_shape[0]} x {self.tiles_shape[1]} of {self.tile} x {self.tile} nodes"]
        if st["filled"]:
            lines.append(f"heights  {st['zmin']:.6g} .. {st['zmax']:.6g} mm, {count(st['filled'])} with surface in the "
                         f"written tiles")
        else:
            lines.append("heights  none in the written tiles")
        lines.append(f"memory   {size(self.nbytes)} in memory, {size(self.disk_bytes())} on disk "
                     f"(heights and {len(self.layers)} layers: {', '.join(self.layers) or '-'})")
        lines.append(f"meta     {json.dumps(self.meta, sort_keys=True)}")
        return lines

    def finish(self, meta: dict | None = None) -> "TiledZMap":
        """Write the completion marker once every tile has its own; returns the store.

        ``meta`` (optional) is merged into the metadata first.
        """
        missing = self.n_tiles - len(self.done_tiles())
        if missing:
            raise ZMapFileError(str(self.path), f"{missing} of {self.n_tiles} tiles are not written yet")
        if meta:
            import zarr

            self.meta.update(meta)
            self._head["meta"] = self.meta
            zarr.open_group(str(self.path), mode="r+").attrs[_ATTR] = self._head
        _atomic_text(self.path / _COMPLETE, json.dumps(self._head), sync=True)
        return self

    # ---- reading ----------------------------------------------------------------------------

    def to_dask(self, layer: str = "z"):
        """The heights (or a layer) as a lazy ``dask.array`` chunked by tile."""
        import dask.array as da

        name = "z" if layer == "z" else _LAYER_PREFIX + layer
        if layer != "z" and layer not in self.layers:
            raise ValueError(f"layer={layer!r} is not one of " + ", ".join(repr(v) for v in ["z", *self.layers]))
        return da.from_zarr(self._array(name))

    def read(self, i0: int, i1: int, j0: int, j1: int, layer: str = "z") -> np.ndarray:
        """Nodes ``[i0:i1, j0:j1]`` of the heights or a layer (only the chunks they touch are read)."""
        name = "z" if layer == "z" else _LAYER_PREFIX + layer
        return np.ascontiguousarray(self._array(name)[i0:i1, j0:j1])

    def index_window(self, window: Sequence[float] | None) -> tuple[int, int, int, int]:
        """Node range ``(i0, i1, j0, j1)`` (ends excluded) of the nodes inside local ``(x0, y0, x1, y1)``."""
        if window is None:
            return 0, self.nx, 0, self.ny
        if np.shape(window) != (4,):
            raise ValueError(f"window must be (x0, y0, x1, y1) in mm, got {np.asarray(window).tolist()!r}")
        wx0, wy0, wx1, wy1 = (float(v) for v in window)
        i0 = max(0, int(math.ceil((wx0 - self.x0) / self.dx - 1e-9)))
        i1 = min(self.nx, int(math.floor((wx1 - self.x0) / self.dx + 1e-9)) + 1)
        j0 = max(0, int(math.ceil((wy0 - self.y0) / self.dy - 1e-9)))
        j1 = min(self.ny, int(math.floor((wy1 - self.y0) / self.dy + 1e-9)) + 1)
        if i1 - i0 < 2 or j1 - j0 < 2:
            raise ValueError(f"window {tuple(window)} holds {max(i1 - i0, 0)} x {max(j1 - j0, 0)} grid nodes of "
                             f"the map (x {self.x0:g} .. {self.x1:g}, y {self.y0:g} .. {self.y1:g}); a ZMap needs "
                             f"at least 2 x 2")
        return i0, i1, j0, j1

    def to_zmap(self, window: Sequence[float] | None = None):
        """The nodes inside ``window = (x0, y0, x1, y1)`` (local mm; default all) as a :class:`zmap.ZMap`.

        Raises
        ------
        zmap.errors.GridTooLargeError
            The window would not fit in 80 % of the memory available.
        """
        from ..grid import ZMap

        i0, i1, j0, j1 = self.index_window(window)
        n = (i1 - i0) * (j1 - j0)
        check_room(n * (8 + sum(np.dtype(d).itemsize for d in self.layers.values())),
                   f"window of {count(i1 - i0)} x {count(j1 - j0)} = {count(n)} nodes",
                   "read a smaller window or work tile by tile (to_dask)")
        z = self.read(i0, i1, j0, j1)
        layers = {k: self.read(i0, i1, j0, j1, k) for k in self.layers}
        meta = dict(self.meta)
        meta["window"] = [i0, i1, j0, j1]
        return ZMap(self.x0 + i0 * self.dx, self.y0 + j0 * self.dy, self.dx, self.dy, z, angle=self.angle,
                    origin=self.origin, meta=meta, layers=layers)

    def iter_tiles(self) -> Iterator[tuple[tuple[int, int], np.ndarray]]:
        """``((ti, tj), heights)`` of every tile, one tile in memory at a time."""
        for ti, tj in self.tiles():
            si, sj = self.tile_slices(ti, tj)
            yield (ti, tj), self.read(si.start, si.stop, sj.start, sj.stop)

    def bezier(self, x, y, **kwargs):
        """:func:`bezier` on this map."""
        return bezier(self, x, y, **kwargs)

    def bilinear(self, x, y, **kwargs):
        """:func:`bilinear` on this map."""
        return bilinear(self, x, y, **kwargs)

    def __repr__(self) -> str:
        state = "complete" if self.is_complete else f"unfinished {len(self.done_tiles())}/{self.n_tiles} tiles"
        return (f"TiledZMap({str(self.path)!r}, nx={self.nx}, ny={self.ny}, x0={self.x0:g}, y0={self.y0:g}, "
                f"dx={self.dx:g}, dy={self.dy:g}, tile={self.tile}, {state}, layers={list(self.layers)})")


def remove_store(path: str | os.PathLike) -> None:
    """Delete a tiled store (only one of ours: a foreign folder raises ZMapFileError)."""
    _read_header(Path(path))
    shutil.rmtree(path)


# ---- height queries ----------------------------------------------------------------------------

def _query(tz: TiledZMap, x, y, strict: bool, evaluate) -> Any:
    from .. import interpolate as _ip
    from . import _kernels as K

    if not isinstance(tz, TiledZMap):
        raise TypeError(f"tz must be a zmap.tiled.TiledZMap, got {type(tz).__name__}")
    xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    shape = xb.shape
    xs = np.ascontiguousarray(xb).ravel()
    ys = np.ascontiguousarray(yb).ravel()
    n = xs.size
    c, s, ox, oy = tz.frame
    ci = np.empty(n, dtype=np.int64)
    cj = np.empty(n, dtype=np.int64)
    K.locate_cells(tz.x0, tz.y0, tz.dx, tz.dy, c, s, ox, oy, tz.nx, tz.ny, xs, ys, ci, cj)
    out = np.full(n, np.nan)
    inside = np.flatnonzero(ci >= 0)
    if inside.size:
        t = tz.tile
        nty = tz.tiles_shape[1]
        key = (ci[inside] // t) * nty + cj[inside] // t
        order = np.argsort(key, kind="stable")
        keys, starts = np.unique(key[order], return_index=True)
        ends = np.append(starts[1:], order.size)
        for kk, a0, a1 in zip(keys.tolist(), starts.tolist(), ends.tolist()):
            ti, tj = divmod(int(kk), nty)
            # the tile's cells read nodes i-2 .. i+3: the tile plus the halo (and one node for the far corner)
            i0 = max(0, ti * t - HALO)
            i1 = min(tz.nx, (ti + 1) * t + HALO + 1)
            j0 = max(0, tj * t - HALO)
            j1 = min(tz.ny, (tj + 1) * t + HALO + 1)
            w = tz.read(i0, i1, j0, j1)
            tz.reads.append((i0, i1, j0, j1))
            idx = np.ascontiguousarray(inside[order[a0:a1]])
            evaluate(w, i0, j0, c, s, ox, oy, xs, ys, idx, out)
    return _ip._finish(out, xs, ys, shape, strict, tz)


def bezier(tz: TiledZMap, x, y, *, tangent: str = "circle", boundary: str = "dummy", strict: bool = False):
    """Non-parametric cubic Bezier heights (paper 004 Eq. 4-7) on a tiled map.

    Reads, for each tile that holds query points, the tile and its 2-node halo; the
    answers equal :func:`zmap.interpolate.bezier` on the whole map in memory to the last
    bit. Options as there.

    Parameters
    ----------
    tz : TiledZMap
    x, y : array_like of float, broadcastable
        World coordinates in mm.
    tangent : {'circle', 'central', 'quartic'}
    boundary : {'dummy', 'one-sided'}
    strict : bool
        Raise OutOfDomainError instead of returning NaN.

    Returns
    -------
    ndarray of float64 (broadcast shape), or float for scalar input
        Heights in mm, NaN outside the map or in a cell with a missing corner.

    Examples
    --------
    >>> import tempfile, os
    >>> from zmap import ZMap
    >>> zm = ZMap.from_function(lambda x, y: 0.5 * x - y, (0, 0, 8, 8), 1.0)
    >>> tz = TiledZMap.from_zmap(zm, os.path.join(tempfile.mkdtemp(), "c.zarr"), tile=4)
    >>> float(bezier(tz, 1.25, 6.5))
    -5.875
    """
    from .. import interpolate as _ip
    from . import _kernels as K

    tcode = _ip._choice("tangent", tangent, _ip.TANGENTS)
    bcode = _ip._choice("boundary", boundary, _ip.BOUNDARIES)

    def evaluate(w, a, b, c, s, ox, oy, xs, ys, idx, out):
        K.bezier_window(w, a, b, tz.x0, tz.y0, tz.dx, tz.dy, c, s, ox, oy, tz.nx, tz.ny, xs, ys, idx, tcode,
                        bcode, out)

    return _query(tz, x, y, strict, evaluate)


def bilinear(tz: TiledZMap, x, y, *, strict: bool = False):
    """Bilinear heights on a tiled map, equal to :func:`zmap.interpolate.bilinear` in memory.

    Examples
    --------
    >>> import tempfile, os
    >>> from zmap import ZMap
    >>> zm = ZMap.from_function(lambda x, y: x * y, (0, 0, 5, 5), 1.0)
    >>> tz = TiledZMap.from_zmap(zm, os.path.join(tempfile.mkdtemp(), "d.zarr"), tile=2)
    >>> float(bilinear(tz, 2.5, 3.5))
    8.75
    """
    from . import _kernels as K

    def evaluate(w, a, b, c, s, ox, oy, xs, ys, idx, out):
        K.bilinear_window(w, a, b, tz.x0, tz.y0, tz.dx, tz.dy, c, s, ox, oy, tz.nx, tz.ny, xs, ys, idx, out)

    return _query(tz, x, y, strict, evaluate)
