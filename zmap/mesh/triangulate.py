"""Triangle meshes of z-maps, height fields and dexel tops, open or closed into a solid.

A grid cell whose four corners have heights gives two triangles; cells with a NaN corner
are left out. The diagonal always runs from node ``(i, j)`` to node ``(i + 1, j + 1)`` (from
the cell's low-x low-y corner to its high-x high-y corner), and both triangles are
counter-clockwise seen from +z, so their normals point up. ``closed=True`` adds vertical
side walls along every boundary of the valid region (outer boundary and holes) down to a
flat bottom, and a bottom cap facing down: the result is a watertight solid whose volume
is the sum of the vertical prisms under the top triangles (paper 003 meshes the machined
stock the same way, one cell at a time).

Nothing here needs VTK: :meth:`TriMesh.to_pyvista` imports pyvista when called.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from ..grid import ZMap

__all__ = ["TriMesh", "triangulate"]


@dataclass(frozen=True, eq=False)
class TriMesh:
    """A triangle mesh: shared vertices, triangles as vertex indices, per-vertex scalars.

    The arrays are made read-only; build a new mesh to change one.

    Parameters
    ----------
    vertices : ndarray of shape (n, 3), float64
        Vertex coordinates in mm.
    faces : ndarray of shape (m, 3), int32
        Vertex indices of each triangle; a top surface from :func:`triangulate` is
        counter-clockwise seen from +z (normals up), a closed mesh has outward normals.
    point_data : dict of str to ndarray of shape (n,)
        Scalars per vertex (e.g. ``deviation``); NaN where a vertex has none.

    Examples
    --------
    >>> import numpy as np
    >>> m = TriMesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]]), np.array([[0, 1, 2]]))
    >>> m.n_vertices, m.n_faces, m.area(), m.bounds()
    (3, 1, 0.5, (0.0, 0.0, 0.0, 1.0, 1.0, 0.0))
    """

    vertices: np.ndarray
    faces: np.ndarray
    point_data: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices)
        if v.ndim != 2 or v.shape[1] != 3 or not np.issubdtype(v.dtype, np.number) or np.iscomplexobj(v):
            raise ValueError(f"vertices must be a real array of shape (n, 3), got shape {v.shape} dtype {v.dtype}")
        v = np.array(v, dtype=np.float64, order="C")
        if not np.isfinite(v).all():
            raise ValueError("vertices hold NaN or infinite coordinates")
        f = np.asarray(self.faces)
        if f.size == 0:
            f = f.reshape(0, 3)
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise ValueError(f"faces must be an integer array of shape (m, 3), got shape {f.shape} dtype {f.dtype}")
        if len(v) > np.iinfo(np.int32).max:
            raise ValueError(f"a TriMesh holds at most {np.iinfo(np.int32).max} vertices, got {len(v)}")
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index vertices 0..{len(v) - 1}, got indices {int(f.min())}..{int(f.max())}")
        f = np.array(f, dtype=np.int32, order="C")
        pd = {}
        for name, arr in dict(self.point_data).items():
            arr = np.array(arr, order="C")
            if arr.shape != (len(v),):
                raise ValueError(f"point_data {name!r} must have shape ({len(v)},), got {arr.shape}")
            arr.flags.writeable = False
            pd[str(name)] = arr
        v.flags.writeable = False
        f.flags.writeable = False
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        object.__setattr__(self, "point_data", pd)

    # ---- sizes ---------------------------------------------------------------------------

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes held by vertices, faces and point data."""
        return int(self.vertices.nbytes + self.faces.nbytes + sum(a.nbytes for a in self.point_data.values()))

    def __repr__(self) -> str:
        return (f"TriMesh(n_vertices={self.n_vertices}, n_faces={self.n_faces}, "
                f"point_data={list(self.point_data)})")

    # ---- geometry ------------------------------------------------------------------------

    def bounds(self) -> tuple[float, float, float, float, float, float]:
        """``(xmin, ymin, zmin, xmax, ymax, zmax)`` in mm (the box order of zmap.sim); NaN if empty.

        Examples
        --------
        >>> import numpy as np
        >>> triangulate(np.zeros((3, 2)), grid=(1.0, 2.0, 0.5, 1.0)).bounds()
        (1.0, 2.0, 0.0, 2.0, 3.0, 0.0)
        """
        if self.n_vertices == 0:
            return (math.nan,) * 6
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        return tuple(float(t) for t in (*lo, *hi))  # type: ignore[return-value]

    def _corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        v = self.vertices
        if self.n_vertices:
            v = v - 0.5 * (v.min(axis=0) + v.max(axis=0))  # centred: less cancellation
        f = self.faces
        return v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]

    def area(self) -> float:
        """Total area of the triangles in mm².

        Examples
        --------
        >>> import numpy as np
        >>> triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1)).area()
        4.0
        """
        a, b, c = self._corners()
        return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())

    def volume(self) -> float:
        """Signed enclosed volume in mm³ (divergence theorem); meaningful for closed meshes.

        Positive when the normals point outwards.

        Examples
        --------
        >>> import numpy as np
        >>> triangulate(np.full((3, 3), 2.0), grid=(0, 0, 1, 1), closed=True, bottom=0.0).volume()
        8.0
        """
        a, b, c = self._corners()
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    def edges(self) -> np.ndarray:
        """Directed edges of the faces, shape (3m, 2), int64: ``(f0, f1), (f1, f2), (f2, f0)`` per face."""
        f = self.faces.astype(np.int64)
        return np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2)

    def is_watertight(self) -> bool:
        """True when every edge is shared by exactly two faces that use it in opposite directions.

        This is a closed, consistently oriented edge-manifold; a mesh without faces counts
        as watertight.

        Examples
        --------
        >>> import numpy as np
        >>> z = np.ones((4, 4))
        >>> top, solid = triangulate(z, grid=(0, 0, 1, 1)), triangulate(z, grid=(0, 0, 1, 1), closed=True)
        >>> top.is_watertight(), solid.is_watertight()
        (False, True)
        """
        e = self.edges()
        if len(e) == 0:
            return True
        n = np.int64(self.n_vertices)
        key = e[:, 0] * n + e[:, 1]
        key.sort()
        if (key[1:] == key[:-1]).any():  # a directed edge used twice: 3+ faces or a flip
            return False
        rev = np.sort(e[:, 1] * n + e[:, 0])
        return bool(np.array_equal(key, rev))

    # ---- interop -------------------------------------------------------------------------

    def to_pyvista(self) -> Any:
        """A ``pyvista.PolyData`` with a ``height`` point scalar (vertex z) and the point data.

        Examples
        --------
        >>> import numpy as np
        >>> pd = triangulate(np.zeros((2, 2)), grid=(0, 0, 1, 1)).to_pyvista()
        >>> pd.n_points, pd.n_cells, sorted(pd.point_data.keys())
        (4, 2, ['height'])
        """
        try:
            import pyvista as pv
        except ImportError as err:  # pragma: no cover - pyvista is a dependency here
            raise ImportError("TriMesh.to_pyvista needs pyvista (pip install pyvista)") from err
        cells = np.empty((self.n_faces, 4), dtype=np.int64)
        cells[:, 0] = 3
        cells[:, 1:] = self.faces
        poly = pv.PolyData(self.vertices.copy(), cells.ravel())
        poly.point_data["height"] = self.vertices[:, 2].copy()
        for name, arr in self.point_data.items():
            poly.point_data[name] = np.array(arr)
        return poly


