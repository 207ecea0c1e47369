"""Pictures of an access analysis, rendered off-screen with pyvista.

The boundary voxels drawn as cubes coloured by the number of accessible directions or by the
set-up that reaches them, and the direction sphere (the k tessels coloured by the area each
direction reaches). Axes in mm, a colour bar with its unit, a title saying what is shown.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..access.directions import count
from .scene import _quiet_vtk, _shot

__all__ = ["voxels_3d", "sphere_3d"]


def _finish(p, path, title) -> Any:
    p.add_text(title, position="upper_left", font_size=11, color="black")
    return _shot(p, path)


def voxels_3d(result, path: str | os.PathLike | None = None, *, by: str = "count", title: str | None = None,
              window_size=(1024, 768)) -> Path | Any:
    """The part's boundary voxels coloured by ``by``: ``"count"`` (accessible directions) or
    ``"setup"`` (the first set-up that reaches each voxel; grey: none).

    Returns the PNG's path, or the Plotter when ``path`` is None.
    """
    if by not in ("count", "setup"):
        raise ValueError(f"by={by!r} is not one of 'count', 'setup'")
    _quiet_vtk()
    import pyvista as pv

    vm = result.vm
    pts = vm.centres
    cloud = pv.PolyData(pts)
    if by == "count":
        vals = count(result.amap).astype(float)
        bar = "accessible directions (of %d)" % vm.directions.k
        cmap = "viridis"
        clim = (0.0, float(max(1, vals.max())))
    else:
        vals = np.full(vm.n_boundary, np.nan)
        for s, su in enumerate(result.setups):
            vals[su["voxels"]] = s + 1
        bar = "set-up number (grey: none)"
        n = max(1, len(result.setups))
        cmap = "tab20" if n <= 20 else "turbo"
        clim = (0.5, n + 0.5)
    cloud["value"] = vals
    glyphs = cloud.glyph(geom=pv.Cube(x_length=vm.d, y_length=vm.d, z_length=vm.d), scale=False, orient=False)
    p = pv.Plotter(off_screen=path is not None, window_size=list(window_size))
    p.set_background("white")
    p.add_mesh(glyphs, scalars="value", cmap=cmap, clim=clim, nan_color="lightgrey",
               scalar_bar_args={"title": bar, "vertical": True, "fmt": "%.0f", "color": "black",
                                "position_x": 0.84, "position_y": 0.15, "height": 0.7, "width": 0.06,
                                "title_font_size": 14, "label_font_size": 12})
    p.show_grid(xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)", color="black", font_size=10)
    p.view_isometric()
    if title is None:
        what = "accessible directions per voxel" if by == "count" else f"{len(result.setups)} set-ups"
        title = (f"{result.source or 'part'}: {what}, d = {vm.d:g} mm, k = {vm.directions.k}, "
                 f"ball {result.tool.diameter:g} mm")
    return _finish(p, path, title)


def sphere_3d(result, path: str | os.PathLike | None = None, *, title: str | None = None,
              window_size=(800, 800)) -> Path | Any:
    """The direction sphere: each tessel coloured by the surface area (mm^2) its direction
    reaches; the chosen set-up directions drawn as arrows with their numbers."""
    _quiet_vtk()
    import pyvista as pv

    vm = result.vm
    ds = vm.directions
    from ..access.directions import to_bool

    reach = to_bool(result.amap, ds.k).T.astype(float) @ vm.area  # (k,)
    verts = ds.vertices.reshape(-1, 3)
    faces = np.hstack([np.full((ds.k, 1), 3), np.arange(3 * ds.k).reshape(-1, 3)]).ravel()
    mesh = pv.PolyData(verts, faces)
    mesh.cell_data["area reached (mm^2)"] = reach
    p = pv.Plotter(off_screen=path is not None, window_size=list(window_size))
    p.set_background("white")
    p.add_mesh(mesh, scalars="area reached (mm^2)", cmap="magma", show_edges=True, edge_color="grey",
               scalar_bar_args={"title": "area reached (mm^2)", "vertical": True, "fmt": "%.3g",
                                "color": "black", "position_x": 0.84, "position_y": 0.15, "height": 0.7,
                                "width": 0.06})
    for s, su in enumerate(result.setups[:12]):
        v = np.asarray(su["vector"])
        p.add_mesh(pv.Arrow(start=v * 1.0, direction=v, scale=0.4), color="deepskyblue")
        p.add_point_labels([v * 1.45], [str(s + 1)], font_size=14, text_color="black", shape=None,
                           show_points=False)
    p.show_grid(xtitle="x", ytitle="y", ztitle="z", color="black", font_size=10)
    p.view_isometric()
    if title is None:
        title = (f"{result.source or 'part'}: direction sphere (q = {vm.q}, k = {ds.k}), "
                 f"area each direction reaches; arrows: set-ups")
    return _finish(p, path, title)
