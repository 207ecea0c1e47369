"""The shank and holder test on the part's surface samples (numba).

Per direction n, every sample is projected onto the plane across n (u, v) and along it (h),
and sorted into square cells of that plane; a cell keeps its samples and their highest h. A
cylinder of radius r about the line through a query's centre along n, from height h0 up,
holds material when a sample lies closer than r to that line and higher than h0: the cells'
maxima, dilated over the cells that a disc centred in a cell can meet and over those it
always covers (:func:`zmap.access._access_kernels.disc_max`), decide most queries; the rest
test the samples of the cells on the disc's rim one by one. So the answer is that of the
samples themselves, with no voxel-sized slack (the voxel boxes of
:func:`zmap.access._access_kernels.tool_kernel` hold the surface up to a voxel diagonal away).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._access_kernels import _basis, disc_max

__all__ = ["sample_tool_kernel"]


@njit(cache=True)
def _cells(u, v, u0, v0, cell, na, nb, h, sorted_, start, top, low, key):
    """Counting sort of the samples into cells: ``sorted_[start[c]:start[c + 1]]`` are cell c's
    (c = ia * nb + ib) as rows (u, v, h), side by side for the scans; ``top[ia, ib]`` their
    highest h and ``low[ia, ib]`` their highest -h (-1e300: none; ``low`` only where it has the
    shape of ``top``); ``key`` is work space."""
    ns = u.shape[0]
    both = low.shape[0] == na
    cnt = np.zeros(na * nb + 1, dtype=np.int64)
    for m in range(ns):
        ia = min(na - 1, max(0, int((u[m] - u0) / cell)))
        ib = min(nb - 1, max(0, int((v[m] - v0) / cell)))
        c = ia * nb + ib
        key[m] = c
        cnt[c + 1] += 1
        if h[m] > top[ia, ib]:
            top[ia, ib] = h[m]
        if both and -h[m] > low[ia, ib]:
            low[ia, ib] = -h[m]
    for c in range(na * nb):
        cnt[c + 1] += cnt[c]
    start[:] = cnt
    for m in range(ns):
        c = key[m]
        s = cnt[c]
        sorted_[s, 0] = u[m]
        sorted_[s, 1] = v[m]
        sorted_[s, 2] = h[m]
        cnt[c] += 1


@njit(cache=True)
def _rim(outer, covered):
    """The cell offsets (dp, dq) a disc centred in cell (0, 0) can meet (half-widths ``outer``
    per row offset |dp|) but does not always cover whole (``covered``): where a scan must look
    once the covered cells' highest is known to lie low enough."""
    out = np.empty((0, 2), dtype=np.int64)
    for pass_ in range(2):
        n = 0
        for ap in range(outer.shape[0]):
            w = outer[ap]
            cw = covered[ap] if ap < covered.shape[0] else -1
            for dp in range(-ap, ap + 1, max(1, 2 * ap)):  # -ap and ap, or 0 once
                for dq in range(-w, w + 1):  # none where w is -1
                    if abs(dq) > cw:
                        if pass_ == 1:
                            out[n, 0] = dp
                            out[n, 1] = dq
                        n += 1
        if pass_ == 0:
            out = np.empty((n, 2), dtype=np.int64)
    return out


