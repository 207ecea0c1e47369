"""Numba kernels of :mod:`zmap.access.voxelmap` (no validation, flat arrays only), under their
old path: they live in one module per job.

- :mod:`zmap.access._voxel_kernels`: building the voxel map (samples folded into voxels and
  pieces, the exterior painted, orientation votes, patch slabs) and the voxel states;
- :mod:`zmap.access._line_kernels`: the plane grid of lines along a direction (shared helpers);
- :mod:`zmap.access._blocker_kernels`: the casting's blockers (skin masks, merged boxes);
- :mod:`zmap.access._bit_kernels`: direction bitsets (packing, lists, dilation, set cover);
- :mod:`zmap.access._cast_kernels`: the visibility casting;
- :mod:`zmap.access._ball_kernels`: the ball-end fit and conditions;
- :mod:`zmap.access._tool_kernels`: the shank and holder tests.
"""

from __future__ import annotations

from ._ball_kernels import ball_conditions, ball_fits
from ._bit_kernels import bit_lists, dilate_bits, greedy_cover, pack_columns
from ._blocker_kernels import merge_runs, row_hash, run_members, self_blocking, skin_masks
from ._cast_kernels import cast_directions
from ._line_kernels import _basis  # noqa: F401  (zmap.access._sample_kernels imports it from here)
from ._tool_kernels import disc_max, tool_kernel
from ._voxel_kernels import (BOUNDARY, EXTERIOR, INTERIOR, UNPAINTED, accumulate,  # noqa: F401
                             orientation_votes, paint_exterior, patch_slab, piece_accumulate)

__all__ = ["ball_fits", "accumulate", "paint_exterior", "skin_masks", "merge_runs", "self_blocking", "run_members", "pack_columns", "row_hash", "patch_slab", "piece_accumulate", "cast_directions", "dilate_bits", "bit_lists",
           "ball_conditions", "disc_max", "tool_kernel", "greedy_cover", "orientation_votes"]
