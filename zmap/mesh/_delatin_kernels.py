"""Numba helpers of the triangulation behind :mod:`zmap.mesh.decimate`'s region refinement:
the orientation and in-circle predicates, the triangles' error queue (a binary max-heap with
each triangle's slot) and the half-edge triangles with their Delaunay legalisation and the
split of an edge through a new vertex (no validation, flat arrays only).

A port of Delatin (mapbox/delatin, ISC licence; Garland and Heckbert's greedy insertion with
Delaunay legalisation) over integer node coordinates; the recursion of the edge legalisation
is an explicit stack. ``st``: [n_vertices, n_triangles, queue length, pending length].
"""

from __future__ import annotations

from numba import njit

__all__ = ["_orient", "_q_push", "_q_pop", "_add_tri", "_legalize", "_collinear"]


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
