"""Accuracy tables: interpolation schemes on a z-map against an exact surface (paper 004, Table 1).

A surface is sampled on a grid of the given interval that covers its query domain plus a
margin of two intervals, so every query cell has its full 12-point stencil (the table
measures the interior scheme; the edge rule is tested on its own). Each scheme is evaluated
at ``n_points`` uniform random points of the domain (seeded) where the surface exists, and
the table reports the most negative and most positive deviation ``interpolated - exact``.
"""

from __future__ import annotations

import csv
import io
from dataclasses import asdict, dataclass
from typing import Iterable, Sequence

import numpy as np

from .grid import ZMap
from .interpolate import SCHEMES
from .surfaces import SURFACES, TABLE1, AnalyticSurface, get

__all__ = ["AccuracyRow", "zmap_of", "accuracy_rows", "format_markdown", "format_csv", "as_dicts", "STENCIL_MARGIN"]

#: Grid intervals of margin around the query domain (the Bezier stencil reaches 2 cells).
STENCIL_MARGIN = 2


@dataclass(frozen=True)
class AccuracyRow:
    """Deviations of one scheme on one surface at one grid interval (mm)."""

    surface: str
    grid: float
    scheme: str
    min_dev: float
    max_dev: float
    rms: float
    n_points: int

    @property
    def max_abs(self) -> float:
        return max(abs(self.min_dev), abs(self.max_dev))


def zmap_of(surface: AnalyticSurface, grid: float, margin: int = STENCIL_MARGIN) -> ZMap:
    """Sample ``surface`` on a grid of interval ``grid`` over its domain plus ``margin`` cells.

    Examples
    --------
    >>> from zmap.surfaces import get
    >>> zmap_of(get("plane"), 1.0).shape
    (105, 105)
    """
    x0, y0, x1, y1 = surface.domain
    m = margin * grid
    return ZMap.from_function(surface.height, (x0 - m, y0 - m, x1 + m, y1 + m), grid,
                              meta={"source": f"analytic:{surface.name}", "method": "exact"})


def accuracy_rows(
    surfaces: Iterable[str | AnalyticSurface] = TABLE1,
    grids: Sequence[float] = (1.0,),
    schemes: Sequence[str] | None = None,
    *,
    n_points: int = 1_000_000,
    seed: int = 0,
) -> list[AccuracyRow]:
    """Evaluate every scheme on every surface and grid interval.

    Parameters
    ----------
    surfaces : iterable of str or AnalyticSurface
        Names from :data:`zmap.surfaces.SURFACES` or surfaces.
    grids : sequence of float
        Grid intervals in mm (dx = dy).
    schemes : sequence of str, optional
        Names from :data:`zmap.interpolate.SCHEMES`; all of them by default.
    n_points : int
        Random query points per surface and grid (>= 1).
    seed : int
        Seed of ``numpy.random.default_rng``.

    Returns
    -------
    list of AccuracyRow

    Examples
    --------
    >>> rows = accuracy_rows(["plane"], [1.0], ["bilinear"], n_points=1000)
    >>> rows[0].max_abs < 1e-12
    True
    """
    schemes = list(SCHEMES) if schemes is None else list(schemes)
    for s in schemes:
        if s not in SCHEMES:
            raise ValueError(f"scheme={s!r} is not one of {', '.join(repr(k) for k in SCHEMES)}")
    if int(n_points) < 1:
        raise ValueError(f"n_points must be at least 1, got {int(n_points)!r}")
    rows = []
    for surf in surfaces:
        surf = get(surf) if isinstance(surf, str) else surf
        for grid in grids:
            grid = float(grid)
            if not np.isfinite(grid) or grid <= 0:
                raise ValueError(f"grid interval must be positive and finite, got {grid!r}")
            zm = zmap_of(surf, grid)
            rng = np.random.default_rng(seed)
            x0, y0, x1, y1 = surf.domain
            x = rng.uniform(x0, x1, int(n_points))
            y = rng.uniform(y0, y1, int(n_points))
            exact = surf.height(x, y)
            for name in schemes:
                dev = SCHEMES[name](zm, x, y) - exact
                dev = dev[np.isfinite(dev)]
                if dev.size == 0:
                    rows.append(AccuracyRow(surf.name, grid, name, np.nan, np.nan, np.nan, 0))
                    continue
                rows.append(AccuracyRow(surf.name, grid, name, float(dev.min()), float(dev.max()),
                                        float(np.sqrt(np.mean(dev * dev))), int(dev.size)))
    return rows


def format_markdown(rows: Sequence[AccuracyRow]) -> str:
    """A table shaped like Table 1: one row per surface and grid, min / max per scheme."""
    schemes = list(dict.fromkeys(r.scheme for r in rows))
    keys = list(dict.fromkeys((r.surface, r.grid) for r in rows))
    by_key = {(r.surface, r.grid, r.scheme): r for r in rows}
    head = "| surface | grid interval | " + " | ".join(f"{s} (min / max)" for s in schemes) + " |"
    sep = "|---|---|" + "---|" * len(schemes)
    lines = [head, sep]
    for surface, grid in keys:
        label = get(surface).label if surface in SURFACES else surface
        cells = []
        for s in schemes:
            r = by_key.get((surface, grid, s))
            cells.append("" if r is None else f"{r.min_dev:+.2e} / {r.max_dev:+.2e}")
        lines.append(f"| {label} | {grid:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_csv(rows: Sequence[AccuracyRow]) -> str:
    """CSV with columns ``surface,grid,scheme,min_dev,max_dev``."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["surface", "grid", "scheme", "min_dev", "max_dev"])
    for r in rows:
        w.writerow([r.surface, f"{r.grid:g}", r.scheme, f"{r.min_dev:.6e}", f"{r.max_dev:.6e}"])
    return buf.getvalue()


def as_dicts(rows: Sequence[AccuracyRow]) -> list[dict]:
    """Rows as plain dicts (for JSON)."""
    return [asdict(r) | {"max_abs": r.max_abs} for r in rows]
