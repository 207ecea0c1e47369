"""What a damaged STEP file lost, told by its effect on the part's faces.

OCC's reader reports a *fail* on every entity it could not read as written. Some fails
change no face: a seam curve that lists the same pcurve twice (OCC reads the one it needs),
a ``name`` that is not a quoted string. They are *notes*. Every other fail on the shape's
geometry or topology, a face of the file missing from the shape, or a face whose extent is
absurd against the rest of the part (a broken wire leaves a plane unbounded: OCC gives its
box as +-1e100 mm) is *damage*: heights may be missing or wrong.

:func:`absurd_faces` finds the faces of a damaged file that :func:`cad_io.read_step` refuses
(they would take the grid to 10^100 points, or keep the mesher and the sampler busy for
minutes); :func:`lost_share` and :data:`MOST_LOST` decide when a file lost so much of the
part that a map of the rest is no result.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = ["HARMLESS", "MOST_LOST", "absurd_faces", "is_harmless", "lost_share", "refuse_runaway_meshes"]

#: Fail messages of OCC's reader that change no face (a note, not damage): a seam curve
#: naming one pcurve twice; a name, description or id that is not a quoted string.
HARMLESS = (re.compile(r"^Seam Curve with twice the same geom$"),
            re.compile(r"^Parameter n0?\.?\s*\d+ \((name|description|id)\) not a quoted String$"))

#: Share of the file's faces that, lost, make the part lost: ``read_step`` refuses such a
#: file unless ``partial=True`` (``--partial``).
MOST_LOST = 0.5

#: A face of a damaged file whose box reaches beyond the box of the bulk of the part (5 to
#: 95 % of the faces' box ends on each axis) by more than this many times that box's
#: largest side is absurd; so is one reaching 1e99 mm (OCC's "infinite").
ABSURD_REACH = 2.0
_INFINITE = 1e99


def is_harmless(messages) -> bool:
    """True where every one of an entity's fail messages changes no face (see :data:`HARMLESS`).

    Examples
    --------
    >>> is_harmless(["Seam Curve with twice the same geom"]), is_harmless(["Parameter n0.1 (name) not a quoted String"])
    (True, True)
    >>> is_harmless(["Parameter n0.4 (edge_geometry) : Entity has illegal type"]), is_harmless([])
    (False, False)
    """
    messages = [" ".join(str(m).split()) for m in messages]
    return bool(messages) and all(any(p.match(m) for p in HARMLESS) for m in messages)


def absurd_faces(boxes) -> np.ndarray:
    """Indices of the faces whose box is absurd against the part's.

    Parameters
    ----------
    boxes : array_like of shape (n, 6), float
        ``(xmin, ymin, zmin, xmax, ymax, zmax)`` of each face, mm; NaN for a void box (a face
        without geometry is never absurd by its box).

    Returns
    -------
    ndarray of int
        Faces reaching 1e99 mm or more (OCC's box of an unbounded face), and faces reaching
        beyond the box of the bulk of the part (the 5 and 95 % points of the faces' box ends,
        per axis) by more than :data:`ABSURD_REACH` times its largest side (at least 1 mm).

    Examples
    --------
    >>> boxes = [[0, 0, 0, 10, 10, 1]] * 20 + [[-1e100, -1e100, -1e100, 1e100, 1e100, 1e100], [0, 0, 0, 900, 10, 1]]
    >>> absurd_faces(boxes).tolist()
    [20, 21]
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    with np.errstate(invalid="ignore"):
        infinite = np.any(np.abs(b) >= _INFINITE, axis=1)
    sane = np.flatnonzero(~infinite & np.all(np.isfinite(b), axis=1))
    out = infinite.copy()
    if sane.size:
        lo = np.percentile(b[sane, :3], 5, axis=0)
        hi = np.percentile(b[sane, 3:], 95, axis=0)
        reach = ABSURD_REACH * max(float(np.max(hi - lo)), 1.0)
        with np.errstate(invalid="ignore"):
            out |= np.any(b[:, :3] < lo - reach, axis=1) | np.any(b[:, 3:] > hi + reach, axis=1)
    return np.flatnonzero(out)


def lost_share(file_faces: int, shape_faces: int, refused: int) -> tuple[int, float]:
    """Faces of the file lost (missing from the shape, or refused) and their share of the file's.

    Examples
    --------
    >>> lost_share(205, 1, 0)
    (204, 0.9951219512195122)
    """
    lost = max(0, int(file_faces) - int(shape_faces)) + int(refused)
    total = max(int(file_faces), int(shape_faces), 1)
    return lost, lost / total


def refuse_runaway_meshes(part) -> list[int]:
    """Faces of ``part`` whose mesh runs absurdly far beyond the part's box, refused in place.

    A control point whose coordinate a damaged file scales by ten (``89.03`` read as
    ``89.03E1``) leaves the face's edges, and so OCC's box of the face, where they were, while
    its surface spikes a metre away: the mesh follows the spike, the grid grows to cover it
    and the sampler spends minutes on the spike's steep flanks. A face whose mesh nodes reach
    beyond the union of the faces' boxes by more than :data:`ABSURD_REACH` times its largest
    side loses its mesh and surface (it is skipped) and ``part.warnings`` names it.

    Returns the indices of the faces refused.
    """
    import warnings as _warnings

    from cad_io.part import FaceMesh

    boxes = np.array([f.bbox for f in part.faces], dtype=np.float64).reshape(-1, 6)
    if not np.isfinite(boxes).any():
        return []
    lo = np.nanmin(boxes[:, :3], axis=0)
    hi = np.nanmax(boxes[:, 3:], axis=0)
    reach = ABSURD_REACH * max(float(np.max(hi - lo)), 1.0)
    out = []
    for f in part.faces:
        m = f.mesh
        if m is None or len(m.nodes) == 0:
            continue
        over = float(max(np.max(lo - m.nodes.min(axis=0)), np.max(m.nodes.max(axis=0) - hi)))
        if over > reach:
            msg = (f"face {f.index} ({f.kind}) refused: its surface runs {over:,.0f} mm beyond the part's box "
                   f"(x {lo[0]:.4g} .. {hi[0]:.4g}, y {lo[1]:.4g} .. {hi[1]:.4g}, z {lo[2]:.4g} .. {hi[2]:.4g} mm) "
                   f"while its edges stay inside: a damaged control point; the face is left out")
            f.mesh = FaceMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32), None, m.deflection)
            f.surface = None
            part.warnings.append(msg)
            _warnings.warn(msg, stacklevel=3)
            out.append(f.index)
    return out
