"""Benchmark of the decimated meshes (paper 003, local mesh decimation).

The die: a 1025 x 1025 map on a 0.1 mm grid (102.4 mm square), a smooth dome with waves,
a raised plateau and a sunk pocket whose sides are eight vertical 5 mm walls (each a step
between two nodes). At the allowance of 0.01 mm it is decimated whole
(:func:`zmap.mesh.decimate`, 64 x 64 cell regions) and by pydelatin (one Delatin over the
whole map, when installed): triangles, seconds (best of 3, JIT warmed up) and the true
maximum vertical error at every node, measured (:func:`zmap.mesh.decimate.max_error`, also
applied to pydelatin's mesh, whose heights are float32). ``crack_rays``: random vertical rays (100,000) through the
domain that miss the mesh or hit it twice. ``region_ms_die_median``: re-meshing one 64 x 64
region of the die (its sides included), median over the 256 regions, and pydelatin's time
for the same regions. ``decimatepro_*``: the paper's own method (VTK DecimatePro per
region, region borders kept), with its measured vertical error.

``local_update_ms``: a real run, flower_mold.nc with the stock and tools of its .camotics
project (rays at 0.26 mm, treap history), followed by :class:`zmap.mesh.LocalMesh`
(64 x 64 regions, allowance 0.01 mm, decimation period ``--period``, default 8: touched
regions updated incrementally, re-decimated afresh every 8th update) in stage ranges of
``--step`` positions from the stock to the end: the median time of re-meshing the regions
a range touched (ranges that touched none left out), with its 90th percentile and mean,
the regions per update, the triangles at the end against a fresh decimation of the end,
and the same figures with ``period=1`` (every update decimates afresh:
``local_period1``); reading the run's display image is reported apart
(``local_display_ms_median``). ``local_scrub_*``: from the end back to half way and
forward again (regions touched, triangles, ms). ``local_end_region_*``: decimating one
region of the finished part afresh, ours and pydelatin's (median of the 16).

Usage: ``python bench/mesh.py [--step N] [--period S] [--no-real]``; prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from zmap.grid import ZMap
from zmap.mesh import LocalMesh, decimate
from zmap.mesh.decimate import _Regions, crack_rays, max_error

ALLOWANCE = 0.01
REGION = 64
DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"


def die(n: int = 1025, h: float = 0.1) -> ZMap:
    """The bench die: smooth, with eight vertical walls of 5 mm."""
    x = np.arange(n) * h
    X, Y = np.meshgrid(x, x, indexing="ij")
    z = 20.0 + 12.0 * np.exp(-((X - 55.0) ** 2 + (Y - 48.0) ** 2) / 900.0)
    z += 0.8 * np.sin(X / 9.0) * np.cos(Y / 11.0)
    plateau = (X > 12.05) & (X < 40.05) & (Y > 14.05) & (Y < 38.05)
    pocket = (X > 60.05) & (X < 88.05) & (Y > 62.05) & (Y < 90.05)
    z = z + 5.0 * plateau - 5.0 * pocket
    return ZMap(0.0, 0.0, h, h, z)


def best(f, repeat: int = 3):
    out, t_best = None, float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        t_best = min(t_best, time.perf_counter() - t)
    return out, t_best


def pydelatin_figures(zm: ZMap) -> dict:
    try:
        from pydelatin import Delatin
    except ImportError:
        return {"pydelatin": "pydelatin not installed"}
    from zmap.mesh.decimate import _measure

    arr = np.ascontiguousarray(zm.z.T)  # rows along y, as pydelatin reads an image
    Delatin(arr[:65, :65].copy(), max_error=ALLOWANCE)
    d, t = best(lambda: Delatin(arr, max_error=ALLOWANCE))
    v = np.asarray(d.vertices)
    # pydelatin's vertices: x = column, y = rows counted from the last one (image up)
    ny = zm.z.shape[1]
    nodes = np.rint(v[:, 0]).astype(np.int64) * ny + (ny - 1 - np.rint(v[:, 1]).astype(np.int64))
    err = _measure(zm.z, nodes, np.asarray(d.triangles, dtype=np.int32))
    # one 64 x 64 region at a time, as LocalMesh re-meshes them
    ms = []
    n = zm.z.shape[0]
    for i0 in range(0, n - 1, REGION):
        for j0 in range(0, n - 1, REGION):
            sub = np.ascontiguousarray(arr[j0:j0 + REGION + 1, i0:i0 + REGION + 1])
            _, tr = best(lambda: Delatin(sub, max_error=ALLOWANCE), 3)
            ms.append(1000 * tr)
    return {"pydelatin_triangles": int(len(d.triangles)), "pydelatin_seconds": round(t, 4),
            "pydelatin_max_err": round(float(err), 6),
            "pydelatin_region_ms_median": round(float(np.median(ms)), 4)}


def region_ms(zm: ZMap) -> float:
    reg = _Regions(zm.z, ALLOWANCE, REGION)
    todo = reg.all_regions()
    reg.remesh(todo)
    ms = []
    for k in range(len(todo)):
        one = todo[k:k + 1]
        _, t = best(lambda: reg.remesh(one), 3)
        ms.append(1000 * t)
    return round(float(np.median(ms)), 4)


def follow(run, step: int, period: int) -> tuple[LocalMesh, dict]:
    """LocalMesh following ``run`` in stage ranges of ``step`` positions; update figures."""
    warm = LocalMesh(run, allowance=ALLOWANCE, region=REGION, period=period)
    warm.goto(step), warm.goto(0)
    lm = LocalMesh(run, allowance=ALLOWANCE, region=REGION, period=period)
    ms, regions, disp = [], [], []
    for k in list(range(step, run.n_stages, step)) + [run.n_stages]:
        c = lm.goto(k)
        disp.append(c["display_ms"])
        if c["regions_touched"]:
            ms.append(c["ms"])
            regions.append(c["regions_touched"])
    ms_a, reg_a = np.array(ms), np.array(regions)
    return lm, {
        "update_ms": round(float(np.median(ms_a)), 4),
        "update_ms_p90": round(float(np.percentile(ms_a, 90)), 4),
        "update_ms_mean": round(float(np.mean(ms_a)), 4),
        "regions_per_update_median": float(np.median(reg_a)),
        "updates": len(ms), "updates_touching_none": len(disp) - len(ms),
        "display_ms_median": round(float(np.median(disp)), 4),
        "triangles_end": int(lm.n_triangles),
        "max_err_end": round(lm.max_error(), 7),
    }


def local_figures(step: int, period: int) -> dict:
    from zmap.sim.session import simulate
    from zmap.sim.tools import load_camotics_project

    nc, project = DATA / "flower_mold.nc", DATA / "flower_mold.camotics"
    if not nc.exists():
        return {"local_update": f"{nc} not found"}
    tools, bounds, _units = load_camotics_project(project)
    default = tools[min(tools)] if tools else None
    run = simulate(nc, bounds, tool=default, tools=tools, pitch=0.26, history="treap")
    lm, f = follow(run, step, period)
    _, f1 = follow(run, step, 1)
    fresh_end = LocalMesh(run.display("end"), allowance=ALLOWANCE, region=REGION).n_triangles
    # scrubbing: from the end back to half way and forward to the end again
    scrub = [lm.goto(run.n_stages // 2), lm.goto(run.n_stages)]
    scrub_err = lm.max_error()
    # the 16 regions of the finished part, one at a time, afresh: ours and pydelatin's
    reg = _Regions(lm.z, ALLOWANCE, REGION)
    reg.remesh(reg.all_regions())
    ours, theirs = [], []
    try:
        from pydelatin import Delatin
    except ImportError:
        Delatin = None
    for one in reg.all_regions():
        one = one[None, :]
        _, t = best(lambda: reg.remesh(one), 3)
        ours.append(1000 * t)
        i0, j0 = int(one[0, 0]) * REGION, int(one[0, 1]) * REGION
        sub = np.ascontiguousarray(reg.z[i0:i0 + REGION + 1, j0:j0 + REGION + 1].T)
        if Delatin is not None and sub.shape[0] > 1 and sub.shape[1] > 1 and not np.isnan(sub).any():
            _, t = best(lambda: Delatin(sub, max_error=ALLOWANCE), 3)
            theirs.append(1000 * t)
    return {
        "local_update_ms": f["update_ms"],
        "local_period": period,
        "local_step_positions": step,
        "local_rays": [int(run.stock.nx), int(run.stock.ny)],
        "local_regions": [int(lm._reg.nrx), int(lm._reg.nry)],
        **{f"local_{k}": v for k, v in f.items() if k != "update_ms"},
        "local_fresh_triangles_end": int(fresh_end),
        "local_period1": f1,
        "local_scrub_end_to_half": {k: scrub[0][k] for k in ("stage", "regions_touched", "triangles", "ms")},
        "local_scrub_half_to_end": {k: scrub[1][k] for k in ("stage", "regions_touched", "triangles", "ms")},
        "local_scrub_max_err": round(scrub_err, 7),
        "local_end_region_ms_median": round(float(np.median(ours)), 4),
        "local_end_region_pydelatin_ms_median": round(float(np.median(theirs)), 4) if theirs else None,
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=int, default=20, help="positions per stage range (20)")
    ap.add_argument("--period", type=int, default=8, help="LocalMesh decimation period (8)")
    ap.add_argument("--no-real", action="store_true", help="skip the real run")
    args = ap.parse_args(argv)
    zm = die()
    decimate(zm.z[:130, :130], ALLOWANCE)  # JIT warm-up
    mesh, t = best(lambda: decimate(zm, ALLOWANCE, region=REGION))
    result = {
        "map": [int(s) for s in zm.z.shape], "grid_mm": zm.dx, "allowance": ALLOWANCE, "region": REGION,
        "triangles": int(mesh.n_faces), "vertices": int(mesh.n_vertices),
        "max_err": round(max_error(mesh, zm), 6), "seconds": round(t, 4),
        "crack_rays": crack_rays(mesh, zm, 100_000, seed=1),
        "region_ms_die_median": region_ms(zm),
    }
    result.update(pydelatin_figures(zm))
    try:
        from zmap.mesh.decimate import decimate_pro

        t = time.perf_counter()
        mp = decimate_pro(zm, ALLOWANCE, region=REGION)
        result.update({"decimatepro_triangles": int(mp.n_faces),
                       "decimatepro_max_err": round(max_error(mp, zm), 6),
                       "decimatepro_seconds": round(time.perf_counter() - t, 3),
                       "decimatepro_crack_rays": crack_rays(mp, zm, 100_000, seed=1)})
    except ImportError:
        result["decimatepro"] = "VTK not installed"
    if not args.no_real:
        result.update(local_figures(args.step, args.period))
    checks = {"max_err<=allowance": result["max_err"] <= ALLOWANCE, "crack_rays==0": result["crack_rays"] == 0}
    if "pydelatin_triangles" in result:
        checks["triangles<=1.2x_pydelatin"] = result["triangles"] <= 1.2 * result["pydelatin_triangles"]
        checks["seconds<=pydelatin"] = result["seconds"] <= result["pydelatin_seconds"]
    if "local_update_ms" in result:
        checks["local_update_ms<=1"] = result["local_update_ms"] <= 1.0
    result["checks"] = checks
    print(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