@njit(cache=True)
def _meets(pu, pv, ia0, ib0, h0, r, rim, sgn, sorted_, start, top, u0, v0, cell, na, nb):
    """Whether a sample lies closer than r to (pu, pv) across n and above h0 along it (its
    height ``sgn * h``: -1 for the opposite direction, on the same cells; ``top`` its cells'
    highest), looking only at the cells ``rim`` around the query's cell (ia0, ib0): the caller
    knows the cells the disc always covers lie at or below h0."""
    r2 = r * r
    for t in range(rim.shape[0]):
        ia = ia0 + rim[t, 0]
        ib = ib0 + rim[t, 1]
        if ia < 0 or ia >= na or ib < 0 or ib >= nb or top[ia, ib] <= h0:
            continue
        ca = u0 + ia * cell
        cb = v0 + ib * cell
        da_near = max(0.0, max(ca - pu, pu - ca - cell))
        db_near = max(0.0, max(cb - pv, pv - cb - cell))
        if da_near * da_near + db_near * db_near >= r2:
            continue
        da_far = max(abs(ca - pu), abs(ca + cell - pu))
        db_far = max(abs(cb - pv), abs(cb + cell - pv))
        if da_far * da_far + db_far * db_far < r2:
            return True  # the whole cell lies inside, and its top is above h0
        c = ia * nb + ib
        for s in range(start[c], start[c + 1]):
            if sgn * sorted_[s, 2] > h0:
                du = sorted_[s, 0] - pu
                dv = sorted_[s, 1] - pv
                if du * du + dv * dv < r2:
                    return True
    return False


@njit(cache=True)
def _queries(d, sgn, ex, ey, ez, nx, ny, nz, top, local, centre, r_shank, stick, r_holder, cell, up_r, low_r, up_h,
             low_h, rim_r, rim_h, out, stats, sorted_, start, u0, v0, na, nb):
    """The queries of direction d, whose heights are ``sgn`` times those along (nx, ny, nz)
    (the plane's basis e, with f = n x e, shared by a direction and its opposite)."""
    mb = centre.shape[0]
    fx, fy, fz = ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex
    wi = d >> 6
    bit = np.uint64(d & 63)
    up = np.empty_like(top)
    low = np.empty_like(top)
    disc_max(top, up_r, low_r, up, low)
    uph = np.empty_like(top)
    lowh = np.empty_like(top)
    if r_holder > 0:
        disc_max(top, up_h, low_h, uph, lowh)
    n_clear = 0
    n_blocked = 0
    n_scan = 0
    for b in range(mb):
        out[d, b] = 0
        if (local[b, wi] >> bit) & np.uint64(1) == 0:
            continue
        cx, cy, cz = centre[b, 0], centre[b, 1], centre[b, 2]
        pu = cx * ex + cy * ey + cz * ez
        pv = cx * fx + cy * fy + cz * fz
        h0 = sgn * (cx * nx + cy * ny + cz * nz)
        ia = min(na - 1, max(0, int((pu - u0) / cell)))
        ib = min(nb - 1, max(0, int((pv - v0) / cell)))
        free = True
        for tube in range(2 if r_holder > 0 else 1):
            hh = h0 if tube == 0 else h0 + stick
            rr = r_shank if tube == 0 else r_holder
            hi_ = up[ia, ib] if tube == 0 else uph[ia, ib]
            lo_ = low[ia, ib] if tube == 0 else lowh[ia, ib]
            if hi_ <= hh:
                n_clear += 1
                continue
            if lo_ > hh:
                n_blocked += 1
                free = False
                break
            n_scan += 1
            if _meets(pu, pv, ia, ib, hh, rr, rim_r if tube == 0 else rim_h, sgn, sorted_, start, top, u0, v0,
                      cell, na, nb):
                free = False
                break
        if free:
            out[d, b] = 1
    stats[d, 0] = n_clear
    stats[d, 1] = n_blocked
    stats[d, 2] = n_scan


