"""The material of a visibility voxel map, and the voxels whose side the map cannot tell.

Two rules make the interior. ``closed``: the paper's paint spreading (every voxel reached
from the grid's border without crossing a boundary voxel is exterior, the rest interior); it
needs a closed shell at the voxel's resolution. ``below``: the material is what lies below
the top-most surface seen from +z, down to a floor (two voxels under the part's lowest point
unless given), as a die is
machined (per voxel column, below the surface's highest sample near the column's centre, as
a z-map samples it); it serves a die face delivered as an open surface model (a quilt of faces, no
solid), where the paint would leak through the shell. ``auto`` takes ``closed`` and turns to
``below`` when the paint leaks (no interior voxel at all).

Uncertain voxels: a sample whose first voxel off the boundary in front of it (along its
normal, within three voxel edges) is interior (the paint never reached the air there: a gap
narrower than the voxel, or a normal pointing inward), or whose first one behind it is
exterior (the paint reached both sides of a wall thinner than the voxel), makes its voxel
uncertain. The casting treats an uncertain voxel as its whole
cube blocking every direction (:meth:`VoxelMap.blockers <zmap.access.build.VoxelMap.blockers>`),
and the tool map keeps for it only what its own cast keeps (:func:`zmap.access.tool.accessibility`).
:func:`report` says how many there are, their area and where; a map refuses only when their
area is more than ``max_uncertain`` of the boundary's.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SOLID_RULES", "check_solid", "uncertain_report", "describe"]

SOLID_RULES = ("auto", "closed", "below")
#: largest share of the boundary area that may be uncertain before a map is refused
MAX_UNCERTAIN = 0.25
#: voxel sizes suggested to resolve thin walls and gaps, mm
_NICE = (5.0, 4.0, 3.0, 2.5, 2.0, 1.5, 1.0, 0.8, 0.75, 0.6, 0.5, 0.4, 0.3, 0.25, 0.2, 0.15, 0.125, 0.1, 0.08,
         0.075, 0.06, 0.05, 0.04, 0.03, 0.025, 0.02, 0.01)


def check_solid(solid, floor) -> tuple[str, float | None]:
    """``(solid, floor)`` checked: a rule of :data:`SOLID_RULES` and a finite floor or None.

    Examples
    --------
    >>> check_solid("below", -5)
    ('below', -5.0)
    """
    from ._common import AccessModelError

    if solid not in SOLID_RULES:
        raise AccessModelError(f"solid={solid!r} is not one of " + ", ".join(repr(s) for s in SOLID_RULES))
    if floor is not None:
        try:
            floor = float(floor)
        except (TypeError, ValueError):
            floor = float("nan")
        if not np.isfinite(floor):
            raise AccessModelError(f"floor must be a finite z in mm, got {floor!r}")
        if solid == "closed":
            raise AccessModelError("a floor applies to the material below the top surface (solid 'below' or "
                                   "'auto'), not to a closed shell")
    return solid, floor


def kfloor_of(floor: float, origin_z: float, d: float) -> int:
    """The lowest voxel layer of the material below the top surface: the one whose centre
    lies at or above ``floor``."""
    return int(np.ceil((floor - origin_z) / d - 0.5 - 1e-9))


def top_heights(pts: np.ndarray, origin: np.ndarray, d: float, shape, step: float) -> np.ndarray:
    """The top surface's height (nx, ny) at each column's centre, as a z-map samples it: the
    highest sample within ``max(d / 4, step / 2)`` of the centre along x and y (-inf where
    none). A surface that only grazes a column's edge (a wall on a voxel boundary, a face
    that ends there) leaves the column to its neighbours."""
    h = max(0.25, 0.5 * step / d) * (1 + 1e-9)
    u = (pts[:, :2] - origin[:2]) / d
    ij = np.floor(u).astype(np.int64)
    near = (np.abs(u - ij - 0.5) <= h).all(axis=1)
    out = np.full(tuple(shape[:2]), -np.inf)
    np.maximum.at(out, (ij[near, 0], ij[near, 1]), pts[near, 2])
    return out


def nice_voxel(thickness: float) -> float:
    """The largest of the usual voxel sizes at most a third of ``thickness`` (nan: none): a
    voxel lies wholly inside a wall or gap at least twice its edge thick, whatever the grid's
    alignment, and a third leaves a margin.

    Examples
    --------
    >>> nice_voxel(0.7)
    0.2
    """
    if not (np.isfinite(thickness) and thickness > 0):
        return float("nan")
    for v in _NICE:
        if v <= thickness / 3.0 * (1 + 1e-9):
            return v
    return float(_NICE[-1])


def thickness(pts: np.ndarray, nrm: np.ndarray, flagged: np.ndarray, d: float) -> np.ndarray:
    """Per flagged sample (at most 20,000 of them, evenly spread), the distance to the nearest
    sample within 2 d whose normal faces the other way (n . m < -0.5): the wall's thickness or
    the gap's width (inf: none near)."""
    from scipy.spatial import cKDTree

    if not len(flagged):
        return np.zeros(0)
    sel = flagged if len(flagged) <= 20000 else flagged[np.linspace(0, len(flagged) - 1, 20000).astype(np.int64)]
    tree = cKDTree(pts)
    dist, near = tree.query(pts[sel], k=min(48, len(pts)), distance_upper_bound=2 * d, workers=-1)
    dist = np.asarray(dist).reshape(len(sel), -1)
    near = np.asarray(near).reshape(len(sel), -1)
    ok = near < len(pts)
    nn = np.where(ok, near, 0)
    opp = ok & ((nrm[nn] * nrm[sel][:, None, :]).sum(axis=2) < -0.5)
    return np.where(opp, dist, np.inf).min(axis=1)


