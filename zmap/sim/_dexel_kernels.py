"""Numba kernels of the dexel workpiece and of the histories recorded while cutting.

Private: the callers in :mod:`zmap.sim.dexel`, :mod:`zmap.sim.session` and
:mod:`zmap.sim.history` own validation and allocation. Kernels take contiguous arrays and
preallocated outputs and never raise for data reasons; when a pool is full they return
early with a status code so that the caller can grow the pool and resume (cutting is
idempotent, so re-running a partly cut position changes nothing twice).

Ray ``r = i * ny + j`` is the vertical line at ``(x0 + i*pitch, y0 + j*pitch)``. Its dexels
are ``near[r, :cnt[r]]``, ``far[r, :cnt[r]]``, sorted by z and disjoint, float32 in mm.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import _sweep_kernels as _sk

__all__: list[str] = []

# status codes returned by cut_positions in stats[ST_STATUS]
OK = 0
NEED_SLOTS = 1   # a ray has no free dexel slot
NEED_POOL = 2    # a history pool is full

# indices of the int64 stats vector
ST_CREATED = 0   # dexels created (splits)
ST_DELETED = 1   # dexels deleted
ST_FRONT = 2     # fronts shortened (NearZ raised)
ST_BACK = 3      # backs shortened (FarZ lowered)
ST_ZT_N = 4      # z-trace elements used
ST_TT_N = 5      # time-trace elements used
ST_TR_N = 6      # treap nodes used
ST_STATUS = 7
ST_RAYS_CUT = 8  # ray/position pairs visited
N_STATS = 9

NO_STAGE = np.int32(2147483647)  # deletion stage of a Z-element still alive

# Interval Treap node encoding: kids = (first_child << 2) | mask; mask bit 0 = left child,
# bit 1 = right child; children of a node are created together and stored contiguously.
# Each node stores the one boundary it introduced (tr_z): a left child stores its Zmax,
# a right child its Zmin, the other boundary is inherited from the parent; an empty leaf
# (deletion) stores NaN. Roots store Zmin in tr_z and Zmax in the separate root_hi array.


@njit(cache=True)
def _zt_new(zt_z, zt_c, zt_d, zt_ray, stats, z, stage, ray):
    k = stats[ST_ZT_N]
    zt_z[k] = z
    zt_c[k] = stage
    zt_d[k] = NO_STAGE
    zt_ray[k] = ray
    stats[ST_ZT_N] = k + 1
    return np.int32(k)


@njit(cache=True)
def _tr_children(tr_z, tr_s, tr_k, tr_ray, stats, parent, mask, zl, zr, stage, ray):
    """Append the children of leaf ``parent`` (mask 1 left, 2 right, 3 both); return first."""
    k = stats[ST_TR_N]
    n = 0
    if mask & 1:
        tr_z[k] = zl
        tr_s[k] = stage
        tr_k[k] = 0
        tr_ray[k] = ray
        n += 1
    if mask & 2:
        tr_z[k + n] = zr
        tr_s[k + n] = stage
        tr_k[k + n] = 0
        tr_ray[k + n] = ray
        n += 1
    tr_k[parent] = (k << 2) | mask
    stats[ST_TR_N] = k + n
    return k


@njit(cache=True)
def cut_ray(r, a, b, stage, near, far, cnt,
            rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
            rec_t, tt_z, tt_s, tt_ray,
            rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats):
    """Subtract the tool interval ``[a, b]`` (float32 values) from ray ``r`` at ``stage``.

    The dexels are scanned bottom-up; a dexel is touched only if condition (1) of paper 000
    holds (tool FarZ > part NearZ and part FarZ > tool NearZ) and the scan stops for good at
    the first dexel whose NearZ >= tool FarZ (condition (2)). The four cases of paper 001
    (create by split, delete, shorten front, shorten back) update the history in place.
    """
    c = cnt[r]
    old_top = far[r, c - 1] if c > 0 else np.float32(np.nan)
    w = 0
    j = 0
    done = False
    while j < c:
        n0 = near[r, j]
        f0 = far[r, j]
        if done or f0 <= a or n0 >= b:
            if n0 >= b:
                done = True
            if w != j:
                near[r, w] = n0
                far[r, w] = f0
                if rec_z:
                    zid_near[r, w] = zid_near[r, j]
                    zid_far[r, w] = zid_far[r, j]
                if rec_tr:
                    leaf[r, w] = leaf[r, j]
            w += 1
            j += 1
            continue
        if a > n0 and b < f0:
            # case 1 of paper 001: the tool is inside the dexel, split it in two.
            # No dexel was deleted before (intervals are disjoint), so w == j here.
            for m in range(c - 1, j, -1):
                near[r, m + 1] = near[r, m]
                far[r, m + 1] = far[r, m]
                if rec_z:
                    zid_near[r, m + 1] = zid_near[r, m]
                    zid_far[r, m + 1] = zid_far[r, m]
                if rec_tr:
                    leaf[r, m + 1] = leaf[r, m]
            far[r, j] = a
            near[r, j + 1] = b
            far[r, j + 1] = f0
            if rec_z:
                zf = zid_far[r, j]
                zid_far[r, j] = _zt_new(zt_z, zt_c, zt_d, zt_ray, stats, a, stage, r)
                zid_near[r, j + 1] = _zt_new(zt_z, zt_c, zt_d, zt_ray, stats, b, stage, r)
                zid_far[r, j + 1] = zf
            if rec_tr:
                k = _tr_children(tr_z, tr_s, tr_k, tr_ray, stats, leaf[r, j], 3, a, b, stage, r)
                leaf[r, j] = k
                leaf[r, j + 1] = k + 1
            stats[ST_CREATED] += 1
            c += 1
            w = c
            j = c
            break
        if a <= n0 and b >= f0:
            # case 2: the tool covers the dexel, delete it
            if rec_z:
                zt_d[zid_near[r, j]] = stage
                zt_d[zid_far[r, j]] = stage
            if rec_tr:
                _tr_children(tr_z, tr_s, tr_k, tr_ray, stats, leaf[r, j], 1, np.float32(np.nan),
                             np.float32(0.0), stage, r)
            stats[ST_DELETED] += 1
            j += 1
            continue
        if a > n0:
            # case 4: shorten the back, FarZ goes down to the tool's NearZ
            far[r, w] = a
            near[r, w] = n0
            if rec_z:
                zt_d[zid_far[r, j]] = stage
                zid_near[r, w] = zid_near[r, j]
                zid_far[r, w] = _zt_new(zt_z, zt_c, zt_d, zt_ray, stats, a, stage, r)
            if rec_tr:
                k = _tr_children(tr_z, tr_s, tr_k, tr_ray, stats, leaf[r, j], 1, a, np.float32(0.0), stage, r)
                leaf[r, w] = k
            stats[ST_BACK] += 1
        else:
            # case 3: shorten the front, NearZ goes up to the tool's FarZ
            near[r, w] = b
            far[r, w] = f0
            if rec_z:
                zt_d[zid_near[r, j]] = stage
                zid_near[r, w] = _zt_new(zt_z, zt_c, zt_d, zt_ray, stats, b, stage, r)
                zid_far[r, w] = zid_far[r, j]
            if rec_tr:
                k = _tr_children(tr_z, tr_s, tr_k, tr_ray, stats, leaf[r, j], 2, np.float32(0.0), b, stage, r)
                leaf[r, w] = k
            stats[ST_FRONT] += 1
            done = True
        w += 1
        j += 1
    cnt[r] = w
    if rec_t:
        new_top = far[r, w - 1] if w > 0 else np.float32(np.nan)
        same = (new_top == old_top) or (math.isnan(new_top) and math.isnan(old_top))
        if not same:
            # rule 6 of paper 001: the displayed value is the last FarZ; it changed
            k = stats[ST_TT_N]
            tt_z[k] = new_top
            tt_s[k] = stage
            tt_ray[k] = r
            stats[ST_TT_N] = k + 1


@njit(cache=True, inline="always")
def f32_up(v):
    """``v`` rounded up to float32: a cut's bottom never lies below the exact sweep."""
    f = np.float32(v)
    if np.float64(f) < v:
        f = np.float32(np.nextafter(f, np.float32(np.inf)))
    return f


