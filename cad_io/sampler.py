"""STEP/NURBS part to master z-map: 2D Jacobian inversion with facet fallback (paper 004 §2.1).

For every face and every grid point that one of the face's mesh triangles covers in xy,
the sampler solves ``x(u, v) = x_g, y(u, v) = y_g`` by damped Newton iteration (2D
Jacobian inversion) on the face's exact NURBS, starting from the barycentric (u, v) of the
grid point in that triangle. The start lies within the mesh deflection of the answer, so
Newton converges in two or three steps, and a face folded over itself gives one start per
layer. A solution counts when it converged, lies within ``face_zgap`` of the facet height
(no jump to another layer) and, for triangles on the mesh boundary, inside the face's trim
loops. Where Newton fails (singular Jacobian on vertical walls and folds, no convergence)
the triangle's exact barycentric height is used instead (the facet path). The top-most
candidate over all faces wins.

The ``face`` layer of the result tells which face gave each height (-1 empty), the
``method`` layer how (0 empty, 1 Jacobian inversion, 2 facet).

This module is the sampler's public face and the grid sampler itself (:func:`sample`); its
stages live beside it: the grid (:mod:`cad_io._sample_grid`), the face set and its meshes
(:mod:`cad_io._sample_faces`, trim loops in :mod:`cad_io._sample_trim`), the pair loop
(:mod:`cad_io._sample_pairs`, kernels in :mod:`cad_io._sample_kernels`), the scattered
points (:mod:`cad_io._sample_points`) and the fine facet pass (:mod:`cad_io._sample_fine`).
Their names stay importable from here; a stage reads its own settings, so patch one where
it lives (``cad_io._sample_points.POINTS_CHUNK``, not ``cad_io.sampler.POINTS_CHUNK``).
"""

from __future__ import annotations

import time
import warnings
from typing import Any, Sequence

import numpy as np

from zmap.grid import ZMap

from ._sample_faces import _face_set
from ._sample_fine import _fine_facets, fine_cast
from ._sample_grid import check_grid_memory, grid_shape
from ._sample_pairs import _MODE, EMPTY, FACET, JACOBIAN, METHODS, NEWTON_MAX_ITER, NEWTON_TOL, _run_pairs
from ._sample_plan import mesh_and_place, plan_inputs
from .part import Part

# importable from here as before: the stages' settings, the scattered-point sampler, and the
# private name cad_io.distance takes (_cached_face_set)
from ._sample_faces import (BOUNDARY_MARGIN, ERROR_SAMPLES, LATTICE, MESH_ERROR_SHARE, SILHOUETTE_RINGS, STEEP_NZ,
                            TIGHT_MESH_ERROR_SHARE, _cached_face_set)
from ._sample_fine import FINE_FACE_TRIANGLES
from ._sample_grid import FACET_SHARE, START_SHARE, estimate_bytes
from ._sample_pairs import CHUNK_PAIRS
from ._sample_points import POINTS_CHUNK, POINTS_DEFLECTION, height_function, sample_points
from ._sample_trim import TRIM_SLACK_MM

__all__ = ["EMPTY", "FACET", "JACOBIAN", "METHODS", "estimate_bytes", "grid_shape", "height_function", "sample",
           "sample_points", "summary", "check_grid_memory"]


def summary(zm: ZMap) -> dict:
    """Counts and shares of the ``method`` layer of a sampled map.

    Returns
    -------
    dict
        ``points``, ``jacobian``, ``facet``, ``empty`` (counts) and ``share_jacobian``,
        ``share_facet``, ``share_empty`` (fractions of all grid points).
    """
    m = zm.layers.get("method")
    n = zm.z.size
    if m is None:
        filled = int(np.isfinite(zm.z).sum())
        counts = {"jacobian": 0, "facet": 0, "empty": n - filled}
    else:
        bc = np.bincount(np.asarray(m, dtype=np.int64).ravel(), minlength=3)
        counts = {"jacobian": int(bc[JACOBIAN]), "facet": int(bc[FACET]), "empty": int(bc[EMPTY])}
    out = {"points": n, **counts}
    for k in ("jacobian", "facet", "empty"):
        out[f"share_{k}"] = counts[k] / n if n else 0.0
    return out


