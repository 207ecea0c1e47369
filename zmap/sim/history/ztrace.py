"""Z-trace (complete trace) of paper 001, section 3.

Every Z of the extended z-buffer (each NearZ and each FarZ) is a Z-element with its value,
creation stage and deletion stage (rules 1-5). The elements are recorded by the cutting
kernel as the dexels change and finalised into one list per ray (CSR, creation order: the
paper inserts each element at its z place, here the few elements alive at a stage are
sorted when they are read). The workpiece at stage n is rebuilt by keeping the elements
with ``creation <= n < deletion`` and pairing them, in z order, into ``[NearZ, FarZ]``
dexels (section 3.3).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _kernels as _hk
from ._common import grow1, slot_index, widen
from .._dexel_kernels import NO_STAGE

__all__ = ["ZTrace"]


class ZTrace:
    """Z-trace over the rays of a dexel workpiece.

    Build with :meth:`start`, let the cutting kernel record into it, then :meth:`finalize`.

    Attributes (finalised)
    ----------------------
    offsets : ndarray of shape (n_rays + 1,), int64
        Ray r owns elements ``offsets[r]:offsets[r+1]``, in creation order.
    z : ndarray of shape (m,), float32
        Z value in mm.
    created, deleted : ndarray of shape (m,), int32
        Stages; ``deleted = 2**31 - 1`` while alive.

    Examples
    --------
    >>> from zmap.sim.dexel import DexelWorkpiece
    >>> zt = ZTrace.start(DexelWorkpiece.from_box((0, 0, -1, 1, 1, 0), pitch=1.0))
    >>> zt.finalize(); zt.n_elements
    8
    """

    kind = "ztrace"

    def __init__(self, n_rays: int, offsets: np.ndarray | None = None, z: np.ndarray | None = None,
                 created: np.ndarray | None = None, deleted: np.ndarray | None = None):
        self.n_rays = int(n_rays)
        self.offsets = offsets
        self.z = z
        self.created = created
        self.deleted = deleted
        self.n = 0 if z is None else int(z.shape[0])

    # ---- building -----------------------------------------------------------------------

    @classmethod
    def start(cls, wp: Any, capacity: int | None = None) -> "ZTrace":
        """Start a trace at stage 0 from the stock ``wp``: two Z-elements per dexel."""
        self = cls(wp.n_rays)
        rows, cols = slot_index(wp.cnt, wp.slots)
        m = rows.shape[0]
        cap = max(int(capacity or 0), 4 * m + 1024)
        self.b_z = np.empty(cap, dtype=np.float32)
        self.b_c = np.empty(cap, dtype=np.int32)
        self.b_d = np.empty(cap, dtype=np.int32)
        self.b_ray = np.empty(cap, dtype=np.int32)
        self.b_z[0:2 * m:2] = wp.near[rows, cols]
        self.b_z[1:2 * m:2] = wp.far[rows, cols]
        self.b_c[: 2 * m] = 0
        self.b_d[: 2 * m] = NO_STAGE
        self.b_ray[: 2 * m] = np.repeat(rows, 2)
        self.zid_near = np.zeros((wp.n_rays, wp.slots), dtype=np.int32)
        self.zid_far = np.zeros((wp.n_rays, wp.slots), dtype=np.int32)
        self.zid_near[rows, cols] = np.arange(0, 2 * m, 2)
        self.zid_far[rows, cols] = np.arange(1, 2 * m, 2)
        self.n = 2 * m
        return self

    @property
    def capacity(self) -> int:
        return int(self.b_z.shape[0])

    def grow_pool(self) -> None:
        cap = 2 * self.capacity
        self.b_z, self.b_c = grow1(self.b_z, cap), grow1(self.b_c, cap)
        self.b_d, self.b_ray = grow1(self.b_d, cap), grow1(self.b_ray, cap)

    def grow_slots(self, slots: int) -> None:
        self.zid_near = widen(self.zid_near, slots)
        self.zid_far = widen(self.zid_far, slots)

    def finalize(self) -> None:
        """Group the recorded elements by ray (creation order within a ray)."""
        n = self.n
        ray = self.b_ray[:n]
        self.offsets = np.empty(self.n_rays + 1, dtype=np.int64)
        _hk.ray_offsets(ray, self.n_rays, self.offsets)
        self.z = np.empty(n, dtype=np.float32)
        self.created = np.empty(n, dtype=np.int32)
        self.deleted = np.empty(n, dtype=np.int32)
        _hk.scatter3(ray, self.offsets, self.b_z[:n], self.b_c[:n], self.b_d[:n],
                     self.z, self.created, self.deleted)
        del self.b_z, self.b_c, self.b_d, self.b_ray, self.zid_near, self.zid_far

    # ---- queries ------------------------------------------------------------------------

    @property
    def n_elements(self) -> int:
        return int(self.z.shape[0]) if self.z is not None else self.n

    @property
    def nbytes(self) -> int:
        """Bytes of the finalised trace (elements and ray offsets)."""
        return int(self.offsets.nbytes + self.z.nbytes + self.created.nbytes + self.deleted.nbytes)

    def reconstruct(self, stage: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Dexels at ``stage`` as CSR ``(offsets (n_rays+1,), near (m,) f4, far (m,) f4)``."""
        k = np.int32(stage)
        cnt = np.empty(self.n_rays, dtype=np.int64)
        _hk.ztrace_count(self.offsets, self.created, self.deleted, k, cnt)
        out_off = np.zeros(self.n_rays + 1, dtype=np.int64)
        np.cumsum(cnt, out=out_off[1:])
        near = np.empty(out_off[-1], dtype=np.float32)
        far = np.empty(out_off[-1], dtype=np.float32)
        buf = np.empty(2 * int(cnt.max(initial=0)) + 2, dtype=np.float32)
        _hk.ztrace_fill(self.offsets, self.z, self.created, self.deleted, k, out_off, near, far, buf)
        return out_off, near, far

    def display(self, stage: int) -> np.ndarray:
        """Top surface (last FarZ) per ray at ``stage``, shape (n_rays,), float64, NaN if empty."""
        out = np.empty(self.n_rays, dtype=np.float64)
        _hk.ztrace_top(self.offsets, self.z, self.created, self.deleted, np.int32(stage), out)
        return out

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"offsets": self.offsets, "z": self.z, "created": self.created, "deleted": self.deleted}

    @classmethod
    def from_arrays(cls, n_rays: int, a: dict) -> "ZTrace":
        return cls(n_rays, a["offsets"], a["z"], a["created"], a["deleted"])
