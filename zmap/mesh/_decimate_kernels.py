"""Numba kernels of :mod:`zmap.mesh.decimate` (no validation, flat arrays only).

The region refinement is a port of Delatin (mapbox/delatin, ISC licence; Garland and
Heckbert's greedy insertion with Delaunay legalisation) over integer node coordinates,
with two changes: the region's border nodes are never candidates (the border vertices are
given, shared with the neighbours, inserted first by splitting hull edges) and the
recursion of the edge legalisation is an explicit stack.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# tiles of a region that holds NaN nodes (:func:`dense_kernel`), in cells
DENSE_TILE = 8

__all__ = ["refine_line", "refine_kernel", "full_kernel", "measure_kernel", "remesh_regions",
           "refine_more_kernel", "dense_kernel",
           "region_has_nan", "changed_regions", "rays_to_regions", "assemble", "cover_counts", "changed_boxes"]


@njit(cache=True)
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - cx) * (ay - cy) - (by - cy) * (ax - cx)


@njit(cache=True)
def _incircle(ax, ay, bx, by, cx, cy, px, py):
    dx = ax - px
    dy = ay - py
    ex = bx - px
    ey = by - py
    fx = cx - px
    fy = cy - py
    ap = dx * dx + dy * dy
    bp = ex * ex + ey * ey
    cp = fx * fx + fy * fy
    return dx * (ey * cp - bp * fy) - dy * (ex * cp - bp * fx) + ap * (ex * fy - ey * fx) < 0


# ---- 1D border polylines ------------------------------------------------------------------

@njit(cache=True)
def refine_line(h, tol, keep):
    """Mark in ``keep`` the nodes of the polyline ``h`` kept so that every node is within
    ``tol`` of the linear interpolation between kept nodes (greedy worst-node insertion)."""
    n = h.shape[0]
    for k in range(n):
        keep[k] = False
    if n == 0:
        return
    keep[0] = True
    keep[n - 1] = True
    stack = np.empty(2 * n + 2, dtype=np.int64)
    sp = 0
    stack[0] = 0
    stack[1] = n - 1
    sp = 2
    while sp > 0:
        b = stack[sp - 1]
        a = stack[sp - 2]
        sp -= 2
        if b - a < 2:
            continue
        ha = h[a]
        hb = h[b]
        inv = 1.0 / (b - a)
        worst = -1.0
        m = -1
        for k in range(a + 1, b):
            e = abs(ha + (hb - ha) * ((k - a) * inv) - h[k])
            if e > worst:
                worst = e
                m = k
        if worst > tol:
            keep[m] = True
            stack[sp] = a
            stack[sp + 1] = m
            stack[sp + 2] = m
            stack[sp + 3] = b
            sp += 4


# ---- Delatin state helpers ---------------------------------------------------------------
# st: [n_vertices, n_triangles, queue length, pending length]

@njit(cache=True)
def _q_swap(q, qerr, qidx, i, j):
    ti = q[i]
    tj = q[j]
    q[i] = tj
    q[j] = ti
    e = qerr[i]
    qerr[i] = qerr[j]
    qerr[j] = e
    qidx[tj] = i
    qidx[ti] = j


@njit(cache=True)
def _q_up(q, qerr, qidx, j):
    while j > 0:
        i = (j - 1) >> 1
        if not qerr[j] > qerr[i]:
            break
        _q_swap(q, qerr, qidx, i, j)
        j = i


@njit(cache=True)
def _q_down(q, qerr, qidx, i0, n):
    i = i0
    while True:
        j1 = 2 * i + 1
        if j1 >= n:
            break
        j2 = j1 + 1
        j = j1
        if j2 < n and qerr[j2] > qerr[j1]:
            j = j2
        if not qerr[j] > qerr[i]:
            break
        _q_swap(q, qerr, qidx, i, j)
        i = j
    return i > i0


@njit(cache=True)
def _q_push(q, qerr, qidx, st, t, err):
    i = st[2]
    qidx[t] = i
    q[i] = t
    qerr[i] = err
    st[2] = i + 1
    _q_up(q, qerr, qidx, i)


@njit(cache=True)
def _q_pop(q, qerr, qidx, st):
    n = st[2] - 1
    _q_swap(q, qerr, qidx, 0, n)
    _q_down(q, qerr, qidx, 0, n)
    t = q[n]
    st[2] = n
    qidx[t] = -1
    return t


@njit(cache=True)
def _q_remove(q, qerr, qidx, st, t):
    i = qidx[t]
    if i < 0:
        return  # pending (its slot is rewritten at once by the caller)
    n = st[2] - 1
    if n != i:
        _q_swap(q, qerr, qidx, i, n)
        if not _q_down(q, qerr, qidx, i, n):
            _q_up(q, qerr, qidx, i)
    st[2] = n
    qidx[t] = -1


@njit(cache=True)
def _add_tri(tri, he, qidx, pend, inpend, st, a, b, c, ab, bc, ca, e):
    if e < 0:
        e = 3 * st[1]
        st[1] += 1
    t = e // 3
    tri[e] = a
    tri[e + 1] = b
    tri[e + 2] = c
    he[e] = ab
    he[e + 1] = bc
    he[e + 2] = ca
    if ab >= 0:
        he[ab] = e
    if bc >= 0:
        he[bc] = e + 1
    if ca >= 0:
        he[ca] = e + 2
    qidx[t] = -1
    if not inpend[t]:
        inpend[t] = True
        pend[st[3]] = t
        st[3] += 1
    return e


@njit(cache=True)
def _legalize(a_start, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack):
    stack[0] = a_start
    sp = 1
    while sp > 0:
        sp -= 1
        a = stack[sp]
        b = he[a]
        if b < 0:
            continue
        a0 = a - a % 3
        b0 = b - b % 3
        al = a0 + (a + 1) % 3
        ar = a0 + (a + 2) % 3
        bl = b0 + (b + 2) % 3
        br = b0 + (b + 1) % 3
        p0 = tri[ar]
        pr = tri[a]
        pl = tri[al]
        p1 = tri[bl]
        if not _incircle(vx[p0], vy[p0], vx[pr], vy[pr], vx[pl], vy[pl], vx[p1], vy[p1]):
            continue
        hal = he[al]
        har = he[ar]
        hbl = he[bl]
        hbr = he[br]
        _q_remove(q, qerr, qidx, st, a0 // 3)
        _q_remove(q, qerr, qidx, st, b0 // 3)
        t0 = _add_tri(tri, he, qidx, pend, inpend, st, p0, p1, pl, -1, hbl, hal, a0)
        t1 = _add_tri(tri, he, qidx, pend, inpend, st, p1, p0, pr, t0, har, hbr, b0)
        if sp + 2 > stack.shape[0]:
            return False
        stack[sp] = t1 + 2
        stack[sp + 1] = t0 + 1
        sp += 2
    return True


@njit(cache=True)
def _collinear(pn, a, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack):
    a0 = a - a % 3
    al = a0 + (a + 1) % 3
    ar = a0 + (a + 2) % 3
    p0 = tri[ar]
    pr = tri[a]
    pl = tri[al]
    hal = he[al]
    har = he[ar]
    b = he[a]
    ok = True
    if b < 0:
        t0 = _add_tri(tri, he, qidx, pend, inpend, st, pn, p0, pr, -1, har, -1, a0)
        t1 = _add_tri(tri, he, qidx, pend, inpend, st, p0, pn, pl, t0, -1, hal, -1)
        ok &= _legalize(t0 + 1, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
        ok &= _legalize(t1 + 2, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
        return ok
    b0 = b - b % 3
    bl = b0 + (b + 2) % 3
    br = b0 + (b + 1) % 3
    p1 = tri[bl]
    hbl = he[bl]
    hbr = he[br]
    _q_remove(q, qerr, qidx, st, b0 // 3)
    t0 = _add_tri(tri, he, qidx, pend, inpend, st, p0, pr, pn, har, -1, -1, a0)
    t1 = _add_tri(tri, he, qidx, pend, inpend, st, pr, p1, pn, hbr, -1, t0 + 1, b0)
    t2 = _add_tri(tri, he, qidx, pend, inpend, st, p1, pl, pn, hbl, -1, t1 + 1, -1)
    t3 = _add_tri(tri, he, qidx, pend, inpend, st, pl, p0, pn, hal, t0 + 2, t2 + 1, -1)
    ok &= _legalize(t0, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
    ok &= _legalize(t1, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
    ok &= _legalize(t2, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
    ok &= _legalize(t3, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
    return ok


@njit(cache=True)
def _candidate(z, i0, j0, NX, NY, t, tri, vx, vy, cand, q, qerr, qidx, st):
    """Rasterise triangle t; push it with its worst interior (non-border) node. Internal x
    runs along j (the contiguous axis of z), internal y along i.

    Each row's span inside the triangle comes from the three edge functions at once (they
    are exact: integer coordinates), clipped to the region's interior, so the inner loop is
    one plane value and one height per node."""
    a = tri[3 * t]
    b = tri[3 * t + 1]
    c = tri[3 * t + 2]
    p0x = vx[a]
    p0y = vy[a]
    p1x = vx[b]
    p1y = vy[b]
    p2x = vx[c]
    p2y = vy[c]
    minx = int(min(p0x, p1x, p2x))
    maxx = int(max(p0x, p1x, p2x))
    # border rows and columns are never candidates
    ylo = max(int(min(p0y, p1y, p2y)), 1)
    yhi = min(int(max(p0y, p1y, p2y)), NY - 2)
    xlo = max(minx, 1)
    xhi = min(maxx, NX - 2)
    fminx = float(minx)
    fy = float(ylo)
    w00 = _orient(p1x, p1y, p2x, p2y, fminx, fy)
    w01 = _orient(p2x, p2y, p0x, p0y, fminx, fy)
    w02 = _orient(p0x, p0y, p1x, p1y, fminx, fy)
    a01 = p1y - p0y
    b01 = p0x - p1x
    a12 = p2y - p1y
    b12 = p1x - p2x
    a20 = p0y - p2y
    b20 = p2x - p0x
    area = _orient(p0x, p0y, p1x, p1y, p2x, p2y)
    z0 = z[i0 + int(p0y), j0 + int(p0x)] / area
    z1 = z[i0 + int(p1y), j0 + int(p1x)] / area
    z2 = z[i0 + int(p2y), j0 + int(p2x)] / area
    dzx = z0 * a12 + z1 * a20 + z2 * a01  # plane slope per node along x
    maxerr = 0.0
    mx = 0
    my = 0
    for y in range(ylo, yhi + 1):
        # x - minx = s must keep w >= 0 on the three edges: w + A s >= 0
        s0 = 0
        s1 = maxx - minx
        empty = False
        for e in range(3):
            if e == 0:
                w = w00
                A = a12
            elif e == 1:
                w = w01
                A = a20
            else:
                w = w02
                A = a01
            if A > 0:
                if w < 0:
                    s0 = max(s0, int(np.ceil(-w / A)))
            elif A < 0:
                s1 = min(s1, int(np.floor(w / -A)))
            elif w < 0:
                empty = True
        w0 = w00
        w1 = w01
        w2 = w02
        w00 += b12
        w01 += b20
        w02 += b01
        if empty:
            continue
        xa = max(minx + s0, xlo)
        xb = min(minx + s1, xhi)
        if xa > xb:
            continue
        s = float(xa - minx)
        zz = z0 * (w0 + a12 * s) + z1 * (w1 + a20 * s) + z2 * (w2 + a01 * s)
        row = z[i0 + y]
        for x in range(xa, xb + 1):
            d = abs(zz - row[j0 + x])
            if d > maxerr:
                maxerr = d
                mx = x
                my = y
            zz += dzx
    if (mx == p0x and my == p0y) or (mx == p1x and my == p1y) or (mx == p2x and my == p2y):
        maxerr = 0.0
    cand[2 * t] = mx
    cand[2 * t + 1] = my
    _q_push(q, qerr, qidx, st, t, maxerr)


@njit(cache=True)
def _flush(z, i0, j0, NX, NY, tri, vx, vy, cand, q, qerr, qidx, pend, inpend, st):
    for k in range(st[3]):
        t = pend[k]
        inpend[t] = False
        _candidate(z, i0, j0, NX, NY, t, tri, vx, vy, cand, q, qerr, qidx, st)
    st[3] = 0


@njit(cache=True)
def _work(nmax):
    """Work arrays of one region's refinement (room for every node as a vertex)."""
    tmax = 2 * nmax + 8
    vx = np.empty(nmax, dtype=np.float64)
    vy = np.empty(nmax, dtype=np.float64)
    tri = np.empty(3 * tmax, dtype=np.int32)
    he = np.empty(3 * tmax, dtype=np.int32)
    cand = np.zeros(2 * tmax, dtype=np.int32)
    q = np.empty(tmax, dtype=np.int32)
    qerr = np.empty(tmax, dtype=np.float64)
    qidx = np.full(tmax, -1, dtype=np.int32)
    pend = np.empty(tmax, dtype=np.int32)
    inpend = np.zeros(tmax, dtype=np.bool_)
    stack = np.empty(6 * tmax + 64, dtype=np.int32)
    st = np.zeros(4, dtype=np.int64)
    return vx, vy, tri, he, cand, q, qerr, qidx, pend, inpend, stack, st


