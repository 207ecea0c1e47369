"""Numba kernels of :mod:`zmap.mesh.decimate` (no validation, flat arrays only), under their old
path (``decimate`` and ``local`` reach them as ``K.<name>``): they live in one module per job.

- :mod:`zmap.mesh._polyline_kernels`: the regions' border polylines;
- :mod:`zmap.mesh._delatin_kernels`: the triangulation (predicates, error queue, half-edges);
- :mod:`zmap.mesh._refine_kernels`: the greedy refinement of one region, afresh or incremental;
- :mod:`zmap.mesh._tile_kernels`: a region meshed in full, or in tiles where it holds NaN nodes;
- :mod:`zmap.mesh._measure_kernels`: the error measure and the faces over each point;
- :mod:`zmap.mesh._region_kernels`: whole maps of regions and their local updates.
"""

from __future__ import annotations

from ._measure_kernels import cover_counts, measure_kernel
from ._polyline_kernels import refine_line
from ._refine_kernels import refine_kernel, refine_more_kernel
from ._region_kernels import (assemble, changed_boxes, changed_regions, rays_to_regions, region_has_nan,
                              remesh_regions)
from ._tile_kernels import DENSE_TILE, dense_kernel, full_kernel  # noqa: F401

__all__ = ["refine_line", "refine_kernel", "full_kernel", "measure_kernel", "remesh_regions",
           "refine_more_kernel", "dense_kernel",
           "region_has_nan", "changed_regions", "rays_to_regions", "assemble", "cover_counts", "changed_boxes"]