# ---- triangulation ---------------------------------------------------------------------


def _grid_tuple(grid: Any) -> tuple[float, float, float, float]:
    try:
        vals = [float(g) for g in grid]
    except (TypeError, ValueError):
        raise ValueError(f"grid must be 4 numbers (x0, y0, dx, dy), got {grid!r}") from None
    if len(vals) != 4 or not all(math.isfinite(g) for g in vals):
        raise ValueError(f"grid must be 4 finite numbers (x0, y0, dx, dy), got {tuple(vals)!r}")
    if vals[2] <= 0 or vals[3] <= 0:
        raise ValueError(f"grid intervals dx, dy must be positive, got dx={vals[2]!r}, dy={vals[3]!r}")
    return vals[0], vals[1], vals[2], vals[3]


def _source_grid(source: Any, grid: Any) -> tuple[np.ndarray, tuple[float, float, float, float], Any, float | None]:
    """Heights, (x0, y0, dx, dy), local-to-world function or None, default bottom or None."""
    dexel = sys.modules.get("zmap.sim.dexel")      # a workpiece exists only if its module is loaded
    hfield = sys.modules.get("zmap.sim.heightfield")
    kind = None
    if isinstance(source, ZMap):
        kind = "ZMap"
    elif hfield is not None and isinstance(source, hfield.HeightField):
        kind = "HeightField"
    elif dexel is not None and isinstance(source, dexel.DexelWorkpiece):
        kind = "DexelWorkpiece"
    if kind is not None and grid is not None:
        raise ValueError(f"grid is taken from the {kind}; pass grid only with a plain array, got grid={grid!r}")
    if kind == "ZMap":
        return source.z, (source.x0, source.y0, source.dx, source.dy), (
            source.local_to_world if source.has_frame else None), None
    if kind == "HeightField":
        t = source.template
        return source.z, (t.x0, t.y0, t.dx, t.dy), None, None
    if kind == "DexelWorkpiece":
        filled = source.cnt > 0
        stock_bottom = float(source.near[filled, 0].min()) if filled.any() else None
        return source.top(), (source.x0, source.y0, source.pitch, source.pitch), None, stock_bottom
    if isinstance(source, (np.ndarray, list, tuple)):
        if grid is None:
            raise ValueError("a plain height array needs grid=(x0, y0, dx, dy)")
        z = np.asarray(source)
        if z.ndim != 2:
            raise ValueError(f"heights must be a 2D array of shape (nx, ny), got shape {z.shape}")
        if not (np.issubdtype(z.dtype, np.number) or z.dtype == np.bool_) or np.iscomplexobj(z):
            raise TypeError(f"heights must be real numbers, got dtype {z.dtype}")
        return z, _grid_tuple(grid), None, None
    raise TypeError("source must be a ZMap, a HeightField, a DexelWorkpiece or a 2D array, "
                    f"got {type(source).__module__}.{type(source).__qualname__}")


