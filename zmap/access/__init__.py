"""Tool access directions from a visibility voxel map (paper 002, Tangelder, Vergeest et al.).

The kernel-free half: the icosahedral direction set and its bitsets
(:mod:`zmap.access.directions`), paint spreading, cylinder casting, the ball-end
accessibility map with shank and holder, the 3-axis verdict and set-up selection
(:mod:`zmap.access.voxelmap`), the whole pipeline over surface samples and over any design
that gives heights, a die seen from +z (:mod:`zmap.access.pipeline`, samples from
:mod:`zmap.access.samples`). The sampling of a part's exact faces lives in :mod:`cad_io.access`. Submodules load on first use: ``import zmap.access`` compiles nothing.
"""

from __future__ import annotations

from .._lazy import attach


_WHERE = {
    "DirectionSet": "directions", "direction_set": "directions", "to_bool": "directions",
    "from_bool": "directions", "count": "directions",
    "VoxelMap": "voxelmap", "Tool": "voxelmap", "parse_tool": "voxelmap", "paint": "voxelmap",
    "global_visibility": "voxelmap", "accessibility": "voxelmap", "tool_clearance": "voxelmap",
    "three_axis": "voxelmap",
    "set_cover": "voxelmap", "node_directions": "voxelmap", "AccessResult": "voxelmap",
    "AccessModelError": "voxelmap", "voxels_3d": ".plot.access", "sphere_3d": ".plot.access",
    "Samples": "samples", "design_samples": "samples",
    "analyse_samples": "pipeline", "analyse_design": "pipeline", "voxelize_design": "pipeline",
}

__all__ = list(_WHERE)


__getattr__, __dir__ = attach(__name__, _WHERE)