@njit(cache=True)
def cut_pieces(pkind, pgeo, smove, st0, st1, tslot, tcode, trad, tcr, tlen, start, stop, stage0,
               x0, y0, pitch, nx, ny, near, far, cnt,
               rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
               rec_t, tt_z, tt_s, tt_ray,
               rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats):
    """Cut stages ``start..stop-1``; stage p's piece makes stage ``stage0 + p + 1``.

    Returns the index of the first stage not (fully) cut: ``stop`` when done, else the
    stage to resume from after growing what ``stats[ST_STATUS]`` names.
    """
    return cut_pieces_window(pkind, pgeo, smove, st0, st1, tslot, tcode, trad, tcr, tlen, _NO_GPOS,
                             start, stop, stage0, x0, y0, pitch, 0, 0, nx, ny, near, far, cnt,
                             rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                             rec_t, tt_z, tt_s, tt_ray,
                             rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats)


#: ``gpos`` of a run over the whole program: stage p is stage ``stage0 + p + 1``
_NO_GPOS = np.zeros(0, dtype=np.int64)


@njit(cache=True, inline="always")
def piece_window(pkind, pgeo, mv, t0, t1, R, x0, y0, pitch, gi0, gj0, tnx, tny):
    """Rays ``i0..i1, j0..j1`` (clipped to the window) one piece's tool can reach."""
    xmin, xmax, ymin, ymax = _sk.piece_box(pkind[mv], pgeo[mv], t0, t1)
    i0 = max(int(math.ceil((xmin - R - x0) / pitch)) - 1, gi0)
    i1 = min(int(math.floor((xmax + R - x0) / pitch)) + 1, gi0 + tnx - 1)
    j0 = max(int(math.ceil((ymin - R - y0) / pitch)) - 1, gj0)
    j1 = min(int(math.floor((ymax + R - y0) / pitch)) + 1, gj0 + tny - 1)
    return i0, i1, j0, j1


