"""Pictures of z-maps and their errors (matplotlib, imported only when called)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..grid import ZMap
from ..interpolate import SCHEMES
from ..surfaces import AnalyticSurface

__all__ = ["error_map", "plot_error_maps", "hillshade", "plot_zmap"]


def error_map(zm: ZMap, surface: AnalyticSurface, scheme: str, *, center: tuple[float, float] | None = None,
              cells: int = 4, samples: int = 200):
    """Deviation ``interpolated - exact`` on a fine lattice over ``cells`` x ``cells`` grid cells.

    The lattice starts at the grid point nearest ``center`` (default: the middle of the
    surface's domain), as the magnified error patterns of paper 004 Fig. 5 do.

    Returns
    -------
    x, y, dev : ndarray of shape (samples, samples)
    """
    x0, y0, x1, y1 = surface.domain
    cx, cy = ((x0 + x1) / 2, (y0 + y1) / 2) if center is None else center
    i0 = int(round((cx - zm.x0) / zm.dx))
    j0 = int(round((cy - zm.y0) / zm.dy))
    xs = zm.x0 + zm.dx * (i0 + np.linspace(0, cells, samples))
    ys = zm.y0 + zm.dy * (j0 + np.linspace(0, cells, samples))
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    return X, Y, SCHEMES[scheme](zm, X, Y) - surface.height(X, Y)


def plot_error_maps(panels: Sequence[tuple], *, cells: int = 4):
    """One magnified error map per panel, side by side (paper 004 Fig. 5).

    Each panel is ``(zmap, surface, scheme)`` or ``(zmap, surface, scheme, (cx, cy))``.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.8), squeeze=False)
    for ax, (zm, surf, scheme, *center) in zip(axes[0], panels):
        X, Y, dev = error_map(zm, surf, scheme, center=center[0] if center else None, cells=cells)
        lim = float(np.nanmax(np.abs(dev))) or 1.0
        im = ax.pcolormesh(X, Y, dev, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
        ax.set_title(f"{surf.label}\n{scheme}, grid {zm.dx:g}", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        fig.colorbar(im, ax=ax, shrink=0.8, label="deviation (mm)", format="%.1e")
    fig.tight_layout()
    return fig


def hillshade(z: np.ndarray, dx: float, dy: float, *, azimuth: float = 315.0, altitude: float = 45.0) -> np.ndarray:
    """Lambertian shading in [0, 1] of heights ``z[i, j]``; NaN where there is no surface."""
    gx, gy = np.gradient(z, dx, dy)
    az, alt = np.radians(azimuth), np.radians(altitude)
    lx, ly, lz = np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)
    shade = (-gx * lx - gy * ly + lz) / np.sqrt(1.0 + gx * gx + gy * gy)
    return np.clip(shade, 0.0, 1.0)


def plot_zmap(zm: ZMap, *, title: str = "", ax=None, colorbar: bool = True, cmap: str = "viridis"):
    """Shaded top view of a z-map, coloured by height, with axes in mm and a colour bar.

    Parameters
    ----------
    zm : ZMap
        Heights in mm; NaN cells are left transparent.
    title : str
        Default the map's ``meta["source"]`` (or "z-map") and its grid.
    ax : matplotlib Axes, optional
        Drawn into; a new figure otherwise.
    colorbar : bool
        Add a colour bar "height (mm)" beside ``ax``.
    cmap : str
        Colour map.

    Returns
    -------
    The Axes.
    """
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LightSource, Normalize

    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    z = np.ma.masked_invalid(zm.z.T)
    finite = np.isfinite(zm.z)
    lo, hi = (float(zm.z[finite].min()), float(zm.z[finite].max())) if finite.any() else (0.0, 1.0)
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    ls = LightSource(azdeg=315, altdeg=45)
    filled = np.where(np.isfinite(zm.z.T), zm.z.T, lo)
    rgb = ls.shade(filled, cmap=plt.get_cmap(cmap), dx=zm.dx, dy=zm.dy, vert_exag=1.0, blend_mode="soft",
                   vmin=lo, vmax=hi)
    rgb[..., 3] = np.where(z.mask, 0.0, 1.0)
    ax.imshow(rgb, origin="lower", extent=(zm.x0 - zm.dx / 2, zm.x1 + zm.dx / 2, zm.y0 - zm.dy / 2, zm.y1 + zm.dy / 2))
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    if colorbar:
        from mpl_toolkits.axes_grid1 import make_axes_locatable

        cax = make_axes_locatable(ax).append_axes("right", size="4%", pad=0.12)  # as tall as the map
        ax.figure.colorbar(ScalarMappable(norm=Normalize(lo, hi), cmap=cmap), cax=cax, label="height (mm)")
    if not title:
        grid = f"{zm.dx:g} mm" if zm.dx == zm.dy else f"{zm.dx:g} x {zm.dy:g} mm"
        title = f"{zm.meta.get('source') or 'z-map'}: heights, grid {grid}"
    ax.set_title(title)
    return ax
