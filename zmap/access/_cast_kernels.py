"""Numba kernel of the cylinder casting of paper 002 §4.5 (:mod:`zmap.access.casting`): per
direction one depth buffer of the blockers, then the queries' bits (no validation, flat arrays
only).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._line_kernels import _box_row, _geometry, _row, _span, _window

__all__ = ["cast_directions"]


@njit(cache=True, parallel=True)
def cast_directions(dirs, opp, bxyz, bhalf, bvox, blight, bplane, qxyz, qhalf, qid, skin, shalf, hide, skin_mask, light,
                    vl, ppt, pnrm, slab, d, cell, radius, lo, tile, strict, qptr, qidx, out):
    """Cylinder casting of paper 002 §4.5 for every direction at once, one depth buffer each.

    For direction n, the lines parallel to n through the cell centres of a plane grid of
    pitch ``cell`` stand for the cylinder's rays. Blockers are the interior skin voxels
    (cubes) and the boundary voxels w with -n in L'(w) (their surface boxes). Per line the
    buffer keeps the largest exit parameter of a blocker box. Voxel v keeps n when no line
    through its box meets a blocker box beyond the line's start: v's entry into the box, or
    later where the patch's slab (``ppt``, ``pnrm``, ``slab``: every point x of v's surface
    patch has ``(x - ppt[v]) . pnrm[v] >= -slab[v]``) shows that no patch point on the line lies
    lower (only where n . pnrm[v] > 0; a blocker behind the patch, such as the interior cube
    under a flat face or the box of the next voxel across a convex edge, cannot stop a ray
    leaving the patch). The boundary blockers (``bxyz``, ``bhalf``: one box per voxel crossed
    by one face, one per face where several meet; ``bvox`` their voxels, ``blight`` their L',
    ``bplane`` their mean point, normal and slab) grow along axis c by (cell / 2)(|e_c| +
    |f_c|), as far as a ray in a cell can be from its centre line, so that a true ray into a
    thin one still shows on the centre line of its cell; where a blocker faces the line its
    exit is cut where the line has passed that far behind its slab. A box of v thinner than a
    cell that no centre line crosses is tested on the cell under its centre from its nearest
    depth. As a query (the cylinder's cross-section) v has its own box (``qxyz``,
    ``qhalf``). ``out[i, b]`` = 1 where direction i stays in V'_g(b); ``opp[i]`` is the index
    of -dirs[i].

    Where some v is both a query and a blocker of direction i (n in V'_l(v) and -n in L'(v):
    only with the paper's tessel sets, never with exact hemispheres) the buffer also keeps the
    second largest exit with the largest one's blocker number, to skip v itself; otherwise it
    keeps the largest alone.

    A skin cube whose neighbours on n's side (``hide[i]``, a mask over ``skin_mask``) are all
    interior is left out of direction i: every line leaving it goes on into the interior and
    leaves it through a later skin cube that is kept, whose exit is larger, so no buffer
    value changes. Per cell the exit and entry parameters are linear in the cell's centre
    along a row (one add per axis), and the buffer covers only the part's footprint.

    bxyz, bhalf : (mb, 3) centres and half extents of the boundary voxels' boxes as blockers;
    qxyz, qhalf : (mb, 3) the queries' boxes (the boundary voxels', then any pieces'), with
    ``light``, ``vl``, ``ppt``, ``pnrm``, ``slab`` per query; qid : (mb,) the blocker number
    (``bvox``) a query skips as itself where it is also a blocker (-3 and below: none);
    skin, shalf : (ms, 3) centres and half extents of boxes of interior skin voxels, each box
    of voxels with one neighbour mask ``skin_mask``
    (:func:`~zmap.access._blocker_kernels.merge_runs`; single cubes: half d);
    radius : half the diagonal of the part's box; lo : (3,) centre of the part's box.

    ``tile`` > 0: a buffer cell matters only under a query that asks for direction i, and only
    where it ends later than that query's start, so the buffer covers only the rectangle of
    cells under such queries, split into tiles of tile x tile cells each holding the lowest
    point along n of the queries' boxes over it; a blocker is drawn only where its latest exit
    (the far corner of its grown box along n) lies beyond that in one of its tiles. A blocker
    left out ends no later than the start of every line it shares with a query, so every
    answer is the same (the same bits, tested). 0: every blocker is drawn.

    ``strict`` = 1 tests a query on every cell some line of which meets its box, not only
    those whose centre line crosses it, each from the lowest start a ray of the cell from a
    patch point can have (bounds over the cell of the box's entry, its lowest point along n,
    the slab's lowest over the cell): a
    ray of the patch lies in one of those cells and starts no lower, and a blocker it meets
    shows on its cell's line (grown as above) no earlier, so a query kept is free for every
    ray of its patch that meets a boundary blocker, not only for the cells' lines (the skin
    cubes are not grown: a ray that reaches one has entered the part through the surface).
    The refinement of ``global_visibility`` casts so with ``_FINE_STRICT``.

    ``qptr`` (k + 1), ``qidx``: where not empty, the queries that ask for each direction
    (:func:`~zmap.access._bit_kernels.bit_lists` of ``vl``; ``out`` must then come zeroed):
    the loops over the queries visit only those, not every query's bit.
    """
    k = dirs.shape[0]
    nb = bxyz.shape[0]
    mb = qxyz.shape[0]
    ms = skin.shape[0]
    g = 0.5 * np.sqrt(2.0) * cell
    u0 = -(radius + 2 * d)
    nc = int(np.ceil(2.0 * (radius + 2 * d) / cell)) + 1
    # the box holding every blocker and every voxel box (grown), relative to lo
    gmin = np.full(3, 1.0e300)
    gmax = np.full(3, -1.0e300)
    for m in range(nb + mb + ms):
        for c in range(3):
            if m < nb:
                x0 = bxyz[m, c] - bhalf[m, c] - g
                x1 = bxyz[m, c] + bhalf[m, c] + g
            elif m < nb + mb:
                x0 = qxyz[m - nb, c] - qhalf[m - nb, c]
                x1 = qxyz[m - nb, c] + qhalf[m - nb, c]
            else:
                x0 = skin[m - nb - mb, c] - shalf[m - nb - mb, c]
                x1 = skin[m - nb - mb, c] + shalf[m - nb - mb, c]
            gmin[c] = min(gmin[c], x0 - lo[c])
            gmax[c] = max(gmax[c], x1 - lo[c])
    for i in prange(k):  # the body is a call: parfor lowering of a big body compiles for minutes
        _cast_one(i, dirs, opp, bxyz, bhalf, bvox, blight, bplane, qxyz, qhalf, qid, skin, shalf, hide, skin_mask, light,
                  vl, ppt, pnrm, slab, d, cell, lo, g, u0, nc, gmin, gmax, tile, strict, qptr, qidx, out)


@njit(cache=True)
def _cast_one(i, dirs, opp, bxyz, bhalf, bvox, blight, bplane, qxyz, qhalf, qid, skin, shalf, hide, skin_mask, light,
              vl, ppt, pnrm, slab, d, cell, lo, g, u0, nc, gmin, gmax, tile, strict, qptr, qidx, out):
    """Direction i of :func:`cast_directions`: its depth buffer, then ``out[i, :]``."""
    listed = qptr.shape[0] > 0
    nq = qptr[i + 1] - qptr[i] if listed else qxyz.shape[0]
    q0 = qptr[i] if listed else 0
    nb = bxyz.shape[0]
    mb = qxyz.shape[0]
    ms = skin.shape[0]
    nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
    geo = _geometry(nx, ny, nz)
    ex, ey, ez, fx, fy, fz = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    pfx, pfy, pfz = geo[12], geo[13], geo[14]
    A0, A1, B0, B1 = _window(gmin, gmax, ex, ey, ez, fx, fy, fz, 0.0, u0, cell, nc)
    wi = i >> 6
    bi = np.uint64(i & 63)
    o = opp[i]
    ow = o >> 6
    ob = np.uint64(o & 63)
    if tile > 0:
        # only the cells under the queries that ask for i are read: the window shrinks to them
        a0, a1, c0_, c1_ = A1 + 1, A0 - 1, B1 + 1, B0 - 1
        for t in range(nq):
            m = qidx[q0 + t] if listed else t
            if (vl[m, wi] >> bi) & np.uint64(1) == 0:
                continue
            pu, pv, ae, af, ia, ib, ja, jb, lxa, lxb, lya, lyb, lza, lzb = _span(
                qxyz[m, 0] - lo[0], qxyz[m, 1] - lo[1], qxyz[m, 2] - lo[2], qhalf[m, 0], qhalf[m, 1], qhalf[m, 2],
                geo, u0, cell, A0, A1, B0, B1)
            a0 = min(a0, min(ia, max(A0, min(A1, int(np.floor((pu - u0) / cell))))))
            a1 = max(a1, max(ib, max(A0, min(A1, int(np.floor((pu - u0) / cell))))))
            c0_ = min(c0_, min(ja, max(B0, min(B1, int(np.floor((pv - u0) / cell))))))
            c1_ = max(c1_, max(jb, max(B0, min(B1, int(np.floor((pv - u0) / cell))))))
        if a0 > a1 or c0_ > c1_:
            for m in range(mb):
                out[i, m] = 0
            return
        A0, A1, B0, B1 = a0, a1, c0_, c1_
    # the top-two bookkeeping is needed only where a query of i is also a blocker of i
    two = False
    for t in range(nq):
        m = qidx[q0 + t] if listed else t
        if (vl[m, wi] >> bi) & (light[m, ow] >> ob) & np.uint64(1):
            two = True
            break
    b1 = np.full((A1 - A0 + 1, B1 - B0 + 1), -1.0e300)
    b2 = np.full((A1 - A0 + 1, B1 - B0 + 1) if two else (1, 1), -1.0e300)
    id1 = np.full((A1 - A0 + 1, B1 - B0 + 1) if two else (1, 1), -1, dtype=np.int64)
    # a ray anywhere in a cell is within (cell / 2)(|e_c| + |f_c|) of its centre line along
    # axis c: the blocker boxes grow by that (at most g), so the centre line meets them
    gx = 0.5 * cell * (abs(ex) + abs(fx))
    gy = 0.5 * cell * (abs(ey) + abs(fy))
    gz = 0.5 * cell * (abs(ez) + abs(fz))
    req = hide[i]
    # per tile (tile > 0) the lowest start of the queries over it that ask for i (1e300: none);
    # a blocker that ends, on every line of its tiles, no later than that changes no answer
    ta = (A1 - A0) // tile + 1 if tile > 0 else 1
    tb = (B1 - B0) // tile + 1 if tile > 0 else 1
    tmin = np.full((ta, tb), 1.0e300)
    if tile > 0:
        for t in range(nq):
            m = qidx[q0 + t] if listed else t
            if (vl[m, wi] >> bi) & np.uint64(1) == 0:
                continue
            rx, ry, rz = qxyz[m, 0] - lo[0], qxyz[m, 1] - lo[1], qxyz[m, 2] - lo[2]
            hx, hy, hz = qhalf[m, 0], qhalf[m, 1], qhalf[m, 2]
            pu, pv, ae, af, ia, ib, ja, jb, lxa, lxb, lya, lyb, lza, lzb = _span(rx, ry, rz, hx, hy, hz, geo, u0, cell,
                                                                                A0, A1, B0, B1)
            # the cell under the centre too (the fallback of a box no centre line crosses)
            ia = min(ia, max(A0, min(A1, int(np.floor((pu - u0) / cell)))))
            ib = max(ib, max(A0, min(A1, int(np.floor((pu - u0) / cell)))))
            ja = min(ja, max(B0, min(B1, int(np.floor((pv - u0) / cell)))))
            jb = max(jb, max(B0, min(B1, int(np.floor((pv - u0) / cell)))))
            # no line's start lies below the box's lowest point along n
            low = rx * nx + ry * ny + rz * nz - (hx * abs(nx) + hy * abs(ny) + hz * abs(nz))
            for p in range((ia - A0) // tile, (ib - A0) // tile + 1):
                for r in range((ja - B0) // tile, (jb - B0) // tile + 1):
                    if low < tmin[p, r]:
                        tmin[p, r] = low
    for m in range(nb + ms):
        # the back plane of a blocker piece: its exit on a line is no later than where the
        # line passes behind the piece's slab by as much as a ray of the cell can be off the
        # centre line along the piece's normal, s = k0 - uc ku - vc kv (none: k0 = inf)
        k0, ku, kv = 1.0e300, 0.0, 0.0
        if m < nb:
            if (blight[m, ow] >> ob) & np.uint64(1) == 0:
                continue
            cx, cy, cz = bxyz[m, 0], bxyz[m, 1], bxyz[m, 2]
            hx, hy, hz = bhalf[m, 0] + gx, bhalf[m, 1] + gy, bhalf[m, 2] + gz
            mx, my, mz = bplane[m, 3], bplane[m, 4], bplane[m, 5]
            nm = nx * mx + ny * my + nz * mz
            if nm < -1e-9 and bplane[m, 6] < 1.0e300:
                em = ex * mx + ey * my + ez * mz
                fm = fx * mx + fy * my + fz * mz
                k0 = ((bplane[m, 0] - lo[0]) * mx + (bplane[m, 1] - lo[1]) * my + (bplane[m, 2] - lo[2]) * mz
                      - bplane[m, 6] - 0.5 * cell * (abs(em) + abs(fm))) / nm
                ku = em / nm
                kv = fm / nm
            who = bvox[m]
        else:
            if (skin_mask[m - nb] & req) == req:
                continue
            cx, cy, cz = skin[m - nb, 0], skin[m - nb, 1], skin[m - nb, 2]
            hx, hy, hz = shalf[m - nb, 0], shalf[m - nb, 1], shalf[m - nb, 2]
            who = -2
        rx, ry, rz = cx - lo[0], cy - lo[1], cz - lo[2]
        pu, pv, ae, af, ia, ib, ja, jb, lxa, lxb, lya, lyb, lza, lzb = _span(rx, ry, rz, hx, hy, hz, geo, u0, cell,
                                                                            A0, A1, B0, B1)
        if tile > 0 and ia <= ib and ja <= jb:
            # its latest exit on any line: the far corner of the (grown) box along n
            top = rx * nx + ry * ny + rz * nz + hx * abs(nx) + hy * abs(ny) + hz * abs(nz)
            over = False
            for p in range((ia - A0) // tile, (ib - A0) // tile + 1):
                for r in range((ja - B0) // tile, (jb - B0) // tile + 1):
                    if tmin[p, r] < top:
                        over = True
                        break
                if over:
                    break
            if not over:
                continue
        wide = jb - ja > 8
        for a in range(ia, ib + 1):
            uc = u0 + (a + 0.5) * cell
            jl, jh, xa, xb, ya, yb, za, zb = _box_row(wide, uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza,
                                                      lzb, geo, u0, cell)
            ra = a - A0
            kr = k0 - uc * ku
            for b in range(jl, jh + 1):
                vc = u0 + (b + 0.5) * cell
                s0 = max(xa - vc * pfx, max(ya - vc * pfy, za - vc * pfz))
                s1 = min(xb - vc * pfx, min(yb - vc * pfy, min(zb - vc * pfz, kr - vc * kv)))
                if s0 >= s1:
                    continue
                rb = b - B0
                if not two:
                    if s1 > b1[ra, rb]:
                        b1[ra, rb] = s1
                elif s1 > b1[ra, rb]:
                    if id1[ra, rb] != who:
                        b2[ra, rb] = b1[ra, rb]
                    b1[ra, rb] = s1
                    id1[ra, rb] = who
                elif s1 > b2[ra, rb] and id1[ra, rb] != who:
                    b2[ra, rb] = s1
    eps = 1e-9 * d
    for t in range(nq):
        m = qidx[q0 + t] if listed else t
        if (vl[m, wi] >> bi) & np.uint64(1) == 0:
            out[i, m] = 0
            continue
        rx, ry, rz = qxyz[m, 0] - lo[0], qxyz[m, 1] - lo[1], qxyz[m, 2] - lo[2]
        hx, hy, hz = qhalf[m, 0], qhalf[m, 1], qhalf[m, 2]
        pu, pv, ae, af, ia, ib, ja, jb, lxa, lxb, lya, lyb, lza, lzb = _span(rx, ry, rz, hx, hy, hz, geo, u0, cell,
                                                                            A0, A1, B0, B1)
        # the patch's slab: on the line (uc, vc) no patch point lies below c0 - uc cu - vc cv
        mx, my, mz = pnrm[m, 0], pnrm[m, 1], pnrm[m, 2]
        nm = nx * mx + ny * my + nz * mz
        c0, cu, cv = -1.0e300, 0.0, 0.0
        if nm > 1e-9 and slab[m] < 1.0e300:
            c0 = ((ppt[m, 0] - lo[0]) * mx + (ppt[m, 1] - lo[1]) * my + (ppt[m, 2] - lo[2]) * mz - slab[m]) / nm
            cu = (ex * mx + ey * my + ez * mz) / nm
            cv = (fx * mx + fy * my + fz * mz) / nm
        ok = 1
        if strict:
            # every cell some line of which meets the box, from the lowest start a ray of the
            # cell from a patch point can have. Per axis c the line's entry into the box's slab
            # is linear in the line's place, so over the cell it is no lower than its value
            # at the centre less half a cell times its slopes; so is each entry less another
            # axis' exit (a line meets the box where every such difference is <= 0). The start:
            # the largest of those entry bounds, the box's lowest point along n and the slab's
            # lowest over the cell.
            low = rx * nx + ry * ny + rz * nz - (hx * abs(nx) + hy * abs(ny) + hz * abs(nz))
            sc = 0.5 * cell * (abs(cu) + abs(cv))
            pex, pey, pez = geo[9], geo[10], geo[11]
            gxh = 0.5 * cell * (abs(pex) + abs(pfx))
            gyh = 0.5 * cell * (abs(pey) + abs(pfy))
            gzh = 0.5 * cell * (abs(pez) + abs(pfz))
            dxy = 0.5 * cell * (abs(pex - pey) + abs(pfx - pfy))
            dxz = 0.5 * cell * (abs(pex - pez) + abs(pfx - pfz))
            dyz = 0.5 * cell * (abs(pey - pez) + abs(pfy - pfz))
            for a in range(ia, ib + 1):
                if ok == 0:
                    break
                uc = u0 + (a + 0.5) * cell
                xa, xb = lxa - uc * pex, lxb - uc * pex
                ya, yb = lya - uc * pey, lyb - uc * pey
                za, zb = lza - uc * pez, lzb - uc * pez
                cr = c0 - uc * cu - sc
                ra = a - A0
                for b in range(ja, jb + 1):
                    vc = u0 + (b + 0.5) * cell
                    ea, eb = xa - vc * pfx, xb - vc * pfx
                    fa, fb_ = ya - vc * pfy, yb - vc * pfy
                    ga, gb = za - vc * pfz, zb - vc * pfz
                    if (ea - fb_ > dxy or ea - gb > dxz or fa - eb > dxy or fa - gb > dyz or ga - eb > dxz
                            or ga - fb_ > dyz):
                        continue
                    if geo[18] and abs(uc * ex + vc * fx - rx) - 0.5 * cell * (abs(ex) + abs(fx)) > hx:
                        continue
                    if geo[19] and abs(uc * ey + vc * fy - ry) - 0.5 * cell * (abs(ey) + abs(fy)) > hy:
                        continue
                    if geo[20] and abs(uc * ez + vc * fz - rz) - 0.5 * cell * (abs(ez) + abs(fz)) > hz:
                        continue
                    s0 = max(max(low, cr - vc * cv), max(ea - gxh, max(fa - gyh, ga - gzh)))
                    rb = b - B0
                    top = b2[ra, rb] if two and id1[ra, rb] == qid[m] else b1[ra, rb]
                    if top > s0 + eps:
                        ok = 0
                        break
            out[i, m] = ok
            continue
        hits = 0
        for a in range(ia, ib + 1):
            if ok == 0:
                break
            uc = u0 + (a + 0.5) * cell
            jl, jh, xa, xb, ya, yb, za, zb = _row(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb,
                                                  geo, u0, cell)
            ra = a - A0
            cr = c0 - uc * cu
            for b in range(jl, jh + 1):
                vc = u0 + (b + 0.5) * cell
                s0 = max(xa - vc * pfx, max(ya - vc * pfy, za - vc * pfz))
                s1 = min(xb - vc * pfx, min(yb - vc * pfy, zb - vc * pfz))
                if s0 >= s1:
                    continue
                hits += 1
                s0 = max(s0, cr - vc * cv)
                rb = b - B0
                top = b2[ra, rb] if two and id1[ra, rb] == qid[m] else b1[ra, rb]
                if top > s0 + eps:
                    ok = 0
                    break
        if hits == 0:
            # a box thinner than the cell: no centre line crosses it; test the cell under
            # its centre from its nearest depth, or the slab's lowest start over the box's
            # footprint (the line is not where the patch is)
            a = min(A1, max(A0, int(np.floor((pu - u0) / cell))))
            b = min(B1, max(B0, int(np.floor((pv - u0) / cell))))
            s0 = rx * nx + ry * ny + rz * nz - (hx * abs(nx) + hy * abs(ny) + hz * abs(nz))
            s0 = max(s0, c0 - pu * cu - pv * cv - ae * abs(cu) - af * abs(cv))
            top = b2[a - A0, b - B0] if two and id1[a - A0, b - B0] == qid[m] else b1[a - A0, b - B0]
            if top > s0 + eps:
                ok = 0
        out[i, m] = ok