def triangulate(source: Any, *, grid: tuple[float, float, float, float] | None = None, closed: bool = False,
                bottom: float | None = None, point_data: Mapping[str, np.ndarray] | None = None) -> TriMesh:
    """Triangulate a height grid: two triangles a cell, cells with a NaN corner left out.

    Parameters
    ----------
    source : ZMap, HeightField, DexelWorkpiece or ndarray of shape (nx, ny)
        The heights ``z[i, j]`` at ``(x0 + i*dx, y0 + j*dy)`` in mm, NaN = no surface. A
        ZMap's local frame (``angle``, ``origin``) is applied, so vertices are in world
        coordinates; a DexelWorkpiece gives its :meth:`top` on its rays (``dx = dy =
        pitch``); a plain array needs ``grid``.
    grid : (x0, y0, dx, dy), optional, keyword-only
        Grid of a plain array, in mm; not allowed with the other sources.
    closed : bool
        Add vertical walls along every boundary of the valid region (holes included) down
        to ``bottom`` and a flat bottom cap, so that the mesh is a watertight solid with
        outward normals. Where two valid cells touch only at a corner the node is doubled
        (two vertices at one place), which keeps every edge between exactly two faces. A
        DexelWorkpiece's solid is all that lies under its top down to ``bottom`` (gaps
        between the dexels of one ray, which cuts from above do not make, are filled).
    bottom : float, optional
        Bottom of the closed solid in mm: default the stock bottom (lowest dexel start) of
        a DexelWorkpiece, else the lowest height minus 1 mm. Must not be above any height.
    point_data : dict of str to ndarray of shape (nx, ny), optional
        Scalars on the grid nodes (e.g. ``{"deviation": dz}``) carried to the vertices;
        bottom vertices of a closed mesh get NaN (0 for integer data).

    Returns
    -------
    TriMesh
        Vertices once per used node (only nodes of a kept cell), ordered by node
        ``i * ny + j``; each cell gives faces ``(i,j), (i+1,j), (i+1,j+1)`` and ``(i,j),
        (i+1,j+1), (i,j+1)``, counter-clockwise seen from +z. All-NaN heights give an empty
        mesh.

    Raises
    ------
    TypeError
        ``source`` of another type, or heights that are not real numbers.
    ValueError
        A plain array that is not 2D or without ``grid``, infinite heights, a bad
        ``bottom`` or ``point_data`` of the wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, np.nan]])
    >>> m = triangulate(z, grid=(0.0, 0.0, 1.0, 1.0))
    >>> m.n_vertices, m.n_faces, m.faces.tolist()
    (4, 2, [[0, 2, 3], [0, 3, 1]])
    >>> s = triangulate(z, grid=(0.0, 0.0, 1.0, 1.0), closed=True, bottom=-1.0)
    >>> s.is_watertight(), round(s.volume(), 12)
    (True, 1.5)
    """
    z, (x0, y0, dx, dy), to_world, stock_bottom = _source_grid(source, grid)
    if z.dtype == np.bool_:
        z = z.astype(np.float64)
    z = np.asarray(z, dtype=np.float64)
    if np.isinf(z).any():
        raise ValueError("heights hold infinite values; use NaN to mark 'no surface'")
    nx, ny = z.shape
    extra = {}
    for name, arr in dict(point_data or {}).items():
        arr = np.asarray(arr)
        if arr.shape != (nx, ny):
            raise ValueError(f"point_data {name!r} must have the grid's shape {(nx, ny)}, got {arr.shape}")
        extra[str(name)] = arr

    valid = np.isfinite(z)
    cell = valid[:-1, :-1] & valid[1:, :-1] & valid[1:, 1:] & valid[:-1, 1:]
    # pc[i + 1, j + 1] = cell (i, j) is kept; a frame of False around it
    pc = np.zeros((nx + 1, ny + 1), dtype=bool)
    pc[1:-1, 1:-1] = cell
    sw, se, nw, ne = pc[:-1, :-1], pc[1:, :-1], pc[:-1, 1:], pc[1:, 1:]  # the 4 cells around each node
    used = sw | se | nw | ne
    if closed:
        # Nodes where two cells meet only at a corner: the cell that has the node as its
        # corner 'a' (cells SW + NE) or its corner 'd' (cells SE + NW) gets a second vertex.
        pinch_a = sw & ne & ~se & ~nw
        pinch_d = se & nw & ~sw & ~ne
    else:
        pinch_a = pinch_d = np.zeros((nx, ny), dtype=bool)
    pinched = pinch_a | pinch_d

    # Vertex ids: used nodes in node order, then the second vertices of pinched nodes.
    nodes = np.flatnonzero(used.ravel())
    copies = np.flatnonzero(pinched.ravel())
    id_plain = np.full(nx * ny, -1, dtype=np.int64)
    id_plain[nodes] = np.arange(len(nodes))
    id_copy = id_plain.copy()
    id_copy[copies] = len(nodes) + np.arange(len(copies))
    id_a = np.where(pinch_a.ravel(), id_copy, id_plain).reshape(nx, ny)  # vertex of a node as a cell's corner a
    id_d = np.where(pinch_d.ravel(), id_copy, id_plain).reshape(nx, ny)  # ... as corner d
    id_plain = id_plain.reshape(nx, ny)                                   # ... as corner b or c

    ci, cj = np.nonzero(cell)
    top_faces = np.empty((2 * len(ci), 3), dtype=np.int64)
    A, B, C, D = id_a[ci, cj], id_plain[ci + 1, cj], id_plain[ci + 1, cj + 1], id_d[ci, cj + 1]
    top_faces[0::2, 0], top_faces[0::2, 1], top_faces[0::2, 2] = A, B, C
    top_faces[1::2, 0], top_faces[1::2, 1], top_faces[1::2, 2] = A, C, D

    src = np.concatenate([nodes, copies])
    ni, nj = src // ny, src % ny
    lx, ly = x0 + ni * dx, y0 + nj * dy
    wx, wy = to_world(lx, ly) if to_world is not None else (lx, ly)
    top_z = z.ravel()[src]
    verts = np.column_stack([wx, wy, top_z]).astype(np.float64)
    pdata = {name: arr.ravel()[src] for name, arr in extra.items()}

    if not closed:
        return TriMesh(verts, top_faces.astype(np.int32), pdata)

    if bottom is None:
        if len(verts) == 0:
            return TriMesh(verts, top_faces.astype(np.int32), pdata)
        bottom = stock_bottom if stock_bottom is not None else float(top_z.min()) - 1.0
    try:
        bottom = float(bottom)
    except (TypeError, ValueError):
        raise ValueError(f"bottom must be a number of mm, got {bottom!r}") from None
    if not math.isfinite(bottom):
        raise ValueError(f"bottom must be finite, got {bottom!r}")
    if len(verts) == 0:
        return TriMesh(verts, top_faces.astype(np.int32), pdata)
    if bottom > top_z.min():
        raise ValueError(f"bottom={bottom!r} is above the lowest height {float(top_z.min())!r}")

    # Boundary edges u -> v, directed as in their cell (counter-clockwise: a->b->c->d).
    above, below = pc[1:-1, 1:], pc[1:-1, :-1]      # x-edge (i, j)-(i+1, j): cells (i, j) and (i, j-1)
    i1, j1 = np.nonzero(above & ~below)             # bottom edge a -> b of cell (i, j)
    i2, j2 = np.nonzero(below & ~above)             # top edge c -> d of cell (i, j-1)
    right, left = pc[1:, 1:-1], pc[:-1, 1:-1]       # y-edge (i, j)-(i, j+1): cells (i, j) and (i-1, j)
    i3, j3 = np.nonzero(right & ~left)              # left edge d -> a of cell (i, j)
    i4, j4 = np.nonzero(left & ~right)              # right edge b -> c of cell (i-1, j)
    u = np.concatenate([id_a[i1, j1], id_plain[i2 + 1, j2], id_d[i3, j3 + 1], id_plain[i4, j4]])
    v = np.concatenate([id_plain[i1 + 1, j1], id_d[i2, j2], id_a[i3, j3], id_plain[i4, j4 + 1]])
    n = len(verts)
    walls = np.empty((2 * len(u), 3), dtype=np.int64)
    walls[0::2, 0], walls[0::2, 1], walls[0::2, 2] = v, u, u + n
    walls[1::2, 0], walls[1::2, 1], walls[1::2, 2] = v, u + n, v + n
    cap = top_faces[:, [0, 2, 1]] + n
    all_verts = np.vstack([verts, np.column_stack([verts[:, :2], np.full(n, bottom)])])
    faces = np.vstack([top_faces, walls, cap]).astype(np.int32)
    for name, arr in pdata.items():
        fill = np.full(n, np.nan) if np.issubdtype(arr.dtype, np.floating) else np.zeros(n, dtype=arr.dtype)
        pdata[name] = np.concatenate([arr, fill.astype(np.result_type(arr.dtype, fill.dtype))])
    return TriMesh(all_verts, faces, pdata)
