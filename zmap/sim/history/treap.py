"""Interval Treap of paper 000: one binary tree of intervals per ray, indexed in time.

A node is an interval ``[Zmin, Zmax]`` that appeared at its creation stage. The stock's
dexels are the roots (stage 0). When the cutter changes a dexel, children are added to the
leaf that stands for it (section 3), all at the present stage:

* Zmin modified (front shortened): a right child ``[new Zmin, Zmax]``;
* Zmax modified (back shortened): a left child ``[Zmin, new Zmax]``;
* interval created (split): a left and a right child;
* interval deleted: one left child, the *empty leaf* (Zmin = Zmax).

The active dexels are the non-empty leaves, left to right (section 4.1). The cutting kernel
reaches them in z order, skipping dexels that fail condition (1) and stopping for good at
condition (2) (section 4.2); the workpiece's slot list keeps, for each active dexel, the
index of its leaf, so the scan starts at the leaves instead of descending from the roots.
:func:`simulate_treap` is the paper's own scheme, the treap as the only workpiece, updated
by an in-order traversal from the roots pruned by conditions (1) and (2); both build
identical node pools (a test checks it), the leaf scan is faster on deep trees.

Storage (flat node pool, 12 bytes a node): ``z`` float32, ``stage`` int32 and ``kids``
int32 = ``(first_child << 2) | mask`` (mask bit 0: left child, bit 1: right child; the
children of a node are created together and stored side by side). A child stores only the
boundary it introduced (a left child its Zmax, a right child its Zmin, an empty leaf NaN);
the other boundary is its parent's, so a traversal carries ``[Zmin, Zmax]`` down from the
root, whose Zmin is in ``z`` and whose Zmax is in ``root_hi``. Finalising re-lays the pool
so that each ray's forest is contiguous (creation order within the ray), which makes the
traversals cache-friendly.

Reading stage n (section 4.3): a node whose children were created after n is a leaf of the
tree cut at n; ``display`` takes the right-most non-empty leaf (reverse in-order) and
``reconstruct`` all non-empty leaves in order.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _kernels as _hk
from ._common import grow1, slot_index, widen

__all__ = ["IntervalTreap", "simulate_treap"]


class IntervalTreap:
    """Forest of Interval Treaps, one per ray of a dexel workpiece.

    Attributes (finalised)
    ----------------------
    node_off : ndarray of shape (n_rays + 1,), int64
        Ray r owns nodes node_off[r]:node_off[r+1].
    root_off : ndarray of shape (n_rays + 1,), int64
        Ray r has root_off[r+1]-root_off[r] roots, the first nodes of its block.
    root_hi : ndarray of shape (n_roots,), float32
        Zmax of each root, mm.
    z, stage, kids : ndarray of shape (m,); float32, int32, int32
        The nodes.

    Examples
    --------
    >>> from zmap.sim.dexel import DexelWorkpiece
    >>> it = IntervalTreap.start(DexelWorkpiece.from_box((0, 0, -1, 1, 1, 0), pitch=1.0))
    >>> it.finalize(); it.n_nodes, it.display(0).tolist()
    (4, [0.0, 0.0, 0.0, 0.0])
    """

    kind = "treap"

    def __init__(self, n_rays: int, node_off: np.ndarray | None = None, root_off: np.ndarray | None = None,
                 root_hi: np.ndarray | None = None, z: np.ndarray | None = None,
                 stage: np.ndarray | None = None, kids: np.ndarray | None = None, max_block: int = 0):
        self.n_rays = int(n_rays)
        self.node_off = node_off
        self.root_off = root_off
        self.root_hi = root_hi
        self.z = z
        self.stage = stage
        self.kids = kids
        self.max_block = int(max_block)
        self.n = 0 if z is None else int(z.shape[0])

    @classmethod
    def start(cls, wp: Any, capacity: int | None = None) -> "IntervalTreap":
        """Start at stage 0: one root per stock dexel, each the leaf of its dexel."""
        self = cls(wp.n_rays)
        rows, cols = slot_index(wp.cnt, wp.slots)
        m = rows.shape[0]
        cap = max(int(capacity or 0), 4 * m + 1024)
        self.b_z = np.empty(cap, dtype=np.float32)
        self.b_s = np.empty(cap, dtype=np.int32)
        self.b_k = np.empty(cap, dtype=np.int32)
        self.b_ray = np.empty(cap, dtype=np.int32)
        self.b_ray[:m] = rows
        self.b_z[:m] = wp.near[rows, cols]
        self.b_s[:m] = 0
        self.b_k[:m] = 0
        self.root_hi = np.ascontiguousarray(wp.far[rows, cols])
        self.root_off = np.zeros(wp.n_rays + 1, dtype=np.int64)
        np.cumsum(wp.cnt, out=self.root_off[1:])
        self.leaf = np.zeros((wp.n_rays, wp.slots), dtype=np.int32)
        self.leaf[rows, cols] = np.arange(m, dtype=np.int32)
        self.n = m
        return self

    @property
    def capacity(self) -> int:
        return int(self.b_z.shape[0])

    def grow_pool(self) -> None:
        cap = self.capacity + self.capacity // 2 + 1024  # 1.5x: less idle pool at the peak
        if cap >= 2 ** 29:
            raise MemoryError("Interval Treap node pool would exceed 2**29 nodes")
        self.b_z, self.b_s, self.b_k = grow1(self.b_z, cap), grow1(self.b_s, cap), grow1(self.b_k, cap)
        self.b_ray = grow1(self.b_ray, cap)

    def grow_slots(self, slots: int) -> None:
        self.leaf = widen(self.leaf, slots)

    def finalize(self) -> None:
        """Re-lay the node pool ray by ray (creation order kept, children side by side).

        One array at a time, each freed as soon as it is copied, so that the peak stays
        near the pool's own size.
        """
        n = self.n
        del self.leaf
        for name in ("b_ray", "b_z", "b_s", "b_k"):  # the pool's unused tail first
            a = getattr(self, name)
            if a.shape[0] > n:
                setattr(self, name, a[:n].copy())
                del a
        self.node_off = np.empty(self.n_rays + 1, dtype=np.int64)
        _hk.ray_offsets(self.b_ray, self.n_rays, self.node_off)
        newidx = np.empty(n, dtype=np.int32)
        _hk.treap_new_index(self.b_ray, self.node_off, newidx)
        del self.b_ray
        self.z = np.empty(n, dtype=np.float32)
        self.z[newidx] = self.b_z
        del self.b_z
        self.stage = np.empty(n, dtype=np.int32)
        self.stage[newidx] = self.b_s
        del self.b_s
        self.kids = np.empty(n, dtype=np.int32)
        _hk.treap_remap_kids(newidx, self.b_k, self.kids)
        del self.b_k
        self.max_block = int(np.diff(self.node_off).max(initial=0))

    @property
    def n_nodes(self) -> int:
        return int(self.z.shape[0]) if self.z is not None else self.n

    @property
    def nbytes(self) -> int:
        """Bytes of the finalised treap (node pool, roots' Zmax, ray offsets)."""
        return int(self.z.nbytes + self.stage.nbytes + self.kids.nbytes + self.root_hi.nbytes
                   + self.node_off.nbytes + self.root_off.nbytes)

    def display(self, stage: int) -> np.ndarray:
        """Zmax of the right-most non-empty leaf per ray at ``stage`` (NaN: background)."""
        out = np.empty(self.n_rays, dtype=np.float64)
        _hk.treap_display(self.node_off, self.root_off, self.root_hi, self.z, self.stage, self.kids,
                          np.int32(stage), out, *self._stacks())
        return out

    def _stacks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # a ray's pending split pieces never outnumber its nodes
        m = self.max_block + 2
        return np.empty(m, dtype=np.int64), np.empty(m, dtype=np.float32), np.empty(m, dtype=np.float32)

    def reconstruct(self, stage: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Dexels at ``stage`` as CSR ``(offsets (n_rays+1,), near (m,) f4, far (m,) f4)``."""
        cnt = np.empty(self.n_rays, dtype=np.int64)
        near = np.empty(self.n_nodes, dtype=np.float32)
        far = np.empty(self.n_nodes, dtype=np.float32)
        m = _hk.treap_reconstruct(self.node_off, self.root_off, self.root_hi, self.z, self.stage,
                                  self.kids, np.int32(stage), cnt, near, far, *self._stacks())
        offsets = np.zeros(self.n_rays + 1, dtype=np.int64)
        np.cumsum(cnt, out=offsets[1:])
        return offsets, near[:m], far[:m]

    def heights(self) -> dict[str, float]:
        """Balance figures of paper 000 section 6 over the rays that have nodes.

        Returns
        -------
        dict
            ``mean_height``: mean over rays of the average node depth (roots at 1);
            ``mean_log2_nodes``: mean over rays of log2(node count);
            ``mean_nodes``, ``max_nodes``; ``max_mean_height``.
        """
        depth = np.empty(self.n_rays, dtype=np.float64)
        nodes = np.empty(self.n_rays, dtype=np.int64)
        _hk.treap_heights(self.node_off, self.root_off, self.kids, depth, nodes)
        has = nodes > 0
        if not has.any():
            return {"mean_height": 0.0, "mean_log2_nodes": 0.0, "mean_nodes": 0.0, "max_nodes": 0,
                    "max_mean_height": 0.0}
        return {
            "mean_height": float(depth[has].mean()),
            "mean_log2_nodes": float(np.log2(nodes[has]).mean()),
            "mean_nodes": float(nodes[has].mean()),
            "max_nodes": int(nodes.max()),
            "max_mean_height": float(depth[has].max()),
        }

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"node_off": self.node_off, "root_off": self.root_off, "root_hi": self.root_hi,
                "z": self.z, "stage": self.stage, "kids": self.kids,
                "max_block": np.array(self.max_block, dtype=np.int64)}

    @classmethod
    def from_arrays(cls, n_rays: int, a: dict) -> "IntervalTreap":
        return cls(n_rays, a["node_off"], a["root_off"], a["root_hi"], a["z"], a["stage"], a["kids"],
                   int(a["max_block"]))


def simulate_treap(stock: Any, xyz: np.ndarray, cutters: Any, tool_slot: np.ndarray | None = None,
                   capacity: int | None = None) -> IntervalTreap:
    """Cut with the Interval Treap as the workpiece (paper 000 section 4.2), no dexel lists.

    Every ray's forest is traversed in order from its roots; a subtree is skipped when its
    interval fails condition (1) (tool FarZ > Zmin and Zmax > tool NearZ), the ray is left
    for good when a node lies above the tool (condition (2)) or a leaf just created reaches
    the tool's FarZ, and the leaves met get the four cases of section 3.

    Parameters
    ----------
    stock : DexelWorkpiece
        Stage 0 (not modified).
    xyz : ndarray of shape (n, 3), float64, or Pieces
        Tool-tip positions (stamps), mm, or the path pieces of a program (each stage its exact
        sweep).
    cutters : Cutter or list of Cutter; tool_slot : ndarray of shape (n,), int, optional.

    Returns
    -------
    IntervalTreap
        Finalised; ``reconstruct(n)`` is the cut workpiece.

    Examples
    --------
    >>> import numpy as np
    >>> from zmap.sim.dexel import DexelWorkpiece
    >>> from zmap.sim.tools import Cutter
    >>> wp = DexelWorkpiece.from_box((0, 0, -2, 1, 1, 0), pitch=0.5)
    >>> it = simulate_treap(wp, np.array([[0.5, 0.5, -1.0]]), Cutter("flat", 0.2))
    >>> it.reconstruct(1)[2].tolist()[4], it.n_nodes
    (-1.0, 10)
    """
    from ..dexel import cutter_table
    from ..pieces import Pieces

    cs = list(cutters) if isinstance(cutters, (list, tuple)) else [cutters]
    pieces = xyz if isinstance(xyz, Pieces) else Pieces.stamps(xyz)
    n = len(pieces)
    slot = (np.zeros(n, dtype=np.int32) if tool_slot is None
            else np.ascontiguousarray(tool_slot, dtype=np.int32))
    code, radius, corner, length = cutter_table(cs)
    mv, t0, t1 = pieces.params(0, n)
    it = IntervalTreap.start(stock, capacity=capacity or 2 * stock.n_dexels + 24 * n + 1024)
    counts = np.zeros(4, dtype=np.int64)
    counts[0] = it.n
    stacks = [np.empty(16, dtype=np.int64), np.empty(16, dtype=np.float32), np.empty(16, dtype=np.float32)]
    p = 0
    while p < n:
        p = int(_hk.treap_cut_pieces(pieces.kind, pieces.geo, mv, t0, t1, slot, code, radius, corner, length,
                                     p, n, 0, stock.x0, stock.y0, stock.pitch, stock.nx, stock.ny,
                                     it.root_off, it.root_hi, it.b_z, it.b_s, it.b_k, it.b_ray, counts,
                                     *stacks))
        if counts[3] == 1:
            it.grow_pool()
        elif counts[3] == 2:
            stacks = [np.empty(2 * a.shape[0], dtype=a.dtype) for a in stacks]
    it.n = int(counts[0])
    it.created, it.deleted = int(counts[1]), int(counts[2])
    it.finalize()
    return it