def sample(part: Part, grid: float | tuple[float, float], *, bounds: Sequence[float] | None = None,
           method: str = "auto", axis: str = "+z", deflection: float | None = None,
           progress: bool = False) -> ZMap:
    """Master z-map of a part: top-most height at every grid point, seen from ``axis``.

    Parameters
    ----------
    part : cad_io.Part
        From :func:`cad_io.read_step` or :func:`cad_io.from_geomdl`. Faces without a mesh
        fine enough are (re)triangulated with :func:`cad_io.triangulate` (this sets
        ``face.mesh`` on ``part``).
    grid : float or (float, float)
        Grid interval in mm, or ``(dx, dy)``.
    bounds : (x0, y0, x1, y1), optional
        Domain in the view frame, mm; default the extents of the part's triangulation seen
        from ``axis`` (its bounding box without OCC's tolerance padding).
        Grid points are ``x0 + i*dx``, ``y0 + j*dy`` up to the first line at or beyond
        ``x1``, ``y1`` (:func:`grid_shape`), so the map covers the whole domain; on the
        default domain the lines are centred on the part's extents instead.
    method : {'auto', 'jacobian', 'facet'}
        'auto': Jacobian inversion, facets where it fails; 'jacobian': inversion only
        (points where it fails stay empty unless another face covers them); 'facet':
        barycentric heights of the mesh triangles only.
    axis : {'+z', '-z', '+x', '-x', '+y', '-y'}
        World direction that becomes the map's +z (see :mod:`cad_io.view`).
    deflection : float, optional
        Mesh deflection in mm for starts and facets. Default: a coarse mesh for the
        Newton starts (``min(dx, dy) / START_SHARE``, the grid interval), and the points
        answered by facets on exact faces solved again on a fine one (``min(dx, dy) /
        FACET_SHARE``, grid / 20) of the faces whose box holds such a point (each meshed alone;
        a face too large to mesh that fine gets OCC's exact ray cast instead: :func:`fine_cast`).
    progress : bool or tqdm bar
        Show progress: True draws a bar of the stages (meshing, sampling, facets) in
        per cent; a tqdm bar given here (``total=100``, as ``zmap convert`` opens one before
        reading the file) is carried on from where it stands.

    Returns
    -------
    ZMap
        ``z`` of shape (nx, ny), float64, mm in the view frame, NaN = no surface; layers
        ``face`` (int32, index into ``part.faces``, -1 empty) and ``method`` (int8: 0
        empty, 1 Jacobian inversion, 2 facet); ``meta`` with the source, axis, method,
        deflection, counts and seconds.

    Raises
    ------
    zmap.errors.GridTooLargeError
        The grid's arrays would not fit in the available memory (the message gives bytes).
    ValueError
        Bad ``grid``, ``bounds``, ``method`` or ``axis``, or a part without faces.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "boss.step")
    >>> zm = sample(part, 1.0)
    >>> zm.shape, round(float(np.nanmax(zm.z)), 9), summary(zm)["share_jacobian"]
    ((81, 61), 22.0, 1.0)
    """
    from . import _sample_kernels as K

    t_start = time.perf_counter()
    plan = plan_inputs(part, grid, bounds=bounds, axis=axis, method=method, deflection=deflection)
    need = check_grid_memory(*plan.spec.shape)
    bar, own_bar = _stage_bar(progress)

    t_mesh = time.perf_counter()
    _stage(bar, "meshing", 0.0)
    vpart, placed = mesh_and_place(part, plan, axis)
    t_mesh = time.perf_counter() - t_mesh
    _stage(bar, "sampling", _MESH_SHARE)
    if placed.spec.shape != plan.spec.shape:
        need = check_grid_memory(*placed.spec.shape)
    plan = placed
    x0, y0, dx, dy, nx, ny = (plan.spec.x0, plan.spec.y0, plan.spec.dx, plan.spec.dy, plan.spec.nx, plan.spec.ny)
    deflection, fine, window = plan.deflection, plan.fine, plan.spec.window
    fs = _face_set(vpart, deflection, window)
    for msg in fs.msgs:
        warnings.warn(msg, stacklevel=2)
    F = len(vpart.faces)

    zflat = np.full(nx * ny, np.nan)
    fflat = np.full(nx * ny, -1, dtype=np.int32)
    mflat = np.zeros(nx * ny, dtype=np.int8)
    n_pairs = 0
    if fs.tris is not None:
        counts = np.zeros(len(fs.tris), dtype=np.int64)
        K.count_pairs(fs.nodes, fs.tris, fs.tri_margin, x0, y0, dx, dy, nx, ny, counts)
        mode = _MODE[method]

        def fill(t, offsets, gidx, tri_p, w):
            K.fill_pairs(fs.nodes, fs.tris, fs.tri_margin, t, offsets, x0, y0, dx, dy, nx, ny, gidx, tri_p, w)

        def solve(gidx, tri_p, w, zc, st):
            K.solve_pairs(gidx, tri_p, w, *fs.solve_args(), x0, y0, dx, dy, ny, mode, NEWTON_TOL,
                          NEWTON_MAX_ITER, zc, st)

        total = max(int(counts.sum()), 1)
        span = _SAMPLE_SHARE - _MESH_SHARE
        done = [0]

        def update(n):
            done[0] += n
            _stage(bar, "sampling", _MESH_SHARE + span * done[0] / total)

        try:
            n_pairs = _run_pairs(fs, counts, fill, solve, zflat, fflat, mflat, update)
        except BaseException:
            if own_bar:
                bar.close()
            raise
    n_refined = n_fine = 0
    if fine is not None and fs.tris is not None:
        # facet answers on exact faces (Newton failed there) come from a fine mesh, as
        # they did when every face was meshed at grid / FACET_SHARE: a fine mesh of the
        # faces that may cover them only (Ventilator: 36 of 305 faces for 3 points)
        again = np.flatnonzero((mflat == FACET) & (fs.face_mode[np.maximum(fflat, 0)] == 1))
        if again.size:
            _stage(bar, "facets", _SAMPLE_SHARE)
            gx = x0 + (again // ny) * dx
            gy = y0 + (again % ny) * dy
            z2, f2, m2, n_fine = _fine_facets(part, vpart, gx, gy, fine, deflection, method, axis,
                                              fine_cast(part, fine))
            zflat[again], fflat[again], mflat[again] = z2, f2, m2
            n_refined = int(again.size)
    _stage(bar, "done", 1.0)
    if own_bar:
        bar.close()
    seconds = time.perf_counter() - t_start
    zm = ZMap(x0, y0, dx, dy, zflat.reshape(nx, ny),
              layers={"face": fflat.reshape(nx, ny), "method": mflat.reshape(nx, ny)},
              meta={"source": str(part.source), "axis": axis, "method": method, "deflection": deflection,
                    "facet_deflection": fine if fine is not None else deflection, "facet_points_refined": n_refined,
                    "facet_faces_meshed": n_fine,
                    "faces": F, "pairs": n_pairs, "seconds": round(seconds, 4), "mesh_seconds": round(t_mesh, 4),
                    "memory_estimate_bytes": need, "warnings": fs.msgs})
    zm.meta.update({k: v for k, v in summary(zm).items() if not k.startswith("share")})
    return zm


#: where the stages of :func:`sample` end on its progress bar (shares of the bar)
_MESH_SHARE = 0.15
_SAMPLE_SHARE = 0.95


def _stage_bar(progress: Any) -> tuple[Any, bool]:
    """``(bar, owned)``: a tqdm bar given by the caller (carried on), a new one for True, None."""
    if hasattr(progress, "update") and hasattr(progress, "set_description"):
        return progress, False
    if not progress:
        return None, False
    from tqdm import tqdm

    return tqdm(total=100, unit="%", desc="meshing: ", leave=False,
                bar_format="{desc}{percentage:3.0f}%|{bar}| {elapsed}"), True


def _stage(bar: Any, name: str, share: float) -> None:
    """Move ``bar`` (total 100) to ``share`` of the way, under the stage ``name``."""
    if bar is None:
        return
    start = getattr(bar, "_zmap_start", None)
    if start is None:
        start = float(bar.n)
        bar._zmap_start = start
    target = start + (100.0 - start) * min(max(share, 0.0), 1.0)
    if bar.desc != name + ": ":
        bar.set_description_str(name + ": ", refresh=True)  # every stage is drawn, however short
    if target > bar.n:
        bar.update(target - bar.n)
