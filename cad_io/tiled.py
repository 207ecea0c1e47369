"""Tiled conversion of a STEP part to a z-map in a zarr store, tile by tile as Dask tasks.

The client reads the part once, meshes it, fixes the grid exactly as :func:`cad_io.sample`
would (same bounds, same deflection), packs the faces (:class:`cad_io._sample_faces._FaceSet`:
plain arrays, no CAD kernel) and ships that to every worker once. Each task samples one
tile of ``tile`` x ``tile`` nodes with the sampler's own kernels (the pair scan restricted to
the tile, :mod:`cad_io._tiled_kernels`; the nodes' coordinates computed as the whole-map
kernel computes them), writes the tile's chunks into the store and then its completion
marker. A worker's memory is bounded by the tile and the packed part, never the map. A
conversion that stops half-way leaves a store that :meth:`zmap.tiled.TiledZMap.open` refuses;
running it again skips the tiles that have their marker.

By default the tasks run on a :class:`dask.distributed.LocalCluster` of worker processes on
this machine; ``scheduler="tcp://host:port"`` sends them to any running Dask cluster (the
workers need zmap installed and the store's folder on a shared file system).
"""

from __future__ import annotations

import contextlib
import os
import time
import warnings
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from zmap.gridspec import GridSpec
from zmap.tiled.cluster import (
    CONNECT_TIMEOUT,
    cpu_figures,
    dask_client,
    peak_rss_mb,
    share,
)

from .part import Part

__all__ = ["DEFAULT_TILE", "CONNECT_TIMEOUT", "TiledGrid", "plan_grid", "sample_tile", "convert_tiled",
           "dask_client"]

#: tile side in grid nodes when none is given (16.7 M nodes, about 0.45 GB of working memory)
DEFAULT_TILE = 4096


@dataclass(frozen=True)
class TiledGrid(GridSpec):
    """The whole map's grid (a :class:`zmap.gridspec.GridSpec`) and what every tile task
    needs to sample its part of it."""

    deflection: float
    axis: str
    method: str
    fine: float | None = None
    #: per face, whether the fine facet pass ray-casts it (:func:`cad_io.sampler.fine_cast`)
    fine_cast: tuple = ()


def plan_grid(part: Part, grid: Any, *, bounds: Sequence[float] | None = None, axis: str = "+z",
              method: str = "auto", deflection: float | None = None) -> TiledGrid:
    """The grid :func:`cad_io.sample` would use for these arguments, without sampling.

    The same steps as ``sample``, by the same code (:mod:`cad_io._sample_plan`: bounds from
    the mesh extents, lines centred on them). Meshes ``part`` at the deflection (as ``sample``
    does) when its meshes are coarser.
    No memory check: the map is never held whole.

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "boss.step")
    >>> g = plan_grid(part, 1.0)
    >>> (g.nx, g.ny) == cad_io.sample(part, 1.0).shape
    True
    """
    from ._sample_plan import mesh_and_place, plan_inputs

    plan = plan_inputs(part, grid, bounds=bounds, axis=axis, method=method, deflection=deflection)
    _vpart, plan = mesh_and_place(part, plan, axis)
    g = plan.spec
    fine = plan.fine
    cast = ()
    if fine is not None:
        from .sampler import fine_cast

        cast = tuple(fine_cast(part, fine).tolist())
    return TiledGrid(g.x0, g.y0, g.dx, g.dy, g.nx, g.ny, plan.deflection, axis, method, fine, cast)


def _face_set(part: Part, g: TiledGrid):
    from .sampler import _face_set as face_set
    from .view import transform_part

    return face_set(transform_part(part, g.axis), g.deflection, g.window)


