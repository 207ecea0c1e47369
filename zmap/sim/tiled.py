"""Tiled NC simulation on Dask: the stock split in xy tiles of rays, one task per tile.

The cut of a ray depends only on that ray and the stages whose swept footprint covers
it, so each tile simulates, in program order, only the stages whose piece's window
reaches it, on its own rays, with its own history (z-trace, time-trace or Interval Treap).
The tile kernel (:mod:`zmap.sim._tiled_kernels`) computes every ray's xy from its global
index and gives every position its global stage, so each tile's rays end up with the
dexels and history events of the single-process run. :class:`TiledHistory` answers
``display(k)`` and ``reconstruct(k)`` by assembling the tiles on demand, so
:class:`zmap.sim.session.Run` works on it unchanged: ``simulate(..., tiles=N)`` and
``zmap simulate --tiles N [--scheduler ADDRESS]``.
"""

from __future__ import annotations

import contextlib
import os
import time
import warnings
from typing import Any, Callable

import numpy as np

from .dexel import DexelWorkpiece, cutter_table
from .history import IntervalTreap, Recorder, TimeTrace, ZTrace

__all__ = ["TiledHistory", "simulate_tiles", "tile_positions", "check_tiles"]

_STRUCTS = {"ztrace": ZTrace, "ttrace": TimeTrace, "treap": IntervalTreap}
#: what every tile task reads: the piece table, each stage's piece and tool, the stock
#: tiles of fewer rays a side, more of them than MANY_TILES, get a warning (a task per handful of rays)
SMALL_TILE, MANY_TILES = 32, 256
_SHARED = ("kind", "geo", "move", "t0", "t1", "slot", "off", "near", "far")


def check_tiles(tiles: Any) -> int:
    """``tiles`` as a whole number of rays a tile side, ValueError unless one and at least 2."""
    try:
        t = int(tiles)
    except (TypeError, ValueError):
        raise ValueError(f"tiles must be a whole number of rays, got {tiles!r}") from None
    if t != tiles or t < 2:
        raise ValueError(f"tiles={tiles!r} rays: a tile needs at least 2 x 2 rays (hundreds for speed)")
    return t


def _tile_rays(nx: int, ny: int, tile: int, ti: int, tj: int) -> tuple[int, int, int, int, np.ndarray]:
    """First ray and size ``(gi0, gj0, tnx, tny)`` of tile (ti, tj), and its global ray ids (i-major)."""
    gi0, gj0 = ti * tile, tj * tile
    tnx, tny = min(tile, nx - gi0), min(tile, ny - gj0)
    idx = (np.arange(gi0, gi0 + tnx, dtype=np.int64)[:, None] * ny
           + np.arange(gj0, gj0 + tny, dtype=np.int64)[None, :]).ravel()
    return gi0, gj0, tnx, tny, idx


def tile_positions(stock: DexelWorkpiece, xyz: Any, slot: np.ndarray, cutters: list,
                   tile: int) -> tuple[tuple[int, int], list[np.ndarray]]:
    """The stages whose piece's footprint window reaches each tile, in program order.

    ``xyz`` is a :class:`zmap.sim.pieces.Pieces` or an (n, 3) array of stamps.

    Returns
    -------
    (ntx, nty) : tuple of int
        Tiles along x and y.
    lists : list of ndarray of int64
        ``lists[ti * nty + tj]``: indices into ``xyz`` of the positions for tile (ti, tj).
    """
    from . import _tiled_kernels as K

    tile = check_tiles(tile)
    ntx, nty = -(-stock.nx // tile), -(-stock.ny // tile)
    _code, radius, _corner, _length = cutter_table(cutters)
    pieces = _as_pieces(xyz)
    n = len(pieces)
    counts = np.zeros(n, dtype=np.int64)
    none = np.zeros(0, dtype=np.int64)
    slot = np.ascontiguousarray(slot, dtype=np.int32)
    mv, t0, t1 = pieces.params(0, n)
    args = (pieces.kind, pieces.geo, mv, t0, t1, slot, radius, stock.x0, stock.y0, stock.pitch, stock.nx,
            stock.ny, tile, nty)
    K.positions_reaching(*args, counts, none, False)
    starts = np.zeros(n, dtype=np.int64)
    np.cumsum(counts[:-1], out=starts[1:]) if n else None
    tile_of = np.empty(int(counts.sum()), dtype=np.int64)
    K.positions_reaching(*args, starts, tile_of, True)
    pos_of = np.repeat(np.arange(n, dtype=np.int64), counts)
    order = np.argsort(tile_of, kind="stable")  # stable: program order within each tile
    bounds = np.searchsorted(tile_of[order], np.arange(ntx * nty + 1))
    return (ntx, nty), [pos_of[order[bounds[k]:bounds[k + 1]]] for k in range(ntx * nty)]


def _assemble_csr(n_rays: int, parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]):
    """Global CSR ``(offsets, near, far)`` from tiles' ``(global ray ids, offsets, near, far)``."""
    cnt = np.zeros(n_rays, dtype=np.int64)
    for idx, off, _near, _far in parts:
        cnt[idx] = np.diff(off)
    offsets = np.zeros(n_rays + 1, dtype=np.int64)
    np.cumsum(cnt, out=offsets[1:])
    total = int(offsets[-1])
    near = np.empty(total, dtype=np.float32)
    far = np.empty(total, dtype=np.float32)
    for idx, off, tnear, tfar in parts:
        c = np.diff(off)
        if not len(tnear):
            continue
        dest = np.repeat(offsets[idx] - off[:-1], c) + np.arange(len(tnear))
        near[dest] = tnear
        far[dest] = tfar
    return offsets, near, far


