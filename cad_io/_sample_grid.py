"""Grid planning of the z-map sampler (:mod:`cad_io.sampler`): the grid intervals, the domain
seen from the view axis and the grid lines that cover it, the default mesh deflections as
shares of the interval, and the memory a grid needs.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from zmap.fmt import count
from zmap.gridspec import GridSpec
from zmap.memory import check_room

from ._sample_pairs import CHUNK_PAIRS
from .part import Part
from .view import view_matrix

__all__ = ["FACET_SHARE", "START_SHARE", "check_grid_memory", "_spacing", "_view_bounds",
           "estimate_bytes", "grid_shape"]

#: default mesh deflections as shares of the grid interval: the Newton starts need only a
#: coarse mesh (grid / START_SHARE); points answered by facets on exact faces are solved
#: again on a fine one (grid / FACET_SHARE)
START_SHARE = 1.0
FACET_SHARE = 20.0
#: bytes per pair in the working arrays (gidx 8, tri 8, w 16, z 8, status 1)
_PAIR_BYTES = 41
#: bytes per grid point kept to the end (z 8, face 4, method 1) and the map's own copy
_POINT_BYTES = 13 + 13


def _spacing(grid: Any) -> tuple[float, float]:
    """``(dx, dy)`` of a grid interval or pair of intervals; ValueError unless positive and finite."""
    if np.ndim(grid) == 0:
        dx = dy = grid
    else:
        if np.shape(grid) != (2,):
            raise ValueError(f"grid must be an interval or a pair (dx, dy), got {np.asarray(grid).tolist()!r}")
        dx, dy = grid
    try:
        dx, dy = float(dx), float(dy)
    except (TypeError, ValueError):
        raise ValueError(f"grid must be a positive number of mm, got {grid!r}") from None
    if not (math.isfinite(dx) and math.isfinite(dy) and dx > 0 and dy > 0):
        raise ValueError(f"grid intervals must be positive and finite, got dx={dx!r}, dy={dy!r}")
    return dx, dy


def _view_bounds(part: Part, axis: str) -> tuple[float, float, float, float]:
    """``(x0, y0, x1, y1)`` of the faces' bounding boxes seen from ``axis`` (view frame)."""
    b = np.array([f.bbox for f in part.faces], dtype=np.float64).reshape(-1, 6)
    R = view_matrix(axis)
    lo = b[:, :3] @ R.T
    hi = b[:, 3:] @ R.T
    both = np.concatenate([lo, hi])
    if not np.isfinite(both[:, :2]).any():
        raise ValueError(f"part {part.source!r} has no face with a bounding box; pass bounds=")
    return (float(np.nanmin(both[:, 0])), float(np.nanmin(both[:, 1])),
            float(np.nanmax(both[:, 0])), float(np.nanmax(both[:, 1])))


def grid_shape(bounds: Sequence[float], dx: float, dy: float) -> tuple[int, int]:
    """Grid points ``(nx, ny)`` that cover ``bounds = (x0, y0, x1, y1)``, at least 2 along each axis.

    The last grid line is the first one at or beyond ``x1`` (``y1``), within 1e-9 of an
    interval: ``x0 + (nx - 1) * dx >= x1``, so no part of the domain is left off the map
    (a domain that is a whole number of intervals keeps its last line on ``x1``).

    Parameters
    ----------
    bounds : (x0, y0, x1, y1)
        The domain, mm.
    dx, dy : float
        Grid intervals, mm.

    Returns
    -------
    (int, int)
        ``nx``, ``ny``.

    Raises
    ------
    ValueError
        Bounds not finite, or ``x1 < x0`` or ``y1 < y0``.

    Examples
    --------
    >>> grid_shape((0.0, 0.0, 10.0, 5.0), 1.0, 1.0), grid_shape((0.0, 0.0, 10.2, 5.0), 1.0, 1.0)
    ((11, 6), (12, 6))
    """
    return GridSpec.covering(bounds, dx, dy).shape


def estimate_bytes(nx: int, ny: int) -> int:
    """Working memory of :func:`cad_io.sampler.sample` on an ``nx`` x ``ny`` grid.

    Returns
    -------
    int
        Bytes, meshes excluded.
    """
    n = int(nx) * int(ny)
    return n * _POINT_BYTES + min(2 * n, CHUNK_PAIRS) * _PAIR_BYTES


def check_grid_memory(nx: int, ny: int) -> int:
    """:func:`estimate_bytes` of an ``nx`` x ``ny`` grid; raises ``GridTooLargeError`` where it
    does not fit in the memory available (:func:`zmap.memory.check_room`).

    Examples
    --------
    >>> check_grid_memory(10**50, 10**50)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    zmap.errors.GridTooLargeError: grid of 1e+50 x 1e+50 = 1e+100 points needs about ...
    """
    return check_room(estimate_bytes(nx, ny), f"grid of {count(nx)} x {count(ny)} = {count(nx * ny)} points",
                      "use a coarser grid or smaller bounds")
