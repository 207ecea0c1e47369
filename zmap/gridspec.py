"""One rule for the grid lines over a domain: :class:`GridSpec`.

A z-map's nodes lie on lines ``x0 + i * dx`` (``i < nx``) and ``y0 + j * dy``. Every map made
over a domain (a function sampled by :meth:`zmap.ZMap.from_function`, a STEP part sampled by
``cad_io.sample``, the tiled planner ``cad_io.tiled.plan_grid``) takes its lines from
:meth:`GridSpec.covering`: the last line is the first one at or beyond the domain's end, so
no part of the domain is left off the map. A domain that is a whole number of intervals
(within 1e-9 of one) keeps its last line on its end.

Examples
--------
>>> GridSpec.covering((0.0, 0.0, 10.2, 5.0), 1.0).shape
(12, 6)
>>> g = GridSpec.covering((0.0, 0.0, 10.0, 5.0), 1.0, centred=True)
>>> g.shape, g.bounds
((11, 6), (0.0, 0.0, 10.0, 5.0))
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["GridSpec", "OnGrid", "lines_covering", "lines_within"]

#: a domain within this share of an interval of a whole number of intervals ends on a line
_SLACK = 1e-9


def lines_covering(lo: float, hi: float, step: float, *, at_least: int = 2) -> int:
    """Grid lines ``step`` apart from ``lo`` up to the first at or beyond ``hi``; at least
    ``at_least`` (a map needs 2; a row of samples may be 1).

    The covering rule of :class:`GridSpec`: a map, a CZ domain, the drop-cutter's samples.

    Examples
    --------
    >>> lines_covering(0.0, 10.0, 1.0), lines_covering(0.0, 10.0 + 1e-12, 1.0), lines_covering(0.0, 10.2, 1.0)
    (11, 11, 12)
    >>> lines_covering(3.0, 3.0, 1.0), lines_covering(3.0, 3.0, 1.0, at_least=1)
    (2, 1)
    """
    return max(at_least, int(math.ceil((hi - lo) / step - _SLACK)) + 1)


def lines_within(lo: float, hi: float, step: float) -> int:
    """Grid lines ``step`` apart from ``lo`` up to the last at or before ``hi`` (within the
    slack of a whole number of steps): the rule where a line beyond ``hi`` would hold what
    is not there (a dexel stock's rays stay inside its block; toolpath passes inside their
    region; a plain map at the tolerance inside the base's domain).

    Examples
    --------
    >>> lines_within(0.0, 10.0, 1.0), lines_within(0.0, 10.0 - 1e-12, 1.0), lines_within(0.0, 10.2, 1.0)
    (11, 11, 11)
    """
    return int(math.floor((hi - lo) / step + _SLACK)) + 1


@dataclass(frozen=True)
class GridSpec:
    """A regular grid: lines ``x0 + i * dx`` for ``i < nx`` and ``y0 + j * dy`` for ``j < ny`` (mm).

    Parameters
    ----------
    x0, y0 : float
        First grid line along x and y.
    dx, dy : float
        Intervals, positive.
    nx, ny : int
        Lines along x and y, at least 2.
    """

    x0: float
    y0: float
    dx: float
    dy: float
    nx: int
    ny: int

    def __post_init__(self) -> None:
        for name in ("x0", "y0", "dx", "dy"):
            v = getattr(self, name)
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"GridSpec {name} must be a finite number, got {v!r}")
        if not (self.dx > 0 and self.dy > 0):
            raise ValueError(f"GridSpec intervals must be positive, got dx={self.dx!r}, dy={self.dy!r}")
        if int(self.nx) < 2 or int(self.ny) < 2:
            raise ValueError(f"GridSpec needs at least 2 lines along each axis, got {self.nx} x {self.ny}")

    @classmethod
    def covering(cls, bounds: Sequence[float], dx: float, dy: float | None = None, *,
                 centred: bool = False) -> GridSpec:
        """The grid whose lines cover ``bounds = (x0, y0, x1, y1)`` (:func:`lines_covering`).

        The lines start on ``x0`` and ``y0``; with ``centred`` they are centred on the domain
        instead (a symmetric part gives a symmetric map), overhanging it equally on both sides.

        Raises
        ------
        ValueError
            Bounds not finite or reversed; intervals not positive.
        """
        dy = dx if dy is None else dy
        x0, y0, x1, y1 = (float(v) for v in bounds)
        if not all(math.isfinite(v) for v in (x0, y0, x1, y1)) or x1 < x0 or y1 < y0:
            raise ValueError(f"bounds must be finite (x0, y0, x1, y1) with x1 >= x0 and y1 >= y0, got {tuple(bounds)}")
        dx, dy = float(dx), float(dy)
        if not (math.isfinite(dx) and math.isfinite(dy) and dx > 0 and dy > 0):
            raise ValueError(f"grid intervals must be positive and finite, got dx={dx!r}, dy={dy!r}")
        nx, ny = lines_covering(x0, x1, dx), lines_covering(y0, y1, dy)
        if centred:
            x0 = 0.5 * (x0 + x1) - 0.5 * (nx - 1) * dx
            y0 = 0.5 * (y0 + y1) - 0.5 * (ny - 1) * dy
        return cls(x0, y0, dx, dy, nx, ny)

    @property
    def shape(self) -> tuple[int, int]:
        """``(nx, ny)``."""
        return (int(self.nx), int(self.ny))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the first and last lines."""
        return (self.x0, self.y0, self.x0 + (self.nx - 1) * self.dx, self.y0 + (self.ny - 1) * self.dy)

    @property
    def window(self) -> tuple[float, float, float, float]:
        """:attr:`bounds` padded by one interval on every side (the faces a node's cell may touch)."""
        x0, y0, x1, y1 = self.bounds
        return (x0 - self.dx, y0 - self.dy, x1 + self.dx, y1 + self.dy)

    @property
    def x(self) -> np.ndarray:
        """The x lines, shape (nx,)."""
        return self.x0 + self.dx * np.arange(self.nx)

    @property
    def y(self) -> np.ndarray:
        """The y lines, shape (ny,)."""
        return self.y0 + self.dy * np.arange(self.ny)


class OnGrid:
    """The lines, bounds and frame of a map on a grid (:class:`zmap.ZMap`,
    :class:`zmap.tiled.TiledZMap`): one formula for every kind of map.

    A subclass gives ``spec``, its :class:`GridSpec` (local frame), and ``x0``, ``y0``,
    ``dx``, ``dy``, ``nx``, ``ny``, ``angle`` (radians) and ``origin`` (world xy of the
    local origin): the local frame is the world turned by ``angle`` about ``origin``.
    """

    spec: GridSpec
    x0: float
    y0: float
    dx: float
    dy: float
    nx: int
    ny: int
    angle: float
    origin: tuple[float, float]

    @property
    def x(self) -> np.ndarray:
        """Local x of the grid lines, shape (nx,) (:attr:`GridSpec.x`)."""
        return self.spec.x

    @property
    def y(self) -> np.ndarray:
        """Local y of the grid lines, shape (ny,) (:attr:`GridSpec.y`)."""
        return self.spec.y

    @property
    def x1(self) -> float:
        """Local x of the last grid line."""
        return self.spec.bounds[2]

    @property
    def y1(self) -> float:
        """Local y of the last grid line."""
        return self.spec.bounds[3]

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """Local domain ``(x0, y0, x1, y1)`` (:attr:`GridSpec.bounds`)."""
        return self.spec.bounds

    @property
    def frame(self) -> tuple[float, float, float, float]:
        """``(cos angle, sin angle, origin x, origin y)``: the frame as the kernels take it."""
        return math.cos(self.angle), math.sin(self.angle), float(self.origin[0]), float(self.origin[1])

    @property
    def has_frame(self) -> bool:
        """True when the local frame is not the world's (a turn or an origin)."""
        return self.angle != 0.0 or tuple(self.origin) != (0.0, 0.0)

    def world_to_local(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World xy to the map's local frame (identity for a plain map)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if not self.has_frame:
            return x, y
        c, s = math.cos(self.angle), math.sin(self.angle)
        px, py = x - self.origin[0], y - self.origin[1]
        return c * px + s * py, -s * px + c * py

    def local_to_world(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local xy to world xy (identity for a plain map)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if not self.has_frame:
            return x, y
        c, s = math.cos(self.angle), math.sin(self.angle)
        return self.origin[0] + c * x - s * y, self.origin[1] + s * x + c * y

    def index_of(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional grid indices ``(i, j)`` of world points (Eq. 3 of paper 004)."""
        lx, ly = self.world_to_local(x, y)
        return (lx - self.x0) / self.dx, (ly - self.y0) / self.dy

    def world_of(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World xy of (possibly fractional) grid indices."""
        i = np.asarray(i, dtype=np.float64)
        j = np.asarray(j, dtype=np.float64)
        return self.local_to_world(self.x0 + i * self.dx, self.y0 + j * self.dy)

    def grid_points(self) -> tuple[np.ndarray, np.ndarray]:
        """World x and y of every grid point, each of shape (nx, ny)."""
        X, Y = np.meshgrid(self.x, self.y, indexing="ij")
        return self.local_to_world(X, Y)

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """True where a world point lies in the closed grid domain."""
        fi, fj = self.index_of(x, y)
        return (fi >= 0) & (fi <= self.nx - 1) & (fj >= 0) & (fj <= self.ny - 1)