@njit(cache=True, nogil=True)
def _cut_line_stages(g, st0, st1, p, q, code, R, rc, L, stage_p, x0, y0, pitch, gi0, gj0, tnx, tny,
                     near, far, cnt, rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                     rec_t, tt_z, tt_s, tt_ray, rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats):
    """Cut stages ``p..q`` (consecutive pieces of one line ``g``; stage p is ``stage_p``)
    into the window, each the exact sweep of its piece; OK or the status to grow."""
    K = near.shape[1]
    zt_cap = zt_z.shape[0]
    tt_cap = tt_z.shape[0]
    tr_cap = tr_z.shape[0]
    ax, ay, az = g[0], g[1], g[2]
    lxy, ux, uy, m, kb = _sk.line_setup(ax, ay, az, g[3], g[4], g[5])
    dz = g[5] - az
    n = int(round(1.0 / (st1[p] - st0[p])))  # the move's stages: equal steps j / n
    j0 = int(round(st0[p] * n))
    tlo = st0[p]
    thi = st1[q]
    xa, ya = ax + (g[3] - ax) * tlo, ay + (g[4] - ay) * tlo
    xb, yb = ax + (g[3] - ax) * thi, ay + (g[4] - ay) * thi
    xmin, xmax = min(xa, xb), max(xa, xb)
    ymin, ymax = min(ya, yb), max(ya, yb)
    R2 = R * R
    i0 = max(int(math.ceil((xmin - R - x0) / pitch)) - 1, gi0)
    i1 = min(int(math.floor((xmax + R - x0) / pitch)) + 1, gi0 + tnx - 1)
    for i in range(i0, i1 + 1):
        qx = x0 + i * pitch
        ddx = max(xmin - qx, qx - xmax, 0.0)
        if ddx > R:
            continue
        hy = math.sqrt(R2 - ddx * ddx)  # the rays of this column within R of the pieces' box
        ja = max(int(math.ceil((ymin - hy - y0) / pitch)) - 1, gj0)
        jb = min(int(math.floor((ymax + hy - y0) / pitch)) + 1, gj0 + tny - 1)
        for j in range(ja, jb + 1):
            r = (i - gi0) * tny + (j - gj0)
            if cnt[r] == 0:
                continue
            qy = y0 + j * pitch
            if lxy == 0.0:  # a plunge: every piece reaches the ray alike
                d2 = (qx - ax) ** 2 + (qy - ay) ** 2
                if d2 > R2:
                    continue
                hq = _sk._h(code, R, rc, math.sqrt(d2))
                ka, kz = j0, j0 + q - p
                tstar = lo = hi = s = e2 = 0.0
            else:
                ok, s, e2, lo, hi, tstar = _sk.line_reach(code, R, rc, lxy, ux, uy, m, kb, ax, ay, tlo * lxy,
                                                          thi * lxy, qx, qy)
                if not ok:
                    continue
                # no piece cuts below the lowest bottom of them all: a ray already as deep is done
                if far[r, cnt[r] - 1] <= _sk.line_piece(code, R, rc, L, az, g[5], lxy, m, s, e2, tstar, lo, hi)[0]:
                    continue
                # the pieces the reach overlaps, one more each side for rounding
                ka = max(int(math.floor(lo / lxy * n)) - 1, j0)
                kz = min(int(math.ceil(hi / lxy * n)), j0 + q - p)
                hq = 0.0
            for k in range(ka, kz + 1):
                if lxy == 0.0:
                    za = az + dz * (k / n)
                    zb = az + dz * ((k + 1) / n) if k + 1 < n else g[5]
                    bottom = min(za, zb) + hq
                    top = max(za, zb) + L
                else:
                    # the same numbers as the piece alone (line_ray): its part of the reach
                    plo = max(lo, (k / n) * lxy)
                    phi = min(hi, ((k + 1) / n) * lxy)
                    if plo > phi:
                        continue
                    bottom, top = _sk.line_piece(code, R, rc, L, az, g[5], lxy, m, s, e2, tstar, plo, phi)
                c = cnt[r]
                # quick reject: conditions (1)/(2) against the whole ray, first in float64
                # (most rays under the tool were cut as deep by the stage before)
                if c == 0 or far[r, c - 1] <= bottom:
                    continue
                a = f32_up(bottom)
                b = np.float32(top)
                if far[r, c - 1] <= a or near[r, 0] >= b:
                    continue
                if c >= K:
                    return NEED_SLOTS
                if (rec_z and stats[ST_ZT_N] + 2 > zt_cap) or (rec_t and stats[ST_TT_N] + 1 > tt_cap) \
                        or (rec_tr and stats[ST_TR_N] + 2 > tr_cap):
                    return NEED_POOL
                stats[ST_RAYS_CUT] += 1
                cut_ray(r, a, b, np.int32(stage_p + k - j0), near, far, cnt,
                        rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                        rec_t, tt_z, tt_s, tt_ray,
                        rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats)
    return OK