def uncertain_report(vm, flags: np.ndarray, vox: np.ndarray, pts: np.ndarray, nrm: np.ndarray,
                     fid: np.ndarray) -> dict:
    """The uncertain voxels' figures: ``voxels``, ``area`` (mm^2), ``share`` of the boundary
    area, ``front`` and ``back`` (samples with an interior voxel in front, an exterior one
    behind), ``regions`` (up to five groups of touching uncertain voxels, largest area first:
    ``voxels``, ``area``, ``centre`` (mm), ``faces``), ``thickness`` (mm: a tenth of the
    uncertain samples that face another surface within 2 d have it nearer than this) and
    ``suggest_d`` (the voxel size that would resolve those walls and gaps; nan: none)."""
    from scipy import ndimage

    unc = vm.uncertain
    total = float(vm.area.sum())
    area = float(vm.area[unc].sum())
    out = {"voxels": int(unc.sum()), "area": area, "share": area / total if total > 0 else 0.0,
           "front": int(np.count_nonzero(flags & 1)), "back": int(np.count_nonzero(flags & 2)), "regions": [],
           "thickness": float("nan"), "suggest_d": float("nan")}
    if not unc.any():
        return out
    grid = np.zeros(vm.state.shape, dtype=bool)
    ui = np.flatnonzero(unc)
    grid[tuple(vm.ijk[ui].T)] = True
    labels, n = ndimage.label(grid, structure=np.ones((3, 3, 3), bool))
    lab = labels[tuple(vm.ijk[ui].T)]
    areas = np.bincount(lab, weights=vm.area[ui], minlength=n + 1)
    sizes = np.bincount(lab, minlength=n + 1)
    flagged = np.flatnonzero(flags != 0)
    slab = labels[tuple(vm.ijk[vox[flagged]].T)]
    for r in np.argsort(-areas)[:5]:
        if r == 0 or sizes[r] == 0:
            continue
        inr = ui[lab == r]
        faces = np.unique(fid[flagged[slab == r]])
        out["regions"].append({"voxels": int(sizes[r]), "area": float(areas[r]),
                               "centre": [float(x) for x in vm.point[inr].mean(axis=0)],
                               "faces": [int(f) for f in faces[:20]]})
    t = thickness(pts, nrm, flagged, vm.d)
    t = t[np.isfinite(t)]
    if len(t):
        out["thickness"] = float(np.percentile(t, 10))
        out["suggest_d"] = nice_voxel(out["thickness"])
    out["regions_total"] = int(n)
    return out


def describe(vm) -> list[str]:
    """Lines that say which rule made the material and what is uncertain (for summaries)."""
    lines = [f"material: {vm.solid_note}"]
    u = vm.uncertain_info or {}
    if u.get("voxels"):
        lines.append(f"uncertain voxels (walls or gaps thinner than d = {vm.d:g} mm, or normals pointing inward): "
                     f"{u['voxels']:,}, {u['area']:,.1f} mm^2 ({100 * u['share']:.2f} % of the boundary area)"
                     + _advice(u))
        for r in u["regions"]:
            c = r["centre"]
            lines.append(f"  {r['voxels']:,} voxels, {r['area']:,.1f} mm^2 near ({c[0]:.1f}, {c[1]:.1f}, {c[2]:.1f}) mm, "
                         f"faces {_faces(r['faces'])}")
    else:
        lines.append("uncertain voxels: none")
    return lines


def _advice(u: dict) -> str:
    if np.isfinite(u.get("thickness", np.nan)) and np.isfinite(u.get("suggest_d", np.nan)):
        return (f"; walls and gaps down to {u['thickness']:.3g} mm: --voxel {u['suggest_d']:g} would resolve them")
    return ""


def _faces(ids) -> str:
    from ._common import _ranges

    return _ranges(ids) if len(ids) else "-"


def refusal(vm, max_uncertain: float) -> str:
    """The message refusing a map whose uncertain share exceeds ``max_uncertain``."""
    u = vm.uncertain_info
    where = "; ".join(f"near ({r['centre'][0]:.1f}, {r['centre'][1]:.1f}, {r['centre'][2]:.1f}) mm, faces "
                      f"{_faces(r['faces'])}" for r in u["regions"][:3])
    return (f"{100 * u['share']:.1f} % of the boundary area ({u['area']:,.1f} mm^2, {u['voxels']:,} voxels) is uncertain "
            f"at d = {vm.d:g} mm, more than the {100 * max_uncertain:g} % allowed: walls or gaps thinner than the "
            f"voxel, or normals pointing inward ({where})" + (_advice(u) or "; try a smaller --voxel"))


def open_walls(vm, per: int = 2) -> np.ndarray:
    """Points (m, 3) on the faces that interior voxels share with exterior ones: the sides and
    floor of the material below an open surface (none for a closed shell, whose paint never
    meets the interior), ``per`` x ``per`` per voxel face. The tool is tested against them as
    against the surface samples."""
    from ._solid_kernels import exposed_faces

    origin = np.ascontiguousarray(vm.origin, dtype=np.float64)
    n = exposed_faces(vm.state, origin, float(vm.d), int(per), np.zeros((0, 3)))
    out = np.empty((n, 3))
    if n:
        exposed_faces(vm.state, origin, float(vm.d), int(per), out)
    return out
