"""Feature curves of a die surface: vertical walls and sharp edges (paper 004, §3).

A plain z-map cannot hold a vertical wall (VW) or a sharp edge (SE): the refinements of
:mod:`zmap.refine` add samples along them. This module finds where they are:

- :func:`steep_edges` the grid edges whose slope is at least ``eps_r``;
- :func:`vertical_wall_curves` VW curves traced on the master z-map through those edges;
- :func:`sharp_edge_curves` SE curves from the part's B-rep edges (dihedral above a
  threshold, and open boundary edges);
- :func:`edges_crossing` the grid edges a set of xy polylines crosses.

Grid edges follow the contract of :mod:`zmap.refine.ez`: the x-edge ``(i, j)`` joins grid
points ``(i, j)`` and ``(i+1, j)`` (arrays of shape ``(nx-1, ny)``), the y-edge ``(i, j)``
joins ``(i, j)`` and ``(i, j+1)`` (shape ``(nx, ny-1)``). Curves are xy polylines in world
coordinates, ``ndarray of shape (n, 2)``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from .grid import ZMap

__all__ = [
    "default_eps_r",
    "edges_crossing",
    "sharp_edge_curves",
    "steep_edges",
    "vertical_wall_curves",
]


def _check_zmap(zm: ZMap) -> None:
    if not isinstance(zm, ZMap):
        raise TypeError(f"zm must be a zmap.ZMap, got {type(zm).__name__}")


def default_eps_r(tol: float, dx: float, dy: float) -> float:
    """Slope threshold of a steep grid edge, from the tolerance and the grid.

    A vertical step of height ``H`` somewhere inside a grid edge of length ``h`` appears on
    the base z-map as a ramp of slope ``H / h`` across the cell. The model point
    ``(d, H * (d + h/2) / h)`` of that ramp (step at ``d = 0``) is at 3D distance
    ``min(|d|, z)`` from the true step (the wall or the floor); the largest such distance is
    ``H h / (2 (H + h))``. It stays within ``tol`` exactly when
    ``H <= 2 tol h / (h - 2 tol)``, i.e. when the edge slope is below

        ``eps_r = 2 tol / (h - 2 tol)``,   ``h = max(dx, dy)``.

    Every step that the base z-map cannot hold within ``tol`` in 3D therefore makes its
    edge steep; edges below ``eps_r`` carry no feature the base misses by more than ``tol``
    (smooth steep slopes above it are flagged too; :func:`zmap.refine.ez.build_ez` drops
    those whose e-points the base's Bezier already holds).

    Parameters
    ----------
    tol : float
        Tolerance in mm, > 0 (``inf`` comes back when ``2 tol >= max(dx, dy)``).
    dx, dy : float
        Grid intervals in mm.

    Returns
    -------
    float
        Slope threshold (dimensionless, dz / dxy).

    Examples
    --------
    >>> round(default_eps_r(0.01, 0.5, 0.5), 4)
    0.0417
    """
    tol, dx, dy = float(tol), float(dx), float(dy)
    if not (math.isfinite(dx) and math.isfinite(dy) and dx > 0 and dy > 0):
        raise ValueError(f"dx and dy must be positive, got dx={dx!r}, dy={dy!r}")
    h = max(dx, dy)
    if not (math.isfinite(tol) and tol > 0.0):
        raise ValueError(f"tol must be a positive length in mm, got {tol!r}")
    if 2.0 * tol >= h:
        return math.inf  # every step is then held within tol: no edge needs e-points
    return 2.0 * tol / (h - 2.0 * tol)


def steep_edges(zm: ZMap, eps_r: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid edges whose slope ``|dz| / interval`` is at least ``eps_r``.

    Parameters
    ----------
    zm : ZMap
        Master z-map; NaN heights mark "no surface".
    eps_r : float
        Slope threshold (see :func:`default_eps_r`), >= 0.

    Returns
    -------
    sx : ndarray of shape (nx-1, ny), bool
        x-edge ``(i, j)`` (between ``(i, j)`` and ``(i+1, j)``) is steep.
    sy : ndarray of shape (nx, ny-1), bool
        y-edge ``(i, j)`` (between ``(i, j)`` and ``(i, j+1)``) is steep.
        An edge with a NaN end is never steep.

    Examples
    --------
    >>> zm = ZMap.from_function(lambda x, y: 10.0 * (x > 1.5), (0, 0, 3, 2), 1.0)
    >>> sx, sy = steep_edges(zm, 1.0)
    >>> sx[:, 0].tolist(), bool(sy.any())
    ([False, True, False], False)
    """
    _check_zmap(zm)
    eps_r = float(eps_r)
    if not (math.isfinite(eps_r) and eps_r >= 0.0):
        raise ValueError(f"eps_r must be a finite slope >= 0, got {eps_r!r}")
    z = zm.z
    with np.errstate(invalid="ignore"):
        gx = np.abs(np.diff(z, axis=0)) / zm.dx
        gy = np.abs(np.diff(z, axis=1)) / zm.dy
        sx = gx >= eps_r
        sy = gy >= eps_r
    sx &= ~np.isnan(gx)
    sy &= ~np.isnan(gy)
    return sx, sy


def vertical_wall_curves(zm: ZMap, eps_r: float) -> list[np.ndarray]:
    """VW curves: xy polylines traced through the steep grid edges of the master z-map.

    Each steep edge holds one wall crossing, placed at the midpoint of the edge (the z-map
    only says the wall is somewhere on it, so a crossing is within half a grid interval of
    the wall). Crossings are chained cell by cell: a cell with two steep edges joins their
    crossings; one with three or four joins the opposite pairs (bottom-top, left-right).
    Chains are returned from end to end, closed loops with their first point repeated.

    Parameters
    ----------
    zm : ZMap
        Master z-map (its local frame is honoured: the curves are in world xy).
    eps_r : float
        Slope threshold of a steep edge.

    Returns
    -------
    list of ndarray of shape (n, 2), float64
        World xy of the crossings, mm; single crossings with no neighbour come as (1, 2).

    Examples
    --------
    >>> zm = ZMap.from_function(lambda x, y: 10.0 * (x > 1.5), (0, 0, 3, 2), 1.0)
    >>> [c.tolist() for c in vertical_wall_curves(zm, 1.0)]
    [[[1.5, 0.0], [1.5, 1.0], [1.5, 2.0]]]
    """
    sx, sy = steep_edges(zm, eps_r)
    nx, ny = zm.shape
    nxe = (nx - 1) * ny
    # Node ids: x-edges i*ny + j, then y-edges nxe + i*(ny-1) + j (the e-map numbering).
    n_nodes = nxe + nx * (ny - 1)
    steep = np.concatenate([sx.ravel(), sy.ravel()])
    # Cell (i, j): bottom x(i, j), top x(i, j+1), left y(i, j), right y(i+1, j).
    ci, cj = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    bottom = (ci * ny + cj).ravel()
    top = (ci * ny + cj + 1).ravel()
    left = (nxe + ci * (ny - 1) + cj).ravel()
    right = (nxe + (ci + 1) * (ny - 1) + cj).ravel()
    sides = np.stack([bottom, right, top, left], axis=1)
    flags = steep[sides]
    count = flags.sum(axis=1)
    links: list[np.ndarray] = []
    two = count == 2
    if two.any():
        pick = np.argsort(~flags[two], axis=1, kind="stable")[:, :2]
        links.append(np.take_along_axis(sides[two], pick, axis=1))
    many = count >= 3
    if many.any():
        s = sides[many]
        f = flags[many]
        bt = f[:, 0] & f[:, 2]
        lr = f[:, 1] & f[:, 3]
        links.append(s[bt][:, [0, 2]])
        links.append(s[lr][:, [1, 3]])
    nbr = np.full((n_nodes, 2), -1, dtype=np.int64)
    if links:
        pairs = np.concatenate(links)
        for a, b in pairs:  # at most two cells per edge, so at most two links per node
            nbr[a, 0 if nbr[a, 0] < 0 else 1] = b
            nbr[b, 0 if nbr[b, 0] < 0 else 1] = a
    # Crossing points (edge midpoints) in local then world xy.
    ids = np.arange(n_nodes)
    is_x = ids < nxe
    i = np.where(is_x, ids // ny, (ids - nxe) // max(ny - 1, 1))
    j = np.where(is_x, ids % ny, (ids - nxe) % max(ny - 1, 1))
    lx = zm.x0 + zm.dx * (i + 0.5 * is_x)
    ly = zm.y0 + zm.dy * (j + 0.5 * ~is_x)
    wx, wy = zm.local_to_world(lx, ly)

    visited = np.zeros(n_nodes, dtype=bool)
    curves: list[np.ndarray] = []

    def walk(start: int) -> list[int]:
        chain = [start]
        visited[start] = True
        prev, cur = -1, start
        while True:
            nxt = -1
            for cand in nbr[cur]:
                if cand >= 0 and cand != prev and not visited[cand]:
                    nxt = int(cand)
                    break
            if nxt < 0:
                if len(chain) > 2 and start in nbr[cur] and prev != start:
                    chain.append(start)  # closed loop
                return chain
            visited[nxt] = True
            chain.append(nxt)
            prev, cur = cur, nxt

    nodes = np.flatnonzero(steep)
    degree = (nbr[nodes] >= 0).sum(axis=1)
    for start in np.concatenate([nodes[degree <= 1], nodes[degree == 2]]):
        if not visited[start]:
            chain = walk(int(start))
            curves.append(np.column_stack([wx[chain], wy[chain]]))
    return curves


def sharp_edge_curves(edges: Iterable, *, min_dihedral: float = math.radians(30.0), boundary: bool = True,
                      axis_matrix: np.ndarray | None = None) -> list[np.ndarray]:
    """SE curves: xy polylines of the part edges that are sharp or open.

    Parameters
    ----------
    edges : iterable of edge objects
        Each with ``.points`` (ndarray (n, 3), mm), ``.dihedral`` (radians between the
        adjacent faces' outward normals, NaN for an open edge) and ``.is_boundary``;
        :class:`cad_io.part.Edge` is one.
    min_dihedral : float
        Radians; an edge is sharp when its dihedral is at least this.
    boundary : bool
        Include open boundary edges (one adjacent face).
    axis_matrix : ndarray of shape (3, 3), optional
        Rotation taking world points into the view frame of the z-map (rows are the view
        axes); the xy of ``points @ axis_matrix.T`` is returned. Default identity.

    Returns
    -------
    list of ndarray of shape (n, 2), float64
        One polyline per selected edge (edges with fewer than two points are skipped).

    Examples
    --------
    >>> from types import SimpleNamespace as E
    >>> e = [E(points=np.array([[0., 0, 1], [1, 0, 1]]), dihedral=1.2, is_boundary=False),
    ...      E(points=np.array([[0., 1, 0], [1, 1, 0]]), dihedral=0.1, is_boundary=False)]
    >>> [c.tolist() for c in sharp_edge_curves(e)]
    [[[0.0, 0.0], [1.0, 0.0]]]
    """
    min_dihedral = float(min_dihedral)
    if not (min_dihedral >= 0.0):
        raise ValueError(f"min_dihedral must be an angle >= 0 in radians, got {min_dihedral!r}")
    if axis_matrix is not None:
        axis_matrix = np.asarray(axis_matrix, dtype=np.float64)
        if axis_matrix.shape != (3, 3):
            raise ValueError(f"axis_matrix must have shape (3, 3), got {axis_matrix.shape}")
    curves = []
    for k, e in enumerate(edges):
        pts = np.asarray(e.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"edge {k}: points must have shape (n, 3), got {pts.shape}")
        dihedral = float(e.dihedral)
        keep = (bool(e.is_boundary) and boundary) or (not math.isnan(dihedral) and dihedral >= min_dihedral)
        if not keep or pts.shape[0] < 2:
            continue
        if axis_matrix is not None:
            pts = pts @ axis_matrix.T
        curves.append(np.ascontiguousarray(pts[:, :2]))
    return curves


def _crossings_on_lines(a: np.ndarray, b: np.ndarray, c0: float, h: float, n_lines: int) -> tuple[np.ndarray, np.ndarray]:
    """Segments a->b (columns: along-line coord, across coord) against lines across = c0 + k*h.

    Returns (line index k, along-line coordinate) of every transversal crossing.
    """
    lo = np.minimum(a[:, 1], b[:, 1])
    hi = np.maximum(a[:, 1], b[:, 1])
    transversal = hi > lo
    k0 = np.ceil((lo - c0) / h - 1e-12).astype(np.int64)
    k1 = np.floor((hi - c0) / h + 1e-12).astype(np.int64)
    k0 = np.maximum(k0, 0)
    k1 = np.minimum(k1, n_lines - 1)
    cnt = np.where(transversal, np.maximum(k1 - k0 + 1, 0), 0)
    seg = np.repeat(np.arange(a.shape[0]), cnt)
    if seg.size == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    first = np.repeat(np.cumsum(cnt) - cnt, cnt)
    k = k0[seg] + (np.arange(seg.size) - first)
    across = c0 + k * h
    t = (across - a[seg, 1]) / (b[seg, 1] - a[seg, 1])
    along = a[seg, 0] + t * (b[seg, 0] - a[seg, 0])
    return k, along


def edges_crossing(zm: ZMap, curves: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Grid edges crossed by any of the xy polylines.

    A segment crosses the x-edge ``(i, j)`` where it meets the grid line ``y = y_j`` at an
    x in ``[x_i, x_i+1]`` (a segment lying along the line does not cross it); likewise for
    y-edges. A crossing exactly at a grid point marks the edge that starts there.

    Parameters
    ----------
    zm : ZMap
        The grid (its local frame is honoured).
    curves : sequence of ndarray of shape (n, 2)
        World xy polylines, mm.

    Returns
    -------
    cx : ndarray of shape (nx-1, ny), bool
    cy : ndarray of shape (nx, ny-1), bool

    Examples
    --------
    >>> zm = ZMap(0.0, 0.0, 1.0, 1.0, np.zeros((3, 3)))
    >>> cx, cy = edges_crossing(zm, [np.array([[0.5, -1.0], [0.5, 3.0]])])
    >>> cx[:, :].tolist(), bool(cy.any())
    ([[True, True, True], [False, False, False]], False)
    """
    _check_zmap(zm)
    nx, ny = zm.shape
    cx = np.zeros((nx - 1, ny), dtype=bool)
    cy = np.zeros((nx, ny - 1), dtype=bool)
    segs_a, segs_b = [], []
    for k, c in enumerate(curves):
        c = np.asarray(c, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] != 2:
            raise ValueError(f"curve {k} must have shape (n, 2), got {c.shape}")
        if c.shape[0] < 2:
            continue
        lx, ly = zm.world_to_local(c[:, 0], c[:, 1])
        p = np.column_stack([lx, ly])
        ok = np.isfinite(p).all(axis=1)
        good = ok[:-1] & ok[1:]
        segs_a.append(p[:-1][good])
        segs_b.append(p[1:][good])
    if not segs_a:
        return cx, cy
    a = np.concatenate(segs_a)
    b = np.concatenate(segs_b)
    # x-edges: horizontal grid lines y = y0 + j*dy, along coordinate x.
    j, xs = _crossings_on_lines(a, b, zm.y0, zm.dy, ny)
    i = np.floor((xs - zm.x0) / zm.dx + 1e-12).astype(np.int64)
    i = np.where((i == nx - 1) & (xs <= zm.x1 + 1e-9 * zm.dx), nx - 2, i)
    ok = (i >= 0) & (i <= nx - 2)
    cx[i[ok], j[ok]] = True
    # y-edges: vertical grid lines x = x0 + i*dx, along coordinate y.
    i, ys = _crossings_on_lines(a[:, ::-1], b[:, ::-1], zm.x0, zm.dx, nx)
    j = np.floor((ys - zm.y0) / zm.dy + 1e-12).astype(np.int64)
    j = np.where((j == ny - 1) & (ys <= zm.y1 + 1e-9 * zm.dy), ny - 2, j)
    ok = (j >= 0) & (j <= ny - 2)
    cy[i[ok], j[ok]] = True
    return cx, cy