@njit(cache=True)
def _sample_tool_pair(i, j, dirs, local, centre, pts, r_shank, stick, r_holder, cell, up_r, low_r, up_h, low_h, rim_r,
                      rim_h, out, stats, u, v, h, sorted_, key):
    """Direction i of :func:`sample_tool_kernel` and its opposite j (-1: none), on one sort
    of the samples into cells across them (``u`` ... ``key``: its worker's space, one entry
    per sample)."""
    nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
    ex, ey, ez, fx, fy, fz = _basis(nx, ny, nz)
    # f = n x e, so that the queries of the opposite direction find the same plane coordinates
    fx, fy, fz = ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex
    ns = pts.shape[0]
    mb = centre.shape[0]
    lo_u = 1.0e300
    hi_u = -1.0e300
    lo_v = 1.0e300
    hi_v = -1.0e300
    for m in range(ns):
        x, y, z = pts[m, 0], pts[m, 1], pts[m, 2]
        u[m] = x * ex + y * ey + z * ez
        v[m] = x * fx + y * fy + z * fz
        h[m] = x * nx + y * ny + z * nz
        lo_u = min(lo_u, u[m])
        hi_u = max(hi_u, u[m])
        lo_v = min(lo_v, v[m])
        hi_v = max(hi_v, v[m])
    # the grid covers the samples and the centres: a centre clamped to an edge cell would take
    # that cell's covered cells, which its own disc may not cover
    for b in range(mb):
        cx, cy, cz = centre[b, 0], centre[b, 1], centre[b, 2]
        pu = cx * ex + cy * ey + cz * ez
        pv = cx * fx + cy * fy + cz * fz
        lo_u = min(lo_u, pu)
        hi_u = max(hi_u, pu)
        lo_v = min(lo_v, pv)
        hi_v = max(hi_v, pv)
    u0 = lo_u - cell
    v0 = lo_v - cell
    na = int((hi_u - u0) / cell) + 2
    nb = int((hi_v - v0) / cell) + 2
    top = np.full((na, nb), -1.0e300)
    topn = np.full((na, nb) if j >= 0 else (1, 1), -1.0e300)
    start = np.empty(na * nb + 1, dtype=np.int64)
    _cells(u, v, u0, v0, cell, na, nb, h, sorted_, start, top, topn, key)
    _queries(i, 1.0, ex, ey, ez, nx, ny, nz, top, local, centre, r_shank, stick, r_holder, cell, up_r, low_r, up_h,
             low_h, rim_r, rim_h, out, stats, sorted_, start, u0, v0, na, nb)
    if j >= 0:
        _queries(j, -1.0, ex, ey, ez, nx, ny, nz, topn, local, centre, r_shank, stick, r_holder, cell, up_r, low_r,
                 up_h, low_h, rim_r, rim_h, out, stats, sorted_, start, u0, v0, na, nb)


@njit(cache=True, parallel=True)
def sample_tool_kernel(dirs, local, centre, pts, r_shank, stick, r_holder, cell, up_r, low_r, up_h, low_h, out,
                       stats, workers, first, second):
    """Shank (radius ``r_shank`` from each ball centre up along n) and holder (radius
    ``r_holder`` from ``stick`` above the centre up; 0: none) against the samples ``pts``
    (ns, 3), for every direction i of ``dirs`` and query b whose ``local[b]`` holds i:
    ``out[i, b]`` = 1 where no sample lies inside either cylinder. ``up_r``/``low_r`` (and
    ``up_h``/``low_h``): half-widths per row offset of the cells a disc centred in a cell can
    meet and of those it always covers, at pitch ``cell``. ``stats`` (k, 3): tests decided
    clear and blocked by the dilated maxima, and by scanning the samples. ``workers``: the
    threads to use (numba's count: asked in Python, where numba caches the kernel).
    ``first``, ``second``: the directions in pairs, each with its opposite (-1: none), which
    shares its plane and its cells: every direction once across both."""
    ns = pts.shape[0]
    npair = first.shape[0]
    nw = max(1, min(npair, workers))
    rim_r = _rim(up_r, low_r)
    rim_h = _rim(up_h, low_h)
    # one worker per thread, its space for the samples allocated once, taking the pairs in turn
    for w in prange(nw):
        u = np.empty(ns)
        v = np.empty(ns)
        h = np.empty(ns)
        sorted_ = np.empty((ns, 3))
        key = np.empty(ns, dtype=np.int64)
        for q in range(w, npair, nw):
            _sample_tool_pair(first[q], second[q], dirs, local, centre, pts, r_shank, stick, r_holder, cell, up_r,
                              low_r, up_h, low_h, rim_r, rim_h, out, stats, u, v, h, sorted_, key)
