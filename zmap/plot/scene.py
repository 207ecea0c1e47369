"""3D views of z-maps and of simulated stock, rendered off-screen with pyvista.

Each picture shows the surface coloured by height (or by deviation from a design) with a
colour bar in mm, axes labelled ``x (mm)``, ``y (mm)``, ``z (mm)`` and a title saying what
is shown: the part, or the run with its stage ``k/n`` and the G-code line of that stage.
pyvista (VTK) is imported inside the functions, so ``import zmap`` stays light.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..grid import ZMap, atomic_write

__all__ = ["zmap_3d", "stock_3d", "axes_in_mm"]

_SCALARS = ("height",)


def _quiet_vtk() -> None:
    """Keep VTK's warnings (e.g. "bad X server connection" off-screen) off stderr; errors still show."""
    try:
        from vtkmodules.vtkCommonCore import vtkLogger
    except ImportError:  # older VTK: nothing to silence
        return
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)


def _auto_z_scale(X: np.ndarray, Y: np.ndarray, Z: np.ndarray) -> float:
    """1, 2, 5, 10 or 20: enough to make the z extent about a third of the xy extent."""
    xy = max(float(np.ptp(X)), float(np.ptp(Y)))
    z = float(np.ptp(Z))
    if z <= 0 or xy <= 0:
        return 1.0
    want = 0.35 * xy / z
    return float(max([f for f in (1, 2, 5, 10, 20) if f <= want], default=1))


def _nice_ticks(lo: float, hi: float, n: int = 4) -> tuple[float, float, int]:
    """Round ends and a count of ticks 1, 2, 2.5 or 5 x 10^k apart, about ``n`` intervals over [lo, hi].

    >>> _nice_ticks(0.0, 39.8), _nice_ticks(-10.0, 0.0, 2), _nice_ticks(3.0, 3.0)
    ((0.0, 40.0, 5), (-10.0, 0.0, 3), (3.0, 4.0, 5))
    """
    import math

    span = hi - lo
    if not span > 0:
        lo, span = math.floor(lo), 1.0
        hi = lo + span
    raw = span / n
    mag = 10.0 ** math.floor(math.log10(raw))
    step = min((f * mag for f in (1, 2, 2.5, 5, 10) if f * mag >= raw * (1 - 1e-9)), default=10 * mag)
    a = math.floor(lo / step + 1e-9) * step
    b = math.ceil(hi / step - 1e-9) * step
    return float(a), float(b), int(round((b - a) / step)) + 1


def axes_in_mm(p: Any, bounds: tuple, *, z_scale: float = 1.0, font_size: int = 10) -> Any:
    """Axes labelled ``x (mm)``, ``y (mm)``, ``z (mm)`` at round ticks around ``bounds``.

    Parameters
    ----------
    p : pyvista.Plotter
    bounds : (x0, x1, y0, y1, z0, z1)
        The scene's extent in true mm.
    z_scale : float
        z is drawn stretched by this factor; the labels say true mm.
    font_size : int

    The axes span the ticks' round ends (3 z labels, about 5 on x and y), so no label is an
    odd 39.8; x's last and y's first label are left blank, where the isometric view brings
    them next to y's last and z's lowest, so no two labels overprint.
    """
    from vtkmodules.vtkCommonCore import vtkStringArray

    (x0, x1, nx), (y0, y1, ny), (z0, z1, nz) = (_nice_ticks(bounds[0], bounds[1]),
                                                _nice_ticks(bounds[2], bounds[3]),
                                                _nice_ticks(bounds[4], bounds[5], 2))
    actor = p.show_grid(bounds=(x0, x1, y0, y1, z0 * z_scale, z1 * z_scale), xtitle="x (mm)", ytitle="y (mm)",
                        ztitle="z (mm)", color="black", font_size=font_size, n_xlabels=nx, n_ylabels=ny,
                        n_zlabels=nz, location="outer")

    def labels(lo: float, hi: float, n: int, blank: int | None) -> vtkStringArray:
        out = vtkStringArray()
        for k in range(n):
            out.InsertNextValue("" if k == blank else f"{lo + (hi - lo) * k / (n - 1):.6g}")
        return out

    actor.SetAxisLabels(0, labels(x0, x1, nx, nx - 1))
    actor.SetAxisLabels(1, labels(y0, y1, ny, 0))
    actor.SetAxisLabels(2, labels(z0, z1, nz, None))
    return actor


