"""Benchmark of the tiled path: tiled conversion and tiled simulation on Dask.

Conversion: a real 1.2 m x 1.45 m part of ``data/step`` (``bm2_ec_t4-A.stp``, OCCT's test
model) converted at ``--grid`` mm into a zarr store in ``--tile``-node tiles, on a
LocalCluster of 1 worker process and then of 2 (each a fresh store; the JIT caches warmed
by a small conversion first). ``seconds`` and ``nodes_per_s`` are the tile tasks of the
2-worker run (from the first submitted to the last finished); ``peak_rss_mb_per_worker`` the
largest peak RSS of a worker process. With ``--check`` (default when the map fits in a
quarter of the memory) the in-memory conversion is made too and every tile of the
2-worker store is compared with it bit for bit (``tiles_checked``, ``tiles_equal``).

Simulation: ``flower_mold.nc`` (CAMotics example, with the stock and tool of its project) at
``--pitch`` mm with an Interval Treap, once in a single process (its own child process, for
its peak RSS) and once in ``--sim-tiles``-ray tiles on a 2-worker LocalCluster (the result
compared with the single run: final stock and display at 9 stages). ``sim_speedup_2_vs_1``
is the single-process wall time over the 2-worker tiled wall time (both from the parsed
program to the Run); ``sim_rss_ratio`` the 2-worker peak RSS per worker over the single
process's peak RSS.

The machine may be shared: timings are wall-clock, best of one. Because a shared machine
gives two workers no two free cores, the CPU seconds are reported too:
``cpu_split_speedup_2_vs_1`` (``sim_cpu_split_speedup_2_vs_1``) is the single run's CPU
seconds over those of the busiest of the 2 workers, the speed-up were each worker alone on
its core. Prints one JSON object.

Usage: ``python bench/scale.py [--part STEP] [--grid MM] [--deflection MM] [--tile N] [--pitch MM]
[--sim-tiles N] [--no-sim] [--no-convert] [--check/--no-check] [--one-tile X0 Y0]``.
``--one-tile 100 100 --grid 0.25 --tile 4096`` converts one full-size tile on one worker for
its peak RSS (keys ``one_tile_*``). The issue's full figure (>= 2e9 nodes):
``python bench/scale.py --grid 0.03 --tile 4096 --no-check --no-sim`` (1.9e9 nodes, 25 GB of
heights and layers before compression; hours on 2 workers, see docs/scaling.md).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PART = ROOT / "data" / "step" / "bm2_ec_t4-A.stp"
WARM_PART = ROOT / "data" / "boss.step"
PROGRAM = ROOT / "data" / "gcode" / "flower_mold.nc"
PROJECT = ROOT / "data" / "gcode" / "flower_mold.camotics"


def _convert(part, grid: float, tile: int, workers: int, folder: Path, name: str,
             deflection: float | None = None) -> tuple:
    from cad_io.tiled import convert_tiled
    from zmap.tiled.cluster import dask_client

    out = folder / name
    shutil.rmtree(out, ignore_errors=True)
    with dask_client(workers=workers) as client:
        # numba caches and imports loaded on every worker of this cluster, outside the timing (on
        # another part: meshing the measured part twice at two deflections would change its mesh)
        warm = folder / f"warm-{name}"
        convert_tiled(WARM_PART, 2.0, warm, tile=16, client=client)
        shutil.rmtree(warm, ignore_errors=True)
        t = time.perf_counter()
        store, rep = convert_tiled(part, grid, out, tile=tile, client=client, deflection=deflection)
        rep["wall_seconds"] = round(time.perf_counter() - t, 3)
    return store, rep


def bench_convert(part_path: Path, grid: float, tile: int, check: bool | None, deflection: float | None) -> dict:
    import cad_io
    from cad_io.sampler import estimate_bytes
    from zmap.memory import available_bytes

    part = str(part_path)  # each run reads the file (the client, and every worker once)
    folder = Path(tempfile.mkdtemp(prefix="zmap-scale-"))
    try:
        s1, r1 = _convert(part, grid, tile, 1, folder, "one.zarr", deflection)
        shutil.rmtree(s1.path, ignore_errors=True)
        s2, r2 = _convert(part, grid, tile, 2, folder, "two.zarr", deflection)
        out = {"part": part_path.name, "deflection_mm": deflection, "grid_mm": grid, "tile": tile, "nodes": r2["nodes"], "tiles": r2["tiles"],
               "workers": r2["workers"], "seconds": r2["seconds"], "nodes_per_s": r2["nodes_per_s"],
               "seconds_1_worker": r1["seconds"], "nodes_per_s_1_worker": r1["nodes_per_s"],
               "speedup_2_vs_1": round(r1["seconds"] / r2["seconds"], 3) if r2["seconds"] else None,
               "peak_rss_mb_per_worker": r2["peak_rss_mb_per_worker"],
               "peak_rss_mb_per_worker_1_worker": r1["peak_rss_mb_per_worker"],
               "cpu_seconds_1_worker": r1["cpu_seconds"],
               "task_thread_cpu_seconds_1_worker": r1.get("task_thread_cpu_seconds"),
               "task_thread_cpu_seconds_2_workers": r2.get("task_thread_cpu_seconds"),
               "cpu_seconds_busiest_of_2": r2["cpu_seconds_busiest_worker"],
               "cpu_split_speedup_2_vs_1": round(r1["cpu_seconds"] / r2["cpu_seconds_busiest_worker"], 3)
               if r2["cpu_seconds_busiest_worker"] else None,
               "prepare_seconds": r2["prepare_seconds"], "store_mb_on_disk": round(s2.disk_bytes() / 1e6, 1),
               "map_mb_in_memory": round(s2.nbytes / 1e6, 1)}
        fits = estimate_bytes(s2.nx, s2.ny) < 0.25 * available_bytes()
        if check is None:
            check = fits
        if check:
            t = time.perf_counter()
            zm = cad_io.sample(cad_io.read_step(part_path), grid, deflection=deflection)
            out["in_memory_seconds"] = round(time.perf_counter() - t, 3)
            same = 0
            for (ti, tj), z in s2.iter_tiles():
                si, sj = s2.tile_slices(ti, tj)
                same += bool(np.array_equal(z, zm.z[si, sj], equal_nan=True))
            out["tiles_checked"] = s2.n_tiles
            out["tiles_equal"] = same
        else:
            out["tiles_checked"] = 0
            out["tiles_equal"] = 0
        return out
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def bench_one_tile(part_path: Path, grid: float, tile: int, origin: tuple) -> dict:
    """One full tile (``tile`` x ``tile`` nodes from ``origin``) on a 1-worker LocalCluster: its memory."""
    from cad_io.tiled import convert_tiled
    from zmap.tiled.cluster import dask_client

    folder = Path(tempfile.mkdtemp(prefix="zmap-scale-tile-"))
    try:
        x0, y0 = origin
        b = (x0, y0, x0 + (tile - 1) * grid, y0 + (tile - 1) * grid)
        with dask_client(workers=1) as client:
            store, rep = convert_tiled(str(part_path), grid, folder / "tile.zarr", tile=tile, bounds=b,
                                       client=client)
        return {"one_tile_nodes": rep["nodes"], "one_tile_shape": [store.nx, store.ny],
                "one_tile_filled": store.tile_stats()["filled"], "one_tile_seconds": rep["seconds"],
                "one_tile_cpu_seconds": rep["cpu_seconds"], "one_tile_peak_rss_mb": rep["peak_rss_mb_per_worker"]}
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _sim_inputs(pitch: float):
    from zmap.sim.gcode import parse
    from zmap.sim.tools import load_camotics_project

    tools, bounds, _units = load_camotics_project(PROJECT)
    return parse(PROGRAM), bounds, tools, tools[min(tools)]


def sim_child(pitch: float, out_path: str) -> None:
    """The single-process run in its own process: time, peak RSS, and its display at 9 stages."""
    from zmap.sim.session import simulate
    from zmap.tiled.cluster import peak_rss_mb

    prog, bounds, tools, tool = _sim_inputs(pitch)
    simulate(np.array([[1.0, 1.0, -0.5]]), (0, 0, -2, 3, 3, 0), tool="ball:1", pitch=0.25)  # JIT
    t = time.perf_counter()
    c = time.process_time()
    run = simulate(prog, bounds, tools=tools, tool=tool, pitch=pitch, history="treap")
    seconds = time.perf_counter() - t
    cpu = time.process_time() - c
    stages = np.linspace(0, run.n_stages, 9).astype(int)
    off, near, far = run.final.to_csr()
    np.savez(out_path, stages=stages, displays=np.stack([run.display(k) for k in stages]), off=off, near=near,
             far=far)
    print(json.dumps({"seconds": seconds, "cpu_seconds": cpu, "peak_rss_mb": peak_rss_mb(),
                      "n_stages": run.n_stages, "rays": run.stock.n_rays,
                      "history_mb": run.summary["history_bytes"] / 1e6}))


def bench_sim(pitch: float, tiles: int) -> dict:
    from zmap.sim.session import simulate
    from zmap.tiled.cluster import dask_client

    folder = Path(tempfile.mkdtemp(prefix="zmap-scale-sim-"))
    try:
        ref_path = folder / "single.npz"
        child = subprocess.run([sys.executable, __file__, "--sim-child", str(pitch), str(ref_path)], check=True,
                               capture_output=True, text=True)
        single = json.loads(child.stdout.strip().splitlines()[-1])
        prog, bounds, tools, tool = _sim_inputs(pitch)
        with dask_client(workers=2) as client:
            addr = client.scheduler.address
            simulate(prog, bounds, tools=tools, tool=tool, pitch=4.0, tiles=8, scheduler=addr)  # JIT on workers
            t = time.perf_counter()
            run = simulate(prog, bounds, tools=tools, tool=tool, pitch=pitch, history="treap", tiles=tiles,
                           scheduler=addr)
            seconds = time.perf_counter() - t
        ref = np.load(ref_path)
        off, near, far = run.final.to_csr()
        exact = bool(np.array_equal(off, ref["off"]) and np.array_equal(near, ref["near"])
                     and np.array_equal(far, ref["far"])
                     and all(np.array_equal(run.display(int(k)), d, equal_nan=True)
                             for k, d in zip(ref["stages"], ref["displays"])))
        t2 = run.summary["tiles"]
        return {"sim_program": PROGRAM.name, "sim_pitch_mm": pitch, "sim_rays": single["rays"],
                "sim_positions": single["n_stages"], "sim_history_mb": round(single["history_mb"], 1),
                "sim_tiles": t2["tiles"], "sim_tile_rays": tiles,
                "sim_seconds_single": round(single["seconds"], 3), "sim_seconds_2_workers": round(seconds, 3),
                "sim_task_seconds_2_workers": t2["seconds"],
                "sim_speedup_2_vs_1": round(single["seconds"] / seconds, 3),
                "sim_peak_rss_mb_single": round(single["peak_rss_mb"], 1),
                "sim_peak_rss_mb_per_worker": t2["peak_rss_mb_per_worker"],
                "sim_rss_ratio": round(t2["peak_rss_mb_per_worker"] / single["peak_rss_mb"], 3),
                "sim_positions_cut_over_tiles": t2["positions_cut"], "sim_ray_cuts": t2["rays_cut"],
                "sim_ray_cuts_per_s_per_worker": round(t2["rays_cut"] / t2["seconds"] / max(t2["workers"], 1), 1),
                "sim_cpu_seconds_single": round(single["cpu_seconds"], 3),
                "sim_task_thread_cpu_seconds_2_workers": t2.get("task_thread_cpu_seconds"),
                "sim_cpu_seconds_2_workers": t2.get("cpu_seconds"),
                "sim_cpu_seconds_busiest_of_2": t2["cpu_seconds_busiest_worker"],
                "sim_cpu_split_speedup_2_vs_1": round(single["cpu_seconds"] / t2["cpu_seconds_busiest_worker"], 3)
                if t2["cpu_seconds_busiest_worker"] else None,
                "sim_first_task_after_s": t2.get("first_task_after_s"),
                "sim_results_after_last_task_s": t2.get("results_after_last_task_s"),
                "sim_workers_busy_share": t2.get("workers_busy_share"),
                "sim_exact": exact}
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--sim-child":
        sim_child(float(sys.argv[2]), sys.argv[3])
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grid", type=float, default=0.5, help="conversion grid, mm (default 0.5: 7 M nodes)")
    ap.add_argument("--part", type=Path, default=PART, help="STEP part (default data/step/bm2_ec_t4-A.stp)")
    ap.add_argument("--deflection", type=float, default=None, help="mesh deflection, mm (default grid/20)")
    ap.add_argument("--tile", type=int, default=512, help="conversion tile side, nodes (default 512: 30 tiles at 0.5 mm, so 2 workers share them evenly)")
    ap.add_argument("--pitch", type=float, default=0.05, help="simulation ray pitch, mm")
    ap.add_argument("--sim-tiles", type=int, default=256, help="simulation tile side, rays")
    ap.add_argument("--one-tile", nargs=2, type=float, default=None, metavar=("X0", "Y0"),
                    help="instead: one --tile x --tile tile from (X0, Y0) on 1 worker, for its memory")
    ap.add_argument("--no-sim", action="store_true")
    ap.add_argument("--no-convert", action="store_true")
    ap.add_argument("--check", dest="check", action="store_true", default=None)
    ap.add_argument("--no-check", dest="check", action="store_false")
    a = ap.parse_args()
    out: dict = {"cpu_count": os.cpu_count(), "load_avg_1min_at_start": round(os.getloadavg()[0], 2)}
    if a.one_tile is not None:
        out.update(bench_one_tile(a.part, a.grid, a.tile, tuple(a.one_tile)))
        print(json.dumps(out))
        return
    if not a.no_convert:
        out.update(bench_convert(a.part, a.grid, a.tile, a.check, a.deflection))
    if not a.no_sim:
        out.update(bench_sim(a.pitch, a.sim_tiles))
    out["load_avg_1min_at_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