@njit(cache=True, nogil=True)  # nogil: a Dask worker sends results while a tile cuts
def cut_pieces_window(pkind, pgeo, smove, st0, st1, tslot, tcode, trad, tcr, tlen, gpos, start, stop,
                      stage0, x0, y0, pitch, gi0, gj0, tnx, tny, near, far, cnt,
                      rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                      rec_t, tt_z, tt_s, tt_ray,
                      rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats):
    """Cut stages ``start..stop-1`` into the rays ``gi0 <= i < gi0 + tnx``, ``gj0 <= j < gj0 + tny``.

    Stage p cuts the exact sweep of the tool ``tslot[p]`` over its piece: parameters
    ``st0[p]..st1[p]`` of row ``smove[p]`` of the piece table ``pkind``/``pgeo``
    (:mod:`zmap.sim._sweep_kernels`). Ray (i, j) sits at ``(x0 + i*pitch, y0 + j*pitch)``
    with the whole stock's global index and is stored at ``(i - gi0) * tny + (j - gj0)`` of
    ``near``/``far``/``cnt``: the whole stock is the window ``(0, 0, nx, ny)``, a tile of it
    (:mod:`zmap.sim.tiled`) any other. Stage p is stage ``stage0 + gpos[p] + 1``
    (``stage0 + p + 1`` when ``gpos`` is empty), so a tile's stages keep their numbers in
    the whole program. Returns the index of the first stage not (fully) cut: ``stop`` when
    done, else the stage to resume from after growing what ``stats[ST_STATUS]`` names.
    Cutting is idempotent, so a stage cut again after a resume changes nothing twice.
    """
    K = near.shape[1]
    zt_cap = zt_z.shape[0]
    tt_cap = tt_z.shape[0]
    tr_cap = tr_z.shape[0]
    has_gpos = gpos.shape[0] > 0
    stats[ST_STATUS] = OK
    buf = np.empty((_sk.MAX_INTERVALS, 2), dtype=np.float64)
    ts = np.empty(_sk.SCRATCH, dtype=np.float64)
    p = start
    while p < stop:
        mv = smove[p]
        kind = pkind[mv]
        if kind == _sk.NO_CUT:
            p += 1
            continue
        if kind == _sk.LINE:
            # the stages of one line, all at once: each ray's reach and lowest point are found
            # once, then each stage's piece cuts its part of the reach (its bottom is lowest
            # at the lowest point clamped to the piece: the bottom is convex along the line)
            q = p
            while q + 1 < stop and smove[q + 1] == mv and (
                    not has_gpos or gpos[q + 1] == gpos[q] + 1):
                q += 1
            first = stage0 + p + 1
            if has_gpos:
                first = stage0 + gpos[p] + 1
            ts_ = tslot[p]
            st = _cut_line_stages(pgeo[mv], st0, st1, p, q, tcode[ts_], trad[ts_], tcr[ts_], tlen[ts_], first,
                                  x0, y0, pitch, gi0, gj0, tnx, tny, near, far, cnt,
                                  rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                                  rec_t, tt_z, tt_s, tt_ray, rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats)
            if st != OK:
                stats[ST_STATUS] = st
                return p
            p = q + 1
            continue
        s = tslot[p]
        code = tcode[s]
        R = trad[s]
        rc = tcr[s]
        L = tlen[s]
        g = pgeo[mv]
        t0 = st0[p]
        t1 = st1[p]
        stage = np.int32(stage0 + (gpos[p] if has_gpos else p) + 1)
        R2 = R * R
        if kind == _sk.STAMP:
            xmin = xmax = g[0]
            ymin = ymax = g[1]
        else:
            xmin, xmax, ymin, ymax = _sk.piece_box(kind, g, t0, t1)
        i0 = max(int(math.ceil((xmin - R - x0) / pitch)) - 1, gi0)
        i1 = min(int(math.floor((xmax + R - x0) / pitch)) + 1, gi0 + tnx - 1)
        for i in range(i0, i1 + 1):
            qx = x0 + i * pitch
            ddx = max(xmin - qx, qx - xmax, 0.0)
            if ddx > R:
                continue
            hy = math.sqrt(R2 - ddx * ddx)  # the rays of this column within R of the piece's box
            ja = max(int(math.ceil((ymin - hy - y0) / pitch)) - 1, gj0)
            jb = min(int(math.floor((ymax + hy - y0) / pitch)) + 1, gj0 + tny - 1)
            if kind == _sk.STAMP:
                for j in range(ja, jb + 1):
                    r = (i - gi0) * tny + (j - gj0)
                    c = cnt[r]
                    if c == 0:
                        continue
                    d2 = (qx - g[0]) ** 2 + (y0 + j * pitch - g[1]) ** 2
                    if d2 > R2:
                        continue
                    lo = g[2] + _sk._h(code, R, rc, math.sqrt(d2))
                    hi = g[2] + L
                    # quick reject: conditions (1)/(2) against the whole ray, first in float64
                    if far[r, c - 1] <= lo:
                        continue
                    a = f32_up(lo)
                    b = np.float32(hi)
                    if far[r, c - 1] <= a or near[r, 0] >= b:
                        continue
                    if c >= K:
                        stats[ST_STATUS] = NEED_SLOTS
                        return p
                    if (rec_z and stats[ST_ZT_N] + 2 > zt_cap) or (rec_t and stats[ST_TT_N] + 1 > tt_cap) \
                            or (rec_tr and stats[ST_TR_N] + 2 > tr_cap):
                        stats[ST_STATUS] = NEED_POOL
                        return p
                    stats[ST_RAYS_CUT] += 1
                    cut_ray(r, a, b, stage, near, far, cnt,
                            rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                            rec_t, tt_z, tt_s, tt_ray,
                            rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats)
            else:
                for j in range(ja, jb + 1):
                    r = (i - gi0) * tny + (j - gj0)
                    if cnt[r] == 0:
                        continue
                    n = _sk.piece_rays(kind, code, R, rc, L, g, t0, t1, qx, y0 + j * pitch, buf, ts)
                    for k in range(n):
                        a = f32_up(buf[k, 0])
                        b = np.float32(buf[k, 1])
                        c = cnt[r]
                        # quick reject: conditions (1)/(2) against the whole ray
                        if c == 0 or far[r, c - 1] <= a or near[r, 0] >= b:
                            continue
                        if c >= K:
                            stats[ST_STATUS] = NEED_SLOTS
                            return p
                        if (rec_z and stats[ST_ZT_N] + 2 > zt_cap) or (rec_t and stats[ST_TT_N] + 1 > tt_cap) \
                                or (rec_tr and stats[ST_TR_N] + 2 > tr_cap):
                            stats[ST_STATUS] = NEED_POOL
                            return p
                        stats[ST_RAYS_CUT] += 1
                        cut_ray(r, a, b, stage, near, far, cnt,
                                rec_z, zid_near, zid_far, zt_z, zt_c, zt_d, zt_ray,
                                rec_t, tt_z, tt_s, tt_ray,
                                rec_tr, leaf, tr_z, tr_s, tr_k, tr_ray, stats)
        p += 1
    return stop


