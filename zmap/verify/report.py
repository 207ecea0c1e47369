"""Writers of a :class:`~zmap.verify.compare.Comparison`: markdown / CSV / JSON reports, the
regions as CSV, a deviation PNG and a pyvista 3D picture.

Colours are tied to the tolerance band: the band ``[-tol, tol]`` is one neutral colour (green),
gouges are shades of blue and excesses shades of red, in steps of ``tol`` up to the largest
deviation (at least 4 steps, at most 10 per side, the last step open-ended). Every writer
writes to a temporary name and renames.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..grid import atomic_write, atomic_write_text

__all__ = ["format_markdown", "format_csv", "format_json", "regions_csv", "write_report",
           "deviation_png", "deviation_3d", "band_colours"]

_REGION_COLS = ["kind", "rays", "area_mm2", "volume_mm3", "depth_mm", "xmin", "ymin", "xmax", "ymax",
                "deepest_x", "deepest_y", "first_stage", "first_line", "first_x", "first_y"]


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        if math.isnan(v):
            return "-"
        return f"{v:.6g}"
    return str(v)


def format_markdown(c: Any, *, name: str = "stock", design: str = "design", program_lines: list | None = None,
                    max_regions: int = 20, collisions: list | None = None) -> str:
    """A markdown report: totals, then the largest regions (gouges first), then collisions."""
    t = c.totals
    out = [f"# {name} against {design}, stage {c.stage}/{c.n_stages}", "",
           f"tolerance +-{c.tol:g} mm, design offset {c.offset:g} mm, ray pitch {c.pitch:g} mm", "",
           "| figure | value |", "|---|---:|"]
    for key in ("covered_rays", "uncovered_area_mm2", "outline_area_mm2", "short_area_mm2", "gouge_regions",
                "gouge_area_mm2", "gouge_volume_mm3", "max_gouge_mm", "excess_regions", "excess_area_mm2",
                "excess_volume_mm3", "max_excess_mm", "within_rays", "first_gouge_stage", "first_gouge_line"):
        if key in t:
            out.append(f"| {key} | {_fmt(t[key])} |")
    regs = c.regions[:max_regions]
    if regs:
        out += ["", f"## Regions ({len(c.regions)}; gouges first, each kind largest volume first)", "",
                "| kind | area mm^2 | volume mm^3 | depth mm | bbox x mm | bbox y mm | first stage | first line |",
                "|---|---:|---:|---:|---|---|---:|---:|"]
        for r in regs:
            line = _fmt(r.first_line) if r.first_line >= 0 else "-"
            if program_lines and 0 < r.first_line <= len(program_lines):
                line += f": `{program_lines[r.first_line - 1].strip()[:40]}`"
            out.append(f"| {r.kind} | {r.area:.4g} | {r.volume:.4g} | {r.depth:.4g} | {r.bbox[0]:.3f}..{r.bbox[2]:.3f} "
                       f"| {r.bbox[1]:.3f}..{r.bbox[3]:.3f} | {r.first_stage if r.first_stage >= 0 else '-'} | {line} |")
    if collisions is not None:
        out += ["", f"## Collisions ({len(collisions)})", ""]
        if collisions:
            out += ["| kind | stage | line | x | y | z | detail |", "|---|---:|---:|---:|---:|---:|---|"]
            for h in collisions[:max_regions]:
                out.append(f"| {h.kind} | {h.stage} | {h.line} | {h.x:.3f} | {h.y:.3f} | {h.z:.3f} | {h.detail} |")
        else:
            out.append("none")
    return "\n".join(out) + "\n"


def format_csv(c: Any) -> str:
    """The totals as two-column CSV (figure, value)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["figure", "value"])
    for k, v in c.totals.items():
        w.writerow([k, v])
    return buf.getvalue()


def format_json(c: Any, *, collisions: list | None = None) -> str:
    """Totals, regions and collisions as one JSON object."""
    obj = {"totals": c.totals, "regions": [r.as_dict() for r in c.regions]}
    if collisions is not None:
        obj["collisions"] = [h.as_dict() for h in collisions]
    return json.dumps(obj, indent=1, default=float) + "\n"