def _surface_plot(X: np.ndarray, Y: np.ndarray, Z: np.ndarray, values: np.ndarray, *, bar: str,
                  title: str, clim: tuple[float, float] | None, cmap: str,
                  window_size: tuple[int, int], path: str | os.PathLike | None,
                  z_scale: float | str = "auto", bottom: float | None = None) -> Any:
    """Render the grid surface ``Z`` over ``(X, Y)`` (NaN = no surface) coloured by ``values``.

    A flat surface is drawn with its z stretched by ``z_scale`` (said in the title); the axis
    labels keep the true millimetres. With ``bottom`` (a stock's), the four sides down to it and
    the bottom are drawn too, in grey: a closed solid.
    """
    _quiet_vtk()
    import pyvista as pv

    valid = np.isfinite(Z) & np.isfinite(values)
    if not valid.any():
        raise ValueError("nothing to show: every height is NaN")
    lo = float(np.nanmin(Z[valid]))
    Zf = np.where(valid, Z, lo)
    f = _auto_z_scale(X[valid], Y[valid], Zf[valid]) if z_scale == "auto" else float(z_scale)
    if not (np.isfinite(f) and f > 0):
        raise ValueError(f"z_scale must be 'auto' or a positive number, got {z_scale!r}")
    if bottom is not None:
        lo = min(lo, float(bottom))
    ranges = [float(X.min()), float(X.max()), float(Y.min()), float(Y.max()), lo, float(Zf.max())]
    if f != 1.0:
        title += f"  (z drawn x{f:g})"
    grid = pv.StructuredGrid(X, Y, Zf * f)
    grid.point_data[bar] = np.where(valid, values, np.nan).ravel(order="F")
    # keep only the cells whose four nodes all have a height
    mesh = grid if valid.all() else grid.extract_points(valid.ravel(order="F"), adjacent_cells=False)
    if clim is None:
        v = values[valid]
        clim = (float(v.min()), float(v.max()))
        if clim[1] <= clim[0]:
            clim = (clim[0] - 0.5, clim[1] + 0.5)
    p = pv.Plotter(off_screen=path is not None, window_size=list(window_size))
    p.set_background("white")
    if bottom is not None:  # the sides and the bottom of the stock
        zb = float(bottom) * f
        for sl in ((slice(None), 0), (slice(None), -1), (0, slice(None)), (-1, slice(None))):
            xs, ys, zs = X[sl], Y[sl], Zf[sl] * f
            side = pv.StructuredGrid(np.stack([xs, xs]), np.stack([ys, ys]), np.stack([zs, np.full_like(zs, zb)]))
            p.add_mesh(side, color="#b8b8b8")
        p.add_mesh(pv.StructuredGrid(X[[0, -1]][:, [0, -1]], Y[[0, -1]][:, [0, -1]], np.full((2, 2), zb)),
                   color="#b8b8b8")
    p.add_mesh(mesh, scalars=bar, cmap=cmap, clim=clim, smooth_shading=True,
               scalar_bar_args={"title": bar, "vertical": True, "fmt": "%.3g", "color": "black",
                                "position_x": 0.86, "position_y": 0.15, "height": 0.7, "width": 0.06,
                                "title_font_size": 16, "label_font_size": 14})
    axes_in_mm(p, ranges[:4] + [lo, float(Zf.max())], z_scale=f)
    p.add_text(title, position="upper_left", font_size=11, color="black")
    p.view_isometric()
    p.camera.zoom(0.9)
    return _shot(p, path)


def _shot(p: Any, path: str | os.PathLike | None) -> Any:
    """The plotter ``p`` itself without a ``path``; else its screenshot written atomically to
    ``path`` (PNG) and the plotter closed."""
    if path is None:
        return p

    def write(tmp: str) -> None:
        p.screenshot(tmp)

    try:
        return atomic_write(path, write, suffix=".png")
    finally:
        p.close()