@njit(cache=True)
def _side_point(s, p, x1, y1):
    """Internal (x, y) of position p on side s (0: i=0, 1: j=H-1, 2: i=W-1, 3: j=0)."""
    if s == 0:
        return float(p), 0.0
    if s == 1:
        return x1, float(p)
    if s == 2:
        return float(p), y1
    return 0.0, float(p)


@njit(cache=True)
def _hull_edge(tri, he, nt, u, v):
    """Half-edge of the hull edge between vertices u and v, or -1."""
    for h in range(3 * nt):
        if he[h] < 0:
            a = tri[h]
            b = tri[h - h % 3 + (h + 1) % 3]
            if (a == u and b == v) or (a == v and b == u):
                return h
    return -1


@njit(cache=True)
def _greedy(z, i0, j0, NX, NY, tol, nmax, tri, he, vx, vy, cand, q, qerr, qidx, pend, inpend, st, stack):
    """Candidates of the pending triangles, then Garland-Heckbert insertion of the worst
    node until every triangle is within ``tol``. Returns False if a work array overflowed."""
    ok = True
    _flush(z, i0, j0, NX, NY, tri, vx, vy, cand, q, qerr, qidx, pend, inpend, st)
    while st[2] > 0 and qerr[0] > tol:
        if st[0] >= nmax:
            break
        t = _q_pop(q, qerr, qidx, st)
        e0 = 3 * t
        e1 = e0 + 1
        e2 = e0 + 2
        p0 = tri[e0]
        p1 = tri[e1]
        p2 = tri[e2]
        ax = vx[p0]
        ay = vy[p0]
        bx = vx[p1]
        by = vy[p1]
        cx = vx[p2]
        cy = vy[p2]
        px = float(cand[2 * t])
        py = float(cand[2 * t + 1])
        pn = st[0]
        vx[pn] = px
        vy[pn] = py
        st[0] = pn + 1
        if _orient(ax, ay, bx, by, px, py) == 0:
            ok &= _collinear(pn, e0, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
        elif _orient(bx, by, cx, cy, px, py) == 0:
            ok &= _collinear(pn, e1, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
        elif _orient(cx, cy, ax, ay, px, py) == 0:
            ok &= _collinear(pn, e2, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
        else:
            h0 = he[e0]
            h1 = he[e1]
            h2 = he[e2]
            a0 = _add_tri(tri, he, qidx, pend, inpend, st, p0, p1, pn, h0, -1, -1, e0)
            a1 = _add_tri(tri, he, qidx, pend, inpend, st, p1, p2, pn, h1, -1, a0 + 1, -1)
            a2 = _add_tri(tri, he, qidx, pend, inpend, st, p2, p0, pn, h2, a0 + 2, a1 + 1, -1)
            ok &= _legalize(a0, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
            ok &= _legalize(a1, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
            ok &= _legalize(a2, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
        _flush(z, i0, j0, NX, NY, tri, vx, vy, cand, q, qerr, qidx, pend, inpend, st)
    return ok


@njit(cache=True)
def _write(H, vx, vy, tri, he, st, vout, tout, keep_tri, keep_he):
    """Vertex node offsets (i*H + j) into ``vout``, triangles counter-clockwise in (i, j)
    into ``tout``; the triangulation itself (internal order, half-edges) into ``keep_tri`` /
    ``keep_he`` when they are given (non-empty), for a later incremental update."""
    nv = st[0]
    nt = st[1]
    for v in range(nv):
        vout[v] = int(vy[v]) * H + int(vx[v])
    for t in range(nt):
        a = tri[3 * t]
        b = tri[3 * t + 1]
        c = tri[3 * t + 2]
        s2 = (vy[b] - vy[a]) * (vx[c] - vx[a]) - (vx[b] - vx[a]) * (vy[c] - vy[a])
        tout[t, 0] = a
        if s2 < 0:
            tout[t, 1] = c
            tout[t, 2] = b
        else:
            tout[t, 1] = b
            tout[t, 2] = c
    if keep_tri.shape[0] > 0:
        for e in range(3 * nt):
            keep_tri[e] = tri[e]
            keep_he[e] = he[e]
    return nv, nt


@njit(cache=True)
def refine_kernel(z, i0, j0, W, H, tol, side0, side1, side2, side3, vout, tout, keep_tri, keep_he):
    """Greedy refinement of the region z[i0:i0+W, j0:j0+H] to vertical error ``tol``.

    side0..side3: sorted positions of the border vertices (corners excluded) on the sides
    i=0 (positions in j), j=H-1 (in i), i=W-1 (in j), j=0 (in i). Writes vertex node
    offsets (i*H + j, local) into ``vout`` and triangles counter-clockwise in (i, j) (local
    vertex indices) into ``tout`` (and the triangulation into ``keep_tri``/``keep_he`` when
    non-empty); returns (n_vertices, n_triangles), or (-1, -1) if a work array
    overflowed. Internally x runs along j (contiguous in memory), y along i.
    """
    NX = H
    NY = W
    nmax = W * H
    vx, vy, tri, he, cand, q, qerr, qidx, pend, inpend, stack, st = _work(nmax)
    x1 = float(NX - 1)
    y1 = float(NY - 1)
    # corners p0 (0,0), p1 (x1,0), p2 (0,y1), p3 (x1,y1)
    vx[0] = 0.0
    vy[0] = 0.0
    vx[1] = x1
    vy[1] = 0.0
    vx[2] = 0.0
    vy[2] = y1
    vx[3] = x1
    vy[3] = y1
    st[0] = 4
    t0 = _add_tri(tri, he, qidx, pend, inpend, st, 3, 0, 2, -1, -1, -1, -1)
    _add_tri(tri, he, qidx, pend, inpend, st, 0, 3, 1, t0, -1, -1, -1)
    ok = True
    for s in range(4):
        if s == 0:
            pos = side0
            start = 0
            end = 1
        elif s == 1:
            pos = side1
            start = 1
            end = 3
        elif s == 2:
            pos = side2
            start = 2
            end = 3
        else:
            pos = side3
            start = 0
            end = 2
        prev = start
        for k in range(pos.shape[0]):
            n = st[0]
            px, py = _side_point(s, pos[k], x1, y1)
            vx[n] = px
            vy[n] = py
            st[0] = n + 1
            e = _hull_edge(tri, he, st[1], prev, end)  # the hull edge prev-end holds the new point
            if e < 0:
                return -1, -1
            ok &= _collinear(n, e, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
            prev = n
    ok &= _greedy(z, i0, j0, NX, NY, tol, nmax, tri, he, vx, vy, cand, q, qerr, qidx, pend, inpend,
                  st, stack)
    if not ok:
        return -1, -1
    return _write(H, vx, vy, tri, he, st, vout, tout, keep_tri, keep_he)


@njit(cache=True)
def refine_more_kernel(z, i0, j0, W, H, tol, side0, side1, side2, side3, vout, tout, keep_tri, keep_he,
                       nv0, nt0, ci0, cj0, ci1, cj1):
    """Incremental update of a region refined before (by :func:`refine_kernel` or this).

    The region's triangulation (``nv0`` vertices in ``vout``, ``nt0`` triangles in
    ``keep_tri``/``keep_he``) is taken as it is; border positions of ``side0..side3`` it
    does not hold yet are inserted into their hull edges; every triangle whose box meets the
    changed nodes (local rows ci0..ci1, columns cj0..cj1) gets its worst node again, and
    the greedy insertion runs until every triangle is within ``tol`` of the current heights.
    Vertices are only added, so the bound holds for every node while the mesh may keep
    vertices a fresh refinement would not need. Returns as :func:`refine_kernel`.
    """
    NX = H
    NY = W
    nmax = W * H
    vx, vy, tri, he, cand, q, qerr, qidx, pend, inpend, stack, st = _work(nmax)
    x1 = float(NX - 1)
    y1 = float(NY - 1)
    vid = np.full(nmax, -1, dtype=np.int32)
    for v in range(nv0):
        o = vout[v]
        yy = o // H
        vx[v] = float(o - yy * H)
        vy[v] = float(yy)
        vid[o] = v
    for e in range(3 * nt0):
        tri[e] = keep_tri[e]
        he[e] = keep_he[e]
    st[0] = nv0
    st[1] = nt0
    ok = True
    for s in range(4):
        if s == 0:
            pos = side0
        elif s == 1:
            pos = side1
        elif s == 2:
            pos = side2
        else:
            pos = side3
        n_side = NX if (s == 0 or s == 2) else NY
        for k in range(pos.shape[0]):
            px, py = _side_point(s, pos[k], x1, y1)
            o = int(py) * H + int(px)
            if vid[o] >= 0:
                continue
            # the vertices either side of it along the side (corners are always vertices)
            u = -1
            for p2 in range(pos[k] - 1, -1, -1):
                ax, ay = _side_point(s, p2, x1, y1)
                u = vid[int(ay) * H + int(ax)]
                if u >= 0:
                    break
            w = -1
            for p2 in range(pos[k] + 1, n_side):
                ax, ay = _side_point(s, p2, x1, y1)
                w = vid[int(ay) * H + int(ax)]
                if w >= 0:
                    break
            e = _hull_edge(tri, he, st[1], u, w)
            if e < 0:
                return -1, -1
            n = st[0]
            vx[n] = px
            vy[n] = py
            vid[o] = n
            st[0] = n + 1
            ok &= _collinear(n, e, tri, he, vx, vy, q, qerr, qidx, pend, inpend, st, stack)
    # triangles over the changed nodes (internal x = j, y = i) get their worst node again
    for t in range(st[1]):
        if inpend[t]:
            continue
        a = tri[3 * t]
        b = tri[3 * t + 1]
        c = tri[3 * t + 2]
        if (max(vx[a], vx[b], vx[c]) < cj0 or min(vx[a], vx[b], vx[c]) > cj1
                or max(vy[a], vy[b], vy[c]) < ci0 or min(vy[a], vy[b], vy[c]) > ci1):
            continue
        inpend[t] = True
        pend[st[3]] = t
        st[3] += 1
    ok &= _greedy(z, i0, j0, NX, NY, tol, nmax, tri, he, vx, vy, cand, q, qerr, qidx, pend, inpend,
                  st, stack)
    if not ok:
        return -1, -1
    return _write(H, vx, vy, tri, he, st, vout, tout, keep_tri, keep_he)


@njit(cache=True)
def full_kernel(z, i0, j0, W, H, vout, tout):
    """Two counter-clockwise triangles per cell whose four corners are finite; vertices are
    the nodes those cells use (local offsets x*H + y). Returns (n_vertices, n_triangles)."""
    ids = np.full(W * H, -1, dtype=np.int64)
    nv = 0
    nt = 0
    for x in range(W - 1):
        for y in range(H - 1):
            if (np.isnan(z[i0 + x, j0 + y]) or np.isnan(z[i0 + x + 1, j0 + y])
                    or np.isnan(z[i0 + x + 1, j0 + y + 1]) or np.isnan(z[i0 + x, j0 + y + 1])):
                continue
            a = x * H + y
            b = (x + 1) * H + y
            c = (x + 1) * H + y + 1
            d = x * H + y + 1
            for o in (a, b, c, d):
                if ids[o] < 0:
                    ids[o] = nv
                    vout[nv] = o
                    nv += 1
            tout[nt, 0] = ids[a]
            tout[nt, 1] = ids[b]
            tout[nt, 2] = ids[c]
            tout[nt + 1, 0] = ids[a]
            tout[nt + 1, 1] = ids[c]
            tout[nt + 1, 2] = ids[d]
            nt += 2
    return nv, nt


@njit(cache=True)
def _box_has_nan(z, i0, j0, i1, j1):
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            if np.isnan(z[i, j]):
                return True
    return False


@njit(cache=True)
def _tile_row_sides(z, i0, j0, W, H, tol, tile, nan, keep, h):
    """Border vertices on the tile rows i = a*tile of the region z[i0:i0+W, j0:j0+H]: every
    node on the region's own sides and next to a NaN tile, a refined polyline between two
    tiles without NaN. :func:`dense_kernel` calls it on the transposed map for the columns."""
    ntx, nty = nan.shape
    for la in range(ntx + 1):
        i = min(la * tile, W - 1)
        for b in range(nty):
            jb0 = b * tile
            jb1 = min(jb0 + tile, H - 1)
            n = jb1 - jb0 + 1
            if la == 0 or la == ntx or nan[la - 1, b] or nan[la, b]:
                for m in range(n):
                    keep[la, jb0 + m] = True
            else:
                for m in range(n):
                    h[m] = z[i0 + i, j0 + jb0 + m]
                refine_line(h[:n], tol, keep[la, jb0:jb1 + 1])


@njit(cache=True)
def dense_kernel(z, i0, j0, W, H, tol, tile, vout, tout):
    """A region that holds NaN nodes: split into tiles of ``tile`` cells; tiles with a NaN node
    are meshed in full (two triangles per valid cell), the others refined to ``tol`` like a
    region, with the sides between two such tiles refined as shared polylines and every other
    side (the region's own sides, sides next to a NaN tile) keeping every node, so the region
    meets its neighbours (which keep every node on a side shared with it) without cracks.
    Returns (n_vertices, n_triangles) as :func:`full_kernel`, or (-1, -1) on overflow."""
    ntx = (W - 2) // tile + 1
    nty = (H - 2) // tile + 1
    nan = np.zeros((ntx, nty), dtype=np.bool_)
    for a in range(ntx):
        for b in range(nty):
            nan[a, b] = _box_has_nan(z, i0 + a * tile, j0 + b * tile, i0 + min((a + 1) * tile, W - 1),
                                     j0 + min((b + 1) * tile, H - 1))
    # border vertices of the tile sides: rows i = a*tile (local) and columns j = b*tile
    keep_i = np.zeros((ntx + 1, H), dtype=np.bool_)
    keep_j = np.zeros((nty + 1, W), dtype=np.bool_)
    h = np.empty(tile + 1, dtype=np.float64)
    _tile_row_sides(z, i0, j0, W, H, tol, tile, nan, keep_i, h)
    # the columns are the rows of the transposed map
    _tile_row_sides(z.T, j0, i0, H, W, tol, tile, nan.T, keep_j, h)
    ids = np.full(W * H, -1, dtype=np.int64)
    tv = np.empty((tile + 1) * (tile + 1), dtype=np.int64)
    tt = np.empty((2 * tile * tile, 3), dtype=np.int32)
    empty = np.zeros(0, dtype=np.int32)
    nv = 0
    nt = 0
    for a in range(ntx):
        for b in range(nty):
            ia0 = a * tile
            jb0 = b * tile
            ia1 = min(ia0 + tile, W - 1)
            jb1 = min(jb0 + tile, H - 1)
            Wt = ia1 - ia0 + 1
            Ht = jb1 - jb0 + 1
            if nan[a, b]:
                cv, ct = full_kernel(z, i0 + ia0, j0 + jb0, Wt, Ht, tv, tt)
            else:
                s0 = _side(keep_i[a, jb0:jb1 + 1], Ht)
                s1 = _side(keep_j[b + 1, ia0:ia1 + 1], Wt)
                s2 = _side(keep_i[a + 1, jb0:jb1 + 1], Ht)
                s3 = _side(keep_j[b, ia0:ia1 + 1], Wt)
                cv, ct = refine_kernel(z, i0 + ia0, j0 + jb0, Wt, Ht, tol, s0, s1, s2, s3, tv, tt, empty, empty)
                if cv < 0:
                    return -1, -1
            for t in range(ct):
                for c in range(3):
                    o = tv[tt[t, c]]
                    x = o // Ht
                    g = (ia0 + x) * H + jb0 + (o - x * Ht)
                    if ids[g] < 0:
                        ids[g] = nv
                        vout[nv] = g
                        nv += 1
                    tout[nt, c] = ids[g]
                nt += 1
    return nv, nt


# ---- the error measure -------------------------------------------------------------------

@njit(cache=True)
def measure_kernel(z, vi, vj, faces, vz):
    """Max over nodes of |mesh height - z| (exact integer barycentrics); a node that is a
    vertex of its triangle counts its vertex height. NaN nodes inside a face give inf."""
    worst = 0.0
    for f in range(faces.shape[0]):
        a = faces[f, 0]
        b = faces[f, 1]
        c = faces[f, 2]
        ax = vi[a]
        ay = vj[a]
        bx = vi[b]
        by = vj[b]
        cx = vi[c]
        cy = vj[c]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0:
            continue
        for x in range(min(ax, bx, cx), max(ax, bx, cx) + 1):
            for y in range(min(ay, by, cy), max(ay, by, cy) + 1):
                wa = (bx - x) * (cy - y) - (by - y) * (cx - x)
                wb = (cx - x) * (ay - y) - (cy - y) * (ax - x)
                wc = (ax - x) * (by - y) - (ay - y) * (bx - x)
                if area > 0:
                    if wa < 0 or wb < 0 or wc < 0:
                        continue
                else:
                    if wa > 0 or wb > 0 or wc > 0:
                        continue
                h = z[x, y]
                if np.isnan(h):
                    return np.inf
                if wb == 0 and wc == 0:
                    m = vz[a]
                elif wa == 0 and wc == 0:
                    m = vz[b]
                elif wa == 0 and wb == 0:
                    m = vz[c]
                else:
                    m = (wa * vz[a] + wb * vz[b] + wc * vz[c]) / area
                d = abs(m - h)
                if d > worst:
                    worst = d
    return worst


# ---- whole maps and local updates ---------------------------------------------------------

@njit(cache=True)
def _region_box(bi, bj, r, nx, ny):
    """First and last node (i0, j0, i1, j1) of region (bi, bj), its borders included."""
    i0 = bi * r
    j0 = bj * r
    return i0, j0, min(i0 + r, nx - 1), min(j0 + r, ny - 1)


@njit(cache=True)
def region_has_nan(z, r, todo, out):
    """out[bi, bj] = region (bi, bj) of ``todo`` holds a NaN node (borders included)."""
    nx, ny = z.shape
    for k in range(todo.shape[0]):
        bi = todo[k, 0]
        bj = todo[k, 1]
        i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
        f = False
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                if np.isnan(z[i, j]):
                    f = True
                    break
            if f:
                break
        out[bi, bj] = f


@njit(cache=True)
def _mark_regions(i, j, r, nrx, nry, hit):
    """hit[bi, bj] = True for every region whose nodes (its borders included) hold node (i, j)."""
    bi_lo = (i - 1) // r if i > 0 else 0
    bi_hi = min(i // r, nrx - 1)
    bj_lo = (j - 1) // r if j > 0 else 0
    bj_hi = min(j // r, nry - 1)
    for bi in range(bi_lo, bi_hi + 1):
        for bj in range(bj_lo, bj_hi + 1):
            hit[bi, bj] = True


@njit(cache=True)
def changed_regions(a, b, r, nrx, nry, hit):
    """hit[bi, bj] |= some node of region (bi, bj) (borders included) differs between a and b."""
    nx, ny = a.shape
    for i in range(nx):
        for j in range(ny):
            u = a[i, j]
            v = b[i, j]
            if u == v or (np.isnan(u) and np.isnan(v)):
                continue
            _mark_regions(i, j, r, nrx, nry, hit)


@njit(cache=True)
def _refine_more_line(h, tol, keep, tmp):
    """Extend ``keep`` (its two ends kept) so that every node of ``h`` is within ``tol`` of
    the polyline through the kept nodes: each span between kept nodes refined greedily."""
    n = h.shape[0]
    keep[0] = True
    keep[n - 1] = True
    a = 0
    for b in range(1, n):
        if not keep[b]:
            continue
        if b - a >= 2:
            refine_line(h[a:b + 1], tol, tmp[:b - a + 1])
            for k in range(a + 1, b):
                if tmp[k - a]:
                    keep[k] = True
        a = b


@njit(cache=True)
def _side(keep, n):
    """Positions 1..n-2 that ``keep`` marks (a region side's border vertices, corners out)."""
    c = 0
    for k in range(1, n - 1):
        if keep[k]:
            c += 1
    out = np.empty(c, dtype=np.int64)
    c = 0
    for k in range(1, n - 1):
        if keep[k]:
            out[c] = k
            c += 1
    return out


@njit(cache=True)
def _line_side(h, tol, keep, tmp, any_dense, all_fresh):
    """The border vertices of one side shared by up to two regions, in ``keep``: every node
    next to a dense region; refined afresh when every region on it is meshed afresh;
    otherwise extended from what the regions already hold (so both keep the same)."""
    n = h.shape[0]
    if any_dense:
        for k in range(n):
            keep[k] = True
    elif all_fresh:
        refine_line(h, tol, keep)
    else:
        _refine_more_line(h, tol, keep, tmp)


@njit(cache=True)
def _sides(z, r, tol, dense, todo, mode, keep_i, keep_j):
    """Border vertices of every side of the regions in ``todo``, each side once.

    ``keep_i[li, j]``: node j of the grid row i = min(li*r, nx-1) is a border vertex;
    ``keep_j[lj, i]``: node i of the grid column j = min(lj*r, ny-1)."""
    nx, ny = z.shape
    nrx, nry = dense.shape
    done_i = np.zeros((nrx + 1, nry), dtype=np.bool_)
    done_j = np.zeros((nry + 1, nrx), dtype=np.bool_)
    h = np.empty(r + 1, dtype=np.float64)
    tmp = np.empty(r + 1, dtype=np.bool_)
    for k in range(todo.shape[0]):
        bi = todo[k, 0]
        bj = todo[k, 1]
        _row_sides(z, r, tol, dense, mode, keep_i, done_i, bi, bj, h, tmp)
        # the columns are the rows of the transposed map
        _row_sides(z.T, r, tol, dense.T, mode.T, keep_j, done_j, bj, bi, h, tmp)


@njit(cache=True)
def _row_sides(z, r, tol, dense, mode, keep, done, bi, bj, h, tmp):
    """The two grid rows i0 and i1 of region (bi, bj), each between regions (li-1, bj) and
    (li, bj), unless ``done``; :func:`_sides` calls it on the transposed map for the columns."""
    nx, ny = z.shape
    nrx = dense.shape[0]
    i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
    for li in (bi, bi + 1):
        if done[li, bj]:
            continue
        done[li, bj] = True
        i = min(li * r, nx - 1)
        any_dense = False
        all_fresh = True
        for a in (li - 1, li):
            if a >= 0 and a < nrx:
                any_dense |= dense[a, bj]
                all_fresh &= mode[a, bj] == 1
        n = j1 - j0 + 1
        for m in range(n):
            h[m] = z[i, j0 + m]
        _line_side(h[:n], tol, keep[li, j0:j1 + 1], tmp, any_dense, all_fresh)


@njit(cache=True)
def remesh_regions(z, r, tol, full, dense, todo, mode, vpool, tpool, nv, nt, keep_i, keep_j,
                   ktri, khe, has, cbox):
    """Mesh the regions listed in ``todo`` (pairs bi, bj) into the pools.

    A region is meshed in full (two triangles per valid cell) when ``full`` is set; a
    ``dense`` one (it holds a NaN node) by :func:`dense_kernel` (in full only in its tiles
    that hold a NaN node), and a border side shared with a dense region keeps every node. Otherwise the sides are refined as polylines to ``tol`` (:func:`_sides`: one
    answer per side, shared by both its regions) and the interior by
    :func:`refine_kernel` (``mode`` 1: afresh) or :func:`refine_more_kernel` (``mode`` 2, a
    region with a kept triangulation, ``has``: incrementally, over the changed nodes'
    box ``cbox[bi, bj]`` = global i0, j0, i1, j1). ``ktri``/``khe`` (regions, 3 * room)
    keep each region's triangulation when they are non-empty. Returns the number of regions
    whose work arrays overflowed (meshed in full instead).
    """
    nx, ny = z.shape
    nrx, nry = dense.shape
    keeping = ktri.shape[0] > 0
    empty = np.zeros(0, dtype=np.int32)
    if not full:
        _sides(z, r, tol, dense, todo, mode, keep_i, keep_j)
    bad = 0
    for k in range(todo.shape[0]):
        bi = todo[k, 0]
        bj = todo[k, 1]
        reg = bi * nry + bj
        i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
        W = i1 - i0 + 1
        H = j1 - j0 + 1
        if full or dense[bi, bj]:
            a = -1
            if not full:
                a, b = dense_kernel(z, i0, j0, W, H, tol, DENSE_TILE, vpool[reg], tpool[reg])
            if a < 0:
                a, b = full_kernel(z, i0, j0, W, H, vpool[reg], tpool[reg])
            nv[reg] = a
            nt[reg] = b
            has[reg] = False
            continue
        # side i=0 (shared with region bi-1), j=H-1 (bj+1), i=W-1 (bi+1), j=0 (bj-1)
        s0 = _side(keep_i[bi, j0:j1 + 1], H)
        s1 = _side(keep_j[bj + 1, i0:i1 + 1], W)
        s2 = _side(keep_i[bi + 1, j0:j1 + 1], H)
        s3 = _side(keep_j[bj, i0:i1 + 1], W)
        kt = ktri[reg] if keeping else empty
        kh = khe[reg] if keeping else empty
        if keeping and mode[bi, bj] == 2 and has[reg]:
            a, b = refine_more_kernel(z, i0, j0, W, H, tol, s0, s1, s2, s3, vpool[reg], tpool[reg],
                                      kt, kh, nv[reg], nt[reg], cbox[bi, bj, 0] - i0,
                                      cbox[bi, bj, 1] - j0, cbox[bi, bj, 2] - i0, cbox[bi, bj, 3] - j0)
        else:
            a, b = refine_kernel(z, i0, j0, W, H, tol, s0, s1, s2, s3, vpool[reg], tpool[reg], kt, kh)
        has[reg] = keeping and a >= 0
        if a < 0:
            bad += 1
            a, b = full_kernel(z, i0, j0, W, H, vpool[reg], tpool[reg])
        nv[reg] = a
        nt[reg] = b
    return bad


@njit(cache=True)
def rays_to_regions(rays, ny, r, nrx, nry, hit):
    """hit[bi, bj] = True for every region whose nodes (borders included) hold one of ``rays``
    (ray = i*ny + j)."""
    for k in range(rays.shape[0]):
        i = rays[k] // ny
        j = rays[k] - i * ny
        _mark_regions(i, j, r, nrx, nry, hit)


@njit(cache=True)
def assemble(vpool, tpool, nv, nt, r, nry, nx, ny, ids):
    """Global mesh of all regions: vertex node ids (i*ny + j) and faces. ``ids`` (nx*ny,
    int32) is scratch, returned filled with -1."""
    nreg = nv.shape[0]
    tv = 0
    tt = 0
    for reg in range(nreg):
        tv += nv[reg]
        tt += nt[reg]
    nodes = np.empty(tv, dtype=np.int64)
    faces = np.empty((tt, 3), dtype=np.int32)
    local = np.empty(vpool.shape[1], dtype=np.int32)
    n = 0
    f = 0
    for reg in range(nreg):
        bi = reg // nry
        bj = reg - bi * nry
        i0, j0, _, j1 = _region_box(bi, bj, r, nx, ny)
        H = j1 - j0 + 1
        for v in range(nv[reg]):
            o = vpool[reg, v]
            x = o // H
            g = (i0 + x) * ny + j0 + (o - x * H)
            if ids[g] < 0:
                ids[g] = n
                nodes[n] = g
                n += 1
            local[v] = ids[g]
        for t in range(nt[reg]):
            faces[f, 0] = local[tpool[reg, t, 0]]
            faces[f, 1] = local[tpool[reg, t, 1]]
            faces[f, 2] = local[tpool[reg, t, 2]]
            f += 1
    for k in range(n):
        ids[nodes[k]] = -1
    return nodes[:n], faces


@njit(cache=True)
def cover_counts(vi, vj, faces, px, py, ny1, cell_off, cell_pts, count):
    """count[p] = number of faces whose xy shadow holds point p (node units); the points are
    bucketed by cell (cell = floor(px) * ny1 + floor(py), CSR ``cell_off``/``cell_pts``)."""
    ncell = cell_off.shape[0] - 1
    nx1 = ncell // ny1
    for f in range(faces.shape[0]):
        a = faces[f, 0]
        b = faces[f, 1]
        c = faces[f, 2]
        ax = float(vi[a])
        ay = float(vj[a])
        bx = float(vi[b])
        by = float(vj[b])
        cx = float(vi[c])
        cy = float(vj[c])
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0:
            continue
        for ci in range(int(min(ax, bx, cx)), min(int(max(ax, bx, cx)), nx1)):
            for cj in range(int(min(ay, by, cy)), min(int(max(ay, by, cy)), ny1)):
                cell = ci * ny1 + cj
                for k in range(cell_off[cell], cell_off[cell + 1]):
                    p = cell_pts[k]
                    x = px[p]
                    y = py[p]
                    wa = (bx - x) * (cy - y) - (by - y) * (cx - x)
                    wb = (cx - x) * (ay - y) - (cy - y) * (ax - x)
                    wc = (ax - x) * (by - y) - (ay - y) * (bx - x)
                    if area > 0:
                        if wa >= 0 and wb >= 0 and wc >= 0:
                            count[p] += 1
                    elif wa <= 0 and wb <= 0 and wc <= 0:
                        count[p] += 1


@njit(cache=True)
def changed_boxes(a, b, r, hit, box):
    """For every region marked in ``hit``: the box of its nodes (borders included) that
    differ between ``a`` and ``b`` (NaN equal to NaN) into ``box[bi, bj]`` (i0, j0, i1, j1);
    ``hit`` cleared where none does (history events below the top surface)."""
    nx, ny = a.shape
    nrx, nry = hit.shape
    for bi in range(nrx):
        for bj in range(nry):
            if not hit[bi, bj]:
                continue
            i0, j0, i1, j1 = _region_box(bi, bj, r, nx, ny)
            lo_i = i1 + 1
            lo_j = j1 + 1
            hi_i = -1
            hi_j = -1
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    u = a[i, j]
                    v = b[i, j]
                    if u != v and not (np.isnan(u) and np.isnan(v)):
                        lo_i = min(lo_i, i)
                        hi_i = max(hi_i, i)
                        lo_j = min(lo_j, j)
                        hi_j = max(hi_j, j)
            if hi_i < 0:
                hit[bi, bj] = False
            else:
                box[bi, bj, 0] = lo_i
                box[bi, bj, 1] = lo_j
                box[bi, bj, 2] = hi_i
                box[bi, bj, 3] = hi_j
