"""Numba kernels of the histories: finalising the pools and reading a stage back.

Private to :mod:`zmap.sim.history`. Stages are int32, z values float32 (NaN = nothing).
"""

from __future__ import annotations


import numpy as np
from numba import njit

from .. import _sweep_kernels as _sk
from .._dexel_kernels import f32_up, piece_window

__all__: list[str] = []


@njit(cache=True)
def ray_offsets(ray, n_rays, offsets_out):
    """CSR offsets of elements grouped by ray: ``offsets_out[r]`` = elements of rays < r."""
    for r in range(n_rays + 1):
        offsets_out[r] = 0
    for e in range(ray.shape[0]):
        offsets_out[ray[e] + 1] += 1
    for r in range(n_rays):
        offsets_out[r + 1] += offsets_out[r]


@njit(cache=True)
def scatter3(ray, offsets, a, b, c, out_a, out_b, out_c):
    """Stable counting-sort scatter of three parallel arrays by ray."""
    fill = offsets[:-1].copy()
    for e in range(ray.shape[0]):
        r = ray[e]
        q = fill[r]
        out_a[q] = a[e]
        out_b[q] = b[e]
        out_c[q] = c[e]
        fill[r] = q + 1


@njit(cache=True)
def scatter2(ray, offsets, a, b, out_a, out_b):
    """Stable counting-sort scatter of two parallel arrays by ray."""
    fill = offsets[:-1].copy()
    for e in range(ray.shape[0]):
        r = ray[e]
        q = fill[r]
        out_a[q] = a[e]
        out_b[q] = b[e]
        fill[r] = q + 1


# ---- z-trace ---------------------------------------------------------------------------

@njit(cache=True)
def ztrace_count(offsets, zc, zd, k, cnt_out):
    """Alive Z-elements per ray at stage k (creation <= k < deletion), halved: dexels."""
    for r in range(offsets.shape[0] - 1):
        m = 0
        for e in range(offsets[r], offsets[r + 1]):
            if zc[e] <= k and zd[e] > k:
                m += 1
        cnt_out[r] = m // 2


@njit(cache=True)
def ztrace_fill(offsets, zz, zc, zd, k, out_off, near, far, buf):
    """Sort the alive Z-elements of each ray by z and pair them into dexels [near, far].

    ``buf`` (length >= the largest alive count of a ray) is scratch for the sort.
    """
    for r in range(offsets.shape[0] - 1):
        m = 0
        for e in range(offsets[r], offsets[r + 1]):
            if zc[e] <= k and zd[e] > k:
                v = zz[e]
                b = m - 1
                while b >= 0 and buf[b] > v:
                    buf[b + 1] = buf[b]
                    b -= 1
                buf[b + 1] = v
                m += 1
        q = out_off[r]
        for t in range(0, m - 1, 2):
            near[q] = buf[t]
            far[q] = buf[t + 1]
            q += 1


@njit(cache=True)
def ztrace_top(offsets, zz, zc, zd, k, out):
    """Largest alive Z of each ray at stage k (the last FarZ), NaN when none."""
    for r in range(offsets.shape[0] - 1):
        best = -np.inf
        for e in range(offsets[r], offsets[r + 1]):
            if zc[e] <= k and zd[e] > k and zz[e] > best:
                best = zz[e]
        out[r] = best if best > -np.inf else np.nan


# ---- time-trace ------------------------------------------------------------------------

@njit(cache=True)
def ttrace_display(offsets, tz, ts, k, out):
    """Value of the last time-element created at or before stage k, per ray (binary search)."""
    for r in range(offsets.shape[0] - 1):
        lo = offsets[r]
        hi = offsets[r + 1]  # ts[lo] == 0 <= k always
        if hi <= lo:
            out[r] = np.nan
            continue
        # last index e in [lo, hi) with ts[e] <= k
        a = lo
        b = hi - 1
        while a < b:
            m = (a + b + 1) // 2
            if ts[m] <= k:
                a = m
            else:
                b = m - 1
        out[r] = tz[a]


# ---- Interval Treap --------------------------------------------------------------------

@njit(cache=True)
def treap_new_index(ray, node_off, newidx):
    """Place of each node when the pool is grouped by ray, creation order kept (a stable
    counting sort): the stock's roots first in each ray's block, the two children of a node
    side by side, a chain of modifications in the order it is walked."""
    fill = node_off[:-1].copy()
    for e in range(ray.shape[0]):
        r = ray[e]
        newidx[e] = fill[r]
        fill[r] += 1


@njit(cache=True)
def treap_remap_kids(newidx, tk, nk):
    """``nk[newidx[e]]`` = node e's ``kids`` with its first child's index remapped."""
    for e in range(tk.shape[0]):
        kids = tk[e]
        if kids & 3:
            nk[newidx[e]] = (newidx[kids >> 2] << 2) | (kids & 3)
        else:
            nk[newidx[e]] = 0