@njit(cache=True)
def top_of(near, far, cnt, out):
    """Last FarZ of every ray (rule 6 of paper 001), NaN where the ray is empty."""
    for r in range(cnt.shape[0]):
        c = cnt[r]
        out[r] = far[r, c - 1] if c > 0 else np.nan


@njit(cache=True)
def heightfield_cut(pkind, pgeo, smove, st0, st1, tslot, tcode, trad, tcr, tlen, x0, y0, dx, dy, z):
    """Height-field cut: ``z[i, j] = min(z[i, j], bottom of the sweep)`` (NaN stays NaN)."""
    nx = z.shape[0]
    ny = z.shape[1]
    buf = np.empty((_sk.MAX_INTERVALS, 2), dtype=np.float64)
    ts = np.empty(_sk.SCRATCH, dtype=np.float64)
    for p in range(smove.shape[0]):
        mv = smove[p]
        kind = pkind[mv]
        if kind == _sk.NO_CUT:
            continue
        s = tslot[p]
        code = tcode[s]
        R = trad[s]
        rc = tcr[s]
        g = pgeo[mv]
        xmin, xmax, ymin, ymax = _sk.piece_box(kind, g, st0[p], st1[p])
        i0 = max(int(math.ceil((xmin - R - x0) / dx)) - 1, 0)
        i1 = min(int(math.floor((xmax + R - x0) / dx)) + 1, nx - 1)
        j0 = max(int(math.ceil((ymin - R - y0) / dy)) - 1, 0)
        j1 = min(int(math.floor((ymax + R - y0) / dy)) + 1, ny - 1)
        for i in range(i0, i1 + 1):
            qx = x0 + i * dx
            for j in range(j0, j1 + 1):
                n = _sk.piece_rays(kind, code, R, rc, tlen[s], g, st0[p], st1[p], qx, y0 + j * dy, buf, ts)
                if n > 0 and buf[0, 0] < z[i, j]:
                    z[i, j] = buf[0, 0]
