"""Decimated meshes of z-maps with a proven vertical error bound (paper 003, regions).

The map is split into square regions of ``region x region`` cells, meshed independently:

1. every region side is refined on its own as a polyline (greedy worst-node insertion)
   until each node of the side is within the allowance of the polyline; both regions that
   share a side get the same vertices, so seams have no T-junctions and no holes;
2. each region's interior is refined by greedy insertion in the manner of Garland and
   Heckbert (Delatin): start from the region's two triangles with the side vertices forced
   in, repeatedly insert the node of largest vertical error, legalising edges to Delaunay,
   until every node is within the allowance.

Every node of the map is then within ``allowance`` of the mesh, measured vertically at the
node (:func:`max_error` measures it). The kernels stop at the allowance less a rounding
margin of ``1e-11 * max(1000, max |z|)`` mm (1e-8 mm for heights up to a metre); an allowance
of 0, or one below that margin, gives the full mesh (two triangles per cell), exact at
every node.

NaN nodes (no surface, e.g. outside a part's outline): a region that holds one is split into
tiles of 8 x 8 cells; a tile with a NaN node is meshed in full over its valid cells (cells
whose four corners are finite, two triangles each), the others are refined like regions,
with their shared sides refined as polylines and every side next to a NaN tile or another
region keeping every node, so its neighbours meet it without cracks; no face ever covers a
NaN node. Cells with a NaN corner are holes in the mesh.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["refine_region", "decimate", "decimate_pro", "max_error", "crack_rays"]


def _grid(source: Any) -> tuple[np.ndarray, float, float, float, float]:
    """(z, x0, y0, dx, dy) of a ZMap or a 2-D array (unit grid at the origin)."""
    if hasattr(source, "z") and hasattr(source, "dx"):
        z = np.ascontiguousarray(source.z, dtype=np.float64)
        return z, float(source.x0), float(source.y0), float(source.dx), float(source.dy)
    z = np.asarray(source)
    if z.ndim != 2 or not (np.issubdtype(z.dtype, np.number) or z.dtype == bool) or np.iscomplexobj(z):
        raise ValueError(f"expected a ZMap or a real 2-D array of heights, got {type(source).__name__} "
                         f"of shape {getattr(z, 'shape', None)}")
    return np.ascontiguousarray(z, dtype=np.float64), 0.0, 0.0, 1.0, 1.0


def check_allowance(allowance: Any) -> float:
    """The allowance as a float; ValueError for a negative, NaN or non-numeric value."""
    try:
        a = float(allowance)
    except (TypeError, ValueError):
        raise ValueError(f"allowance must be a number of mm >= 0, got {allowance!r}") from None
    if not a >= 0 or math.isinf(a):
        raise ValueError(f"allowance must be a finite number of mm >= 0, got {allowance!r}")
    return a


def check_region(region: Any) -> int:
    """The region size in cells as an int; ValueError unless an integer >= 2."""
    if isinstance(region, bool) or not isinstance(region, (int, np.integer)) or region < 2:
        raise ValueError(f"region must be an integer number of cells >= 2, got {region!r}")
    return int(region)


def _tolerance(allowance: float, zscale: float) -> float:
    """The threshold the kernels use: the allowance less a rounding margin (<= 0: full mesh)."""
    if allowance == 0:
        return 0.0
    return allowance - 1e-11 * max(1000.0, zscale)


class _Regions:
    """Per-region meshes of one map in flat pools (the state behind decimate and LocalMesh).

    ``keep_i``/``keep_j`` hold the border vertices of every region side (one answer per
    side, shared by the two regions on it). With ``stateful`` each region also keeps its
    triangulation, so that :meth:`remesh` can update it incrementally (``fresh=False``).
    """

    def __init__(self, z: np.ndarray, allowance: float, region: int, zscale: float | None = None,
                 stateful: bool = False):
        from . import _decimate_kernels as K

        self.K = K
        self.z = z
        self.r = region
        nx, ny = z.shape
        self.nx, self.ny = nx, ny
        self.nrx = max(0, math.ceil((nx - 1) / region)) if nx >= 2 and ny >= 2 else 0
        self.nry = max(0, math.ceil((ny - 1) / region)) if nx >= 2 and ny >= 2 else 0
        if zscale is None:
            zscale = float(np.nanmax(np.abs(z))) if z.size and not np.isnan(z).all() else 0.0
        self.allowance = allowance
        self.tol = _tolerance(allowance, zscale)
        self.full = self.tol <= 0
        nreg = self.nrx * self.nry
        room = 2 * region * region
        self.vpool = np.zeros((nreg, (region + 1) ** 2), dtype=np.int64)
        self.tpool = np.zeros((nreg, room, 3), dtype=np.int32)
        self.nv = np.zeros(nreg, dtype=np.int64)
        self.nt = np.zeros(nreg, dtype=np.int64)
        self.nan = np.zeros((self.nrx, self.nry), dtype=np.bool_)
        self.keep_i = np.zeros((self.nrx + 1, ny), dtype=np.bool_)
        self.keep_j = np.zeros((self.nry + 1, nx), dtype=np.bool_)
        keeping = stateful and not self.full and nreg > 0
        self.ktri = np.zeros((nreg, 3 * room) if keeping else (0, 0), dtype=np.int32)
        self.khe = np.zeros_like(self.ktri)
        self.has = np.zeros(nreg, dtype=np.bool_)
        self.box = np.zeros((self.nrx, self.nry, 4), dtype=np.int64)
        self.ids = np.full(nx * ny, -1, dtype=np.int32) if nreg else np.zeros(0, dtype=np.int32)
        self._mesh_cache = None

    def all_regions(self) -> np.ndarray:
        bi, bj = np.meshgrid(np.arange(self.nrx), np.arange(self.nry), indexing="ij")
        return np.stack([bi.ravel(), bj.ravel()], axis=1).astype(np.int64)

    def remesh(self, todo: np.ndarray, *, fresh: bool = True) -> int:
        """Re-mesh the regions ``todo`` (k, 2) of the current ``z``: afresh, or with
        ``fresh=False`` incrementally from their kept triangulations over the changed boxes
        in ``self.box``. Neighbours whose shared side changed density (a region gained or
        lost a NaN node) are re-meshed afresh too. Returns the number of regions meshed."""
        K = self.K
        if self.nrx == 0 or len(todo) == 0:
            return 0
        old = self.nan.copy()
        K.region_has_nan(self.z, self.r, todo, self.nan)
        mode = np.zeros((self.nrx, self.nry), dtype=np.int8)
        mode[todo[:, 0], todo[:, 1]] = 1 if fresh else 2
        flip = self.nan != old
        if flip.any():
            fb, fj = np.nonzero(flip)
            for di, dj in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
                a, b = fb + di, fj + dj
                ok = (a >= 0) & (a < self.nrx) & (b >= 0) & (b < self.nry)
                mode[a[ok], b[ok]] = 1
            todo = np.argwhere(mode > 0).astype(np.int64)
        bad = K.remesh_regions(self.z, self.r, self.tol, self.full, self.nan, todo, mode,
                               self.vpool, self.tpool, self.nv, self.nt, self.keep_i, self.keep_j,
                               self.ktri, self.khe, self.has, self.box)
        if bad:  # pragma: no cover - the work arrays are sized for the full mesh
            raise RuntimeError(f"{bad} regions overflowed their work arrays")
        self._mesh_cache = None
        return len(todo)

    def triangles(self) -> int:
        return int(self.nt.sum())

    def nodes_faces(self) -> tuple[np.ndarray, np.ndarray]:
        if self.nrx == 0:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3), dtype=np.int32)
        return self.K.assemble(self.vpool, self.tpool, self.nv, self.nt, self.r, self.nry,
                               self.nx, self.ny, self.ids)

    def max_error(self) -> float:
        nodes, faces = self.nodes_faces()
        return _measure(self.z, nodes, faces)

    def mesh(self, x0: float, y0: float, dx: float, dy: float) -> Any:
        if self._mesh_cache is None:
            self._mesh_cache = _trimesh(self.z, nodes_faces=self.nodes_faces(), grid=(x0, y0, dx, dy))
        return self._mesh_cache


def _measure(z: np.ndarray, nodes: np.ndarray, faces: np.ndarray) -> float:
    from . import _decimate_kernels as K

    if len(faces) == 0:
        return 0.0
    ny = z.shape[1]
    vi, vj = np.divmod(nodes, ny)
    return float(K.measure_kernel(z, vi, vj, faces, z[vi, vj]))


def _trimesh(z: np.ndarray, *, nodes_faces: tuple[np.ndarray, np.ndarray], grid: tuple) -> Any:
    from .triangulate import TriMesh

    nodes, faces = nodes_faces
    x0, y0, dx, dy = grid
    vi, vj = np.divmod(nodes, z.shape[1])
    v = np.empty((len(nodes), 3), dtype=np.float64)
    v[:, 0] = x0 + vi * dx
    v[:, 1] = y0 + vj * dy
    v[:, 2] = z[vi, vj]
    return TriMesh(v, faces)


def _node_faces(mesh: Any, z: np.ndarray, grid: tuple) -> tuple[np.ndarray, np.ndarray]:
    x0, y0, dx, dy = grid
    v = np.asarray(mesh.vertices)
    vi = np.rint((v[:, 0] - x0) / dx).astype(np.int64)
    vj = np.rint((v[:, 1] - y0) / dy).astype(np.int64)
    return vi * z.shape[1] + vj, np.asarray(mesh.faces)


def max_error(mesh: Any, source: Any) -> float:
    """Largest vertical distance between a mesh on the grid's nodes and the map's nodes.

    Measured at every node covered by a face (exact barycentric interpolation over the
    triangle that holds it; a node on a shared edge is checked in both triangles).

    Parameters
    ----------
    mesh : TriMesh
        Vertices at grid nodes of ``source`` (as made by :func:`decimate`).
    source : ZMap or ndarray of shape (nx, ny), float64

    Returns
    -------
    float
        mm; ``inf`` if a face covers a NaN node.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.add.outer(np.arange(5.0), np.arange(4.0)) ** 2 / 10
    >>> max_error(decimate(z, 0.3), z) <= 0.3
    True
    """
    z, x0, y0, dx, dy = _grid(source)
    nodes, faces = _node_faces(mesh, z, (x0, y0, dx, dy))
    return _measure(z, nodes, faces)


def crack_rays(mesh: Any, source: Any, n: int = 10_000, *, seed: int = 0) -> int:
    """Vertical rays through random points of the domain that miss the mesh or hit it twice.

    ``n`` points uniform over the map's xy extent (seeded); each should lie in exactly one
    face's xy shadow (a hole or a crack: none; an overlap: two or more). For a map with
    NaN nodes, points in cells with a NaN corner are left out (those cells are holes).

    Returns
    -------
    int
        Misses plus overlaps (0 for a crack-free mesh).

    Examples
    --------
    >>> import numpy as np
    >>> z = np.fromfunction(lambda i, j: np.sin(i / 4) * j / 9, (40, 30))
    >>> crack_rays(decimate(z, 0.01, region=8), z, 2000)
    0
    """
    from . import _decimate_kernels as K

    z, x0, y0, dx, dy = _grid(source)
    nx, ny = z.shape
    if nx < 2 or ny < 2 or n <= 0:
        return 0
    rng = np.random.default_rng(seed)
    px = rng.uniform(0, nx - 1, int(n))
    py = rng.uniform(0, ny - 1, int(n))
    ci = np.minimum(px.astype(np.int64), nx - 2)
    cj = np.minimum(py.astype(np.int64), ny - 2)
    bad_cell = (np.isnan(z[:-1, :-1]) | np.isnan(z[1:, :-1]) | np.isnan(z[:-1, 1:])
                | np.isnan(z[1:, 1:]))
    ok = ~bad_cell[ci, cj]
    px, py, ci, cj = px[ok], py[ok], ci[ok], cj[ok]
    cell = ci * (ny - 1) + cj
    order = np.argsort(cell, kind="stable").astype(np.int64)
    off = np.zeros((nx - 1) * (ny - 1) + 1, dtype=np.int64)
    np.cumsum(np.bincount(cell, minlength=(nx - 1) * (ny - 1)), out=off[1:])
    nodes, faces = _node_faces(mesh, z, (x0, y0, dx, dy))
    vi, vj = np.divmod(nodes, ny)
    count = np.zeros(len(px), dtype=np.int64)
    K.cover_counts(vi, vj, np.ascontiguousarray(faces), px, py, ny - 1, off, order, count)
    return int(np.sum(count != 1))


def decimate(zmap_or_array: Any, allowance: float, *, region: int = 64) -> Any:
    """Decimated triangle mesh of a whole map, every node within ``allowance`` vertically.

    Parameters
    ----------
    zmap_or_array : ZMap or ndarray of shape (nx, ny), float64
        Heights in mm, ``z[i, j]`` at ``(x0 + i*dx, y0 + j*dy)`` (an array: unit grid at
        the origin); NaN = no surface.
    allowance : float
        Largest vertical error in mm at any node, >= 0 (0: full mesh, exact).
    region : int
        Region size in cells (>= 2); regions are meshed independently, crack-free seams.

    Returns
    -------
    TriMesh
        Vertices at grid nodes, faces counter-clockwise seen from +z.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.zeros((65, 65)); z[20:, :] = 5.0
    >>> m = decimate(z, 0.01, region=16)
    >>> m.n_faces < 2 * 64 * 64, max_error(m, z) == 0.0
    (True, True)
    """
    a = check_allowance(allowance)
    r = check_region(region)
    z, x0, y0, dx, dy = _grid(zmap_or_array)
    reg = _Regions(z, a, r)
    reg.remesh(reg.all_regions())
    return reg.mesh(x0, y0, dx, dy)


def decimate_pro(zmap_or_array: Any, allowance: float, *, region: int = 64) -> Any:
    """The paper's method: each region's full mesh decimated by VTK's DecimatePro.

    Paper 003 removes vertices while their distance to the average plane of their
    neighbourhood stays within the allowance; VTK's ``vtkDecimatePro`` with an absolute
    error, topology preserved and no splitting applies the same criterion. Region border
    vertices are never deleted, so seams stay crack-free. The criterion does not bound the
    vertical error at the nodes: measure it with :func:`max_error` (about 4x the allowance
    on walls). Needs VTK (pyvista's dependency).

    Parameters
    ----------
    zmap_or_array, allowance, region
        As :func:`decimate`.

    Returns
    -------
    TriMesh

    Examples
    --------
    >>> import numpy as np
    >>> z = np.fromfunction(lambda i, j: np.sin(i / 5) * np.cos(j / 7), (33, 33))
    >>> m = decimate_pro(z, 0.01, region=16)
    >>> m.n_faces < 2 * 32 * 32, crack_rays(m, z, 2000)
    (True, 0)
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkFiltersCore import vtkDecimatePro

    a = check_allowance(allowance)
    r = check_region(region)
    z, x0, y0, dx, dy = _grid(zmap_or_array)
    reg = _Regions(z, 0.0, r)  # the full mesh of every region (allowance 0)
    reg.remesh(reg.all_regions())
    nx, ny = z.shape
    all_nodes, all_faces, base = [], [], 0
    for k in range(reg.nrx * reg.nry):
        nv, nt = int(reg.nv[k]), int(reg.nt[k])
        if nt == 0:
            continue
        bi, bj = divmod(k, reg.nry)
        i0, j0 = bi * r, bj * r
        h = min(j0 + r, ny - 1) - j0 + 1
        o = reg.vpool[k, :nv]
        gi, gj = i0 + o // h, j0 + o % h
        pts = np.stack([gi.astype(np.float64), gj.astype(np.float64), z[gi, gj]], axis=1)
        faces = reg.tpool[k, :nt]
        if a > 0:
            poly = vtkPolyData()
            vp = vtkPoints()
            vp.SetData(numpy_to_vtk(np.ascontiguousarray(pts), deep=True))
            poly.SetPoints(vp)
            cells = vtkCellArray()
            cells.SetData(numpy_to_vtkIdTypeArray(np.arange(0, 3 * nt + 1, 3, dtype=np.int64), deep=True),
                          numpy_to_vtkIdTypeArray(faces.ravel().astype(np.int64), deep=True))
            poly.SetPolys(cells)
            dec = vtkDecimatePro()
            dec.SetInputData(poly)
            dec.SetTargetReduction(1.0)
            dec.PreserveTopologyOn()
            dec.SplittingOff()
            dec.BoundaryVertexDeletionOff()
            dec.SetErrorIsAbsolute(1)
            dec.SetAbsoluteError(a)
            dec.Update()
            out = dec.GetOutput()
            pts = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
            faces = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
        gi = np.rint(pts[:, 0]).astype(np.int64)
        gj = np.rint(pts[:, 1]).astype(np.int64)
        all_nodes.append(gi * ny + gj)
        all_faces.append(faces.astype(np.int64) + base)
        base += len(pts)
    if not all_faces:
        return _trimesh(z, nodes_faces=(np.zeros(0, np.int64), np.zeros((0, 3), np.int32)),
                        grid=(x0, y0, dx, dy))
    nodes, inv = np.unique(np.concatenate(all_nodes), return_inverse=True)
    faces = inv[np.concatenate(all_faces)].astype(np.int32)
    # counter-clockwise seen from +z
    vi, vj = np.divmod(nodes, ny)
    fa, fb, fc = faces[:, 0], faces[:, 1], faces[:, 2]
    cross = (vi[fb] - vi[fa]) * (vj[fc] - vj[fa]) - (vj[fb] - vj[fa]) * (vi[fc] - vi[fa])
    faces[cross < 0] = faces[cross < 0][:, [0, 2, 1]]
    return _trimesh(z, nodes_faces=(nodes, faces), grid=(x0, y0, dx, dy))


def refine_region(z: Any, x0: float = 0.0, y0: float = 0.0, dx: float = 1.0, dy: float = 1.0,
                  allowance: float = 0.01, *, boundary: Any = None) -> Any:
    """Greedy terrain refinement of one region (Delatin / Garland-Heckbert).

    Parameters
    ----------
    z : ndarray of shape (nx, ny), float64
        The region's heights in mm, ``z[i, j]`` at ``(x0 + i*dx, y0 + j*dy)``, finite
        (a region with NaN is meshed in full over its valid cells).
    x0, y0, dx, dy : float
        Placement of the region's nodes, mm.
    allowance : float
        Largest vertical error in mm at any node, >= 0.
    boundary : ndarray of bool of shape (nx, ny), optional
        Nodes on the region's border to keep as vertices (e.g. shared with a neighbour);
        border nodes not marked are left out (the sides between marked nodes are straight),
        corners are always kept. None: each side is refined as a polyline to the allowance.

    Returns
    -------
    TriMesh
        Every node within ``allowance`` of the mesh when ``boundary`` is None or keeps
        enough side nodes; counter-clockwise faces.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.fromfunction(lambda i, j: np.sin(i / 5) * np.cos(j / 7), (33, 33))
    >>> m = refine_region(z, allowance=0.01)
    >>> m.n_faces < 2 * 32 * 32, max_error(m, z) <= 0.01
    (True, True)
    """
    from . import _decimate_kernels as K

    a = check_allowance(allowance)
    z, _, _, _, _ = _grid(z)
    nx, ny = z.shape
    if nx < 2 or ny < 2:
        return _trimesh(z, nodes_faces=(np.zeros(0, np.int64), np.zeros((0, 3), np.int32)),
                        grid=(x0, y0, dx, dy))
    vout = np.zeros(nx * ny, dtype=np.int64)
    tout = np.zeros((2 * (nx - 1) * (ny - 1), 3), dtype=np.int32)
    tol = _tolerance(a, float(np.nanmax(np.abs(z))) if not np.isnan(z).all() else 0.0)
    if tol <= 0 or np.isnan(z).any():
        nv, nt = K.full_kernel(z, 0, 0, nx, ny, vout, tout)
    else:
        if boundary is None:
            sides = []
            for h in (z[0, :], z[:, -1], z[-1, :], z[:, 0]):
                keep = np.zeros(len(h), dtype=np.bool_)
                K.refine_line(np.ascontiguousarray(h), tol, keep)
                sides.append(np.flatnonzero(keep[1:-1]).astype(np.int64) + 1)
        else:
            b = np.asarray(boundary, dtype=bool)
            if b.shape != z.shape:
                raise ValueError(f"boundary must have the shape of z {z.shape}, got {b.shape}")
            sides = [np.flatnonzero(m[1:-1]).astype(np.int64) + 1
                     for m in (b[0, :], b[:, -1], b[-1, :], b[:, 0])]
        empty = np.zeros(0, dtype=np.int32)
        nv, nt = K.refine_kernel(z, 0, 0, nx, ny, tol, *sides, vout, tout, empty, empty)
        if nv < 0:  # pragma: no cover
            raise RuntimeError("the refinement overflowed its work arrays")
    o = vout[:nv]
    nodes = (o // ny) * ny + o % ny
    return _trimesh(z, nodes_faces=(nodes, tout[:nt].copy()), grid=(x0, y0, dx, dy))