@njit(cache=True)
def treap_top_at(node_off, root_off, root_hi, tz, ts, tk, r, k, stack_n, stack_lo, stack_hi):
    """Zmax of the right-most non-empty leaf of ray ``r``'s treap cut at stage ``k`` (NaN: empty).

    Reverse in-order traversal (right child first); a node whose children were created
    after stage k is a leaf at stage k. A node with one child is descended without the
    stack; the stacks (length >= nodes of the biggest ray + 1) hold pending left children.
    """
    base = node_off[r]
    r0 = root_off[r]
    for t in range(root_off[r + 1] - r0 - 1, -1, -1):
        node = base + t
        lo = tz[node]
        hi = root_hi[r0 + t]
        sp = 0
        while True:
            kids = tk[node]
            mask = kids & 3
            first = kids >> 2
            if mask == 0 or ts[first] > k:
                if lo < hi:
                    return np.float64(hi)
            elif mask == 3:  # split: visit the right piece first, keep the left one
                stack_n[sp] = first
                stack_lo[sp] = lo
                stack_hi[sp] = tz[first]
                sp += 1
                node = first + 1
                lo = tz[first + 1]
                continue
            elif mask == 1:
                zl = tz[first]
                if zl == zl:  # Zmax modified; NaN marks the empty leaf of a deletion
                    node = first
                    hi = zl
                    continue
            else:
                node = first
                lo = tz[first]
                continue
            if sp == 0:
                break
            sp -= 1
            node = stack_n[sp]
            lo = stack_lo[sp]
            hi = stack_hi[sp]
    return np.nan


@njit(cache=True)
def treap_display(node_off, root_off, root_hi, tz, ts, tk, k, out, stack_n, stack_lo, stack_hi):
    """:func:`treap_top_at` of every ray: the stock's top at stage k (NaN where empty)."""
    for r in range(node_off.shape[0] - 1):
        out[r] = treap_top_at(node_off, root_off, root_hi, tz, ts, tk, r, k, stack_n, stack_lo, stack_hi)


# a plain call (inlining it made the cold compile slow); _nrt=False: no reference counting
# of its four arrays on each step of the traversals
@njit(cache=True, _nrt=False)
def _descend(tz, mask, first, node, lo, hi, sp, stack_n, stack_lo, stack_hi):
    """One step down an in-order treap traversal from ``node`` [lo, hi], whose children
    start at ``first`` (``mask`` != 0).

    ``mask`` 3 (split): the right piece goes on the stack and the left one is entered; 1:
    the left child, the modified Zmax, unless it is NaN (the empty leaf of a deletion); 2:
    the right child, the modified Zmin. Returns ``(node, lo, hi, sp, moved)``; ``moved`` is
    False where there is nothing below to enter. The caller makes sure the stack has room.
    """
    if mask == 3:
        stack_n[sp] = first + 1
        stack_lo[sp] = tz[first + 1]
        stack_hi[sp] = hi
        return first, lo, tz[first], sp + 1, True
    if mask == 1:
        zl = tz[first]
        if zl == zl:
            return first, lo, zl, sp, True
        return node, lo, hi, sp, False
    return first, tz[first], hi, sp, True


@njit(cache=True)
def treap_reconstruct(node_off, root_off, root_hi, tz, ts, tk, k, cnt_out, near, far,
                      stack_n, stack_lo, stack_hi):
    """Non-empty leaves of the treap cut at stage k, left to right: the dexels of stage k.

    A branch stops where the children were created after stage k (they are cut away) or
    at a leaf. Dexels go to ``near``/``far`` in ray order, counts to ``cnt_out``; returns
    their total.
    """
    n_rays = node_off.shape[0] - 1
    q = 0
    for r in range(n_rays):
        q0 = q
        base = node_off[r]
        r0 = root_off[r]
        for t in range(root_off[r + 1] - r0):
            node = base + t
            lo = tz[node]
            hi = root_hi[r0 + t]
            sp = 0
            while True:
                kids = tk[node]
                mask = kids & 3
                first = kids >> 2
                if mask == 0 or ts[first] > k:
                    if lo < hi:
                        near[q] = lo
                        far[q] = hi
                        q += 1
                else:
                    node, lo, hi, sp, moved = _descend(tz, mask, first, node, lo, hi, sp, stack_n, stack_lo, stack_hi)
                    if moved:
                        continue
                if sp == 0:
                    break
                sp -= 1
                node = stack_n[sp]
                lo = stack_lo[sp]
                hi = stack_hi[sp]
        cnt_out[r] = q - q0
    return q


@njit(cache=True)
def treap_heights(node_off, root_off, tk, out_mean_depth, out_nodes):
    """Per ray: mean node depth (roots at depth 1) and node count of its forest."""
    n_rays = node_off.shape[0] - 1
    depth = np.zeros(node_off[n_rays], dtype=np.int32)
    for r in range(n_rays):
        base = node_off[r]
        end = node_off[r + 1]
        nroot = root_off[r + 1] - root_off[r]
        total = 0
        for t in range(nroot):
            depth[base + t] = 1
        # children always come after their parent within the block
        for node in range(base, end):
            total += depth[node]
            kids = tk[node]
            mask = kids & 3
            if mask:
                first = kids >> 2
                depth[first] = depth[node] + 1
                if mask == 3:
                    depth[first + 1] = depth[node] + 1
        out_nodes[r] = end - base
        out_mean_depth[r] = total / (end - base) if end > base else 0.0


