"""The grid a part is sampled on, planned once for :func:`cad_io.sample` and
:func:`cad_io.tiled.plan_grid` (so a tiled map's grid is the in-memory map's by construction).

Two steps, because ``sample`` checks memory and starts its progress bar between them:
:func:`plan_inputs` checks the arguments and places the grid on the bounds asked for (or the
faces' boxes), :func:`mesh_and_place` meshes the part where its meshes are coarser than the
deflection and, when no bounds were given, centres the grid on the meshes' extents (on the
surface, unlike the tolerance-padded boxes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Sequence

import numpy as np

from zmap.gridspec import GridSpec

from ._sample_faces import _needs_mesh
from ._sample_grid import FACET_SHARE, START_SHARE, _spacing, _view_bounds
from ._sample_pairs import _MODE, METHODS
from .part import Part
from .view import check_axis, transform_part

__all__ = ["SamplePlan", "mesh_and_place", "plan_inputs"]


@dataclass(frozen=True)
class SamplePlan:
    """Where and how a part is sampled.

    Attributes
    ----------
    spec : GridSpec
        The grid (view frame).
    deflection : float
        Mesh deflection of the Newton starts, mm.
    fine : float or None
        Deflection of the second pass over facet answers on exact faces; None for none.
    default_bounds : bool
        No bounds were asked for: the grid is centred on the meshes' extents.
    domain : tuple of 4 floats
        ``(x0, y0, x1, y1)`` the grid covers: the bounds asked for, else the faces' boxes.
    """

    spec: GridSpec
    deflection: float
    fine: float | None
    default_bounds: bool
    domain: tuple[float, float, float, float]


def plan_inputs(part: Part, grid: Any, *, bounds: Sequence[float] | None, axis: str, method: str,
                deflection: float | None) -> SamplePlan:
    """Check the arguments of ``sample`` and place the grid's lines on ``bounds``.

    ``bounds`` None takes the faces' bounding boxes seen from ``axis``; the default
    ``deflection`` is the interval / ``START_SHARE`` with a second pass at the interval /
    ``FACET_SHARE``.

    Raises
    ------
    ValueError
        An unknown method or axis, a bad grid or bounds, no faces, a deflection not positive.
    """
    if method not in _MODE:
        raise ValueError(f"method={method!r} is not one of {', '.join(repr(m) for m in METHODS)}")
    check_axis(axis)
    dx, dy = _spacing(grid)
    if not part.faces:
        raise ValueError(f"part {part.source!r} has no faces")
    default_bounds = bounds is None
    if default_bounds:
        bounds = _view_bounds(part, axis)
    elif np.shape(bounds) != (4,):
        raise ValueError(f"bounds must be (x0, y0, x1, y1), got {np.asarray(bounds).tolist()!r}")
    spec = GridSpec.covering(bounds, dx, dy)
    fine = None
    if deflection is None:  # a coarse start mesh; facet answers solved again on a fine one
        deflection = min(dx, dy) / START_SHARE
        fine = min(dx, dy) / FACET_SHARE
    deflection = float(deflection)
    if not (math.isfinite(deflection) and deflection > 0):
        raise ValueError(f"deflection must be positive, got {deflection!r}")
    return SamplePlan(spec, deflection, fine if fine is not None and fine < deflection else None, default_bounds,
                      tuple(float(v) for v in bounds))


def mesh_and_place(part: Part, plan: SamplePlan, axis: str) -> tuple[Part, SamplePlan]:
    """Mesh ``part`` at the plan's deflection where needed; returns the part in the view
    frame and the plan with its grid centred on the meshes' extents when no bounds were
    given (a symmetric part gives a symmetric map)."""
    if _needs_mesh(part, plan.deflection):
        from .mesh import triangulate

        triangulate(part, plan.deflection)
    vpart = transform_part(part, axis)
    if not plan.default_bounds:
        return vpart, plan
    ext = [(m.nodes[:, 0].min(), m.nodes[:, 1].min(), m.nodes[:, 0].max(), m.nodes[:, 1].max())
           for m in (f.mesh for f in vpart.faces) if m is not None and len(m.nodes)]
    bounds = plan.domain
    if ext:
        e = np.array(ext)
        bounds = (float(e[:, 0].min()), float(e[:, 1].min()), float(e[:, 2].max()), float(e[:, 3].max()))
    g = GridSpec.covering(bounds, plan.spec.dx, plan.spec.dy, centred=True)
    return vpart, replace(plan, spec=g, domain=bounds)
