"""Slow, obvious references of the access kernels, for tests on small maps.

:func:`global_visibility_reference` restates the cylinder casting of
:func:`zmap.access.voxelmap.global_visibility` pair by pair: for each boundary voxel v and
each direction n of V'_l(v), for each line of the plane grid that crosses v's surface box,
every blocker box (interior skin cube, or boundary blocker of :meth:`VoxelMap.blockers`
not of v with -n in its L', grown per axis c by (cell / 2)(|e_c| + |f_c|), its exit no
later than that far behind its slab along its normal) is clipped against the line in numpy; v loses n when one reaches beyond
the line's start (v's entry into its tight box, or the lowest point of v's patch slab on
the line). No depth buffer,
no top-two bookkeeping: the kernel must give the same bits.

:func:`tool_clearance_reference` restates the shank and holder tests of
:func:`zmap.access.voxelmap.tool_clearance` plainly: per direction the exits of every (unmerged)
blocker on every cell's centre line in numpy, one buffer per face, then for each pair every
buffer cell that meets the cylinder's disc, compared with its start. No dilated buffers, no
pre-tests, no top-two bookkeeping: the kernel's bits must lie between the reference's with
its heights 1e-9 mm stricter and laxer (the same exits, rounded in another order).
"""

from __future__ import annotations

import numpy as np

from zmap.access.directions import from_bool, to_bool

__all__ = ["global_visibility_reference", "tool_clearance_reference"]


def _basis(n):
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0.0, 1, 0])
    e = a - (a @ n) * n
    e /= np.linalg.norm(e)
    return e, np.cross(n, e)


def _clip(base, n, c, h):
    """(s0, s1) of the line base + s n in the boxes (c, h) (arrays of boxes; ``base`` one point
    or one per box); s0 > s1: miss."""
    s0 = np.full(len(c), -np.inf)
    s1 = np.full(len(c), np.inf)
    for m in range(3):
        if abs(n[m]) < 1e-12:
            out = np.abs(base[..., m] - c[:, m]) > h[:, m]
            s0[out], s1[out] = 1.0, -1.0
            continue
        a0 = (c[:, m] - h[:, m] - base[..., m]) / n[m]
        a1 = (c[:, m] + h[:, m] - base[..., m]) / n[m]
        s0 = np.maximum(s0, np.minimum(a0, a1))
        s1 = np.minimum(s1, np.maximum(a0, a1))
    return s0, s1


