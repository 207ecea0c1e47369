"""Numba kernels of the cutter shapes (no validation; see :mod:`zmap.sim.tools`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["_envelope", "_envelope_many"]


@njit(cache=True)
def _envelope(code: int, radius: float, corner_radius: float, r: float) -> float:
    """Height above the tip of the cutter's bottom at radial distance ``r`` (NaN outside).

    ``code`` is 0 flat, 1 ball, 2 bull nose; the same torus formula serves all three with
    ``corner_radius`` 0 (flat), ``radius`` (ball) or in between (bull).
    """
    if not (r <= radius) or r < 0.0:
        return np.nan
    if code == 0:
        return 0.0
    r0 = radius - corner_radius
    if r <= r0:
        return 0.0
    d = r - r0
    q = corner_radius * corner_radius - d * d
    if q < 0.0:
        q = 0.0
    return corner_radius - math.sqrt(q)


@njit(cache=True)
def _envelope_many(code: int, radius: float, corner_radius: float, r: np.ndarray,
                   out: np.ndarray) -> None:
    """``out[i] = _envelope(code, radius, corner_radius, r[i])`` for contiguous 1-D arrays."""
    for i in range(r.shape[0]):
        out[i] = _envelope(code, radius, corner_radius, r[i])