def _assemble(stock: DexelWorkpiece, tile: int, nty: int, results: dict) -> DexelWorkpiece:
    """The whole stock from the tiles' results (per-ray lists of each tile, in its ray order)."""
    from . import _csr_kernels

    slots = max([4] + [int(np.diff(r["off"]).max(initial=0)) for r in results.values()])
    near = np.zeros((stock.n_rays, slots), dtype=np.float32)
    far = np.zeros((stock.n_rays, slots), dtype=np.float32)
    cnt = np.zeros(stock.n_rays, dtype=np.int32)
    for k, r in results.items():
        rows = _tile_rays(stock.nx, stock.ny, tile, *divmod(k, nty))[4]
        _csr_kernels.scatter(rows, np.ascontiguousarray(r["off"], dtype=np.int64), r["near"], r["far"], near, far, cnt)
    return DexelWorkpiece(stock.x0, stock.y0, stock.pitch, stock.nx, stock.ny, near, far, cnt,
                          stock.created + sum(r["created"] for r in results.values()),
                          stock.deleted + sum(r["deleted"] for r in results.values()))


def _as_pieces(xyz: Any) -> Any:
    from .pieces import Pieces

    return xyz if isinstance(xyz, Pieces) else Pieces.stamps(xyz)


def _sim_tile(near: np.ndarray, far: np.ndarray, cnt: np.ndarray, pieces: tuple, slot: np.ndarray,
              gpos: np.ndarray, table: tuple, history: str, x0: float, y0: float, pitch: float, gi0: int, gj0: int,
              tnx: int, tny: int, chunk: int = 4096, handoff: str | None = None) -> dict:
    """One Dask task: cut the tile's stages into its rays, recording its own history.

    ``pieces`` is ``(kind, geo, move, t0, t1)``: the piece table and the tile's stages.

    With ``handoff`` (a folder the client sees, :class:`zmap.tiled.handoff.Handoff`) the
    tile's stock and history are written there and the result holds their reference
    (``arrays``) instead of the arrays.
    """
    from zmap.tiled.cluster import peak_rss_mb

    from . import _dexel_kernels as _k
    from . import _tiled_kernels as K
    from .dexel import _empty_history_args

    t0 = time.perf_counter()
    wall0 = time.time()
    c0 = time.process_time()
    th0 = time.thread_time()
    wp = DexelWorkpiece(x0 + gi0 * pitch, y0 + gj0 * pitch, pitch, tnx, tny, near, far, cnt)
    n_dexels0 = wp.n_dexels
    rec = None
    if history != "none":
        struct = _STRUCTS[history].start(wp, capacity=int(2 * n_dexels0 + 24 * len(slot) + 1024))
        rec = Recorder(**{history: struct})
    code, radius, corner, length = table
    stats = np.zeros(_k.N_STATS, dtype=np.int64)
    if rec is not None:
        rec.load_counts(stats)
    pkind, pgeo, smove, st0, st1 = pieces
    p, stop = 0, len(slot)
    while p < stop:
        q = min(stop, p + chunk)
        args = rec.kernel_args() if rec is not None else _empty_history_args()
        nxt = K.cut_pieces_tile(pkind, pgeo, smove, st0, st1, slot, code, radius, corner, length, gpos, p, q, 0,
                                x0, y0, pitch, gi0, gj0, tnx, tny, wp.near, wp.far, wp.cnt, *args, stats)
        status = stats[_k.ST_STATUS]
        if status == _k.NEED_SLOTS:
            wp.grow(2 * wp.slots)
            if rec is not None:
                rec.grow_slots(wp.slots)
        elif status == _k.NEED_POOL:
            rec.grow_pools(stats)
        p = nxt
    structure = None
    if rec is not None:
        rec.store_counts(stats)
        rec.finalize()
        structure = getattr(rec, history)
    off, fnear, ffar = wp.to_csr()
    out: dict = {"off": off, "near": fnear, "far": ffar, "structure": structure}
    if handoff is not None:
        from zmap.tiled.handoff import save_arrays

        arrays = {"off": off, "near": fnear, "far": ffar}
        if structure is not None:
            arrays.update({"s_" + k: v for k, v in structure.to_arrays().items()})
        out = {"arrays": save_arrays(handoff, f"tile_{gi0}_{gj0}", arrays)}
    return {**out, "created": int(stats[_k.ST_CREATED]),
            "deleted": int(stats[_k.ST_DELETED]), "positions": int(len(slot)),
            "rays_cut": int(stats[_k.ST_RAYS_CUT]), "seconds": time.perf_counter() - t0,
            "wall_span": (wall0, time.time()),
            "cpu_seconds": time.process_time() - c0, "thread_cpu_seconds": time.thread_time() - th0,
            "pid": os.getpid(), "peak_rss_mb": peak_rss_mb()}


