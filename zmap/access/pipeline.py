"""The whole access pipeline over surface samples, and over any design that gives heights.

:func:`analyse_samples` runs paper 002's steps on samples from any source: the voxel map,
``V'_g`` by cylinder casting, the tool's ``A'``, the 3-axis verdict and the set-ups, with
timings and progress. ``cad_io.access.analyse`` feeds it a part's exact faces;
:func:`analyse_design` and :func:`voxelize_design` feed it the top-most surface of a z-map,
tiled z-map, precision model or registered part (:func:`zmap.access.samples.design_samples`),
with the material below that surface (the ``below`` rule of :mod:`zmap.access.solid`), as a
die is machined from +z.

Examples
--------
A slot 2 mm wide and 5 mm deep in a flat z-map: a 6 mm ball reaches the plateau from 40
directions and the slot's floor from none; a 0.8 mm ball reaches the floor.

>>> import numpy as np
>>> from zmap import ZMap
>>> from zmap.access import Tool, analyse_design, node_directions
>>> slot = ZMap.from_function(lambda x, y: np.where(abs(x - 10) < 1, -5.0, 0.0), (0, 0, 20, 20), 0.25)
>>> for ball in (6.0, 0.8):
...     r = analyse_design(slot, d=0.5, q=2, tool=Tool(ball))
...     print(ball, node_directions(r.vm, r.amap, [4.0, 10.0], [10.0, 10.0])[1].tolist())
6.0 [40, 0]
0.8 [40, 5]
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from .build import AccessModelError, VoxelMap, check_voxel_size, refuse_oversized
from .casting import global_visibility
from .result import AccessResult, set_cover, three_axis
from .samples import Samples, design_samples
from .tool import Tool, accessibility

__all__ = ["check_args", "check_voxel_count", "analyse_samples", "analyse_design", "voxelize_design"]


def check_args(d, step, q) -> tuple[float, float, int]:
    """``(d, step, q)`` checked: a voxel edge, a sampling step below it (d / 4 when None) and a
    direction-set frequency >= 1; :class:`AccessModelError` naming the value otherwise."""
    d = check_voxel_size(d)
    step = d / 4 if step is None else float(step)
    if not np.isfinite(step) or step <= 0 or step >= d:
        raise AccessModelError(f"sampling step d' must be positive and smaller than the voxel d = {d:g} mm, "
                               f"got d' = {step:g} mm")
    if isinstance(q, bool) or not isinstance(q, (int, np.integer)) or q < 1:
        raise AccessModelError(f"q must be an integer >= 1, got {q!r}")
    return d, step, int(q)


def check_voxel_count(bbox, d: float, floor: float | None = None) -> None:
    """Refuse a box ``(xmin, ymin, zmin, xmax, ymax, zmax)`` whose voxel grid at ``d`` would
    exceed :data:`~zmap.access.build.MAX_VOXELS` (counted as ``from_samples`` counts it), before
    minutes of sampling (:func:`~zmap.access.build.refuse_oversized`)."""
    bb = np.asarray(bbox, dtype=np.float64)
    lo = bb[:3].copy()
    if floor is not None:
        lo[2] = min(lo[2], floor)
    refuse_oversized(np.floor((bb[3:] - lo) / d).astype(np.int64) + 5, d)


def _check_tool_fits(tool: Tool, bbox) -> None:
    size = np.asarray(bbox, dtype=np.float64)[3:] - np.asarray(bbox, dtype=np.float64)[:3]
    if tool.diameter > float(np.nanmax(size)):
        raise AccessModelError(f"tool diameter {tool.diameter:g} mm is larger than the part "
                               f"({size[0]:.1f} x {size[1]:.1f} x {size[2]:.1f} mm)")


def _samples_box(s: Samples) -> np.ndarray:
    return np.concatenate([s.points.min(axis=0), s.points.max(axis=0)])


def analyse_samples(sample_at: Callable[[float], Samples], *, d: float = 0.5, q: int = 4, tool: Tool,
                    step: float | None = None, bbox=None, source: str = "", cone: float | None = None,
                    exact: bool = True, rays: int = 2, refine: bool = True, progress=None,
                    tool_step: float | None = None, solid: str = "auto", solid_note: str = "",
                    floor: float | None = None, max_uncertain: float | None = None) -> AccessResult:
    """The whole pipeline on the samples ``sample_at(step)`` gives: voxel map, V'_g, A', 3-axis
    verdict and set-ups, with timings (``result.seconds``).

    Parameters
    ----------
    sample_at : callable ``step -> Samples``
        The surface samples at a step, mm (called at ``step`` and, when it differs, at the
        tool's step).
    d, q, step
        Voxel edge (mm), direction-set frequency (k = 20 q^2), sampling step d' (d / 4).
    tool : Tool
        The ball-end cutter, shank and holder.
    bbox : (xmin, ymin, zmin, xmax, ymax, zmax), optional
        The shape's box, to refuse an oversized grid before sampling (default: the samples').
    source : str
        What was analysed (a file name), kept in the result.
    cone : float, optional
        Set-ups only within this tilt from +z, radians.
    exact, rays, refine
        The exact hemispheres; lines per voxel edge of the cylinder casting
        (:func:`~zmap.access.casting.global_visibility`); cast the half-voxel pieces again where
        a voxel's cylinder is blocked.
    progress : callable ``message -> None``, optional
        Called at each stage.
    tool_step : float, optional
        The step of the samples that A' tests the tool on, max(d', d / 2) by default.
    solid, solid_note, floor, max_uncertain
        The material rule and why, as :meth:`VoxelMap.from_samples
        <zmap.access.build.VoxelMap.from_samples>` takes them.

    Returns
    -------
    AccessResult
    """
    from .solid import check_solid

    say = progress or (lambda msg: None)
    d, step, q = check_args(d, step, q)
    check_solid(solid, floor)
    if bbox is not None:  # before minutes of sampling
        _check_tool_fits(tool, bbox)
        check_voxel_count(bbox, d, floor)
    tstep = max(step, d / 2) if tool_step is None else float(tool_step)
    if not (np.isfinite(tstep) and tstep > 0):
        raise AccessModelError(f"tool_step must be a positive number of mm, got {tool_step!r}")
    sec = {}
    t0 = time.perf_counter()
    say(f"sampling the surface at d' = {step:g} mm")
    s = sample_at(step)
    if bbox is None:  # from_samples refuses an oversized grid itself
        _check_tool_fits(tool, _samples_box(s))
    sec["sample"] = time.perf_counter() - t0
    t = time.perf_counter()
    say(f"{len(s):,} samples; voxel map at d = {d:g} mm, q = {q} (k = {20 * q * q})")
    vm = VoxelMap.from_samples(s.points, s.normals, s.curvature, s.face, s.weight, d=d, q=q, step=step,
                               exact=exact, fine=refine, solid=solid, floor=floor, max_uncertain=max_uncertain,
                               solid_note=solid_note)
    sec["voxelize"] = time.perf_counter() - t
    t = time.perf_counter()
    say(f"material: {vm.solid_note}")
    say(f"{vm.n_boundary:,} boundary, {vm.n_interior:,} interior, {int(vm.uncertain.sum()):,} uncertain voxels; "
        "cylinder casting")
    stats: dict = {"refine": {}, "tool": {}}
    if refine:
        vg, vg_pieces, vg_fine = global_visibility(vm, rays=rays, pieces=True, refine=True, stats=stats["refine"])
    else:
        (vg, vg_pieces), vg_fine = global_visibility(vm, rays=rays, pieces=True), None
    sec["visibility"] = time.perf_counter() - t
    t = time.perf_counter()
    say("accessibility for the tool")
    ts = s if tstep == step else sample_at(tstep)
    amap, amap_pieces = accessibility(vm, vg, tool, pieces=True,
                                      samples=(ts.points, vm.orient(ts.points, ts.normals, ts.face), ts.face),
                                      vg_pieces=vg_pieces, stats=stats["tool"])
    sec["access"] = time.perf_counter() - t
    t = time.perf_counter()
    verdict = three_axis(vm, amap)
    setups = set_cover(vm, amap, cone=cone)
    sec["setups"] = time.perf_counter() - t
    sec["total"] = time.perf_counter() - t0
    return AccessResult(vm=vm, vg=vg, amap=amap, tool=tool, verdict=verdict, setups=setups, seconds=sec,
                        source=source, vg_pieces=vg_pieces, vg_fine=vg_fine,
                        amap_pieces=amap_pieces, stats=stats)


def _design_solid(solid: str) -> str:
    """A design gives the top-most surface only: its material is what lies below it."""
    if solid not in ("auto", "below"):
        raise AccessModelError(f"a design that gives heights has no closed shell: its material is what lies "
                               f"below its surface (solid 'below' or 'auto'), got solid={solid!r}")
    return "below"


def _design_note(design) -> str:
    from ..design import as_design

    return f"below the {as_design(design).kind}'s surface, seen from +z"


def voxelize_design(design, d: float, *, step: float | None = None, q: int = 4, exact: bool = True,
                    check: bool = True, solid: str = "below", floor: float | None = None,
                    max_uncertain: float | None = None, bounds: tuple | None = None) -> VoxelMap:
    """The visibility voxel map of a design's top-most surface at voxel ``d`` (mm), sampled at
    ``step`` (d / 4), with the material below it down to ``floor`` (two voxels under its lowest
    point by default).

    ``design``: anything :func:`zmap.design.as_design` takes; ``bounds``: the region (default:
    the design's). A ``solid`` other than ``'below'`` or ``'auto'`` is refused.
    """
    d, step, q = check_args(d, step, q)
    rule = _design_solid(solid)
    s = design_samples(design, step, bounds=bounds)
    return VoxelMap.from_samples(s.points, s.normals, s.curvature, s.face, s.weight, d=d, q=q, step=step,
                                 exact=exact, check=check, solid=rule, floor=floor, max_uncertain=max_uncertain,
                                 solid_note=_design_note(design))


def analyse_design(design, *, d: float = 0.5, q: int = 4, tool: Tool, step: float | None = None,
                   cone: float | None = None, exact: bool = True, rays: int = 2, refine: bool = True,
                   progress=None, tool_step: float | None = None, solid: str = "below",
                   floor: float | None = None, max_uncertain: float | None = None,
                   bounds: tuple | None = None, source: str = "") -> AccessResult:
    """:func:`analyse_samples` on a design's top-most surface (:func:`design_samples`), the
    material below it: tool access of a z-map, tiled z-map, precision model or part as a die
    seen from +z. Parameters as :func:`analyse_samples`; ``bounds`` the region (default: the
    design's); ``solid`` ``'below'`` (or ``'auto'``, the same here).
    """
    rule = _design_solid(solid)
    return analyse_samples(lambda st: design_samples(design, st, bounds=bounds), d=d, q=q, tool=tool, step=step,
                           source=source, cone=cone, exact=exact, rays=rays, refine=refine, progress=progress,
                           tool_step=tool_step, solid=rule, solid_note=_design_note(design), floor=floor,
                           max_uncertain=max_uncertain)