def regions_csv(c: Any) -> str:
    """One CSV row per region (columns ``kind, rays, area_mm2, ..., first_line``)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=_REGION_COLS, lineterminator="\n")
    w.writeheader()
    for r in c.regions:
        w.writerow(r.as_dict())
    return buf.getvalue()


def write_report(c: Any, path: str | os.PathLike, *, fmt: str | None = None, **kw: Any) -> Path:
    """Write the report as markdown, CSV or JSON (``fmt`` default: from the suffix)."""
    fmt = fmt or {".md": "markdown", ".csv": "csv", ".json": "json"}.get(Path(path).suffix.lower(), "markdown")
    if fmt not in ("markdown", "csv", "json"):
        raise ValueError(f"fmt={fmt!r} is not one of 'markdown', 'csv', 'json'")
    if fmt == "markdown":
        text = format_markdown(c, **kw)
    elif fmt == "json":
        text = format_json(c, collisions=kw.get("collisions"))
    else:
        text = format_csv(c)
    return atomic_write_text(path, text)


def band_colours(c: Any) -> tuple[list, list]:
    """``(boundaries, colours)`` of the deviation colour scale tied to the tolerance band."""
    tol = c.tol if c.tol > 0 else max(1e-3, 0.01)
    fin = c.deviation[np.isfinite(c.deviation)]
    lim = float(np.abs(fin).max()) if fin.size else tol
    n = int(min(10, max(4, math.ceil(lim / tol))))
    step = max(tol, (lim - tol) / (n - 1)) if lim > tol else tol
    pos = [tol + q * step for q in range(n)]
    bounds = [-b for b in reversed(pos)] + pos
    from matplotlib import colormaps

    blues = colormaps["Blues"]
    reds = colormaps["Reds"]
    under = [blues(0.35 + 0.65 * (n - 1 - q) / max(n - 2, 1)) for q in range(n - 1)]
    over = [reds(0.35 + 0.65 * q / max(n - 2, 1)) for q in range(n - 1)]
    colours = under + [(0.55, 0.85, 0.45, 1.0)] + over
    return bounds, colours


def deviation_png(c: Any, path: str | os.PathLike, *, title: str | None = None, mark_first: bool = True) -> Path:
    """Top view of the deviation in mm: blue gouge, green within +-tol, red excess, grey uncovered,
    sand-coloured the outline and short rays (below the band but never cut: not gouges)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.figure import Figure

    bounds, colours = band_colours(c)
    cmap = ListedColormap(colours).with_extremes(under=colours[0], over=colours[-1], bad=(0.8, 0.8, 0.8, 1.0))
    norm = BoundaryNorm(bounds, cmap.N)
    nx, ny = c.deviation.shape
    ext = (c.x0 - c.pitch / 2, c.x0 + (nx - 0.5) * c.pitch, c.y0 - c.pitch / 2, c.y0 + (ny - 0.5) * c.pitch)
    # a figure with its own canvas: the caller's backend (a notebook's) is left as it is
    fig = Figure(figsize=(8, 6.5))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    from .deviation import CLASSES

    apart = np.isin(c.classes, (CLASSES["outline"], CLASSES["short"]))
    im = ax.imshow(np.ma.masked_where(apart.T | ~np.isfinite(c.deviation.T), c.deviation.T), origin="lower",
                   extent=ext, cmap=cmap, norm=norm, interpolation="nearest")
    if apart.any():
        ax.imshow(np.ma.masked_where(~apart.T, np.ones(apart.T.shape)), origin="lower", extent=ext,
                  cmap=ListedColormap([(0.93, 0.82, 0.55, 1.0)]), vmin=0, vmax=2, interpolation="nearest")
    cb = fig.colorbar(im, ax=ax, extend="both", spacing="uniform")
    cb.set_label(f"stock - (design + {c.offset:g}) (mm); green: within +-{c.tol:g} mm; sand: outline / short")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    t = c.totals
    # over the whole figure, wrapped: a title as wide as the axes would run under the colour bar
    import textwrap

    fig.suptitle(textwrap.fill(title or (f"deviation at stage {c.stage}/{c.n_stages}: {t['gouge_regions']} gouges "
                                         f"(max {t['max_gouge_mm']:.4g} mm), {t['excess_regions']} excesses "
                                         f"(max {t['max_excess_mm']:.4g} mm)"), 80), fontsize=10)
    g = c.first_gouge() if mark_first else None
    if g is not None:
        ax.plot(*g.first_xy, marker="x", color="k", ms=10)
        ax.annotate(f"first gouge: line {g.first_line}", g.first_xy, xytext=(8, 8), textcoords="offset points",
                    fontsize=9)

    def write(tmp: str) -> None:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")

    return atomic_write(path, write, suffix=".png")


def deviation_3d(c: Any, path: str | os.PathLike | None = None, *, title: str | None = None,
                 window_size: tuple[int, int] = (1024, 768)) -> Any:
    """pyvista 3D view of the stock top coloured by deviation (same tolerance-tied colours)."""
    from matplotlib.colors import ListedColormap

    from ..plot.scene import _surface_plot

    bounds, colours = band_colours(c)
    # a continuous colour map sampled so that each band keeps its colour over the clim
    lo, hi = bounds[0], bounds[-1]
    n = 256
    vals = lo + (hi - lo) * (np.arange(n) + 0.5) / n
    idx = np.clip(np.searchsorted(bounds, vals) - 1, 0, len(colours) - 1)
    cmap = ListedColormap([colours[i] for i in idx])
    nx, ny = c.top.shape
    x = c.x0 + c.pitch * np.arange(nx)
    y = c.y0 + c.pitch * np.arange(ny)
    X, Y = np.meshgrid(x, y, indexing="ij")
    t = c.totals
    title = title or (f"stock at stage {c.stage}/{c.n_stages} coloured by deviation from design "
                      f"(tol +-{c.tol:g} mm)\n{t['gouge_regions']} gouges, {t['excess_regions']} excesses")
    return _surface_plot(X, Y, c.top, np.clip(c.deviation, lo, hi), bar="deviation (mm)", title=title,
                         clim=(lo, hi), cmap=cmap, window_size=window_size, path=path)