def _sim_tile_of(shared: tuple | dict, pos: np.ndarray, table: tuple, history: str, x0: float, y0: float,
                 pitch: float, gi0: int, gj0: int, tnx: int, tny: int, ny: int, handoff: str | None = None) -> dict:
    """One Dask task: tile (gi0, gj0, tnx, tny) of the whole stock and program sent once per worker.

    ``shared`` is ``(kind, geo, move, t0, t1, slot, offsets, near, far)`` of the whole run:
    the piece table, the stages' pieces and tools, and the stock as compact
    per-ray lists (:func:`zmap.tiled.cluster.share`), or the reference of those arrays
    written to the ``handoff`` folder (mapped here, read-only); the task takes its rays and
    its positions ``pos`` from it.
    """
    if isinstance(shared, dict):
        from zmap.tiled.handoff import load_arrays

        a = load_arrays(shared, writeable=False)
        shared = tuple(a[k] for k in _SHARED)
    pkind, pgeo, smove, st0, st1, slot, off, near, far = shared
    idx = (np.arange(gi0, gi0 + tnx, dtype=np.int64)[:, None] * ny
           + np.arange(gj0, gj0 + tny, dtype=np.int64)[None, :]).ravel()
    cnt = off[idx + 1] - off[idx]
    sub = np.zeros(idx.size + 1, dtype=np.int64)
    np.cumsum(cnt, out=sub[1:])
    src = np.repeat(off[idx], cnt) + (np.arange(int(sub[-1])) - np.repeat(sub[:-1], cnt))
    wp = DexelWorkpiece.from_csr(x0, y0, pitch, tnx, tny, sub, near[src], far[src])
    pieces = (pkind, pgeo, np.ascontiguousarray(smove[pos]), np.ascontiguousarray(st0[pos]),
              np.ascontiguousarray(st1[pos]))
    return _sim_tile(wp.near, wp.far, wp.cnt, pieces, np.ascontiguousarray(slot[pos]), pos,
                     table, history, x0, y0, pitch, gi0, gj0, tnx, tny, handoff=handoff)


def _unpack(r: dict, history: str, tnx: int, tny: int) -> dict:
    """A tile's result with its arrays in place: mapped from the handoff folder if written there."""
    if "arrays" not in r:
        return r
    from zmap.tiled.handoff import load_arrays

    a = load_arrays(r.pop("arrays"))
    r.update(off=a["off"], near=a["near"], far=a["far"], structure=None)
    if history != "none":
        r["structure"] = _STRUCTS[history].from_arrays(tnx * tny, {k[2:]: v for k, v in a.items() if k.startswith("s_")})
    return r


