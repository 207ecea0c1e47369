"""Slow, obvious references for the simulation kernels (plain Python, for tests only).

Each ray is a Python list of ``[near, far]`` pairs; the cutter at each position is
subtracted by plain interval arithmetic. The cutter shape comes from the same formula as
the kernels (``_envelope.py_func``) and bottoms are rounded up to float32 as there, so the
results must agree with the fast kernels exactly.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from zmap.sim._tool_kernels import _envelope

__all__ = ["dexel_lists", "cut_reference", "heightfield_reference"]

_env = _envelope.py_func


def _f32_up(v: float) -> float:
    """``v`` rounded up to float32 (the kernels keep the stock above the exact cut)."""
    f = np.float32(v)
    if float(f) < v:
        f = np.nextafter(f, np.float32(np.inf))
    return float(f)


def dexel_lists(wp: Any) -> list[list[tuple[float, float]]]:
    """The dexels of a DexelWorkpiece as one Python list of (near, far) per ray."""
    out = []
    for r in range(wp.n_rays):
        c = int(wp.cnt[r])
        out.append([(float(wp.near[r, m]), float(wp.far[r, m])) for m in range(c)])
    return out


def _subtract(intervals: list, a: float, b: float) -> list:
    out = []
    for n, f in intervals:
        if f <= a or n >= b:
            out.append((n, f))
            continue
        if n < a:
            out.append((n, a))
        if f > b:
            out.append((b, f))
    return out


def cut_reference(lists: list, x0: float, y0: float, pitch: float, nx: int, ny: int,
                  xyz: np.ndarray, cutters: Sequence[Any], slot: Sequence[int] | None = None) -> list:
    """Subtract each cutter position from every ray, brute force over all rays.

    Parameters
    ----------
    lists : list of list of (near, far)
        Dexels per ray ``r = i*ny + j`` (not modified).
    xyz : ndarray of shape (n, 3)
        Tool-tip positions in mm.
    cutters, slot : cutters and the index of the cutter per position (default 0).
    """
    rays = [list(v) for v in lists]
    for p in range(len(xyz)):
        c = cutters[0 if slot is None else int(slot[p])]
        R = float(c.radius)
        tx, ty, tz = (float(v) for v in xyz[p])
        b = float(np.float32(tz + float(c.length)))
        for i in range(nx):
            dx = x0 + i * pitch - tx
            for j in range(ny):
                dy = y0 + j * pitch - ty
                d2 = dx * dx + dy * dy
                if d2 > R * R:
                    continue
                a = _f32_up(tz + _env(int(c.code), R, float(c.corner_radius), math.sqrt(d2)))
                r = i * ny + j
                rays[r] = _subtract(rays[r], a, b)
    return rays


def heightfield_reference(z: np.ndarray, x0: float, y0: float, dx: float, dy: float,
                          xyz: np.ndarray, cutter: Any) -> np.ndarray:
    """``min(z, tip + envelope)`` over all grid points, brute force (returns a new array)."""
    z = np.array(z, dtype=np.float64)
    R = float(cutter.radius)
    for tx, ty, tz in np.asarray(xyz, dtype=np.float64):
        for i in range(z.shape[0]):
            ddx = x0 + i * dx - tx
            for j in range(z.shape[1]):
                ddy = y0 + j * dy - ty
                d2 = ddx * ddx + ddy * ddy
                if d2 > R * R:
                    continue
                h = tz + _env(int(cutter.code), R, float(cutter.corner_radius), math.sqrt(d2))
                if h < z[i, j]:
                    z[i, j] = h
    return z
