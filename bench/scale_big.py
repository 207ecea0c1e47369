"""The issue-13 run beyond one machine's memory: a real 1.2 m part at a grid of >= 2e9 nodes.

Converts ``--part`` (default OCCT's ``bm2_ec_t4-A.stp``, 1.2 m x 1.45 m) at ``--grid`` mm
(default 0.03: about 1.9e9 nodes, 25 GB of heights and layers before compression, more than
this machine's memory) into the zarr store ``--out`` on a LocalCluster of ``--workers``
worker processes, with a progress bar from the first second. The store is resumable: run
the same command again after an interruption and only the missing tiles are sampled (the
figures of every run are appended to ``OUT.runs.json``).

Then it checks the finished store against the in-memory path: ``--check-points`` random
nodes of the store (everywhere, so empty nodes too) against
:func:`cad_io.sampler.sample_points` at the same node coordinates on the part meshed as the
conversion meshed it (the same kernel the in-memory :func:`cad_io.sample` runs), and
``--check-tiles`` whole tiles against :func:`cad_io.tiled.sample_tile` in this process
(the tiled tests prove ``sample_tile`` equal to ``cad_io.sample`` bit for bit).

Prints one JSON object: ``nodes``, ``tiles``, ``workers``, ``seconds`` (tile tasks, summed
over the runs), ``nodes_per_s``, ``peak_rss_mb_per_worker`` (largest over all runs),
``store_gb_on_disk``, ``map_gb_in_memory`` (what the whole map would need),
``machine_memory_gb``, ``points_checked``, ``points_equal``, ``points_max_abs_dz``,
``tiles_checked``, ``tiles_equal`` (random tiles and the ``--check-fine-tiles`` tiles whose
fine facet pass solved the most points, ``fine_pass_tiles`` and ``fine_pass_points`` in all),
the load averages.

Usage: ``python bench/scale_big.py [--grid 0.03] [--tile 4096] [--out /tmp/zmap-big/bm2.zarr]``
(about 35 min of two free cores on a 2-core laptop; ``--keep`` leaves the store).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PART = ROOT / "data" / "step" / "bm2_ec_t4-A.stp"


def _machine_memory_gb() -> float:
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9


def convert(part: Path, grid: float, tile: int, out: Path, workers: int, memory_limit: str | None) -> dict:
    from cad_io.tiled import convert_tiled
    from zmap.tiled.cluster import dask_client

    say = lambda line: print(line, file=sys.stderr, flush=True)
    load0 = os.getloadavg()[0]
    with dask_client(workers=workers, memory_limit=memory_limit) as client:
        store, rep = convert_tiled(str(part), grid, out, tile=tile, client=client, progress=True, echo=say)
    rep["load_avg_1min_at_start"] = round(load0, 2)
    rep["load_avg_1min_at_end"] = round(os.getloadavg()[0], 2)
    runs_path = out.with_name(out.name + ".runs.json")
    runs = json.loads(runs_path.read_text()) if runs_path.exists() else []
    if rep["tiles_done_now"]:
        runs.append(rep)
        runs_path.write_text(json.dumps(runs, indent=1))
    return {"store": store, "runs": runs}


def check(part_path: Path, store, grid: float, points: int, tiles: int, fine_tiles: int = 2, runs: list = (),
          seed: int = 7) -> dict:
    import cad_io
    from cad_io.sampler import sample_points
    from cad_io.tiled import _face_set, plan_grid, sample_tile

    part = cad_io.read_step(str(part_path))
    g = plan_grid(part, grid)  # meshes the part at the conversion's deflection, as the workers' client did
    assert (g.x0, g.y0, g.nx, g.ny) == (store.x0, store.y0, store.nx, store.ny), "grid differs from the store's"
    rng = np.random.default_rng(seed)
    out: dict = {}
    if points:
        i = rng.integers(0, store.nx, points)
        j = rng.integers(0, store.ny, points)
        order = np.lexsort((j, i))
        i, j = i[order], j[order]
        got = np.asarray(store._array("z").vindex[i, j], dtype=np.float64)
        gx = g.x0 + i * g.dx  # the node coordinates as the whole-map kernels compute them
        gy = g.y0 + j * g.dy
        ref, _face, _how = sample_points(part, gx, gy, deflection=g.deflection, method=g.method, axis=g.axis)
        both = np.isfinite(ref) & np.isfinite(got)
        same_empty = np.isnan(ref) == np.isnan(got)
        out.update({"points_checked": int(points), "points_with_surface": int(np.isfinite(ref).sum()),
                    "points_empty_disagree": int((~same_empty).sum()),
                    "points_equal": int((same_empty & (~both | (ref == got))).sum()),
                    "points_max_abs_dz": float(np.abs(ref[both] - got[both]).max()) if both.any() else 0.0})
    if tiles or fine_tiles:
        fs = _face_set(part, g)
        have = [t for t in store.tiles()]
        pick = [tuple(have[k]) for k in rng.choice(len(have), size=min(tiles, len(have)), replace=False)]
        # and the tiles whose fine pass solved the most points (facet answers on exact faces
        # solved again on fine meshes or by ray casts), as the conversion's runs reported them
        fine = sorted({(int(a), int(b), int(c)) for r in runs for a, b, c in r.get("fine_pass_tiles", [])},
                      key=lambda t: -t[2])
        fine_pick = [t[:2] for t in fine if tuple(t[:2]) not in pick][:fine_tiles]
        out["fine_pass_points"] = int(sum(t[2] for t in fine))
        out["fine_pass_tiles"] = len(fine)
        out["fine_tiles_checked"] = len(fine_pick)
        pick += fine_pick
        same = 0
        t0 = time.perf_counter()
        nodes = 0
        for ti, tj in pick:
            si, sj = store.tile_slices(ti, tj)
            z, f, m = sample_tile(part, fs, g, si.start, si.stop, sj.start, sj.stop)
            nodes += z.size
            box = (si.start, si.stop, sj.start, sj.stop)
            same += bool(np.array_equal(z, store.read(*box), equal_nan=True)
                         and np.array_equal(f, store.read(*box, layer="face"))
                         and np.array_equal(m, store.read(*box, layer="method")))
        secs = time.perf_counter() - t0
        out.update({"tiles_checked": len(pick), "tiles_equal": same,
                    "one_process_nodes_per_s_on_checked_tiles": round(nodes / secs, 1)})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", type=Path, default=PART)
    ap.add_argument("--grid", type=float, default=0.03)
    ap.add_argument("--tile", type=int, default=4096)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("/tmp/zmap-big/bm2.zarr"))
    ap.add_argument("--check-points", type=int, default=20000)
    ap.add_argument("--check-tiles", type=int, default=2)
    ap.add_argument("--check-fine-tiles", type=int, default=2,
                    help="also check this many of the tiles whose fine facet pass solved the most points")
    ap.add_argument("--memory-limit", default=None,
                    help="restart a worker above this RSS (e.g. 3GB) instead of letting the machine run out")
    ap.add_argument("--keep", action="store_true", help="leave the store (default: removed after the check)")
    a = ap.parse_args()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    res = convert(a.part, a.grid, a.tile, a.out, a.workers, a.memory_limit)
    store, runs = res["store"], res["runs"]
    secs = sum(r["seconds"] for r in runs)
    done = sum(r["nodes"] / r["tiles"] * r["tiles_done_now"] for r in runs)  # tile sides vary; about
    out = {"part": a.part.name, "grid_mm": a.grid, "tile": a.tile, "nodes": store.nx * store.ny,
           "tiles": store.n_tiles, "workers": a.workers, "runs": len(runs), "seconds": round(secs, 1),
           "nodes_per_s": round(done / secs, 1) if secs else None,
           "peak_rss_mb_per_worker": max((r["peak_rss_mb_per_worker"] for r in runs), default=None),
           "store_gb_on_disk": round(store.disk_bytes() / 1e9, 2),
           "map_gb_in_memory": round(store.nbytes / 1e9, 2), "machine_memory_gb": round(_machine_memory_gb(), 1),
           "load_avg_1min": [r.get("load_avg_1min_at_start") for r in runs]}
    out.update(check(a.part, store, a.grid, a.check_points, a.check_tiles, a.check_fine_tiles, runs))
    print(json.dumps(out))
    if not a.keep:
        shutil.rmtree(a.out, ignore_errors=True)


if __name__ == "__main__":
    main()