def sample_tile(part: Part, fs: Any, g: TiledGrid, i0: int, i1: int, j0: int, j1: int,
                stats: dict | None = None) -> tuple[np.ndarray, ...]:
    """Heights, face and method layers of nodes ``[i0:i1, j0:j1]`` of the grid ``g``.

    ``fs`` is the part's face set at ``g.deflection`` (:func:`_face_set`). Equal to the same
    block of ``cad_io.sample(part, ...)`` to the last bit: the same pairs in the same order,
    solved at the same coordinates, and the same second pass of facet answers on a fine
    mesh (``g.fine``) of the faces that may cover them, as ``sample`` makes it.
    """
    from . import _sample_kernels as K
    from . import _tiled_kernels as TK
    from .sampler import _MODE, NEWTON_MAX_ITER, NEWTON_TOL, _run_pairs

    tnx, tny = i1 - i0, j1 - j0
    n = tnx * tny
    zflat = np.full(n, np.nan)
    fflat = np.full(n, -1, dtype=np.int32)
    mflat = np.zeros(n, dtype=np.int8)
    if fs.tris is not None:
        # node coordinates as the whole-map kernels compute them: x0 + i*dx with the global i
        px = np.ascontiguousarray(np.repeat(g.x0 + np.arange(i0, i1, dtype=np.int64) * g.dx, tny))
        py = np.ascontiguousarray(np.tile(g.y0 + np.arange(j0, j1, dtype=np.int64) * g.dy, tnx))
        counts = np.zeros(len(fs.tris), dtype=np.int64)
        TK.count_pairs_tile(fs.nodes, fs.tris, fs.tri_margin, g.x0, g.y0, g.dx, g.dy, g.nx, g.ny, i0, i1, j0, j1,
                            counts)
        mode = _MODE[g.method]

        def fill(t, offsets, gidx, tri_p, w):
            TK.fill_pairs_tile(fs.nodes, fs.tris, fs.tri_margin, t, offsets, g.x0, g.y0, g.dx, g.dy, g.nx, g.ny,
                               i0, i1, j0, j1, gidx, tri_p, w)

        def solve(gidx, tri_p, w, zc, st):
            K.solve_pairs_xy(gidx, tri_p, w, *fs.solve_args(), px, py, mode, NEWTON_TOL, NEWTON_MAX_ITER, zc, st)

        _run_pairs(fs, counts, fill, solve, zflat, fflat, mflat)
        if g.fine is not None:
            from .sampler import FACET, _fine_facets
            from .view import transform_part

            again = np.flatnonzero((mflat == FACET) & (fs.face_mode[np.maximum(fflat, 0)] == 1))
            if stats is not None:
                stats["fine_points"] = int(again.size)
            if again.size:
                gx = g.x0 + (i0 + again // tny) * g.dx  # as sample(): x0 + (global index // ny) * dx
                gy = g.y0 + (j0 + again % tny) * g.dy
                whole = part.get() if isinstance(part, _LazyPart) else part
                z2, f2, m2, _ = _fine_facets(whole, transform_part(whole, g.axis), gx, gy, g.fine, g.deflection,
                                             g.method, g.axis, np.asarray(g.fine_cast, dtype=np.bool_))
                zflat[again], fflat[again], mflat[again] = z2, f2, m2
    return zflat.reshape(tnx, tny), fflat.reshape(tnx, tny), mflat.reshape(tnx, tny)


#: per worker process: the part read from its file and meshed as the client meshed it
_WORKER_PART: dict = {}


def _worker_part(part_path: str, g: TiledGrid) -> Part:
    """The part in this worker, read once per process from the file (not meshed).

    Only a tile that keeps facet answers on exact faces needs it: the second pass meshes the
    faces that may cover them fine, each on a copy, or ray-casts them, as the grid's
    ``fine_cast`` says (the CAD kernel); the pair scan works on the face set the client ships.
    """
    st = os.stat(part_path)
    key = (os.path.abspath(part_path), st.st_mtime_ns, st.st_size, g)
    hit = _WORKER_PART.get(key)
    if hit is None:
        from .step import read_step

        hit = read_step(part_path)
        _WORKER_PART.clear()
        _WORKER_PART[key] = hit
    return hit


class _LazyPart:
    """Stands for the part in :func:`sample_tile` and reads it only when the fine pass asks."""

    def __init__(self, part_path: str, g: TiledGrid):
        self._path, self._g = part_path, g

    def __getattr__(self, name: str) -> Any:
        return getattr(_worker_part(self._path, self._g), name)

    def get(self) -> Part:
        return _worker_part(self._path, self._g)


def _largest_first(todo: list, store: Any) -> list:
    """Tiles in order of decreasing node count, so the short edge tiles fill the end of the run."""
    def nodes(t):
        si, sj = store.tile_slices(*t)
        return (si.stop - si.start) * (sj.stop - sj.start)

    return sorted(todo, key=nodes, reverse=True)


def _tile_task(part_path: str, g: TiledGrid, store: Any, ti: int, tj: int, threads: int, fs: Any) -> dict:
    """One Dask task: sample tile (ti, tj), write it and its marker; returns its figures.

    ``fs`` is the client's face set, sent to each worker once (:func:`zmap.tiled.cluster.share`).
    """
    import numba

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    t0 = time.perf_counter()
    c0 = time.process_time()
    th0 = time.thread_time()
    si, sj = store.tile_slices(ti, tj)
    stats: dict = {"fine_points": 0}
    z, face, how = sample_tile(_LazyPart(part_path, g), fs, g, si.start, si.stop, sj.start, sj.stop, stats)
    store.write_tile(ti, tj, z, {"face": face, "method": how})
    return {"tile": (ti, tj), "nodes": int(z.size), "seconds": time.perf_counter() - t0, **stats,
            "cpu_seconds": time.process_time() - c0, "thread_cpu_seconds": time.thread_time() - th0,
            "filled": int(np.isfinite(z).sum()), "jacobian": int((how == 1).sum()), "facet": int((how == 2).sum()),
            "pid": os.getpid(), "peak_rss_mb": peak_rss_mb()}


def convert_tiled(part: str | os.PathLike, grid: Any, output: str | os.PathLike, *, tile: int = DEFAULT_TILE,
                  bounds: Sequence[float] | None = None, method: str = "auto", axis: str = "+z",
                  deflection: float | None = None, scheduler: str | None = None, workers: int = 2,
                  client: Any = None, progress: bool = False, echo: Any = None, _stop_after: int | None = None):
    """Convert a part to a tiled z-map store, one Dask task per tile; resumes an unfinished store.

    Parameters
    ----------
    part : str or PathLike
        The STEP file. The client reads it to fix the grid; every worker reads it once
        itself (the file must be readable where the workers run).
    grid : float or (float, float)
        Grid interval in mm, as for :func:`cad_io.sample`.
    output : str or PathLike
        Folder of the zarr store to write (``PART.zarr``).
    tile : int
        Tile side in grid nodes (at least the 2-node stencil halo; thousands for speed).
    bounds, method, axis, deflection
        As for :func:`cad_io.sample`; the grid is the one it would use.
    scheduler : str, optional
        Address of a running Dask scheduler; default a LocalCluster of ``workers``
        processes on this machine.
    workers : int
        Worker processes of the LocalCluster.
    client : dask.distributed.Client, optional
        Use this client (and its cluster) instead.
    progress : bool
        A tqdm bar over the tiles (the Dask dashboard shows the tasks too).
    echo : callable, optional
        ``echo(line)`` receives the status lines (dashboard address, tiles to do).

    Returns
    -------
    store : zmap.tiled.TiledZMap
        The finished store.
    report : dict
        ``nodes``, ``tiles``, ``tiles_skipped``, ``tiles_done_now``, ``workers``, ``seconds``
        (the tile tasks, from the first submitted to the last finished), ``nodes_per_s``,
        ``peak_rss_mb_per_worker`` (largest peak RSS of a worker process), ``prepare_seconds``.

    Raises
    ------
    ValueError
        A tile below the halo, bad grid or options.
    zmap.errors.ZMapFileError
        ``output`` is not ours, or holds another grid.
    zmap.errors.ZMapError
        ``scheduler`` does not answer.
    """
    from tqdm import tqdm

    from zmap.tiled import TiledZMap

    t_start = time.perf_counter()
    say = echo or (lambda line: None)
    from zmap.tiled.store import check_tile

    tile = check_tile(tile)
    from .step import read_step

    part_path = os.path.abspath(str(part))
    source = os.path.basename(part_path)
    part = read_step(part_path)
    if not part.faces:
        from zmap.errors import StepImportError

        raise StepImportError(f"{part_path}: no faces in the file")
    g = plan_grid(part, grid, bounds=bounds, axis=axis, method=method, deflection=deflection)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fs = _face_set(part, g)
    msgs = list(part.warnings) + list(fs.msgs)
    meta = {"source": source, "axis": axis, "method": method, "deflection": g.deflection, "faces": len(part.faces),
            "tile": tile, "warnings": msgs}
    store = TiledZMap.create(output, x0=g.x0, y0=g.y0, dx=g.dx, dy=g.dy, nx=g.nx, ny=g.ny, tile=tile, meta=meta,
                             layers={"face": "int32", "method": "int8"}, resume=True)
    todo = [t for t in store.tiles() if not store.tile_done(*t)]
    skipped = store.n_tiles - len(todo)
    prepare = time.perf_counter() - t_start
    results: list[dict] = []
    n_workers = 0
    t_tasks = time.perf_counter()
    seconds = 0.0
    if todo:
        ctx = contextlib.nullcontext(client) if client is not None else dask_client(scheduler, workers=workers)
        with ctx as cl:
            info = cl.scheduler_info()
            n_workers = len(info.get("workers", {}))
            threads = max(1, min(int(w.get("nthreads", 1)) for w in info["workers"].values())) if n_workers else 1
            say(f"dask     {n_workers} workers at {cl.scheduler.address}, dashboard {cl.dashboard_link}")
            say(f"tiles    {len(todo)} of {store.n_tiles} to sample ({skipped} finished before), "
                f"{tile} x {tile} nodes each")
            from dask.distributed import as_completed

            t_tasks = time.perf_counter()
            # the packed faces go to every worker once; a worker reads the file itself only
            # for a fine facet pass
            fs_remote = share(cl, fs)
            futures = [cl.submit(_tile_task, part_path, g, store, ti, tj, threads, fs_remote, pure=False)
                       for ti, tj in _largest_first(todo, store)]
            try:
                with tqdm(total=len(todo), unit="tile", desc="tiles", disable=not progress, leave=False) as bar:
                    for fut in as_completed(futures):
                        results.append(fut.result())
                        bar.update(1)
                        if _stop_after is not None and len(results) >= _stop_after:
                            raise KeyboardInterrupt  # tests: an interruption after some tiles
            except BaseException:
                cl.cancel(futures)
                raise
            seconds = time.perf_counter() - t_tasks
    filled = store.tile_stats()["filled"]
    store.finish({"warnings": msgs + [str(c.message) for c in caught], "filled": filled})
    nodes_now = sum(r["nodes"] for r in results)
    per_worker: dict[int, float] = {}
    for r in results:
        per_worker[r["pid"]] = max(per_worker.get(r["pid"], 0.0), r["peak_rss_mb"])
    report = {"nodes": g.nx * g.ny, "tiles": store.n_tiles, "tiles_skipped": skipped, "tiles_done_now": len(results),
              "workers": n_workers, "seconds": round(seconds, 3), "prepare_seconds": round(prepare, 3),
              "nodes_per_s": round(nodes_now / seconds, 1) if seconds > 0 else 0.0,
              "peak_rss_mb_per_worker": round(max(per_worker.values()), 1) if per_worker else 0.0,
              # tiles whose facet answers on exact faces went through the fine pass, most first
              "fine_pass_tiles": [[*r["tile"], r["fine_points"]] for r in
                                  sorted(results, key=lambda r: -r.get("fine_points", 0)) if r.get("fine_points")]}
    report.update(cpu_figures(results))
    return store, report