def zmap_3d(zm: ZMap, path: str | os.PathLike | None = None, *, title: str | None = None,
            scalars: str | np.ndarray = "height", scalar_title: str | None = None,
            clim: tuple[float, float] | None = None, cmap: str = "viridis",
            window_size: tuple[int, int] = (1024, 768), z_scale: float | str = "auto") -> Path | Any:
    """3D view of a z-map's surface, coloured by height, with colour bar and axes in mm.

    Parameters
    ----------
    zm : ZMap
        Heights in mm; NaN nodes are left out (with their cells).
    path : str or PathLike, optional
        PNG to write (atomically, off-screen). Without it the pyvista Plotter is returned, not
        shown, for a notebook to ``show()``.
    title : str, optional
        Default the map's ``meta["source"]`` and its grid.
    scalars : "height" or ndarray of shape (nx, ny)
        What colours the surface.
    scalar_title : str, optional
        Colour bar title with its unit for an array ``scalars`` (default ``"value"``);
        ``"height (mm)"`` for heights.
    clim : (lo, hi), optional
        Colour range; default the finite range.
    cmap : str
        Colour map.
    window_size : (width, height)
        Pixels.
    z_scale : "auto" or float
        z drawn stretched by this factor (axis labels stay true mm); "auto" stretches a flat surface
        by 2, 5, 10 or 20 so that its relief shows.

    Returns
    -------
    Path of the PNG, or the Plotter when ``path`` is None.

    Examples
    --------
    >>> import numpy as np
    >>> zm = ZMap.from_function(lambda x, y: np.exp(-(x * x + y * y) / 50), (-10, -10, 10, 10), 1.0)
    >>> zmap_3d(zm, "bump3d.png").name  # doctest: +SKIP
    'bump3d.png'
    """
    X, Y = zm.grid_points()
    if isinstance(scalars, str):
        if scalars not in _SCALARS:
            raise ValueError(f"scalars={scalars!r} is not one of " + ", ".join(repr(s) for s in _SCALARS)
                             + " or an array of shape (nx, ny)")
        values, bar = zm.z, "height (mm)"
    else:
        values = np.asarray(scalars, dtype=np.float64)
        if values.shape != zm.z.shape:
            raise ValueError(f"scalars must have the shape of z {zm.z.shape}, got {values.shape}")
        bar = scalar_title or "value"
    if title is None:
        src = zm.meta.get("source") or "z-map"
        grid = f"{zm.dx:g} mm" if zm.dx == zm.dy else f"{zm.dx:g} x {zm.dy:g} mm"
        title = f"{src}: {zm.nx} x {zm.ny} heights, grid {grid}"
    return _surface_plot(X, Y, zm.z, values, bar=bar, title=title, clim=clim, cmap=cmap,
                         window_size=window_size, path=path, z_scale=z_scale)


def stock_3d(run: Any, stage: Any, path: str | os.PathLike | None = None, *, design: ZMap | None = None,
             name: str = "run", program: str | os.PathLike | None = None,
             clim: tuple[float, float] | None = None, cmap: str | None = None,
             window_size: tuple[int, int] = (1024, 768), z_scale: float | str = "auto") -> Path | Any:
    """3D view of a run's stock at a stage: its top surface, coloured by height or by deviation.

    Parameters
    ----------
    run : zmap.sim.session.Run
    stage : int, "end" or fraction text like "1/2".
    path : str or PathLike, optional
        PNG to write; without it the Plotter is returned.
    design : ZMap, optional
        Colour by ``stock - design`` (mm, bilinear design heights, symmetric range) instead of by
        height.
    name : str
        The run's name in the title.
    program : str or PathLike, optional
        The run's G-code file, to quote the stage's line; by default the program the run keeps
        (``run.program_text``).
    clim, cmap, window_size, z_scale : as in :func:`zmap_3d`.

    Returns
    -------
    Path of the PNG, or the Plotter when ``path`` is None.

    Examples
    --------
    >>> from zmap.sim import simulate
    >>> run = simulate(np.array([[2.0, 2.0, -1.0]]), (0, 0, -3, 4, 4, 0), tool="ball:2", pitch=0.25)
    >>> stock_3d(run, "end", "stock3d.png").name  # doctest: +SKIP
    'stock3d.png'
    """
    from .stages import height_range, program_lines, stage_line, stage_title

    k = run.stage(stage)
    s = run.stock
    z = run.display(k)
    x = s.x0 + s.pitch * np.arange(s.nx)
    y = s.y0 + s.pitch * np.arange(s.ny)
    X, Y = np.meshgrid(x, y, indexing="ij")
    text = getattr(run, "program_text", None)  # the .zsim keeps the program it was made from
    lines = program_lines(program) if program is not None else (text.splitlines() if text else None)
    title = stage_title(name, k, run.n_stages, stage_line(run, k), lines)
    if design is None:
        values, bar = z, "height (mm)"
        clim = height_range(run) if clim is None else clim
        cmap = cmap or "viridis"
    else:
        from ..interpolate import bilinear

        values, bar = z - bilinear(design, X, Y), "stock - design (mm)"
        if clim is None:
            fin = values[np.isfinite(values)]
            lim = float(np.abs(fin).max()) if fin.size else 1.0
            clim = (-lim, lim) if lim > 0 else (-1.0, 1.0)
        cmap = cmap or "RdBu_r"
        title += "\ncoloured by stock - design"
    _, near, _ = run.stock.to_csr()
    return _surface_plot(X, Y, z, values, bar=bar, title=title, clim=clim, cmap=cmap,
                         window_size=window_size, path=path, z_scale=z_scale,
                         bottom=float(near.min()) if near.size else None)
