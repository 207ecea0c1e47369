"""Small array helpers shared by the history structures."""

from __future__ import annotations

import numpy as np

__all__ = ["grow1", "widen", "slot_index"]


def grow1(a: np.ndarray, n: int) -> np.ndarray:
    """A copy of 1-D ``a`` with capacity ``n`` (>= len(a))."""
    out = np.empty(n, dtype=a.dtype)
    out[: a.shape[0]] = a
    return out


def widen(a: np.ndarray, slots: int) -> np.ndarray:
    """A copy of 2-D ``a`` with ``slots`` columns."""
    out = np.zeros((a.shape[0], slots), dtype=a.dtype)
    out[:, : a.shape[1]] = a
    return out


def slot_index(cnt: np.ndarray, slots: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of every used slot, in ray-major (CSR) order."""
    mask = np.arange(slots)[None, :] < cnt[:, None]
    rows, cols = np.nonzero(mask)
    return rows, cols
