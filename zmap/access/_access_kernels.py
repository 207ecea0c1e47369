"""Numba kernels of :mod:`zmap.access.voxelmap` (no validation, flat arrays only).

Voxel (i, j, l) covers ``origin + d * [i, i + 1) x [j, j + 1) x [l, l + 1)``; its centre is
``origin + d * (i + 0.5, ...)``. States: 0 exterior, 1 boundary, 2 interior, 3 not yet painted.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._direction_kernels import lookup_one

__all__ = ["accumulate", "paint_exterior", "cast_directions", "ball_neighbours", "access_kernel",
           "orientation_votes"]

EXTERIOR, BOUNDARY, INTERIOR, UNPAINTED = 0, 1, 2, 3


@njit(cache=True)
def accumulate(vox, pts, nrm, kmax, face, weight, centres, frames, q, hv, hl, exact, dirs,
               vl, light, curv, surf, crease, cos_crease, psum, nsum, area, nsamp, first):
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
def _slab(bx, by, bz, nx, ny, nz, cx, cy, cz, h):
    """Parameter interval [s0, s1] of the line base + s n inside the cube (centre c, half h);
    s0 > s1 when it misses."""
    s0 = -1.0e300
    s1 = 1.0e300
    for m in range(3):
        if m == 0:
            b, n, c = bx, nx, cx
        elif m == 1:
            b, n, c = by, ny, cy
        else:
            b, n, c = bz, nz, cz
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
def cast_directions(dirs, opp, bxyz, skin, light, vl, d, cell, radius, lo, out):
    """Cylinder casting of paper 002 §4.5 for every direction at once, one depth buffer each.

    For direction n: the lines parallel to n through the cell centres of a plane grid (pitch
    ``cell``) are the cylinder's rays. Blockers are the interior skin voxels and the boundary
    voxels w with -n in L'(w); per line the buffer keeps the largest exit parameter of a
    blocker cube (and the second largest with the blocker's number, to skip v itself). Voxel v
    keeps n when no line through its cube meets a blocker cube ahead of v's entry.
    ``out[i, b]`` = 1 where direction i stays in V'_g(b); ``opp[i]`` is the index of -dirs[i].

    bxyz : (mb, 3) boundary voxel centres; skin : (ms, 3) interior skin voxel centres;
    radius : half the diagonal of the part's box (projected extents are within it);
    lo : (3,) centre of the part's box.
    """
    k = dirs.shape[0]
    mb = bxyz.shape[0]
    ms = skin.shape[0]
    h = 0.5 * d
    nc = int(np.ceil(2.0 * (radius + 2 * d) / cell)) + 1
    for i in prange(k):
        nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        ex, ey, ez, fx, fy, fz = _basis(nx, ny, nz)
        u0 = -(radius + 2 * d)
        b1 = np.full((nc, nc), -1.0e300)
        b2 = np.full((nc, nc), -1.0e300)
        id1 = np.full((nc, nc), -1, dtype=np.int64)
        ae = h * (abs(ex) + abs(ey) + abs(ez))
        af = h * (abs(fx) + abs(fy) + abs(fz))
        wi = i >> 6
        o = opp[i]
        ow = o >> 6
        ob = np.uint64(o & 63)
        for m in range(mb + ms):
            if m < mb:
                if (light[m, ow] >> ob) & np.uint64(1) == 0:
                    continue
                cx, cy, cz = bxyz[m, 0], bxyz[m, 1], bxyz[m, 2]
            else:
                cx, cy, cz = skin[m - mb, 0], skin[m - mb, 1], skin[m - mb, 2]
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
                    bx = uc * ex + vc * fx
                    by = uc * ey + vc * fy
                    bz = uc * ez + vc * fz
                    s0, s1 = _slab(bx, by, bz, nx, ny, nz, rx, ry, rz, h)
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
            pu = rx * ex + ry * ey + rz * ez
            pv = rx * fx + ry * fy + rz * fz
            ia = max(0, int(np.floor((pu - ae - u0) / cell)))
            ib = min(nc - 1, int(np.floor((pu + ae - u0) / cell)))
            ja = max(0, int(np.floor((pv - af - u0) / cell)))
            jb = min(nc - 1, int(np.floor((pv + af - u0) / cell)))
            ok = 1
            for a in range(ia, ib + 1):
                if ok == 0:
                    break
                uc = u0 + (a + 0.5) * cell
                for b in range(ja, jb + 1):
                    vc = u0 + (b + 0.5) * cell
                    bx = uc * ex + vc * fx
                    by = uc * ey + vc * fy
                    bz = uc * ez + vc * fz
                    s0, s1 = _slab(bx, by, bz, nx, ny, nz, rx, ry, rz, h)
                    if s0 >= s1:
                        continue
                    top = b2[a, b] if id1[a, b] == m else b1[a, b]
                    if top > s0 + eps:
                        ok = 0
                        break
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
def access_kernel(dirs, vg, bxyz, centre, ptr, nb, inside, curv, crease, kmax_ok, occ, d,
                  a, cell2, stick, holder_r, lo, radius, check_holder, out):
    """Accessibility map A' for a ball-end tool: per direction, the paper's three conditions
    over E_n(v) and the shank / holder cylinders against a max-depth buffer of the occupied
    (boundary and interior skin) voxels. ``out[i, b]`` = 1 where direction i is in A'(b)."""
    k = dirs.shape[0]
    mb = bxyz.shape[0]
    h = 0.5 * d
    hd = np.sqrt(3.0) * h
    u0 = -(radius + 2 * d + holder_r)
    nc = int(np.ceil(-2.0 * u0 / cell2)) + 1
    for i in prange(k):
        nx, ny, nz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        wi = i >> 6
        bit = np.uint64(i & 63)
        ex, ey, ez, fx, fy, fz = _basis(nx, ny, nz)
        buf = np.full((nc, nc), -1.0e300)
        ext = h * (abs(nx) + abs(ny) + abs(nz))
        ae = h * (abs(ex) + abs(ey) + abs(ez))
        af = h * (abs(fx) + abs(fy) + abs(fz))
        for m in range(occ.shape[0]):
            rx, ry, rz = occ[m, 0] - lo[0], occ[m, 1] - lo[1], occ[m, 2] - lo[2]
            pu = rx * ex + ry * ey + rz * ez
            pv = rx * fx + ry * fy + rz * fz
            top = rx * nx + ry * ny + rz * nz + ext
            ia = max(0, int(np.floor((pu - ae - u0) / cell2)))
            ib = min(nc - 1, int(np.floor((pu + ae - u0) / cell2)))
            ja = max(0, int(np.floor((pv - af - u0) / cell2)))
            jb = min(nc - 1, int(np.floor((pv + af - u0) / cell2)))
            for p in range(ia, ib + 1):
                for q in range(ja, jb + 1):
                    if top > buf[p, q]:
                        buf[p, q] = top
        for b in range(mb):
            out[i, b] = 0
            if inside[b] or (vg[b, wi] >> bit) & np.uint64(1) == 0:
                continue
            cx, cy, cz = centre[b, 0], centre[b, 1], centre[b, 2]
            ok = 1
            # conditions 1-3 over E_n(v): shell voxels on the eraser's lower side, and v
            for e in range(ptr[b], ptr[b + 1]):
                w = nb[e]
                if (bxyz[w, 0] - cx) * nx + (bxyz[w, 1] - cy) * ny + (bxyz[w, 2] - cz) * nz > hd:
                    continue
                if (vg[w, wi] >> bit) & np.uint64(1) == 0 or curv[w] > kmax_ok or crease[w]:
                    ok = 0
                    break
            if ok == 0 or curv[b] > kmax_ok or crease[b]:
                continue
            # shank (radius a, from the ball's centre up) and holder (radius holder_r, from
            # the stick-out up): no occupied voxel may reach above their bottoms
            rx, ry, rz = cx - lo[0], cy - lo[1], cz - lo[2]
            pu = rx * ex + ry * ey + rz * ez
            pv = rx * fx + ry * fy + rz * fz
            hc = rx * nx + ry * ny + rz * nz
            for stage in range(2):
                if stage == 0:
                    rr, h0 = a, hc
                else:
                    if check_holder == 0:
                        break
                    rr, h0 = holder_r, hc + stick
                ia = max(0, int(np.floor((pu - rr - u0) / cell2)))
                ib = min(nc - 1, int(np.floor((pu + rr - u0) / cell2)))
                ja = max(0, int(np.floor((pv - rr - u0) / cell2)))
                jb = min(nc - 1, int(np.floor((pv + rr - u0) / cell2)))
                for p in range(ia, ib + 1):
                    if ok == 0:
                        break
                    # nearest point of the cell to the axis, within the radius?
                    ua = u0 + p * cell2
                    du = 0.0 if ua <= pu <= ua + cell2 else min(abs(ua - pu), abs(ua + cell2 - pu))
                    for q in range(ja, jb + 1):
                        va = u0 + q * cell2
                        dv = 0.0 if va <= pv <= va + cell2 else min(abs(va - pv), abs(va + cell2 - pv))
                        if du * du + dv * dv >= rr * rr:
                            continue
                        if buf[p, q] > h0:
                            ok = 0
                            break
                if ok == 0:
                    break
            out[i, b] = ok
