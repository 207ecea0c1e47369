"""Every picture zmap draws, in one place: z-maps and error maps (matplotlib), 3D scenes of maps
and stocks (pyvista), the simulation's stage pictures and GIFs, and the access model's voxels
and direction spheres. The computing packages never import it; commands, the demo, the viewer
and the verify report do.

``from zmap.plot import plot_zmap`` works; submodules load on first use, so ``import zmap.plot``
imports neither matplotlib nor pyvista.

- :mod:`zmap.plot.maps`: :func:`plot_zmap`, :func:`plot_error_maps`, :func:`error_map`, :func:`hillshade`;
- :mod:`zmap.plot.scene`: :func:`zmap_3d`, :func:`stock_3d`, :func:`axes_in_mm`;
- :mod:`zmap.plot.stages`: :class:`StageFigure`, :func:`save_png`, :func:`save_gif` and the stage captions;
- :mod:`zmap.plot.access`: :func:`voxels_3d`, :func:`sphere_3d`.
"""

from __future__ import annotations

from .._lazy import attach

_WHERE = {
    "plot_zmap": "maps", "plot_error_maps": "maps", "error_map": "maps", "hillshade": "maps",
    "zmap_3d": "scene", "stock_3d": "scene", "axes_in_mm": "scene",
    "StageFigure": "stages", "save_png": "stages", "save_gif": "stages", "shade": "stages",
    "stage_line": "stages", "stage_title": "stages", "program_lines": "stages", "height_range": "stages",
    "voxels_3d": "access", "sphere_3d": "access",
}

__all__ = list(_WHERE)

__getattr__, __dir__ = attach(__name__, _WHERE)
