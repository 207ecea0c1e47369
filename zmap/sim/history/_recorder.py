"""Glue between the cutting kernel and the history structures being recorded."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _dexel_kernels as _k

__all__ = ["HISTORY_KINDS", "Recorder"]

HISTORY_KINDS = ("none", "ztrace", "ttrace", "treap")

_NO_I2 = np.zeros((1, 1), dtype=np.int32)
_NO_F = np.zeros(1, dtype=np.float32)
_NO_I = np.zeros(1, dtype=np.int32)


class Recorder:
    """The histories recorded during one run (any of z-trace, time-trace, treap).

    Parameters
    ----------
    ztrace, ttrace, treap : structure or None
        Histories in their building state, started from the same stock.
    """

    def __init__(self, ztrace: Any = None, ttrace: Any = None, treap: Any = None):
        self.ztrace = ztrace
        self.ttrace = ttrace
        self.treap = treap

    def kernel_args(self) -> tuple:
        z, t, tr = self.ztrace, self.ttrace, self.treap
        zargs = ((True, z.zid_near, z.zid_far, z.b_z, z.b_c, z.b_d, z.b_ray) if z is not None
                 else (False, _NO_I2, _NO_I2, _NO_F, _NO_I, _NO_I, _NO_I))
        targs = ((True, t.b_z, t.b_s, t.b_ray) if t is not None else (False, _NO_F, _NO_I, _NO_I))
        rargs = ((True, tr.leaf, tr.b_z, tr.b_s, tr.b_k, tr.b_ray) if tr is not None
                 else (False, _NO_I2, _NO_F, _NO_I, _NO_I, _NO_I))
        return zargs + targs + rargs

    def _parts(self):
        return [p for p in (self.ztrace, self.ttrace, self.treap) if p is not None]

    def load_counts(self, stats: np.ndarray) -> None:
        if self.ztrace is not None:
            stats[_k.ST_ZT_N] = self.ztrace.n
        if self.ttrace is not None:
            stats[_k.ST_TT_N] = self.ttrace.n
        if self.treap is not None:
            stats[_k.ST_TR_N] = self.treap.n

    def store_counts(self, stats: np.ndarray) -> None:
        if self.ztrace is not None:
            self.ztrace.n = int(stats[_k.ST_ZT_N])
        if self.ttrace is not None:
            self.ttrace.n = int(stats[_k.ST_TT_N])
        if self.treap is not None:
            self.treap.n = int(stats[_k.ST_TR_N])

    def grow_slots(self, slots: int) -> None:
        for p in self._parts():
            p.grow_slots(slots)

    def grow_pools(self, stats: np.ndarray) -> None:
        if self.ztrace is not None and stats[_k.ST_ZT_N] + 2 > self.ztrace.capacity:
            self.ztrace.grow_pool()
        if self.ttrace is not None and stats[_k.ST_TT_N] + 1 > self.ttrace.capacity:
            self.ttrace.grow_pool()
        if self.treap is not None and stats[_k.ST_TR_N] + 2 > self.treap.capacity:
            self.treap.grow_pool()

    def finalize(self) -> None:
        for p in self._parts():
            p.finalize()
