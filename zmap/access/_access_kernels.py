"""Numba kernels of :mod:`zmap.access.voxelmap` (no validation, flat arrays only).

Voxel (i, j, l) covers ``origin + d * [i, i + 1) x [j, j + 1) x [l, l + 1)``; its centre is
``origin + d * (i + 0.5, ...)``. States: 0 exterior, 1 boundary, 2 interior, 3 not yet painted.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._direction_kernels import above_words, lookup_one

__all__ = ["ball_fits", "accumulate", "paint_exterior", "skin_masks", "merge_runs", "self_blocking", "run_members", "pack_columns", "row_hash", "patch_slab", "piece_accumulate", "cast_directions", "dilate_bits", "bit_lists",
           "ball_conditions", "disc_max", "tool_kernel", "greedy_cover", "orientation_votes"]

EXTERIOR, BOUNDARY, INTERIOR, UNPAINTED = 0, 1, 2, 3


@njit(cache=True)
def _hemisphere(dirs, nx, ny, nz, words, last):
    """The bitset of the directions strictly above the plane of normal n (bit i set where
    dirs[i] . n > 0) in ``words``, made again only when n leaves the margin of the normal it
    was made for. ``last`` holds that normal and its margin min_i |dirs[i] . n| (start: NaN,
    NaN, NaN, -1): a normal within the margin, less 1e-12 of rounding, sets the same bits,
    since no dot product can change sign. A planar face's samples, and neighbours on a curved
    one, so cost a fraction of the k dot products each."""
    dx, dy, dz = nx - last[0], ny - last[1], nz - last[2]
    if math.sqrt(dx * dx + dy * dy + dz * dz) + 1e-12 < last[3]:
        return
    margin = above_words(dirs, nx, ny, nz, 0.0, words)
    last[0], last[1], last[2], last[3] = nx, ny, nz, margin


@njit(cache=True)
def accumulate(vox, pts, nrm, kmax, face, weight, centres, frames, q, hv, hl, exact, dirs,
               vl, light, curv, surf, crease, cos_crease, psum, nsum, area, nsamp, first, pmin, pmax):
    """Fold each sample into its boundary voxel: V' &= H_V(t), L' |= H_L(t), curvature, surface.

    ``vox[s]`` is the boundary voxel of sample s; ``exact`` = 1 replaces H_V / H_L of the tessel
    by the exact hemisphere of the sample's normal (bit i set where dirs[i] . n > 0); 2 leaves
    ``vl`` and ``light`` alone (the caller folds them from the half-voxel pieces').
    """
    W = vl.shape[1]
    words = np.zeros(W, dtype=np.uint64)  # the last hemisphere made (:func:`_hemisphere`)
    last = np.array([np.nan, np.nan, np.nan, -1.0])
    for s in range(vox.shape[0]):
        b = vox[s]
        nx, ny, nz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        if exact == 2:  # the caller folds the bitsets itself
            pass
        elif exact:
            _hemisphere(dirs, nx, ny, nz, words, last)
            for w in range(W):
                vl[b, w] &= words[w]
                light[b, w] |= words[w]
        else:
            t = lookup_one(nx, ny, nz, centres, frames, q)
            for w in range(W):
                if t < 0:  # a sample without a normal: nothing is known visible (conservative)
                    vl[b, w] = np.uint64(0)
                else:
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


@njit(cache=True)
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


@njit(cache=True)
def skin_masks(state, ijk, out):
    """Per skin voxel, a 27-bit mask of its interior neighbours: bit ``(dx+1)*9 + (dy+1)*3 + (dz+1)``
    is set where voxel (i+dx, j+dy, l+dz) is interior."""
    nx, ny, nz = state.shape
    for s in range(ijk.shape[0]):
        i, j, l = ijk[s, 0], ijk[s, 1], ijk[s, 2]
        m = np.int64(0)
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    a, b, c = i + dx, j + dy, l + dz
                    if 0 <= a < nx and 0 <= b < ny and 0 <= c < nz and state[a, b, c] == INTERIOR:
                        m |= np.int64(1) << np.int64((dx + 1) * 9 + (dy + 1) * 3 + (dz + 1))
        out[s] = m


@njit(cache=True)
def merge_runs(code, out):
    """Greedy boxes of equal codes: every voxel with ``code > 0`` lies in exactly one box of
    voxels that all hold its code. Boxes grow along the last axis first, then the middle,
    then the first (the voxels' order of :func:`numpy.argwhere`). ``out`` (n, 7) gets rows
    ``(i0, j0, l0, i1, j1, l1, code)`` (inclusive ends); returns the number of boxes.

    The skin cubes of a face's layer share their neighbour mask, so they merge into a few
    boxes: a line meets the union of the cubes exactly where it meets the box, and leaves it
    at the largest of their exits, so a depth buffer drawn from the boxes holds the values
    drawn from the cubes, for a fraction of the cells visited."""
    ni, nj, nl = code.shape
    used = np.zeros(code.shape, dtype=np.uint8)
    nb = 0
    for i in range(ni):
        for j in range(nj):
            for l in range(nl):
                c = code[i, j, l]
                if c <= 0 or used[i, j, l]:
                    continue
                l1 = l
                while l1 + 1 < nl and code[i, j, l1 + 1] == c and not used[i, j, l1 + 1]:
                    l1 += 1
                j1 = j
                while j1 + 1 < nj:
                    ok = True
                    for ll in range(l, l1 + 1):
                        if code[i, j1 + 1, ll] != c or used[i, j1 + 1, ll]:
                            ok = False
                            break
                    if not ok:
                        break
                    j1 += 1
                i1 = i
                while i1 + 1 < ni:
                    ok = True
                    for jj in range(j, j1 + 1):
                        for ll in range(l, l1 + 1):
                            if code[i1 + 1, jj, ll] != c or used[i1 + 1, jj, ll]:
                                ok = False
                                break
                        if not ok:
                            break
                    if not ok:
                        break
                    i1 += 1
                used[i:i1 + 1, j:j1 + 1, l:l1 + 1] = 1
                out[nb, 0], out[nb, 1], out[nb, 2] = i, j, l
                out[nb, 3], out[nb, 4], out[nb, 5] = i1, j1, l1
                out[nb, 6] = c
                nb += 1
    return nb


@njit(cache=True)
def self_blocking(vl, light, opp, out):
    """out[m] = 1 where some direction i is in vl[m] and opp[i] in light[m] (bitsets)."""
    k = opp.shape[0]
    for m in range(vl.shape[0]):
        out[m] = 0
        for i in range(k):
            if (vl[m, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                o = opp[i]
                if (light[m, o >> 6] >> np.uint64(o & 63)) & np.uint64(1):
                    out[m] = 1
                    break


@njit(cache=True)
def run_members(runs, first, ax, lo, hi, offset, slab, mlo, mhi, mslab):
    """Per run of :func:`merge_runs` over blockers (``first``: the blocker of each voxel):
    the union of its members' extents along their axis, and the slab that reaches as low as
    the lowest of theirs, measured from the plane offset of the run's first member."""
    for r in range(runs.shape[0]):
        a = ax[first[runs[r, 0], runs[r, 1], runs[r, 2]]]
        ref = offset[first[runs[r, 0], runs[r, 1], runs[r, 2]]]
        lo_ = 1.0e300
        hi_ = -1.0e300
        low = 1.0e300
        for i in range(runs[r, 0], runs[r, 3] + 1):
            for j in range(runs[r, 1], runs[r, 4] + 1):
                for l in range(runs[r, 2], runs[r, 5] + 1):
                    m = first[i, j, l]
                    lo_ = min(lo_, lo[m, a])
                    hi_ = max(hi_, hi[m, a])
                    low = min(low, offset[m] - slab[m])
        mlo[r, a] = lo_
        mhi[r, a] = hi_
        mslab[r] = ref - low


@njit(cache=True, parallel=True)
def pack_columns(out, bits):
    """bits[m] (words) = the bitset of column m of ``out`` (k, mb) uint8 (bit i: out[i, m] != 0):
    blocks of 64 columns per thread, each reading its stretch of every row."""
    k, m = out.shape
    for bl in prange((m + 63) // 64):
        m0 = bl * 64
        m1 = min(m, m0 + 64)
        for mm in range(m0, m1):
            for w in range(bits.shape[1]):
                bits[mm, w] = np.uint64(0)
        for i in range(k):
            w = i >> 6
            bit = np.uint64(1) << np.uint64(i & 63)
            for mm in range(m0, m1):
                if out[i, mm]:
                    bits[mm, w] |= bit


@njit(cache=True)
def row_hash(key, out):
    """out[r] = a 64-bit FNV-1a hash of row r of ``key`` (int64): rows equal, hashes equal."""
    for r in range(key.shape[0]):
        h = np.uint64(14695981039346656037)
        for c in range(key.shape[1]):
            x = np.uint64(key[r, c])
            for b in range(8):
                h ^= (x >> np.uint64(8 * b)) & np.uint64(255)
                h *= np.uint64(1099511628211)
        out[r] = h


@njit(cache=True)
def _line_setup(n, e, f):
    """Per axis c of direction n: (zero, 1/n_c, e_c/n_c, f_c/n_c, sign n_c)."""
    z = abs(n) < 1e-12
    if z:
        return True, 0.0, 0.0, 0.0, 1.0
    inv = 1.0 / n
    return False, inv, e * inv, f * inv, 1.0 if n > 0 else -1.0


@njit(cache=True)
def _zin(uc, vc, e, f, r, h):
    # the slab test of an axis the line runs parallel to: it misses when |base - centre| > h
    return not (abs(uc * e + vc * f - r) > h)


@njit(cache=True)
def _zcols(uc, e, f, r, h, u0, cell, jlo, jhi):
    """Columns b in [jlo, jhi] whose line (uc, vc_b) passes the slab test of an axis it runs
    parallel to: a range found in closed form, its ends fixed with the exact test."""
    if abs(f) < 1e-300:
        if _zin(uc, 0.0, e, 0.0, r, h):
            return jlo, jhi
        return 1, 0
    w = uc * e - r
    va = (-h - w) / f
    vb = (h - w) / f
    if va > vb:
        va, vb = vb, va
    lo = max(jlo, int(np.ceil((va - u0) / cell - 0.5)) - 1)
    hi = min(jhi, int(np.floor((vb - u0) / cell - 0.5)) + 1)
    while lo <= hi and not _zin(uc, u0 + (lo + 0.5) * cell, e, f, r, h):
        lo += 1
    while hi >= lo and not _zin(uc, u0 + (hi + 0.5) * cell, e, f, r, h):
        hi -= 1
    return lo, hi


@njit(cache=True)
def piece_accumulate(piece, pts, nrm, centres, frames, q, hv, hl, exact, dirs, vl, light, psum, nsum, pmin, pmax):
    """Fold samples into pieces (one face's samples in one voxel): V'_l (AND) and L' (OR) of
    each sample's exact hemisphere, or of H_V / H_L of its tessel, as :func:`accumulate` does
    for voxels (``exact`` = 2: neither); point and normal sums, samples' box."""
    W = light.shape[1]
    words = np.zeros(W, dtype=np.uint64)  # the last hemisphere made (:func:`_hemisphere`)
    last = np.array([np.nan, np.nan, np.nan, -1.0])
    for s in range(piece.shape[0]):
        p = piece[s]
        nx, ny, nz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        if exact == 2:  # the caller folds the bitsets itself
            pass
        elif exact:
            _hemisphere(dirs, nx, ny, nz, words, last)
            for w in range(W):
                vl[p, w] &= words[w]
                light[p, w] |= words[w]
        else:
            t = lookup_one(nx, ny, nz, centres, frames, q)
            for w in range(W):
                if t < 0:  # a sample without a normal: nothing is known visible (conservative)
                    vl[p, w] = np.uint64(0)
                else:
                    vl[p, w] &= hv[t, w]
                    light[p, w] |= hl[t, w]
        for c in range(3):
            psum[p, c] += pts[s, c]
            nsum[p, c] += nrm[s, c]
            pmin[p, c] = min(pmin[p, c], pts[s, c])
            pmax[p, c] = max(pmax[p, c], pts[s, c])


@njit(cache=True)
def patch_slab(vox, pts, nrm, point, normal, step, slab, grow):
    """Bounds of each boundary voxel's surface patch from its samples.

    ``slab[b]``: half-thickness of the patch about the plane through ``point[b]`` with normal
    ``normal[b]``: the samples' largest distance from it, plus 2 d' (``step``) times the
    largest sine s_b between a sample's normal and ``normal[b]`` (the patch runs on up to d'
    past its outer samples, turning at most as much again), so that every patch point x has
    ``(x - point[b]) . normal[b] >= -slab[b]``. ``grow[b, c]``: how far the patch can reach
    along axis c past its samples' box, ``d' min(1, t_c + s_b)``, t_c the largest
    ``sqrt(1 - n_c^2)`` of its samples' normals (a move of d' along the surface changes
    coordinate c by at most d' times that): 1e-6 d' across a flat face square to an axis.
    Where b has no mean normal: slab inf, grow d'.
    """
    mb = point.shape[0]
    dev = np.zeros(mb)
    sn = np.zeros(mb)
    tang = np.zeros((mb, 3))
    for s in range(vox.shape[0]):
        b = vox[s]
        mx, my, mz = normal[b, 0], normal[b, 1], normal[b, 2]
        t = abs((pts[s, 0] - point[b, 0]) * mx + (pts[s, 1] - point[b, 1]) * my + (pts[s, 2] - point[b, 2]) * mz)
        if t > dev[b]:
            dev[b] = t
        ux, uy, uz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        cx = uy * mz - uz * my
        cy = uz * mx - ux * mz
        cz = ux * my - uy * mx
        c = np.sqrt(cx * cx + cy * cy + cz * cz)
        if c > sn[b]:
            sn[b] = c
        # sqrt(1 - n_c^2) from the other two components: exactly 0 on an axis
        tx = np.sqrt(uy * uy + uz * uz)
        ty = np.sqrt(ux * ux + uz * uz)
        tz = np.sqrt(ux * ux + uy * uy)
        tang[b, 0] = max(tang[b, 0], tx)
        tang[b, 1] = max(tang[b, 1], ty)
        tang[b, 2] = max(tang[b, 2], tz)
    for b in range(mb):
        if normal[b, 0] == 0.0 and normal[b, 1] == 0.0 and normal[b, 2] == 0.0:
            slab[b] = np.inf
            for c in range(3):
                grow[b, c] = step
        else:
            slab[b] = dev[b] + 2.0 * step * sn[b]
            for c in range(3):
                # never flat: the casting's lines must cross a query's box, not graze it
                grow[b, c] = max(step * min(1.0, tang[b, c] + sn[b]), 1e-6 * step)


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
    of voxels with one neighbour mask ``skin_mask`` (:func:`merge_runs`; single cubes: half d);
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
    (:func:`bit_lists` of ``vl``; ``out`` must then come zeroed): the loops over the queries
    visit only those, not every query's bit.
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
def _geometry(nx, ny, nz):
    """Per direction: the plane basis e, f and, per axis c, (1/n_c, e_c/n_c, f_c/n_c, sign n_c,
    1 where the line runs parallel to axis c's planes) as one tuple of floats."""
    ex, ey, ez, fx, fy, fz = _basis(nx, ny, nz)
    zx, ix_, pex, pfx, sx = _line_setup(nx, ex, fx)
    zy, iy_, pey, pfy, sy = _line_setup(ny, ey, fy)
    zz, iz_, pez, pfz, sz = _line_setup(nz, ez, fz)
    return (ex, ey, ez, fx, fy, fz, ix_, iy_, iz_, pex, pey, pez, pfx, pfy, pfz, sx, sy, sz,
            1.0 if zx else 0.0, 1.0 if zy else 0.0, 1.0 if zz else 0.0)


@njit(cache=True)
def _span(rx, ry, rz, hx, hy, hz, geo, u0, cell, A0, A1, B0, B1):
    """The grid cells (ia..ib, ja..jb) under a box (centre r relative to the grid's origin,
    half extents h) and its per-axis entry / exit parameters on the line through the
    grid's origin: (r -/+ sign h) / n (-/+inf on an axis the line runs parallel to)."""
    ex, ey, ez, fx, fy, fz = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    ae = hx * abs(ex) + hy * abs(ey) + hz * abs(ez)
    af = hx * abs(fx) + hy * abs(fy) + hz * abs(fz)
    pu = rx * ex + ry * ey + rz * ez
    pv = rx * fx + ry * fy + rz * fz
    ia = max(A0, int(np.floor((pu - ae - u0) / cell)))
    ib = min(A1, int(np.floor((pu + ae - u0) / cell)))
    ja = max(B0, int(np.floor((pv - af - u0) / cell)))
    jb = min(B1, int(np.floor((pv + af - u0) / cell)))
    lxa = -1.0e300 if geo[18] else (rx - geo[15] * hx) * geo[6]
    lxb = 1.0e300 if geo[18] else (rx + geo[15] * hx) * geo[6]
    lya = -1.0e300 if geo[19] else (ry - geo[16] * hy) * geo[7]
    lyb = 1.0e300 if geo[19] else (ry + geo[16] * hy) * geo[7]
    lza = -1.0e300 if geo[20] else (rz - geo[17] * hz) * geo[8]
    lzb = 1.0e300 if geo[20] else (rz + geo[17] * hz) * geo[8]
    return pu, pv, ae, af, ia, ib, ja, jb, lxa, lxb, lya, lyb, lza, lzb


@njit(cache=True)
def _row(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell):
    """Row uc of a box's cells: its column range (cut to the slab of an axis the line runs
    parallel to) and the per-axis entry / exit parameters at column centre 0."""
    jl, jh = ja, jb
    if geo[18]:
        jl, jh = _zcols(uc, geo[0], geo[3], rx, hx, u0, cell, jl, jh)
    if geo[19]:
        jl, jh = _zcols(uc, geo[1], geo[4], ry, hy, u0, cell, jl, jh)
    if geo[20]:
        jl, jh = _zcols(uc, geo[2], geo[5], rz, hz, u0, cell, jl, jh)
    return (jl, jh, lxa - uc * geo[9], lxb - uc * geo[9], lya - uc * geo[10], lyb - uc * geo[10],
            lza - uc * geo[11], lzb - uc * geo[11])


@njit(cache=True)
def _row_tight(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell):
    """:func:`_row` for a long box (merged skin cubes): its columns cut to the row's chord
    through the box's projection (a hexagon), the columns whose line enters every slab
    before it leaves any. The cut comes from the six pairs of an entry and another axis'
    exit (linear in the column's centre) and is widened by a column; the callers' per-cell
    test decides. (On small boxes it costs more than the cells it saves.)"""
    jl, jh, xa, xb, ya, yb, za, zb = _row(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo,
                                          u0, cell)
    px, py, pz = geo[12], geo[13], geo[14]
    vlo, vhi = -1.0e300, 1.0e300
    vlo, vhi = _pair_cut(xa, px, yb, py, vlo, vhi)
    vlo, vhi = _pair_cut(xa, px, zb, pz, vlo, vhi)
    vlo, vhi = _pair_cut(ya, py, xb, px, vlo, vhi)
    vlo, vhi = _pair_cut(ya, py, zb, pz, vlo, vhi)
    vlo, vhi = _pair_cut(za, pz, xb, px, vlo, vhi)
    vlo, vhi = _pair_cut(za, pz, yb, py, vlo, vhi)
    if vlo >= vhi:
        return jl, jl - 1, xa, xb, ya, yb, za, zb
    if vlo > -1.0e299:
        jl = max(jl, int(np.floor((vlo - u0) / cell - 0.5)))
    if vhi < 1.0e299:
        jh = min(jh, int(np.ceil((vhi - u0) / cell - 0.5)))
    return jl, jh, xa, xb, ya, yb, za, zb


@njit(cache=True)
def _box_row(wide, uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell):
    """Row uc of a box's cells: :func:`_row_tight` for a wide box (more than 8 columns, where
    the cut pays), else :func:`_row`."""
    if wide:
        return _row_tight(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell)
    return _row(uc, rx, ry, rz, hx, hy, hz, ja, jb, lxa, lxb, lya, lyb, lza, lzb, geo, u0, cell)


@njit(cache=True)
def _pair_cut(a, pa, b, pb, vlo, vhi):
    """(vlo, vhi) cut to the v where entry ``a - v pa`` comes before exit ``b - v pb``."""
    dd = pb - pa
    cc = b - a
    if dd > 0.0:
        vhi = min(vhi, cc / dd)
    elif dd < 0.0:
        vlo = max(vlo, cc / dd)
    elif not (cc > 0.0):
        vhi = -1.0e300
    return vlo, vhi


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


@njit(cache=True)
def bit_lists(bits, k, ptr, idx):
    """Per direction i < k, the rows of ``bits`` (rows, words) with bit i set, as CSR:
    ``idx[ptr[i]:ptr[i + 1]]`` (``ptr`` (k + 1); ``idx`` as long as the bits set)."""
    n = bits.shape[0]
    for i in range(k + 1):
        ptr[i] = 0
    for r in range(n):
        for i in range(k):
            if (bits[r, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                ptr[i + 1] += 1
    for i in range(k):
        ptr[i + 1] += ptr[i]
    fill = ptr[:k].copy()
    for r in range(n):
        for i in range(k):
            if (bits[r, i >> 6] >> np.uint64(i & 63)) & np.uint64(1):
                idx[fill[i]] = r
                fill[i] += 1


@njit(cache=True, parallel=True)
def dilate_bits(index, ijk, bits, rad, out):
    """out[b] = OR of bits[w] over the boundary voxels w within ``rad`` voxels of b along each
    axis (b itself included): the directions some voxel near b keeps."""
    nx, ny, nz = index.shape
    W = bits.shape[1]
    for b in prange(ijk.shape[0]):
        for w in range(W):
            out[b, w] = np.uint64(0)
        i0, j0, l0 = ijk[b, 0], ijk[b, 1], ijk[b, 2]
        for i in range(max(0, i0 - rad), min(nx, i0 + rad + 1)):
            for j in range(max(0, j0 - rad), min(ny, j0 + rad + 1)):
                for l in range(max(0, l0 - rad), min(nz, l0 + rad + 1)):
                    m = index[i, j, l]
                    if m >= 0:
                        for w in range(W):
                            out[b, w] |= bits[m, w]


@njit(cache=True)
def _shell_conditions(b, vg, bxyz, centre, origin, d, index, state, r_in, r_out, bad, cap, centres, frames, q, out):
    """Conditions 1-3 of :func:`ball_conditions` for voxel b, ANDed into ``out[b]`` (which holds
    ``V'_g(b)``); False as soon as a boundary or interior voxel centre lies closer than
    ``r_in`` to the ball's centre (the ball would cut material). Only the columns of the
    voxel grid and the stretch of each column that the sphere of radius ``r_out`` meets are
    visited (a cell of slack; each centre is still tested against both radii)."""
    nx, ny, nz = index.shape
    W = vg.shape[1]
    reach = int(np.ceil(r_out / d)) + 1
    cx = (centre[b, 0] - origin[0]) / d - 0.5
    cy = (centre[b, 1] - origin[1]) / d - 0.5
    cz = (centre[b, 2] - origin[2]) / d - 0.5
    ic, jc, lc = int(np.round(cx)), int(np.round(cy)), int(np.round(cz))
    r2 = (r_out / d) ** 2
    px, py, pz = centre[b, 0], centre[b, 1], centre[b, 2]
    for i in range(max(0, ic - reach), min(nx, ic + reach + 1)):
        dx = (i - cx) * d
        for j in range(max(0, jc - reach), min(ny, jc + reach + 1)):
            dy = (j - cy) * d
            rest = r2 - (i - cx) ** 2 - (j - cy) ** 2
            if rest < -1.0:  # the column misses the sphere (by more than rounding)
                continue
            t = np.sqrt(max(rest, 0.0)) + 1.0
            l0 = max(0, lc - reach, int(np.floor(cz - t)))
            l1 = min(nz, lc + reach + 1, int(np.ceil(cz + t)) + 1)
            for l in range(l0, l1):
                st = state[i, j, l]
                if st == EXTERIOR:
                    continue
                dz = (l - cz) * d
                r = np.sqrt(dx * dx + dy * dy + dz * dz)
                if r < r_in:
                    return False
                if st != BOUNDARY or r > r_out:
                    continue
                m = index[i, j, l]
                tt = lookup_one(bxyz[m, 0] - px, bxyz[m, 1] - py, bxyz[m, 2] - pz, centres, frames, q)
                if tt < 0:  # w's centre on the ball's centre: the ball cannot be there (conservative)
                    for w in range(W):
                        out[b, w] = np.uint64(0)
                elif bad[m] & 2:
                    for w in range(W):
                        out[b, w] &= cap[tt, w]
                else:
                    for w in range(W):
                        out[b, w] &= vg[m, w] | cap[tt, w]
    return True


@njit(cache=True, parallel=True)
def ball_conditions(vg, bxyz, centre, origin, d, index, state, r_in, r_out, bad, cap, centres, frames, q, out):
    """Conditions 1-3 of paper 002 §4.6 as bitsets, for all directions at once.

    The boundary voxels w whose centres lie within [r_in, r_out] of the ball's centre
    ``centre[b]`` form the shell the eraser's surface may meet (E(v) before the half-space
    test). w belongs to E_n(v) unless n lies in ``cap[t]`` (t: the tessel of x_w - c_v), the
    directions for which w lies beyond the eraser's equator. So
    ``A(v) = V'_g(v) & AND_w (V'_g(w) | cap[t_w])`` with ``V'_g(w)`` replaced by nothing where
    w is bad as a neighbour (``bad`` bit 2); v itself must not be bad (bit 1), and the ball
    must fit: no boundary or interior voxel centre closer than r_in. One pass over the sphere
    per voxel, in parallel, with no neighbour lists.
    """
    mb = bxyz.shape[0]
    W = vg.shape[1]
    for b in prange(mb):
        for w in range(W):
            out[b, w] = np.uint64(0) if bad[b] & 1 else vg[b, w]
        if bad[b] & 1:
            continue
        if not _shell_conditions(b, vg, bxyz, centre, origin, d, index, state, r_in, r_out, bad, cap, centres,
                                 frames, q, out):
            for w in range(W):
                out[b, w] = np.uint64(0)


@njit(cache=True, parallel=True)
def ball_fits(centre, origin, d, state, r_in, out):
    """``out[b]`` True where no boundary or interior voxel centre lies closer than ``r_in`` to
    ``centre[b]`` (the ball of the capsule test holds no material, to half a voxel diagonal)."""
    nx, ny, nz = state.shape
    reach = int(np.ceil(r_in / d)) + 1
    for b in prange(centre.shape[0]):
        cx = (centre[b, 0] - origin[0]) / d - 0.5
        cy = (centre[b, 1] - origin[1]) / d - 0.5
        cz = (centre[b, 2] - origin[2]) / d - 0.5
        ic, jc, lc = int(np.round(cx)), int(np.round(cy)), int(np.round(cz))
        ok = True
        for i in range(max(0, ic - reach), min(nx, ic + reach + 1)):
            if not ok:
                break
            dx = (i - cx) * d
            for j in range(max(0, jc - reach), min(ny, jc + reach + 1)):
                if not ok:
                    break
                dy = (j - cy) * d
                for l in range(max(0, lc - reach), min(nz, lc + reach + 1)):
                    if state[i, j, l] == EXTERIOR:
                        continue
                    dz = (l - cz) * d
                    if dx * dx + dy * dy + dz * dz < r_in * r_in:
                        ok = False
                        break
        out[b] = ok


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
def _window(cmin, cmax, ex, ey, ez, fx, fy, fz, grow, u0, cell, nc):
    cx, cy, cz = 0.5 * (cmin[0] + cmax[0]), 0.5 * (cmin[1] + cmax[1]), 0.5 * (cmin[2] + cmax[2])
    hx, hy, hz = 0.5 * (cmax[0] - cmin[0]), 0.5 * (cmax[1] - cmin[1]), 0.5 * (cmax[2] - cmin[2])
    cu = cx * ex + cy * ey + cz * ez
    cv = cx * fx + cy * fy + cz * fz
    au = hx * abs(ex) + hy * abs(ey) + hz * abs(ez) + grow
    av = hx * abs(fx) + hy * abs(fy) + hz * abs(fz) + grow
    A0 = max(0, int(np.floor((cu - au - u0) / cell)) - 1)
    A1 = min(nc - 1, int(np.floor((cu + au - u0) / cell)) + 1)
    B0 = max(0, int(np.floor((cv - av - u0) / cell)) - 1)
    B1 = min(nc - 1, int(np.floor((cv + av - u0) / cell)) + 1)
    return A0, A1, B0, B1


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