def global_visibility_reference(vm, *, rays: int = 2, pieces: bool = False, fine: bool = False) -> np.ndarray:
    """V'_g (mb, words) computed plainly; small maps only (O(k mb^2)). ``pieces``: the bits of
    the pieces' own queries (np, words) instead (:func:`zmap.access.voxelmap.global_visibility`);
    ``fine``: those of the half-voxel pieces of ``vm.fine`` cast on their own, every direction
    of their V'_l (what the refinement of ``global_visibility`` casts at ``rays`` = twice its
    own, for the directions it needs)."""
    from zmap.access.voxelmap import _query_boxes

    ds = vm.directions
    bc, bh, bvox, blight, bplane = vm.blockers()
    qc, qh_ = _query_boxes(vm)
    q_point, q_normal, q_slab, q_vl, q_self = vm.point, vm.normal, vm.slabs(), vm.vl, np.arange(vm.n_boundary)
    if pieces or fine:
        pc = vm.fine if fine else vm.pieces
        pqc, pqh = _query_boxes(vm, pieces=True, fine=fine)
        q_point, q_normal, q_slab, q_vl, q_self = pc.point, pc.normal, pc.slab, pc.vl, np.full(len(pc.voxel), -3)
        if vm.uncertain is not None:  # a piece of an uncertain voxel skips its cube, as the voxel does
            q_self = np.where(vm.uncertain[pc.voxel], pc.voxel, q_self)
    skin = vm.skin()
    allc = np.concatenate([qc, skin]) if len(skin) else qc
    lo_, hi_ = allc.min(axis=0), allc.max(axis=0)
    mid = 0.5 * (lo_ + hi_)
    radius = 0.5 * float(np.linalg.norm(hi_ - lo_)) + vm.d
    cell = vm.d / rays
    u0 = -(radius + 2 * vm.d)
    nc = int(np.ceil(2.0 * (radius + 2 * vm.d) / cell)) + 1
    light = to_bool(blight, ds.k)
    vl = to_bool(q_vl, ds.k)
    if pieces or fine:
        qc, qh_ = pqc, pqh
    opp = ds.lookup(-ds.normals)
    sc = skin - mid
    sh = np.full((len(skin), 3), 0.5 * vm.d)
    rel = bc - mid
    out = np.zeros((len(qc), ds.k), bool)
    slab = q_slab
    for i in range(ds.k):
        n = ds.normals[i]
        e, f = _basis(n)
        blk = np.flatnonzero(light[:, opp[i]])
        for b in np.flatnonzero(vl[:, i]):
            others = blk[bvox[blk] != q_self[b]]
            cs = np.concatenate([rel[others], sc])
            gc = 0.5 * cell * (np.abs(e) + np.abs(f))  # a ray's offset from its cell's line, per axis
            hs = np.concatenate([bh[others] + gc, sh])
            # a piece's exit comes no later than a ray's offset behind its slab (facing the line)
            wm = bplane[others, 3:6]
            wn = wm @ n
            back = (wn < -1e-9) & (bplane[others, 6] < 1e300)
            wk = np.where(back, ((bplane[others, :3] - mid) * wm).sum(axis=1) - bplane[others, 6]
                          - 0.5 * cell * (np.abs(wm @ e) + np.abs(wm @ f)), 0.0)

            def clip(base, cs=cs, hs=hs, wm=wm, wn=wn, back=back, wk=wk):
                t0, t1 = _clip(base, n, cs, hs)
                lim = np.where(back, (wk - wm @ base) / np.where(back, wn, -1.0), np.inf)
                t1[:len(lim)] = np.minimum(t1[:len(lim)], lim)
                return t0, t1

            qh, qr = qh_[b], qc[b] - mid  # v's box as a query
            pu, pv = qr @ e, qr @ f
            ae, af = qh @ np.abs(e), qh @ np.abs(f)
            # the patch's slab: on a line base + s n no patch point lies below start(base)
            m_ = q_normal[b]
            nm = float(n @ m_)
            use = nm > 1e-9 and slab[b] < 1e300

            def start(base, m_=m_, nm=nm, use=use, b=b):
                return ((q_point[b] - mid) @ m_ - slab[b] - base @ m_) / nm if use else -np.inf

            ia, ib = max(0, int(np.floor((pu - ae - u0) / cell))), min(nc - 1, int(np.floor((pu + ae - u0) / cell)))
            ja, jb = max(0, int(np.floor((pv - af - u0) / cell))), min(nc - 1, int(np.floor((pv + af - u0) / cell)))
            free, hits = True, 0
            for a in range(ia, ib + 1):
                for c in range(ja, jb + 1):
                    base = (u0 + (a + 0.5) * cell) * e + (u0 + (c + 0.5) * cell) * f
                    s0, s1 = _clip(base, n, qr[None], qh[None])
                    if s0[0] >= s1[0]:
                        continue
                    hits += 1
                    t0, t1 = clip(base)
                    if np.any((t0 < t1) & (t1 > max(s0[0], start(base)) + 1e-9 * vm.d)):
                        free = False
            if hits == 0:
                # the kernel's fallback: the cell under the box's centre, from its nearest depth
                # or the slab's lowest start over the box's footprint
                a = min(nc - 1, max(0, int(np.floor((pu - u0) / cell))))
                c = min(nc - 1, max(0, int(np.floor((pv - u0) / cell))))
                base = (u0 + (a + 0.5) * cell) * e + (u0 + (c + 0.5) * cell) * f
                s0 = qr @ n - qh @ np.abs(n)
                if use:
                    cu, cv = (e @ m_) / nm, (f @ m_) / nm
                    s0 = max(s0, start(pu * e + pv * f) - ae * abs(cu) - af * abs(cv))
                t0, t1 = clip(base)
                if np.any((t0 < t1) & (t1 > s0 + 1e-9 * vm.d)):
                    free = False
            out[b, i] = free
    return from_bool(out)


