"""The visibility voxel map of paper 002 and what it answers, without the CAD kernel.

Pipeline (paper §4.2, steps 1-4):

1. :meth:`VoxelMap.from_samples`: surface samples (point, outward normal, largest concave
   curvature, face id, area weight) at a step d' << d are binned into voxels of edge d. Per
   boundary voxel: ``V'_l`` = AND of ``H_V(t)`` over its samples, ``L'`` = OR of ``H_L(t)``, the
   largest curvature, the surface id (-1 where several faces meet), a crease flag.
2. Paint spreading (:func:`paint`) splits the other voxels into exterior (reached from the
   grid's border without crossing a boundary voxel) and interior, with the paper's model
   checks: boundary voxels edge-connected, one outward side per surface. A part that fails
   raises :class:`AccessModelError` naming the faces and where.
3. :func:`global_visibility`: ``V'_g`` by cylinder casting.
4. :func:`accessibility`: the ball-end map ``A'`` (three conditions over ``E_n(v)``), with
   shank and holder cylinders; :func:`three_axis`, :func:`set_cover` and
   :func:`node_directions` turn it into answers.

Examples
--------
>>> import numpy as np
>>> from zmap.access.voxelmap import VoxelMap
>>> rng = np.random.default_rng(0)
>>> p = rng.normal(size=(20000, 3)); p /= np.linalg.norm(p, axis=1)[:, None]
>>> vm = VoxelMap.from_samples(10 * p, p, np.full(len(p), -0.1), np.zeros(len(p), int),
...                            np.full(len(p), 0.06), d=1.0, q=2)
>>> vm.n_interior > 0 and vm.n_boundary > 0
True
"""

from __future__ import annotations

from .build import (BOUNDARY, EXTERIOR, INTERIOR, MAX_VOXELS, UNPAINTED, AccessModelError,  # noqa: F401
                    Pieces, VoxelMap, _check_connected, check_voxel_size, _direction_set, _orient, vl_all,
                    _fine_pieces, _octant, _octant_lo, _ranges, paint)
from .casting import (_FINE_RAYS, _FINE_STRICT, _REFINE_NEAR, _TILE,  # noqa: F401
                      _FINE_TILE, _cast, _casting, _hide_masks, _merged_blockers, _opposite, _piece_index,
                      _query_boxes, _refine, _row_groups, _self_blocking, _skin_boxes, global_visibility)
from .result import AccessResult, _timer, node_directions, set_cover, three_axis  # noqa: F401
from .tool import (_GRAZE, Tool, _ball_inputs, _blocker_faces, _concave_creases,  # noqa: F401
                   _covered_rows, _curved, _direction_pairs, _disc_rows, _has_pieces, _hemisphere_bits,
                   _plane_faces, _plane_queries, _sample_clearance, _sampled_access, _snap, _split_pieces,
                   accessibility, parse_holder, parse_tool, tool_clearance)

__all__ = ["AccessModelError", "VoxelMap", "Tool", "parse_tool", "parse_holder", "paint",
           "global_visibility", "accessibility", "tool_clearance", "three_axis", "set_cover", "node_directions",
           "AccessResult", "check_voxel_size"]