# ---- Interval Treap as the workpiece itself (paper 000, section 4.2) ---------------------

@njit(cache=True)
def _treap_add(tz, ts, tk, tr_ray, counts, parent, mask, zl, zr, stage, ray):
    k = counts[0]
    n = 0
    if mask & 1:
        tz[k] = zl
        ts[k] = stage
        tk[k] = 0
        tr_ray[k] = ray
        n += 1
    if mask & 2:
        tz[k + n] = zr
        ts[k + n] = stage
        tk[k + n] = 0
        tr_ray[k + n] = ray
        n += 1
    tk[parent] = (k << 2) | mask
    counts[0] = k + n


@njit(cache=True)
def treap_cut_ray(r, a, b, stage, root_off, root_hi, tz, ts, tk, tr_ray, counts,
                  stack_n, stack_lo, stack_hi):
    """Subtract ``[a, b]`` from ray r by traversing its Interval Treap in order.

    Condition (1): a node can change only if tool FarZ > its Zmin and its Zmax > tool
    NearZ; otherwise its subtree is skipped (momentarily), and the traversal stops for
    good when the node lies above the tool (its Zmax >= tool FarZ, condition (2)), or when a
    leaf just created reaches the tool's FarZ. Returns 0, 1 if the node pool is full, 2 if
    the stack is (the caller grows it and cuts the ray again: cutting is idempotent).
    """
    cap = tz.shape[0]
    for t in range(root_off[r], root_off[r + 1]):
        node = t
        lo = tz[t]
        hi = root_hi[t]
        sp = 0
        while True:
            descend = False
            if b > lo and hi > a:  # condition (1)
                kids = tk[node]
                mask = kids & 3
                first = kids >> 2
                if mask == 0:
                    if lo < hi:  # an active dexel: the four cases
                        if counts[0] + 2 > cap:
                            return 1
                        if a > lo and b < hi:
                            _treap_add(tz, ts, tk, tr_ray, counts, node, 3, a, b, stage, r)
                            counts[1] += 1
                            return 0  # new FarZ >= tool FarZ: stop for good
                        elif a <= lo and b >= hi:
                            _treap_add(tz, ts, tk, tr_ray, counts, node, 1, np.float32(np.nan),
                                       np.float32(0.0), stage, r)
                            counts[2] += 1
                        elif a > lo:
                            _treap_add(tz, ts, tk, tr_ray, counts, node, 1, a, np.float32(0.0), stage, r)
                        else:
                            _treap_add(tz, ts, tk, tr_ray, counts, node, 2, np.float32(0.0), b, stage, r)
                            return 0  # new Zmin = tool FarZ: stop for good
                else:
                    descend = True
            elif lo >= b:  # (1) false and (2) true: everything further lies above the tool
                return 0
            if descend:
                if mask == 3 and sp >= stack_n.shape[0]:
                    return 2
                node, lo, hi, sp, moved = _descend(tz, mask, first, node, lo, hi, sp, stack_n, stack_lo, stack_hi)
                if moved:
                    continue
            if sp == 0:
                break
            sp -= 1
            node = stack_n[sp]
            lo = stack_lo[sp]
            hi = stack_hi[sp]
    return 0


@njit(cache=True)
def treap_cut_pieces(pkind, pgeo, smove, st0, st1, tslot, tcode, trad, tcr, tlen, start, stop, stage0,
                     x0, y0, pitch, nx, ny, root_off, root_hi, tz, ts, tk, tr_ray, counts,
                     stack_n, stack_lo, stack_hi):
    """Cut stages start..stop-1 (each the exact sweep of its path piece, as
    :func:`zmap.sim._dexel_kernels.cut_pieces_window`) into the treap forest; returns the
    first stage not done.

    ``counts`` = [nodes used, created, deleted, status]; status 1: pool full, 2: stack full.
    """
    counts[3] = 0
    buf = np.empty((_sk.MAX_INTERVALS, 2), dtype=np.float64)
    scratch = np.empty(_sk.SCRATCH, dtype=np.float64)
    for p in range(start, stop):
        mv = smove[p]
        kind = pkind[mv]
        if kind == _sk.NO_CUT:
            continue
        s = tslot[p]
        R = trad[s]
        stage = np.int32(stage0 + p + 1)
        i0, i1, j0, j1 = piece_window(pkind, pgeo, mv, st0[p], st1[p], R, x0, y0, pitch, 0, 0, nx, ny)
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                n = _sk.piece_rays(kind, tcode[s], R, tcr[s], tlen[s], pgeo[mv], st0[p], st1[p],
                                   x0 + i * pitch, y0 + j * pitch, buf, scratch)
                for m in range(n):
                    st = treap_cut_ray(i * ny + j, f32_up(buf[m, 0]), np.float32(buf[m, 1]), stage, root_off,
                                       root_hi, tz, ts, tk, tr_ray, counts, stack_n, stack_lo, stack_hi)
                    if st != 0:
                        counts[3] = st
                        return p
    return stop
