"""View axes: the frame in which a part is seen as a height field.

A z-map is always ``z = f(x, y)`` in its own frame. ``axis`` names the world direction that
becomes the frame's +z (the viewer looks down the opposite way, as a tool does along +z).
Every frame is a signed permutation of the world axes, right-handed, so bounding boxes,
NURBS poles (weights unchanged) and meshes map exactly:

====  ===========================
axis  frame (x', y', z') of world
====  ===========================
+z    ( x,  y,  z)
-z    ( x, -y, -z)
+x    ( y,  z,  x)
-x    ( y, -z, -x)
+y    ( x, -z,  y)
-y    ( x,  z, -y)
====  ===========================
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .part import FaceMesh, Part

__all__ = ["AXES", "check_axis", "from_view", "to_view", "transform_part", "view_matrix", "view_part"]

AXES = ("+z", "-z", "+x", "-x", "+y", "-y")

_ROWS = {
    "+z": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    "-z": ((1, 0, 0), (0, -1, 0), (0, 0, -1)),
    "+x": ((0, 1, 0), (0, 0, 1), (1, 0, 0)),
    "-x": ((0, 1, 0), (0, 0, -1), (-1, 0, 0)),
    "+y": ((1, 0, 0), (0, 0, -1), (0, 1, 0)),
    "-y": ((1, 0, 0), (0, 0, 1), (0, -1, 0)),
}


def check_axis(axis: str) -> str:
    """Return ``axis`` if it is one of :data:`AXES`, else raise ValueError naming them."""
    if axis not in _ROWS:
        raise ValueError(f"axis={axis!r} is not one of {', '.join(repr(a) for a in AXES)}")
    return axis


def view_matrix(axis: str = "+z") -> np.ndarray:
    """Rotation ``R`` (3, 3) with ``view = R @ world``; ``R[2]`` is the view axis.

    Examples
    --------
    >>> view_matrix("+x") @ np.array([1.0, 2.0, 3.0])
    array([2., 3., 1.])
    """
    return np.array(_ROWS[check_axis(axis)], dtype=np.float64)


def to_view(points: np.ndarray, axis: str = "+z") -> np.ndarray:
    """World points ``(..., 3)`` to the view frame."""
    return np.asarray(points, dtype=np.float64) @ view_matrix(axis).T


def from_view(points: np.ndarray, axis: str = "+z") -> np.ndarray:
    """View-frame points ``(..., 3)`` back to world."""
    return np.asarray(points, dtype=np.float64) @ view_matrix(axis)


def _bbox(b: tuple, R: np.ndarray) -> tuple:
    lo, hi = np.asarray(b[:3], dtype=np.float64), np.asarray(b[3:], dtype=np.float64)
    a, c = R @ lo, R @ hi
    return (*np.minimum(a, c).tolist(), *np.maximum(a, c).tolist())


def transform_part(part: Part, axis: str = "+z") -> Part:
    """The part seen from ``axis``: poles, meshes and bounding boxes in the view frame.

    The trim loops and (u, v) stay as they are (a rotation does not touch parameters);
    ``shape`` is kept as the world-frame OCP shape. ``+z`` returns ``part`` itself.
    """
    if check_axis(axis) == "+z":
        return part
    R = view_matrix(axis)
    faces = []
    for f in part.faces:
        s = f.surface
        if s is not None:
            s = dataclasses.replace(s, poles=np.ascontiguousarray(s.poles @ R.T))
        m = f.mesh
        if m is not None:
            m = FaceMesh(np.ascontiguousarray(m.nodes @ R.T), m.triangles, m.uv, m.deflection)
        faces.append(dataclasses.replace(f, surface=s, bbox=_bbox(f.bbox, R), mesh=m))
    edges = [dataclasses.replace(e, points=np.asarray(e.points) @ R.T) for e in part.edges]
    return dataclasses.replace(part, faces=faces, edges=edges, warnings=list(part.warnings))


def view_part(part: Part, axis: str = "+z") -> Part:
    """The part in the view frame of ``axis``, its OCP shape rotated too.

    :func:`transform_part` keeps the world-frame OCP shape; this also rotates it, so that
    what works on the shape in the view frame does so there: a later
    :func:`cad_io.triangulate` meshes it in the view frame (the nodes match the rotated
    poles) and OCC's distances (:func:`cad_io.distance.occ_distance`) are measured to the
    rotated faces. The refinement and report steps, which see a part along +z only, take
    this part and a z-map sampled along ``axis``. ``+z`` returns ``part`` itself.

    Parameters
    ----------
    part : Part
        As read (world frame).
    axis : {'+z', '-z', '+x', '-x', '+y', '-y'}
        World direction that becomes the view's +z.

    Returns
    -------
    Part
        A new part in the view frame; ``part`` is not changed.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "boss.step")
    >>> [round(float(v), 6) for v in view_part(part, "+y").bbox] == [round(float(v), 6) for v in
    ...     (part.bbox[0], -part.bbox[5], part.bbox[1], part.bbox[3], -part.bbox[2], part.bbox[4])]
    True
    """
    if check_axis(axis) == "+z":
        return part
    vpart = transform_part(part, axis)
    shape = part.shape
    if shape is not None:
        from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
        from OCP.gp import gp_Trsf

        R = view_matrix(axis)
        t = gp_Trsf()
        t.SetValues(*R[0], 0.0, *R[1], 0.0, *R[2], 0.0)
        # copy=True: the rotated shape gets its own triangulations (meshed in the view frame)
        shape = BRepBuilderAPI_Transform(shape, t, True).Shape()
    return dataclasses.replace(vpart, shape=shape)
