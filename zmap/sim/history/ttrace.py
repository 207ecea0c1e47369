"""Time-trace (fast trace) of paper 001, section 4.

Rule 6: the pixel shown is the last FarZ of the ray. A time-element (value, creation stage)
is added when that value changes: the last dexel's back is shortened (case 4) or the last
dexel is deleted (case 2; the new value is the previous dexel's FarZ, or the background,
NaN, when none is left). Elements are finalised into one time-ordered list per ray; the
value shown at stage n is that of the last element created at or before n (binary search).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _kernels as _hk
from ._common import grow1

__all__ = ["TimeTrace"]


class TimeTrace:
    """Time-trace over the rays of a dexel workpiece.

    Attributes (finalised)
    ----------------------
    offsets : ndarray of shape (n_rays + 1,), int64
    z : ndarray of shape (m,), float32
        Last FarZ in mm, NaN for background.
    stage : ndarray of shape (m,), int32
        Creation stage, increasing within a ray.

    Examples
    --------
    >>> from zmap.sim.dexel import DexelWorkpiece
    >>> tt = TimeTrace.start(DexelWorkpiece.from_box((0, 0, -1, 1, 1, 0), pitch=1.0))
    >>> tt.finalize(); tt.display(0).tolist()
    [0.0, 0.0, 0.0, 0.0]
    """

    kind = "ttrace"

    def __init__(self, n_rays: int, offsets: np.ndarray | None = None, z: np.ndarray | None = None,
                 stage: np.ndarray | None = None):
        self.n_rays = int(n_rays)
        self.offsets = offsets
        self.z = z
        self.stage = stage
        self.n = 0 if z is None else int(z.shape[0])

    @classmethod
    def start(cls, wp: Any, capacity: int | None = None) -> "TimeTrace":
        """Start at stage 0 with one time-element per ray: the stock's top (or NaN)."""
        self = cls(wp.n_rays)
        cap = max(int(capacity or 0), 2 * wp.n_rays + 1024)
        self.b_z = np.empty(cap, dtype=np.float32)
        self.b_s = np.empty(cap, dtype=np.int32)
        self.b_ray = np.empty(cap, dtype=np.int32)
        self.b_z[: wp.n_rays] = wp.top().ravel().astype(np.float32)
        self.b_s[: wp.n_rays] = 0
        self.b_ray[: wp.n_rays] = np.arange(wp.n_rays, dtype=np.int32)
        self.n = wp.n_rays
        return self

    @property
    def capacity(self) -> int:
        return int(self.b_z.shape[0])

    def grow_pool(self) -> None:
        cap = 2 * self.capacity
        self.b_z, self.b_s, self.b_ray = grow1(self.b_z, cap), grow1(self.b_s, cap), grow1(self.b_ray, cap)

    def grow_slots(self, slots: int) -> None:
        pass

    def finalize(self) -> None:
        """Group the elements by ray, keeping their time order."""
        n = self.n
        ray = self.b_ray[:n]
        self.offsets = np.empty(self.n_rays + 1, dtype=np.int64)
        _hk.ray_offsets(ray, self.n_rays, self.offsets)
        self.z = np.empty(n, dtype=np.float32)
        self.stage = np.empty(n, dtype=np.int32)
        _hk.scatter2(ray, self.offsets, self.b_z[:n], self.b_s[:n], self.z, self.stage)
        del self.b_z, self.b_s, self.b_ray

    @property
    def n_elements(self) -> int:
        return int(self.z.shape[0]) if self.z is not None else self.n

    @property
    def nbytes(self) -> int:
        """Bytes of the finalised trace (elements and ray offsets)."""
        return int(self.offsets.nbytes + self.z.nbytes + self.stage.nbytes)

    def display(self, stage: int) -> np.ndarray:
        """Last FarZ per ray at ``stage``, shape (n_rays,), float64, NaN for background."""
        out = np.empty(self.n_rays, dtype=np.float64)
        _hk.ttrace_display(self.offsets, self.z, self.stage, np.int32(stage), out)
        return out

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"offsets": self.offsets, "z": self.z, "stage": self.stage}

    @classmethod
    def from_arrays(cls, n_rays: int, a: dict) -> "TimeTrace":
        return cls(n_rays, a["offsets"], a["z"], a["stage"])