class TiledHistory:
    """One history per tile, read as one: ``display(k)`` and ``reconstruct(k)`` over the whole stock.

    Each call assembles the tiles' answers (nothing is assembled before it is asked for).

    Parameters
    ----------
    kind : {'ztrace', 'ttrace', 'treap'}
    nx, ny : int
        Rays of the whole stock.
    tile : int
        Tile side in rays.
    structures : list
        ``structures[ti * nty + tj]``: the finished history of tile (ti, tj).
    """

    def __init__(self, kind: str, nx: int, ny: int, tile: int, structures: list):
        self.kind = kind
        self.nx, self.ny, self.tile = int(nx), int(ny), int(tile)
        self.ntx, self.nty = -(-self.nx // self.tile), -(-self.ny // self.tile)
        if len(structures) != self.ntx * self.nty:
            raise ValueError(f"{len(structures)} tile histories for {self.ntx} x {self.nty} tiles")
        self.structures = list(structures)

    def _tiles(self):
        for ti in range(self.ntx):
            for tj in range(self.nty):
                yield self.structures[ti * self.nty + tj], _tile_rays(self.nx, self.ny, self.tile, ti, tj)[4]

    @property
    def n_rays(self) -> int:
        return self.nx * self.ny

    @property
    def nbytes(self) -> int:
        return int(sum(s.nbytes for s in self.structures))

    @property
    def n_nodes(self) -> int:
        return int(sum(int(getattr(s, "n_nodes", getattr(s, "n_elements", 0))) for s in self.structures))

    n_elements = n_nodes

    def display(self, stage: int) -> np.ndarray:
        """Top-surface heights at ``stage``, flat (nx*ny,), NaN where no material."""
        out = np.full(self.n_rays, np.nan)
        for s, idx in self._tiles():
            out[idx] = s.display(stage)
        return out

    def reconstruct(self, stage: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Dexels at ``stage`` as the whole stock's CSR ``(offsets, near, far)``."""
        if self.kind == "ttrace":
            raise ValueError("a time-trace has no reconstruction; the run replays instead")
        parts = [(idx, *s.reconstruct(stage)) for s, idx in self._tiles()]
        return _assemble_csr(self.n_rays, parts)

    def to_arrays(self) -> dict[str, np.ndarray]:
        out = {"tiles_layout": np.array([self.nx, self.ny, self.tile], dtype=np.int64)}
        for k, s in enumerate(self.structures):
            for name, arr in s.to_arrays().items():
                out[f"t{k}_{name}"] = np.asarray(arr)
        return out

    @classmethod
    def from_arrays(cls, kind: str, a: dict) -> "TiledHistory":
        nx, ny, tile = (int(v) for v in a["tiles_layout"])
        ntx, nty = -(-nx // tile), -(-ny // tile)
        structures = []
        for k in range(ntx * nty):
            ti, tj = divmod(k, nty)
            tnx, tny = _tile_rays(nx, ny, tile, ti, tj)[2:4]
            pre = f"t{k}_"
            arrs = {n[len(pre):]: v for n, v in a.items() if n.startswith(pre)}
            structures.append(_STRUCTS[kind].from_arrays(tnx * tny, arrs))
        return cls(kind, nx, ny, tile, structures)


def simulate_tiles(stock: DexelWorkpiece, xyz: np.ndarray, slot: np.ndarray, cutters: list, history: str, *,
                   tiles: int, scheduler: str | None = None, workers: int = 2, client: Any = None,
                   progress: bool = False, _on_result: Callable | None = None):
    """Cut a program's stages into ``stock`` tile by tile as Dask tasks; the single-process result, exactly.

    Parameters
    ----------
    stock : DexelWorkpiece
        The stock (not changed).
    xyz, slot, cutters
        The stages' path pieces (:class:`zmap.sim.pieces.Pieces`, or an (n, 3) array of
        stamps in mm), cutter slot per stage, cutters (as :func:`zmap.sim.session.simulate`).
    history : {'none', 'ztrace', 'ttrace', 'treap'}
    tiles : int
        Tile side in rays (at least 2).
    scheduler : str, optional
        A running Dask scheduler's address; default a LocalCluster of ``workers`` processes.
    client : dask.distributed.Client, optional
        Use this client instead.
    progress : bool
        A tqdm bar over the tiles.

    Returns
    -------
    final : DexelWorkpiece
    structure : TiledHistory or None
    report : dict
        ``tiles``, ``tiles_with_positions``, ``workers``, ``seconds`` (tasks), ``positions_cut``
        (sum over tiles: positions reaching several tiles count in each), ``peak_rss_mb_per_worker``.
    """
    from tqdm import tqdm

    from zmap.tiled.cluster import cpu_figures, dask_client, share
    from zmap.tiled.handoff import Handoff, save_arrays

    tile = check_tiles(tiles)
    (ntx, nty), lists = tile_positions(stock, xyz, slot, cutters, tile)
    if tile < SMALL_TILE and ntx * nty > MANY_TILES:  # a task per handful of rays: slower than untiled
        from zmap.fmt import count

        warnings.warn(f"tiles={tile} makes {count(ntx * nty)} tiles of {tile} x {tile} rays, each a Dask task "
                      f"with little work: slower than no tiles and a larger run file; use tiles of "
                      f"{4 * SMALL_TILE} rays or more", stacklevel=2)
    table = cutter_table(cutters)
    pieces = _as_pieces(xyz)
    smove, st0, st1 = pieces.params(0, len(pieces))
    slot = np.ascontiguousarray(slot, dtype=np.int32)
    results: dict[int, dict] = {}
    ctx = contextlib.nullcontext(client) if client is not None else dask_client(scheduler, workers=workers)
    t0 = time.perf_counter()
    wall_start = time.time()
    with ctx as cl:
        n_workers = len(cl.scheduler_info().get("workers", {}))
        futures = {}
        # the busiest tiles first (positions x rays, about the work), so the short ones fill the end
        weight = [len(lists[k]) * min(tile, stock.nx - k // nty * tile) * min(tile, stock.ny - k % nty * tile)
                  for k in range(ntx * nty)]
        # workers on this machine get the program and stock, and give their tiles back,
        # through files (no pickling, no TCP copies); elsewhere the program and the stock go
        # to every worker once, straight from here (not through the scheduler with each task)
        handoff = Handoff.open(cl)
        folder = handoff.path if handoff is not None else None
        try:
            off0, near0, far0 = stock.to_csr()
            arrays = (pieces.kind, pieces.geo, smove, st0, st1, slot, off0, near0, far0)
            if handoff is not None:
                shared = save_arrays(folder, "shared", dict(zip(_SHARED, arrays)))
            else:
                shared = share(cl, arrays)
            for k in sorted(range(ntx * nty), key=lambda k: -weight[k]):
                ti, tj = divmod(k, nty)
                gi0, gj0 = ti * tile, tj * tile
                tnx, tny = min(tile, stock.nx - gi0), min(tile, stock.ny - gj0)
                fut = cl.submit(_sim_tile_of, shared, lists[k], table, history, stock.x0, stock.y0, stock.pitch,
                                gi0, gj0, tnx, tny, stock.ny, folder, pure=False)
                futures[fut] = (k, tnx, tny)
            from dask.distributed import as_completed

            try:
                with tqdm(total=len(futures), unit="tile", desc="tiles", disable=not progress, leave=False) as bar:
                    for fut in as_completed(list(futures)):
                        k, tnx, tny = futures[fut]
                        results[k] = _unpack(fut.result(), history, tnx, tny)
                        bar.update(1)
                        if _on_result is not None:
                            _on_result(cl, len(results))
            except BaseException:
                cl.cancel(list(futures))
                raise
        finally:
            if handoff is not None:
                handoff.close()  # what the results map stays readable until they are dropped
    seconds = time.perf_counter() - t0
    wall_end = time.time()
    final = _assemble(stock, tile, nty, results)
    structure = None
    if history != "none":
        structure = TiledHistory(history, stock.nx, stock.ny, tile, [results[k]["structure"] for k in range(ntx * nty)])
    per_worker: dict[int, float] = {}
    for r in results.values():
        per_worker[r["pid"]] = max(per_worker.get(r["pid"], 0.0), r["peak_rss_mb"])
    report = {"tiles": ntx * nty, "tile": tile, "tiles_with_positions": int(sum(len(v) > 0 for v in lists)),
              "workers": n_workers, "seconds": round(seconds, 3),
              "positions_cut": int(sum(r["positions"] for r in results.values())),
              "rays_cut": int(sum(r["rays_cut"] for r in results.values())),
              "peak_rss_mb_per_worker": round(max(per_worker.values()), 1) if per_worker else 0.0}
    # where the wall time goes: before the first task starts, after the last one ends, and
    # the share of the span the workers spent inside tasks
    spans = [r["wall_span"] for r in results.values() if "wall_span" in r]
    if spans:
        first, last = min(a for a, _ in spans), max(b for _, b in spans)
        busy = sum(b - a for a, b in spans)
        report.update({"first_task_after_s": round(first - wall_start, 3),
                       "results_after_last_task_s": round(wall_end - last, 3),
                       "workers_busy_share": round(busy / max(n_workers, 1) / max(last - first, 1e-9), 3)})
    report.update(cpu_figures(list(results.values())))
    return final, structure, report
