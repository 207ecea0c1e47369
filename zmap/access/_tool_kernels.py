"""Numba kernels of the shank and holder tests (:mod:`zmap.access.tool`): per direction
max-depth buffers of the blockers' exits, dilated by disc max filters, then a disc test per
query; a plane face's own exits counted apart where its plane may rise into the cylinder
(no validation, flat arrays only).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._line_kernels import _box_row, _geometry, _span, _window

__all__ = ["disc_max", "tool_kernel"]


@njit(cache=True)
def _draw_exits(buf, A0, B0, geo, nx, ny, nz, u0, cell, rx, ry, rz, hx, hy, hz, plane, lo, two, fid, buf2, face):
    """Raise the window ``buf`` (grid cells A0.., B0..) to the latest exit, on any line of a
    cell along n, from a blocker: its box (centre r relative to the grid's origin, half
    extents h) grown by a ray's offset from the cell's centre line, as the casting draws it,
    and cut by its patch's slab (``plane``: mean point, unit normal m and half-thickness; inf:
    none): every patch point x has ``|(x - point) . m| <= slab``, so a line leaves the patch
    before it passes the slab's far side by more than the cell's offset along m.

    ``two``: also keep, per cell, the face of its top exit in ``fid`` and in ``buf2`` (both the
    shape of ``buf``) the top exit of the other faces (the blocker's face: ``face``)."""
    na, nb = buf.shape
    ex, ey, ez, fx, fy, fz = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    pfx, pfy, pfz = geo[12], geo[13], geo[14]
    hx += 0.5 * cell * (abs(ex) + abs(fx))
    hy += 0.5 * cell * (abs(ey) + abs(fy))
    hz += 0.5 * cell * (abs(ez) + abs(fz))
    pu, pv, ae, af, ia, ib, ja, jb, lxa, lxb, lya, lyb, lza, lzb = _span(rx, ry, rz, hx, hy, hz, geo, u0, cell,
                                                                        A0, A0 + na - 1, B0, B0 + nb - 1)
    # the slab's far side along the line, s = k0 - uc ku - vc kv (none: k0 = inf)
    k0, ku, kv = 1.0e300, 0.0, 0.0
    if plane[6] < 1.0e300:
        mx, my, mz = plane[3], plane[4], plane[5]
        nm = nx * mx + ny * my + nz * mz
        if abs(nm) > 1e-9:
            em = ex * mx + ey * my + ez * mz
            fm = fx * mx + fy * my + fz * mz
            off = plane[6] + 0.5 * cell * (abs(em) + abs(fm))
            pm = (plane[0] - lo[0]) * mx + (plane[1] - lo[1]) * my + (plane[2] - lo[2]) * mz
            k0 = (pm + off) / nm if nm > 0.0 else (pm - off) / nm
            ku = em / nm
            kv = fm / nm
    wide = jb - ja > 8
    for a in range(ia, ib + 1):
        uc = u0 + (a + 0.5) * cell
        jl, jh, xa, xb, ya, yb, za, zb = _box_row(wide, uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza,
                                                  lzb, geo, u0, cell)
        kr = k0 - uc * ku
        row = buf[a - A0]
        for b in range(jl, jh + 1):
            vc = u0 + (b + 0.5) * cell
            s0 = max(xa - vc * pfx, max(ya - vc * pfy, za - vc * pfz))
            s1 = min(xb - vc * pfx, min(yb - vc * pfy, min(zb - vc * pfz, kr - vc * kv)))
            if not s0 < s1:
                continue
            rb = b - B0
            if not two:
                if s1 > row[rb]:
                    row[rb] = s1
            elif s1 > row[rb]:
                if fid[a - A0, rb] != face:
                    buf2[a - A0, rb] = row[rb]
                row[rb] = s1
                fid[a - A0, rb] = face
            elif s1 > buf2[a - A0, rb] and fid[a - A0, rb] != face:
                buf2[a - A0, rb] = s1


@njit(cache=True)
def _linear_max_in(ua, va, cell, pu, pv, rr, k0, ku, kv):
    """The largest ``k0 - u ku - v kv`` over the cell [ua, ua + cell] x [va, va + cell] within
    the disc (centre pu, pv, radius rr): at the disc's own maximiser if the cell holds it, else
    at a cell corner inside the disc or where a cell edge crosses the circle (-1e300: none)."""
    gn = np.sqrt(ku * ku + kv * kv)
    if gn > 0.0:
        mu, mv = pu - rr * ku / gn, pv - rr * kv / gn
        if ua <= mu <= ua + cell and va <= mv <= va + cell:
            return k0 - mu * ku - mv * kv
    best = -1.0e300
    r2 = rr * rr
    for c in range(4):
        # corners, then the crossings of the edge u = const (c < 2) or v = const (c >= 2)
        cu = ua + (c & 1) * cell
        cv = va + (c >> 1) * cell
        if (cu - pu) * (cu - pu) + (cv - pv) * (cv - pv) <= r2:
            best = max(best, k0 - cu * ku - cv * kv)
        x = ua + (c & 1) * cell if c < 2 else va + (c & 1) * cell
        w = r2 - (x - (pu if c < 2 else pv)) ** 2
        if w < 0.0:
            continue
        for sg in (-1.0, 1.0):
            y = (pv if c < 2 else pu) + sg * np.sqrt(w)
            lo_, hi_ = (va, va + cell) if c < 2 else (ua, ua + cell)
            if lo_ <= y <= hi_:
                best = max(best, k0 - x * ku - y * kv if c < 2 else k0 - y * ku - x * kv)
    return best


@njit(cache=True)
def _disc_clear(buf, A0, B0, u0, cell, pu, pv, rr, h0, skip, fid, buf2, face, k0, ku, kv):
    """True when no buffer cell meeting the disc (centre pu, pv, radius rr) is above h0 (cells
    outside the window hold nothing). ``skip[|dp|]``: half-width of the columns around the
    centre's cell, in row dp from it, known to be at or below h0 (-1: none).

    ``face`` >= 0, a plane face whose exit on the line (u, v) is ``k0 - u ku - v kv``: a cell
    whose top exit is of that face (``fid``) counts the other faces' (``buf2``), and the face's
    own only as high as its plane rises over the part of the cell within the disc."""
    na, nb = buf.shape
    ia = max(A0, int(np.floor((pu - rr - u0) / cell)))
    ib = min(A0 + na - 1, int(np.floor((pu + rr - u0) / cell)))
    ja = max(B0, int(np.floor((pv - rr - u0) / cell)))
    jb = min(B0 + nb - 1, int(np.floor((pv + rr - u0) / cell)))
    pc = int(np.floor((pu - u0) / cell))
    rc = int(np.floor((pv - u0) / cell))
    r2 = rr * rr
    for p in range(ia, ib + 1):
        ua = u0 + p * cell
        du = 0.0 if ua <= pu <= ua + cell else min(abs(ua - pu), abs(ua + cell - pu))
        dp = abs(p - pc)
        w = skip[dp] if dp < skip.shape[0] else -1
        # the columns left and right of the skipped run
        for side in range(2):
            if w < 0:
                if side == 1:
                    break
                r0, r1 = ja, jb
            elif side == 0:
                r0, r1 = ja, min(jb, rc - w - 1)
            else:
                r0, r1 = max(ja, rc + w + 1), jb
            for r in range(r0, r1 + 1):
                va = u0 + r * cell
                dv = 0.0 if va <= pv <= va + cell else min(abs(va - pv), abs(va + cell - pv))
                if du * du + dv * dv >= r2:
                    continue
                z = buf[p - A0, r - B0]
                if z > h0 and face >= 0 and fid[p - A0, r - B0] == face:
                    z2 = buf2[p - A0, r - B0]
                    # the plane's highest corner over the cell first: below h0, the face's own
                    # exits in the cell do not count
                    if z2 <= h0 and (k0 - (ua if ku > 0.0 else ua + cell) * ku
                                     - (va if kv > 0.0 else va + cell) * kv) > h0:
                        z2 = min(z, _linear_max_in(ua, va, cell, pu, pv, rr, k0, ku, kv))
                    z = z2
                if z > h0:
                    return False
    return True


@njit(cache=True)
def _rows_max(H, widths, out):
    na, nb = out.shape
    R = widths.shape[0] - 1
    for p in range(na):
        o = out[p]
        o[:] = -1.0e300
        for dp in range(-R, R + 1):
            w = widths[abs(dp)]
            if w < 0 or p + dp < 0 or p + dp >= na:
                continue
            src_ = H[w, p + dp]
            for q in range(nb):
                if src_[q] > o[q]:
                    o[q] = src_[q]


@njit(cache=True)
def disc_max(buf, wa, wb, outa, outb):
    """outa[p, q] = max of buf over the cells (p + dp, q + dq) with |dq| <= wa[|dp|] (rows
    with width -1 or beyond the array hold none), clipped to the array; outb the same with wb.
    Row maxima of growing half-width, each from the last by one three-way max, then one max
    per row offset, all along contiguous rows: O(widths) per cell, shared by both filters."""
    na, nb = buf.shape
    W = max(0, max(wa.max(), wb.max()))
    H = np.empty((W + 1, na, nb))
    H[0] = buf
    for w in range(1, W + 1):
        for p in range(na):
            prev = H[w - 1, p]
            cur = H[w, p]
            if nb == 1:
                cur[0] = prev[0]
                continue
            cur[0] = max(prev[0], prev[1])
            for q in range(1, nb - 1):
                cur[q] = max(prev[q - 1], max(prev[q], prev[q + 1]))
            cur[nb - 1] = max(prev[nb - 2], prev[nb - 1])
    _rows_max(H, wa, outa)
    _rows_max(H, wb, outb)


@njit(cache=True)
def _disc_test(buf, up, lo_, A0, B0, u0, cell, pu, pv, rr, h0, skip, stats, fid, buf2, lo2, face, k0, ku, kv):
    """_disc_clear with two O(1) pre-tests: ``up`` (the max filter of buf over every cell a
    disc centred in the cell can meet) at or below h0: clear; ``lo_`` (the max filter over the
    cells every such disc meets) above h0: blocked. Otherwise the scan. A face query
    (``face`` >= 0) is blocked by ``lo2``, the second filter of ``buf2`` (a cell counts at least
    that for any face), and skips the columns ``lo_`` vouches for."""
    na, nb = buf.shape
    p = int(np.floor((pu - u0) / cell)) - A0
    r = int(np.floor((pv - u0) / cell)) - B0
    if 0 <= p < na and 0 <= r < nb:
        if up[p, r] <= h0:
            stats[0] += 1
            return True
        if (lo2[p, r] if face >= 0 else lo_[p, r]) > h0:
            stats[1] += 1
            return False
        stats[2] += 1
        return _disc_clear(buf, A0, B0, u0, cell, pu, pv, rr, h0, skip if lo_[p, r] <= h0 else skip[:0], fid, buf2,
                           face, k0, ku, kv)
    stats[2] += 1
    return _disc_clear(buf, A0, B0, u0, cell, pu, pv, rr, h0, skip[:0], fid, buf2, face, k0, ku, kv)


@njit(cache=True)
def _block_max(buf, A0, B0, hm, bufh, H0, G0):
    """Raise ``bufh`` (cells H0.., G0.. of pitch hm times buf's) to the max of buf's cells
    (A0.., B0..) in each of its cells."""
    na, nb = buf.shape
    nh, ng = bufh.shape
    for p in range(na):
        P = (A0 + p) // hm - H0
        if P < 0 or P >= nh:
            continue
        row = buf[p]
        for q in range(nb):
            z = row[q]
            if z > -1.0e300:
                Q = (B0 + q) // hm - G0
                if 0 <= Q < ng and z > bufh[P, Q]:
                    bufh[P, Q] = z


@njit(cache=True)
def _block_max_faces(buf, fid, buf2, A0, B0, hm, bufh, fidh, bufh2, H0, G0):
    """:func:`_block_max` of the faces' top-two buffers: per coarse cell the top exit of its
    fine cells with its face, then the top of the other faces': per fine cell, its second
    where its top is of that face, else its top."""
    na, nb = buf.shape
    nh, ng = bufh.shape
    for rnd in range(2):
        for p in range(na):
            P = (A0 + p) // hm - H0
            if P < 0 or P >= nh:
                continue
            for q in range(nb):
                z = buf[p, q]
                if z <= -1.0e300:
                    continue
                Q = (B0 + q) // hm - G0
                if Q < 0 or Q >= ng:
                    continue
                if rnd == 0:
                    if z > bufh[P, Q]:
                        bufh[P, Q] = z
                        fidh[P, Q] = fid[p, q]
                else:
                    if fid[p, q] == fidh[P, Q]:
                        z = buf2[p, q]
                    if z > bufh2[P, Q]:
                        bufh2[P, Q] = z


@njit(cache=True)
def _own_plane(b, qpoint, qnormal, lo, geo, nx, ny, nz, d, a, cell, cell_h, stick, holder_r):
    """Query b on a plane face, direction n: ``(mode, k0, ku, kv)``, the face's exit on the line
    (u, v), ``k0 - u ku - v kv`` (its plane through the voxel's mean point, raised by 1e-6 d for
    the normals' rounding), and in ``mode`` bit 1 (bit 2) where the plane may rise above the
    shank's (holder's) start within the cells its disc meets: on the line under the ball's
    centre it lies a / (n . m) below, and it rises by at most its slope g times the disc's
    radius plus 1.5 cells (a cell's reach past the disc and a drawn exit's offset within its
    cell; for the holder, a shank cell more), with 0.01 d to spare. Neither bit: the face's
    blockers stay below the start there, so counting them as any other's gives the same bit.
    The tilt within 0.06 degrees of 90 (n . m <= 1e-3): 0 (counted, conservative)."""
    mx, my, mz = qnormal[b, 0], qnormal[b, 1], qnormal[b, 2]
    nm = nx * mx + ny * my + nz * mz
    if not nm > 1e-3:
        return 0, 0.0, 0.0, 0.0
    k0 = ((qpoint[b, 0] - lo[0]) * mx + (qpoint[b, 1] - lo[1]) * my + (qpoint[b, 2] - lo[2]) * mz + 1e-6 * d) / nm
    ku = (geo[0] * mx + geo[1] * my + geo[2] * mz) / nm
    kv = (geo[3] * mx + geo[4] * my + geo[5] * mz) / nm
    g = np.sqrt(ku * ku + kv * kv)
    drop = a / nm  # the plane under the ball's centre, below it along n
    mode = 0
    if (a + 1.5 * cell) * g > drop - 0.01 * d:
        mode |= 1
    if holder_r > 0 and (holder_r + 1.5 * cell_h + cell) * g > drop + stick - 0.01 * d:
        mode |= 2
    return mode, k0, ku, kv


@njit(cache=True, parallel=True)
def tool_kernel(dirs, local, centre, qpoint, qnormal, occ, ohalf, oplane, oface, qface, d, a, cell, cell_h, hm, stick, holder_r, lo, radius,
                up_r, low_r, up_h, low_h, out, stats):
    """Shank and holder cylinders: per direction, max-depth buffers of the blockers (the
    casting's boxes with their patches' slabs ``oplane``, and, if given, interior skin cubes
    with slab inf): per cell the latest exit along n of any line of the cell
    (:func:`_draw_exits`), at pitch ``cell`` for the shank (radius a, from the ball's centre up)
    and ``cell_h`` for the holder (radius holder_r, from ``stick`` above the ball's centre up;
    holder_r = 0: none). ``out[i, b]`` = 1 where direction i of ``local[b]`` survives.

    Each buffer is dilated once per direction by two max filters (:func:`disc_max`, with the
    half-widths per row offset ``up_r`` / ``low_r`` for the shank, ``up_h`` / ``low_h`` for the
    holder): over every cell a disc centred in a cell can meet (at or below the cylinder's
    start: clear), and over the cells every such disc meets (above it: blocked). Only the pairs
    in between scan the disc's cells (less those the second filter vouched for), so the bits
    are those of the plain disc scan. ``stats`` (k, 3): pairs decided
    clear, blocked and scanned, per direction (shank and holder tests together).

    ``hm`` > 0: ``cell_h`` is ``hm`` (a power of two) times ``cell`` on the same origin, and the
    holder's buffer is the shank's maximum over blocks of hm x hm cells (every line of a coarse
    cell is a line of one of its fine cells, whose exits bound it: ``floor(floor(t) / hm) =
    floor(t / hm)``, and the division by a power of two rounds alike), instead of drawing every
    box again (which, grown by the coarse cell, would give as much or more).
    """
    k = dirs.shape[0]
    mb = centre.shape[0]
    u0 = -(radius + 2 * d + holder_r + cell_h)
    nc = int(np.ceil(-2.0 * u0 / cell)) + 1
    nch = int(np.ceil(-2.0 * u0 / cell_h)) + 1
    # the box of the occupied voxels and of the ball centres, relative to lo
    cmin = np.full(3, 1.0e300)
    cmax = np.full(3, -1.0e300)
    for m in range(occ.shape[0]):
        for c in range(3):
            cmin[c] = min(cmin[c], occ[m, c] - ohalf[m, c] - lo[c])
            cmax[c] = max(cmax[c], occ[m, c] + ohalf[m, c] - lo[c])
    for m in range(mb):
        for c in range(3):
            cmin[c] = min(cmin[c], centre[m, c] - lo[c])
            cmax[c] = max(cmax[c], centre[m, c] - lo[c])
    for i in prange(k):  # the body is a call: parfor lowering of a big body compiles for minutes
        _tool_one(i, dirs, local, centre, qpoint, qnormal, occ, ohalf, oplane, oface, qface, d, a, cell, cell_h, hm, stick, holder_r, lo, up_r, low_r,
                  up_h, low_h, u0, nc, nch, cmin, cmax, out, stats)


@njit(cache=True)
def _tool_one(i, dirs, local, centre, qpoint, qnormal, occ, ohalf, oplane, oface, qface, d, a, cell, cell_h, hm, stick, holder_r, lo, up_r, low_r, up_h,
              low_h, u0, nc, nch, cmin, cmax, out, stats):
    """Direction i of :func:`tool_kernel`: its shank and holder buffers, then ``out[i, :]``."""
    mb = centre.shape[0]
    nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
    wi = i >> 6
    bit = np.uint64(i & 63)
    geo = _geometry(nx, ny, nz)
    ex, ey, ez, fx, fy, fz = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    # the boxes grow by at most a cell: the windows hold every cell a grown box reaches
    A0, A1, B0, B1 = _window(cmin, cmax, ex, ey, ez, fx, fy, fz, d + cell, u0, cell, nc)
    H0, H1, G0, G1 = _window(cmin, cmax, ex, ey, ez, fx, fy, fz, d + cell_h, u0, cell_h, nch)
    buf = np.full((A1 - A0 + 1, B1 - B0 + 1), -1.0e300)
    bufh = np.full((H1 - H0 + 1, G1 - G0 + 1) if holder_r > 0 else (1, 1), -1.0e300)
    # the faces' top-two bookkeeping only where a query of a plane face asks for i with its
    # plane rising above the shank's or the holder's start within its disc's cells
    two = False
    for b in range(mb):
        if qface[b] >= 0 and (local[b, wi] >> bit) & np.uint64(1):
            mode, k0, ku, kv = _own_plane(b, qpoint, qnormal, lo, geo, nx, ny, nz, d, a, cell, cell_h, stick,
                                          holder_r)
            if mode:
                two = True
                break
    fid = np.full(buf.shape if two else (1, 1), -1, dtype=np.int64)
    buf2 = np.full(buf.shape if two else (1, 1), -1.0e300)
    twoh = two and holder_r > 0
    fidh = np.full(bufh.shape if twoh else (1, 1), -1, dtype=np.int64)
    bufh2 = np.full(bufh.shape if twoh else (1, 1), -1.0e300)
    for m in range(occ.shape[0]):
        rx, ry, rz = occ[m, 0] - lo[0], occ[m, 1] - lo[1], occ[m, 2] - lo[2]
        _draw_exits(buf, A0, B0, geo, nx, ny, nz, u0, cell, rx, ry, rz, ohalf[m, 0], ohalf[m, 1], ohalf[m, 2],
                    oplane[m], lo, two, fid, buf2, oface[m])
        if holder_r > 0 and hm <= 0:
            _draw_exits(bufh, H0, G0, geo, nx, ny, nz, u0, cell_h, rx, ry, rz, ohalf[m, 0], ohalf[m, 1],
                        ohalf[m, 2], oplane[m], lo, twoh, fidh, bufh2, oface[m])
    if holder_r > 0 and hm > 0:
        if twoh:
            _block_max_faces(buf, fid, buf2, A0, B0, hm, bufh, fidh, bufh2, H0, G0)
        else:
            _block_max(buf, A0, B0, hm, bufh, H0, G0)
    up = np.empty_like(buf)
    low = np.empty_like(buf)
    disc_max(buf, up_r, low_r, up, low)
    up2 = np.empty_like(buf2)
    low2 = np.empty_like(buf2)
    if two:
        disc_max(buf2, up_r, low_r, up2, low2)
    uph = np.empty_like(bufh)
    lowh = np.empty_like(bufh)
    if holder_r > 0:
        disc_max(bufh, up_h, low_h, uph, lowh)
    uph2 = np.empty_like(bufh2)
    lowh2 = np.empty_like(bufh2)
    if twoh:
        disc_max(bufh2, up_h, low_h, uph2, lowh2)
    st = np.zeros(3, dtype=np.int64)
    for b in range(mb):
        out[i, b] = 0
        if (local[b, wi] >> bit) & np.uint64(1) == 0:
            continue
        rx, ry, rz = centre[b, 0] - lo[0], centre[b, 1] - lo[1], centre[b, 2] - lo[2]
        pu = rx * ex + ry * ey + rz * ez
        pv = rx * fx + ry * fy + rz * fz
        hc = rx * nx + ry * ny + rz * nz
        mode, k0, ku, kv = 0, 0.0, 0.0, 0.0
        if two and qface[b] >= 0:
            mode, k0, ku, kv = _own_plane(b, qpoint, qnormal, lo, geo, nx, ny, nz, d, a, cell, cell_h, stick,
                                          holder_r)
        if not _disc_test(buf, up, low, A0, B0, u0, cell, pu, pv, a, hc, low_r, st, fid, buf2, low2,
                          qface[b] if mode & 1 else -1, k0, ku, kv):
            continue
        if holder_r > 0 and not _disc_test(bufh, uph, lowh, H0, G0, u0, cell_h, pu, pv, holder_r, hc + stick,
                                           low_h, st, fidh, bufh2, lowh2, qface[b] if mode & 2 else -1, k0, ku, kv):
            continue
        out[i, b] = 1
    for c in range(3):
        stats[i, c] = st[c]
