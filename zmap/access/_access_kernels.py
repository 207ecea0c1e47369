"""Numba kernels of :mod:`zmap.access.voxelmap` (no validation, flat arrays only).

Voxel (i, j, l) covers ``origin + d * [i, i + 1) x [j, j + 1) x [l, l + 1)``; its centre is
``origin + d * (i + 0.5, ...)``. States: 0 exterior, 1 boundary, 2 interior, 3 not yet painted.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._direction_kernels import lookup_one

__all__ = ["accumulate", "paint_exterior", "cast_directions", "ball_neighbours", "local_conditions",
           "tool_kernel", "greedy_cover", "orientation_votes"]

EXTERIOR, BOUNDARY, INTERIOR, UNPAINTED = 0, 1, 2, 3


@njit(cache=True)
def accumulate(vox, pts, nrm, kmax, face, weight, centres, frames, q, hv, hl, exact, dirs,
               vl, light, curv, surf, crease, cos_crease, psum, nsum, area, nsamp, first, pmin, pmax):
    """Fold each sample into its boundary voxel: V' &= H_V(t), L' |= H_L(t), curvature, surface.

    ``vox[s]`` is the boundary voxel of sample s; ``exact`` = 1 replaces H_V / H_L of the tessel
    by the exact hemisphere of the sample's normal (bit i set where dirs[i] . n > 0).
    """
    W = vl.shape[1]
    k = dirs.shape[0]
    for s in range(vox.shape[0]):
        b = vox[s]
        nx, ny, nz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        if exact:
            for w in range(W):
                acc = np.uint64(0)
                for i in range(w * 64, min(k, w * 64 + 64)):
                    if dirs[i, 0] * nx + dirs[i, 1] * ny + dirs[i, 2] * nz > 0.0:
                        acc |= np.uint64(1) << np.uint64(i - w * 64)
                vl[b, w] &= acc
                light[b, w] |= acc
        else:
            t = lookup_one(nx, ny, nz, centres, frames, q)
            for w in range(W):
                vl[b, w] &= hv[t, w]
                light[b, w] |= hl[t, w]
        if kmax[s] > curv[b]:
            curv[b] = kmax[s]
        if nsamp[b] == 0:
            surf[b] = face[s]
            first[b, 0] = nx
            first[b, 1] = ny
            first[b, 2] = nz
        elif surf[b] != face[s]:
            surf[b] = -1
        if surf[b] == -1 and first[b, 0] * nx + first[b, 1] * ny + first[b, 2] * nz < cos_crease:
            crease[b] = 1
        nsamp[b] += 1
        for c in range(3):
            psum[b, c] += pts[s, c]
            if pts[s, c] < pmin[b, c]:
                pmin[b, c] = pts[s, c]
            if pts[s, c] > pmax[b, c]:
                pmax[b, c] = pts[s, c]
            nsum[b, c] += nrm[s, c]
        area[b] += weight[s]


@njit(cache=True)
def paint_exterior(state):
    """Paint spreading: every non-boundary voxel 6-connected to the grid's border is exterior;
    the rest of the non-boundary voxels are interior. Returns the number of exterior voxels."""
    nx, ny, nz = state.shape
    n = nx * ny * nz
    stack = np.empty(n, dtype=np.int64)
    top = 0
    for i in range(nx):
        for j in range(ny):
            for l in range(nz):
                if i == 0 or j == 0 or l == 0 or i == nx - 1 or j == ny - 1 or l == nz - 1:
                    if state[i, j, l] == UNPAINTED:
                        state[i, j, l] = EXTERIOR
                        stack[top] = (i * ny + j) * nz + l
                        top += 1
    painted = top
    while top > 0:
        top -= 1
        f = stack[top]
        l = f % nz
        j = (f // nz) % ny
        i = f // (ny * nz)
        for m in range(6):
            a, b, c = i, j, l
            if m == 0:
                a -= 1
            elif m == 1:
                a += 1
            elif m == 2:
                b -= 1
            elif m == 3:
                b += 1
            elif m == 4:
                c -= 1
            else:
                c += 1
            if a < 0 or b < 0 or c < 0 or a >= nx or b >= ny or c >= nz:
                continue
            if state[a, b, c] == UNPAINTED:
                state[a, b, c] = EXTERIOR
                stack[top] = (a * ny + b) * nz + c
                top += 1
                painted += 1
    for i in range(nx):
        for j in range(ny):
            for l in range(nz):
                if state[i, j, l] == UNPAINTED:
                    state[i, j, l] = INTERIOR
    return painted


@njit(cache=True)
def orientation_votes(pts, nrm, face, origin, d, state, out):
    """Per face, count samples whose normal points (one voxel away) into an exterior voxel
    (out[f, 0]) and into an interior one (out[f, 1])."""
    nx, ny, nz = state.shape
    for s in range(pts.shape[0]):
        for sign in range(2):
            fac = d if sign == 0 else -d
            x = (pts[s, 0] + fac * nrm[s, 0] - origin[0]) / d
            y = (pts[s, 1] + fac * nrm[s, 1] - origin[1]) / d
            z = (pts[s, 2] + fac * nrm[s, 2] - origin[2]) / d
            i, j, l = int(np.floor(x)), int(np.floor(y)), int(np.floor(z))
            if i < 0 or j < 0 or l < 0 or i >= nx or j >= ny or l >= nz:
                st = EXTERIOR
            else:
                st = state[i, j, l]
            if sign == 0:
                if st == EXTERIOR:
                    out[face[s], 0] += 1
                elif st == INTERIOR:
                    out[face[s], 1] += 1
            else:
                if st == INTERIOR:
                    out[face[s], 2] += 1
                elif st == EXTERIOR:
                    out[face[s], 3] += 1


@njit(cache=True, inline="always")
def _slab(bx, by, bz, nx, ny, nz, cx, cy, cz, hx, hy, hz):
    """Parameter interval [s0, s1] of the line base + s n inside the cube (centre c, half h);
    s0 > s1 when it misses."""
    s0 = -1.0e300
    s1 = 1.0e300
    for m in range(3):
        if m == 0:
            b, n, c, h = bx, nx, cx, hx
        elif m == 1:
            b, n, c, h = by, ny, cy, hy
        else:
            b, n, c, h = bz, nz, cz, hz
        if abs(n) < 1e-12:
            if abs(b - c) > h:
                return 1.0, -1.0
        else:
            a0 = (c - h - b) / n
            a1 = (c + h - b) / n
            if a0 > a1:
                a0, a1 = a1, a0
            if a0 > s0:
                s0 = a0
            if a1 < s1:
                s1 = a1
    return s0, s1


@njit(cache=True, inline="always")
def _basis(nx, ny, nz):
    # e1 perpendicular to n, e2 = n x e1
    if abs(nx) < 0.9:
        ax, ay, az = 1.0, 0.0, 0.0
    else:
        ax, ay, az = 0.0, 1.0, 0.0
    # e1 = a - (a.n) n, normalised
    dn = ax * nx + ay * ny + az * nz
    ex, ey, ez = ax - dn * nx, ay - dn * ny, az - dn * nz
    r = np.sqrt(ex * ex + ey * ey + ez * ez)
    ex, ey, ez = ex / r, ey / r, ez / r
    fx = ny * ez - nz * ey
    fy = nz * ex - nx * ez
    fz = nx * ey - ny * ex
    return ex, ey, ez, fx, fy, fz


@njit(cache=True, parallel=True)
def cast_directions(dirs, opp, bxyz, bhalf, skin, light, vl, d, cell, radius, lo, out):
    """Cylinder casting of paper 002 §4.5 for every direction at once, one depth buffer each.

    For direction n, the lines parallel to n through the cell centres of a plane grid of
    pitch ``cell`` stand for the cylinder's rays. Blockers are the interior skin voxels
    (cubes) and the boundary voxels w with -n in L'(w) (their surface boxes). Per line the
    buffer keeps the largest exit parameter of a blocker box (and the second largest with the
    blocker's number, to skip v itself). Voxel v keeps n when no line through its box meets
    a blocker box beyond v's entry. The boundary blockers' boxes are grown by half a cell
    diagonal, so that a true ray into a thin one still shows on the centre line of its cell;
    a box of v thinner than a cell that no centre line crosses is tested on the cell under its
    centre from its nearest depth. ``out[i, b]`` = 1 where direction i stays in V'_g(b); ``opp[i]`` is the
    index of -dirs[i].

    bxyz, bhalf : (mb, 3) centres and half extents of the boundary voxels' surface boxes;
    skin : (ms, 3) interior skin voxel centres (cubes of edge d);
    radius : half the diagonal of the part's box; lo : (3,) centre of the part's box.
    """
    k = dirs.shape[0]
    mb = bxyz.shape[0]
    ms = skin.shape[0]
    g = 0.5 * np.sqrt(2.0) * cell
    h = 0.5 * d
    u0 = -(radius + 2 * d)
    nc = int(np.ceil(2.0 * (radius + 2 * d) / cell)) + 1
    for i in prange(k):
        nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        ex, ey, ez, fx, fy, fz = _basis(nx, ny, nz)
        b1 = np.full((nc, nc), -1.0e300)
        b2 = np.full((nc, nc), -1.0e300)
        id1 = np.full((nc, nc), -1, dtype=np.int64)
        wi = i >> 6
        o = opp[i]
        ow = o >> 6
        ob = np.uint64(o & 63)
        for m in range(mb + ms):
            if m < mb:
                if (light[m, ow] >> ob) & np.uint64(1) == 0:
                    continue
                cx, cy, cz = bxyz[m, 0], bxyz[m, 1], bxyz[m, 2]
                hx, hy, hz = bhalf[m, 0] + g, bhalf[m, 1] + g, bhalf[m, 2] + g
            else:
                cx, cy, cz = skin[m - mb, 0], skin[m - mb, 1], skin[m - mb, 2]
                hx, hy, hz = h, h, h
            ae = hx * abs(ex) + hy * abs(ey) + hz * abs(ez)
            af = hx * abs(fx) + hy * abs(fy) + hz * abs(fz)
            rx, ry, rz = cx - lo[0], cy - lo[1], cz - lo[2]
            pu = rx * ex + ry * ey + rz * ez
            pv = rx * fx + ry * fy + rz * fz
            ia = max(0, int(np.floor((pu - ae - u0) / cell)))
            ib = min(nc - 1, int(np.floor((pu + ae - u0) / cell)))
            ja = max(0, int(np.floor((pv - af - u0) / cell)))
            jb = min(nc - 1, int(np.floor((pv + af - u0) / cell)))
            for a in range(ia, ib + 1):
                uc = u0 + (a + 0.5) * cell
                for b in range(ja, jb + 1):
                    vc = u0 + (b + 0.5) * cell
                    s0, s1 = _slab(uc * ex + vc * fx, uc * ey + vc * fy, uc * ez + vc * fz, nx, ny, nz,
                                   rx, ry, rz, hx, hy, hz)
                    if s0 >= s1:
                        continue
                    if s1 > b1[a, b]:
                        if id1[a, b] != m:
                            b2[a, b] = b1[a, b]
                        b1[a, b] = s1
                        id1[a, b] = m
                    elif s1 > b2[a, b] and id1[a, b] != m:
                        b2[a, b] = s1
        eps = 1e-9 * d
        for m in range(mb):
            if (vl[m, wi] >> np.uint64(i & 63)) & np.uint64(1) == 0:
                out[i, m] = 0
                continue
            rx, ry, rz = bxyz[m, 0] - lo[0], bxyz[m, 1] - lo[1], bxyz[m, 2] - lo[2]
            hx, hy, hz = bhalf[m, 0], bhalf[m, 1], bhalf[m, 2]
            ae = hx * abs(ex) + hy * abs(ey) + hz * abs(ez)
            af = hx * abs(fx) + hy * abs(fy) + hz * abs(fz)
            pu = rx * ex + ry * ey + rz * ez
            pv = rx * fx + ry * fy + rz * fz
            ia = max(0, int(np.floor((pu - ae - u0) / cell)))
            ib = min(nc - 1, int(np.floor((pu + ae - u0) / cell)))
            ja = max(0, int(np.floor((pv - af - u0) / cell)))
            jb = min(nc - 1, int(np.floor((pv + af - u0) / cell)))
            ok = 1
            hits = 0
            for a in range(ia, ib + 1):
                if ok == 0:
                    break
                uc = u0 + (a + 0.5) * cell
                for b in range(ja, jb + 1):
                    vc = u0 + (b + 0.5) * cell
                    s0, s1 = _slab(uc * ex + vc * fx, uc * ey + vc * fy, uc * ez + vc * fz, nx, ny, nz,
                                   rx, ry, rz, hx, hy, hz)
                    if s0 >= s1:
                        continue
                    hits += 1
                    top = b2[a, b] if id1[a, b] == m else b1[a, b]
                    if top > s0 + eps:
                        ok = 0
                        break
            if hits == 0:
                # a box thinner than the cell: no centre line crosses it; test the cell under
                # its centre from its nearest depth
                a = min(nc - 1, max(0, int(np.floor((pu - u0) / cell))))
                b = min(nc - 1, max(0, int(np.floor((pv - u0) / cell))))
                s0 = rx * nx + ry * ny + rz * nz - (hx * abs(nx) + hy * abs(ny) + hz * abs(nz))
                top = b2[a, b] if id1[a, b] == m else b1[a, b]
                if top > s0 + eps:
                    ok = 0
            out[i, m] = ok


@njit(cache=True)
def ball_neighbours(centre, origin, d, index, state, r_in, r_out, ptr, nb, inside):
    """Per boundary voxel b: the boundary voxels whose centres lie within [r_in, r_out] of the
    ball centre ``centre[b]`` (the shell the eraser's surface may meet: E(v) before the
    half-space test), as CSR (ptr, nb); ``inside[b]`` = 1 where a boundary or interior voxel
    centre lies closer than r_in (the ball would cut material). ``nb`` must be large enough;
    returns the number of entries written (or -1 when nb overflowed)."""
    nx, ny, nz = index.shape
    mb = centre.shape[0]
    reach = int(np.ceil(r_out / d)) + 1
    pos = 0
    for b in range(mb):
        ptr[b] = pos
        cx = (centre[b, 0] - origin[0]) / d - 0.5
        cy = (centre[b, 1] - origin[1]) / d - 0.5
        cz = (centre[b, 2] - origin[2]) / d - 0.5
        ic, jc, lc = int(np.round(cx)), int(np.round(cy)), int(np.round(cz))
        for i in range(max(0, ic - reach), min(nx, ic + reach + 1)):
            dx = (i - cx) * d
            for j in range(max(0, jc - reach), min(ny, jc + reach + 1)):
                dy = (j - cy) * d
                for l in range(max(0, lc - reach), min(nz, lc + reach + 1)):
                    st = state[i, j, l]
                    if st == EXTERIOR:
                        continue
                    dz = (l - cz) * d
                    r = np.sqrt(dx * dx + dy * dy + dz * dz)
                    if r < r_in:
                        inside[b] = 1
                    if st == BOUNDARY and r <= r_out:
                        if pos >= nb.shape[0]:
                            return -1
                        nb[pos] = index[i, j, l]
                        pos += 1
    ptr[mb] = pos
    return pos


@njit(cache=True, parallel=True)
def local_conditions(vg, bxyz, centre, ptr, nb, inside, bad, cap, centres, frames, q, out):
    """Conditions 1-3 of paper 002 §4.6 as bitsets, for all directions at once.

    w of the shell list of v belongs to E_n(v) unless n lies in ``cap[t]`` (t: the tessel of
    x_w - c_v), the directions for which w lies beyond the eraser's equator. So
    ``A(v) = V'_g(v) & AND_w (V'_g(w) | cap[t_w])`` with ``V'_g(w)`` replaced by nothing where
    w is bad (curvature above 1/a, crease); v itself must not be bad, and the ball must fit.
    """
    mb = bxyz.shape[0]
    W = vg.shape[1]
    for b in prange(mb):
        for w in range(W):
            out[b, w] = np.uint64(0) if (inside[b] or bad[b]) else vg[b, w]
        if inside[b] or bad[b]:
            continue
        cx, cy, cz = centre[b, 0], centre[b, 1], centre[b, 2]
        for e in range(ptr[b], ptr[b + 1]):
            m = nb[e]
            t = lookup_one(bxyz[m, 0] - cx, bxyz[m, 1] - cy, bxyz[m, 2] - cz, centres, frames, q)
            if bad[m]:
                for w in range(W):
                    out[b, w] &= cap[t, w]
            else:
                for w in range(W):
                    out[b, w] &= vg[m, w] | cap[t, w]


@njit(cache=True, inline="always")
def _rasterise_max(buf, u0, cell, pu, pv, ae, af, top):
    nc = buf.shape[0]
    ia = max(0, int(np.floor((pu - ae - u0) / cell)))
    ib = min(nc - 1, int(np.floor((pu + ae - u0) / cell)))
    ja = max(0, int(np.floor((pv - af - u0) / cell)))
    jb = min(nc - 1, int(np.floor((pv + af - u0) / cell)))
    for p in range(ia, ib + 1):
        for r in range(ja, jb + 1):
            if top > buf[p, r]:
                buf[p, r] = top


@njit(cache=True, inline="always")
def _disc_clear(buf, u0, cell, pu, pv, rr, h0):
    """True when no buffer cell meeting the disc (centre pu, pv, radius rr) is above h0."""
    nc = buf.shape[0]
    ia = max(0, int(np.floor((pu - rr - u0) / cell)))
    ib = min(nc - 1, int(np.floor((pu + rr - u0) / cell)))
    ja = max(0, int(np.floor((pv - rr - u0) / cell)))
    jb = min(nc - 1, int(np.floor((pv + rr - u0) / cell)))
    r2 = rr * rr
    for p in range(ia, ib + 1):
        ua = u0 + p * cell
        du = 0.0 if ua <= pu <= ua + cell else min(abs(ua - pu), abs(ua + cell - pu))
        for r in range(ja, jb + 1):
            va = u0 + r * cell
            dv = 0.0 if va <= pv <= va + cell else min(abs(va - pv), abs(va + cell - pv))
            if du * du + dv * dv >= r2:
                continue
            if buf[p, r] > h0:
                return False
    return True


@njit(cache=True, parallel=True)
def tool_kernel(dirs, local, centre, occ, ohalf, d, a, cell, cell_h, stick, holder_r, lo, radius, out):
    """Shank and holder cylinders: per direction, max-depth buffers of the occupied voxels
    (boundary sample boxes and interior skin cubes: footprint box and far end along n), at pitch
    ``cell`` for the shank (radius a, from the ball's centre up) and ``cell_h`` for the holder
    (radius holder_r, from ``stick`` above the ball's centre up; holder_r = 0: none).
    ``out[i, b]`` = 1 where direction i of ``local[b]`` survives."""
    k = dirs.shape[0]
    mb = centre.shape[0]
    h = 0.5 * d
    u0 = -(radius + 2 * d + holder_r + cell_h)
    nc = int(np.ceil(-2.0 * u0 / cell)) + 1
    nch = int(np.ceil(-2.0 * u0 / cell_h)) + 1
    for i in prange(k):
        nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        wi = i >> 6
        bit = np.uint64(i & 63)
        ex, ey, ez, fx, fy, fz = _basis(nx, ny, nz)
        buf = np.full((nc, nc), -1.0e300)
        bufh = np.full((nch, nch), -1.0e300)
        for m in range(occ.shape[0]):
            hx, hy, hz = ohalf[m, 0], ohalf[m, 1], ohalf[m, 2]
            ext = hx * abs(nx) + hy * abs(ny) + hz * abs(nz)
            ae = hx * abs(ex) + hy * abs(ey) + hz * abs(ez)
            af = hx * abs(fx) + hy * abs(fy) + hz * abs(fz)
            rx, ry, rz = occ[m, 0] - lo[0], occ[m, 1] - lo[1], occ[m, 2] - lo[2]
            pu = rx * ex + ry * ey + rz * ez
            pv = rx * fx + ry * fy + rz * fz
            top = rx * nx + ry * ny + rz * nz + ext
            _rasterise_max(buf, u0, cell, pu, pv, ae, af, top)
            if holder_r > 0:
                _rasterise_max(bufh, u0, cell_h, pu, pv, ae, af, top)
        for b in range(mb):
            out[i, b] = 0
            if (local[b, wi] >> bit) & np.uint64(1) == 0:
                continue
            rx, ry, rz = centre[b, 0] - lo[0], centre[b, 1] - lo[1], centre[b, 2] - lo[2]
            pu = rx * ex + ry * ey + rz * ez
            pv = rx * fx + ry * fy + rz * fz
            hc = rx * nx + ry * ny + rz * nz
            if not _disc_clear(buf, u0, cell, pu, pv, a, hc):
                continue
            if holder_r > 0 and not _disc_clear(bufh, u0, cell_h, pu, pv, holder_r, hc + stick):
                continue
            out[i, b] = 1


@njit(cache=True)
def greedy_cover(amap, area, cand, max_setups, chosen, gains):
    """Greedy set cover by area over bitsets: gains kept up to date by subtracting the voxels
    each choice covers. Returns the number chosen; ``chosen[s]`` the direction of set-up s and
    ``gains[s]`` the area it newly covered."""
    mb, W = amap.shape
    k = cand.shape[0]
    gain = np.zeros(k)
    left = np.zeros(mb, dtype=np.uint8)
    for b in range(mb):
        for i in range(k):
            if cand[i] and (amap[b, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                gain[i] += area[b]
                left[b] = 1
    n = 0
    while n < max_setups:
        j = -1
        best = 0.0
        for i in range(k):
            if gain[i] > best:
                best = gain[i]
                j = i
        if j < 0:
            break
        chosen[n] = j
        gains[n] = best
        n += 1
        for b in range(mb):
            if left[b] and (amap[b, j >> 6] >> np.uint64(j & 63)) & np.uint64(1):
                left[b] = 0
                for i in range(k):
                    if cand[i] and (amap[b, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                        gain[i] -= area[b]
        gain[j] = 0.0
    return n
