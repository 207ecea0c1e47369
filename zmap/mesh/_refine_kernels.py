"""Numba kernels of the greedy refinement of one region of :mod:`zmap.mesh.decimate`, afresh
or incrementally (no validation, flat arrays only).

Garland and Heckbert's greedy insertion over the Delatin port of
:mod:`zmap.mesh._delatin_kernels`, whose region's border nodes are never candidates (the
border vertices are given, shared with the neighbours, inserted first by splitting hull
edges); a refined region can keep its triangulation, to be updated over its changed nodes.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._delatin_kernels import _add_tri, _collinear, _legalize, _orient, _q_pop, _q_push

__all__ = ["refine_kernel", "refine_more_kernel"]


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
