"""Slow, obvious references of the access kernels, for tests on small maps.

:func:`global_visibility_reference` restates the cylinder casting of
:func:`zmap.access.voxelmap.global_visibility` pair by pair: for each boundary voxel v and
each direction n of V'_l(v), for each line of the plane grid that crosses v's surface box,
every blocker box (interior skin cube, or boundary box w != v with -n in L'(w), grown by
half a cell diagonal) is clipped
against the line in numpy; v loses n when one reaches beyond v's entry. No depth buffer,
no top-two bookkeeping: the kernel must give the same bits.
"""

from __future__ import annotations

import numpy as np

from .directions import from_bool, to_bool

__all__ = ["global_visibility_reference"]


def _basis(n):
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0.0, 1, 0])
    e = a - (a @ n) * n
    e /= np.linalg.norm(e)
    return e, np.cross(n, e)


def _clip(base, n, c, h):
    """(s0, s1) of the line base + s n in the boxes (c, h) (arrays of boxes); s0 > s1: miss."""
    s0 = np.full(len(c), -np.inf)
    s1 = np.full(len(c), np.inf)
    for m in range(3):
        if abs(n[m]) < 1e-12:
            out = np.abs(base[m] - c[:, m]) > h[:, m]
            s0[out], s1[out] = 1.0, -1.0
            continue
        a0 = (c[:, m] - h[:, m] - base[m]) / n[m]
        a1 = (c[:, m] + h[:, m] - base[m]) / n[m]
        s0 = np.maximum(s0, np.minimum(a0, a1))
        s1 = np.minimum(s1, np.maximum(a0, a1))
    return s0, s1


def global_visibility_reference(vm, *, rays: int = 2) -> np.ndarray:
    """V'_g (mb, words) computed plainly; small maps only (O(k mb^2))."""
    ds = vm.directions
    bc, bh = vm.boxes()
    skin = vm.skin()
    allc = np.concatenate([bc, skin]) if len(skin) else bc
    lo_, hi_ = allc.min(axis=0), allc.max(axis=0)
    mid = 0.5 * (lo_ + hi_)
    radius = 0.5 * float(np.linalg.norm(hi_ - lo_)) + vm.d
    cell = vm.d / rays
    u0 = -(radius + 2 * vm.d)
    nc = int(np.ceil(2.0 * (radius + 2 * vm.d) / cell)) + 1
    light = to_bool(vm.light, ds.k)
    vl = to_bool(vm.vl, ds.k)
    opp = ds.lookup(-ds.normals)
    sc = skin - mid
    sh = np.full((len(skin), 3), 0.5 * vm.d)
    rel = bc - mid
    out = np.zeros((vm.n_boundary, ds.k), bool)
    for i in range(ds.k):
        n = ds.normals[i]
        e, f = _basis(n)
        blk = np.flatnonzero(light[:, opp[i]])
        for b in np.flatnonzero(vl[:, i]):
            others = blk[blk != b]
            cs = np.concatenate([rel[others], sc])
            hs = np.concatenate([bh[others] + 0.5 * np.sqrt(2.0) * cell, sh])
            pu, pv = rel[b] @ e, rel[b] @ f
            ae, af = bh[b] @ np.abs(e), bh[b] @ np.abs(f)
            ia, ib = max(0, int(np.floor((pu - ae - u0) / cell))), min(nc - 1, int(np.floor((pu + ae - u0) / cell)))
            ja, jb = max(0, int(np.floor((pv - af - u0) / cell))), min(nc - 1, int(np.floor((pv + af - u0) / cell)))
            free, hits = True, 0
            for a in range(ia, ib + 1):
                for c in range(ja, jb + 1):
                    base = (u0 + (a + 0.5) * cell) * e + (u0 + (c + 0.5) * cell) * f
                    s0, s1 = _clip(base, n, rel[b][None], bh[b][None])
                    if s0[0] >= s1[0]:
                        continue
                    hits += 1
                    t0, t1 = _clip(base, n, cs, hs)
                    if np.any((t0 < t1) & (t1 > s0[0] + 1e-9 * vm.d)):
                        free = False
            if hits == 0:
                # the kernel's fallback: the cell under the box's centre, from its nearest depth;
                # blockers counted there are those crossing that cell's centre line
                a = min(nc - 1, max(0, int(np.floor((pu - u0) / cell))))
                c = min(nc - 1, max(0, int(np.floor((pv - u0) / cell))))
                base = (u0 + (a + 0.5) * cell) * e + (u0 + (c + 0.5) * cell) * f
                s0 = rel[b] @ n - bh[b] @ np.abs(n)
                t0, t1 = _clip(base, n, cs, hs)
                if np.any((t0 < t1) & (t1 > s0 + 1e-9 * vm.d)):
                    free = False
            out[b, i] = free
    return from_bool(out)