def _exits(c, h, plane, n, e, f, u0, cell, nc):
    """The latest exit along n of each cell's centre line (cells of pitch ``cell`` from u0 along
    e and f, nc x nc) from each box (c, h) (arrays of boxes) grown by (cell / 2)(|e_x| + |f_x|)
    per axis x and cut at its slab's far side (``plane``: point, unit normal, slab; the cell's
    offset along the normal added): ``(m, p, q, s)`` over the cells (p, q) under each grown
    box m's projection that its line meets."""
    g = h + 0.5 * cell * (np.abs(e) + np.abs(f))
    pu, pv, au, av = c @ e, c @ f, g @ np.abs(e), g @ np.abs(f)
    ia = np.maximum(0, np.floor((pu - au - u0) / cell).astype(int) - 1)
    ib = np.minimum(nc - 1, np.floor((pu + au - u0) / cell).astype(int) + 1)
    ja = np.maximum(0, np.floor((pv - av - u0) / cell).astype(int) - 1)
    jb = np.minimum(nc - 1, np.floor((pv + av - u0) / cell).astype(int) + 1)
    na, nb = np.maximum(ib - ia + 1, 0), np.maximum(jb - ja + 1, 0)
    m = np.repeat(np.arange(len(c)), na * nb)
    k = np.arange(len(m)) - np.repeat(np.cumsum(na * nb) - na * nb, na * nb)  # cell number within its box
    p = ia[m] + k // nb[m]
    q = ja[m] + k % nb[m]
    base = (u0 + (p + 0.5) * cell)[:, None] * e + (u0 + (q + 0.5) * cell)[:, None] * f
    s0, s1 = _clip(base, n, c[m], g[m])
    nrm = plane[m, 3:6]
    nm = nrm @ n
    cut = np.isfinite(plane[m, 6]) & (np.abs(nm) > 1e-9)
    off = plane[m, 6] + 0.5 * cell * (np.abs(nrm @ e) + np.abs(nrm @ f))
    with np.errstate(invalid="ignore", divide="ignore"):
        lim = (((plane[m, :3] - base) * nrm).sum(axis=1) + np.sign(nm) * off) / nm
    s1 = np.where(cut, np.minimum(s1, lim), s1)
    hit = s0 < s1
    return m[hit], p[hit], q[hit], s1[hit]


def _disc_cells(nc, u0, cell, pu, pv, rr):
    """Indices (ia, ja) and the mask of the cells of an nc x nc grid that meet the disc."""
    ia, ib = max(0, int(np.floor((pu - rr - u0) / cell))), min(nc - 1, int(np.floor((pu + rr - u0) / cell)))
    ja, jb = max(0, int(np.floor((pv - rr - u0) / cell))), min(nc - 1, int(np.floor((pv + rr - u0) / cell)))
    ua = u0 + np.arange(ia, ib + 1) * cell
    va = u0 + np.arange(ja, jb + 1) * cell
    du = np.where((ua <= pu) & (pu <= ua + cell), 0.0, np.minimum(np.abs(ua - pu), np.abs(ua + cell - pu)))
    dv = np.where((va <= pv) & (pv <= va + cell), 0.0, np.minimum(np.abs(va - pv), np.abs(va + cell - pv)))
    return ia, ja, du[:, None] ** 2 + dv[None, :] ** 2 < rr * rr


def _disc_blocked(buf, other, u0, cell, pu, pv, rr, h0, lin) -> bool:
    """Whether a cell meeting the disc holds an exit above h0: ``buf`` all blockers', or, for a
    query on a plane face, ``other`` (the other faces') and of ``buf`` only as much as the
    face's plane ``lin`` = (k0, ku, kv) rises over the cell's part within the disc."""
    from zmap.access._tool_kernels import _linear_max_in

    ia, ja, meets = _disc_cells(buf.shape[0], u0, cell, pu, pv, rr)
    ps, qs = np.nonzero(meets)
    z = buf[ia + ps, ja + qs]
    if other is None:
        return bool((z > h0).any())
    if (other[ia + ps, ja + qs] > h0).any():
        return True
    for p, q, zc in zip(ps[z > h0], qs[z > h0], z[z > h0]):
        if min(zc, _linear_max_in(u0 + (ia + p) * cell, u0 + (ja + q) * cell, cell, pu, pv, rr, *lin)) > h0:
            return True
    return False


def tool_clearance_reference(vm, local, tool, *, cell=None, cell_holder=None, skin=False,
                             slack: float | tuple[float, ...] = 0.0):
    """The bits of :func:`zmap.access.voxelmap.tool_clearance`, computed plainly (small maps):
    per direction and cell the latest exit of every blocker of :meth:`VoxelMap.blockers` (not
    merged), one buffer per face (and one of the skin cubes), so one of all faces and, per
    plane face with a query, one of the others'; then per pair every cell that meets the disc,
    blocking when above the cylinder's start plus ``slack`` (mm; a tuple: one map each). The
    exits are those of the kernel but for rounding (other operations in another order, the
    merged boxes' last bits), so the kernel's bits lie between those of slack -1e-9 and +1e-9."""
    from zmap.access.voxelmap import _blocker_faces, _plane_faces, _plane_queries

    ds = vm.directions
    a = tool.radius
    slacks = slack if isinstance(slack, tuple) else (slack,)
    centre = vm.point + a * vm.normal
    bc, bh, _, _, bplane = vm.blockers()
    bface = _blocker_faces(vm)
    sk = vm.skin()
    lo_, hi_ = np.concatenate([bc, sk]).min(axis=0), np.concatenate([bc, sk]).max(axis=0)
    sk = sk if skin else sk[:0]
    occ = np.concatenate([bc, sk])
    ohalf = np.concatenate([bh, np.full((len(sk), 3), 0.5 * vm.d)])
    oplane = np.concatenate([bplane, np.tile([0, 0, 0, 0, 0, 0, np.inf], (len(sk), 1))])
    oface = np.concatenate([bface, np.full(len(sk), -2)])
    mid = 0.5 * (lo_ + hi_)
    radius = 0.5 * float(np.linalg.norm(hi_ - lo_)) + vm.d + a
    holder_r = tool.holder_diameter / 2.0
    cell = float(cell or vm.d)
    cell_h = float(cell_holder or max(vm.d, holder_r / 5))
    ratio = cell_h / cell
    hm = int(round(ratio))
    hm = hm if hm >= 1 and ratio == hm and hm & (hm - 1) == 0 else 0
    u0 = -(radius + 2 * vm.d + holder_r + cell_h)
    rel, crel = occ - mid, centre - mid
    prel = np.concatenate([oplane[:, :3] - mid, oplane[:, 3:]], axis=1)
    qface = _plane_queries(vm, _plane_faces(vm, bface, bplane))
    groups = sorted(set(oface.tolist()))
    gidx = np.searchsorted(groups, oface)
    loc = to_bool(local, ds.k)
    outs = [np.zeros((vm.n_boundary, ds.k), bool) for _ in slacks]
    for i in range(ds.k):
        n = ds.normals[i]
        e, f = _basis(n)
        asking = np.flatnonzero(loc[:, i])
        faces = sorted(set(qface[asking][qface[asking] >= 0].tolist()))
        sizes = [cell, cell_h] if holder_r > 0 else [cell]
        per_face = []  # per cell size: one buffer per blocker group (face or skin)
        for level, c in enumerate(sizes):
            nc = int(np.ceil(-2.0 * u0 / c)) + 1
            if level == 1 and hm:
                # the holder's cells from the shank's by block maxima (as the kernel)
                nf = per_face[0].shape[1]
                pad = np.full((len(groups), nc * hm, nc * hm), -1.0e300)
                pad[:, :nf, :nf] = per_face[0]
                per_face.append(pad.reshape(len(groups), nc, hm, nc, hm).max(axis=(2, 4)))
                continue
            bufs = np.full((len(groups), nc, nc), -1.0e300)
            m, p, q, ext = _exits(rel, ohalf, prel, n, e, f, u0, c, nc)
            np.maximum.at(bufs, (gidx[m], p, q), ext)
            per_face.append(bufs)
        alls = [b.max(axis=0) for b in per_face]
        others = [{F: np.delete(b, groups.index(F), axis=0).max(axis=0, initial=-1.0e300) if F in groups else b.max(axis=0)
                   for F in faces} for b in per_face]
        for b in asking:
            pu, pv, h0 = crel[b] @ e, crel[b] @ f, crel[b] @ n
            F, lin = int(qface[b]), None
            nm = float(n @ vm.normal[b])
            if F >= 0 and nm > 1e-12:
                lin = (((vm.point[b] - mid) @ vm.normal[b] + 1e-6 * vm.d) / nm, float(e @ vm.normal[b]) / nm,
                       float(f @ vm.normal[b]) / nm)
            else:
                F = -1
            for out, sl in zip(outs, slacks):
                if _disc_blocked(alls[0], others[0][F] if F >= 0 else None, u0, cell, pu, pv, a, h0 + sl, lin):
                    continue
                if holder_r > 0 and _disc_blocked(alls[1], others[1][F] if F >= 0 else None, u0, cell_h, pu, pv,
                                                  holder_r, h0 + sl + tool.stickout - a, lin):
                    continue
                out[b, i] = True
    res = [from_bool(o) for o in outs]
    return tuple(res) if isinstance(slack, tuple) else res[0]
