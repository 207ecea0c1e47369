"""Benchmark of the NC simulation with history (papers 000 and 001, section 5 of each).

The bench program (bench/make_mould_program.py): a 107x72x33 mm stock, a 3 mm ball cutter,
rays at 0.26 mm, about 17,000 moves mostly 0.5 mm long. Real workloads: flower_mold.nc and
cameo.nc from data/gcode with the stock and tools of their .camotics projects.

For each history kind the program is simulated (JIT warmed up first) several times,
interleaved, and the best time is kept (``seconds`` of the run: cutting with in-kernel
recording plus finalising the history; parsing and DDA are reported apart).
``time_treap_traversal`` is the paper's own treap update (the treap as the only workpiece,
traversed from the roots, :func:`zmap.sim.history.treap.simulate_treap`). Reconstruction
(``Run.reconstruct``: treap; ``reconstruct_ms_ztrace``: z-trace) and display
(``Run.display``: treap; ``display_ms_ttrace``, ``display_ms_ztrace``) are timed at stages
1/10, 1/4, 1/2, 3/4 and the end, best of 5.

``exact``: how close the simulated stock is to the exact sweep of the program, for
flower_mold.nc (its .camotics stock, cut with a 6.35 mm ball) and the relief program
(bench/make_relief_program.py: 71,000 moves, 3D ramps, helices, G18/G19 arcs, a 2.5 mm flat
and a 6 mm bull nose): at 3,000 random cut rays (seeded) the simulated top (float32, rounded
up) against the top of an independent reference that samples the path densely
(bench/exact_sweep.py): ``exact_max_err_mm``, ``exact_share_over_1um``,
``exact_max_deeper_mm`` (how far the simulated stock lies below the reference; ~0), the same
for a float64 HeightField cut (``exact_max_err_f64_mm``), and rays the simulation left uncut.

``fine``: flower_mold.nc (its .camotics tool) at 0.05 mm and the relief program at 0.1 mm
(``relief_fine_pitch``; 0.05 mm would take about 8 times as long), untiled, one process, treap history,
in stages of one pitch (``fine_*``) and of one move (``fine_move_*``): seconds of
``simulate`` (wall, ``fine_s``; cutting and recording, ``fine_cut_s``), peak memory of the
process (``fine_peak_mb``, each case in a fresh child process) and history size.
Prints one JSON object.

Usage: ``python bench/simulate.py [--repeat N] [--no-real] [--quick]`` (``--quick``: a smoke
run: one repeat, no real programs, 200 rays, the fine cases at 0.26 mm).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from exact_sweep import RayReference  # noqa: E402
from make_mould_program import STOCK, TOOL, write_mould_program  # noqa: E402
from make_relief_program import STOCK as RELIEF_STOCK  # noqa: E402
from make_relief_program import TOOLS as RELIEF_TOOLS  # noqa: E402
from make_relief_program import write_relief_program  # noqa: E402

from zmap.grid import ZMap  # noqa: E402
from zmap.sim.gcode import parse  # noqa: E402
from zmap.sim.heightfield import HeightField  # noqa: E402
from zmap.sim.history.treap import simulate_treap  # noqa: E402
from zmap.sim.path import positions  # noqa: E402
from zmap.sim.pieces import Pieces  # noqa: E402
from zmap.sim.session import simulate  # noqa: E402
from zmap.sim.tools import load_camotics_project, load_tool_table, parse_tool_spec  # noqa: E402

PITCH = 0.26
FRACTIONS = (0.1, 0.25, 0.5, 0.75, 1.0)
KINDS = ("none", "ztrace", "ttrace", "treap")
DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
FLOWER_BALL = "ball:6.35"  # the exactness check cuts flower_mold.nc with a 1/4" ball
EXACT_RAYS = 3000
FINE_PITCH = 0.05
RELIEF_FINE_PITCH = 0.1  # at 0.05 mm: ~8x the rays x stages of 0.1 mm (52 s there), minutes
WARM_PROGRAM = "G0 Z1\nG0 X1 Y1\nG1 Z-0.5 F100\nG1 X2 Y1.5 Z-0.7\nG2 X3 Y1.5 I0.5 J0 Z-0.6\n"


def _best_ms(f, repeat: int = 5) -> float:
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t)
    return round(1000.0 * best, 3)


def _warm_up() -> None:
    xyz = np.array([[1.0, 1.0, -0.5], [1.5, 1.0, -0.7], [2.0, 1.2, -0.2]])
    for h in KINDS:
        run = simulate(xyz, (0, 0, -2, 3, 3, 0), tool="ball:1", pitch=0.25, history=h)
        run.reconstruct(1), run.display(1)
    for tool in ("ball:1", "flat:1", "bull:1:0.2"):  # the swept pieces: lines and arcs
        for st in ("pitch", "move"):
            simulate(WARM_PROGRAM, (0, 0, -2, 4, 3, 0), tool=tool, pitch=0.25, history="treap", stages=st)


def figures(program_path: str | Path, stock, tool, tools, repeat: int) -> dict:
    """All figures for one program."""
    t = time.perf_counter()
    prog = parse(program_path, tool_table=tools or None)
    t_parse = time.perf_counter() - t
    t = time.perf_counter()
    pos = positions(prog, pitch=PITCH)
    t_dda = time.perf_counter() - t
    runs: dict = {}
    times: dict = {h: [] for h in KINDS}
    for _ in range(repeat):
        for h in KINDS:
            run = simulate(pos, stock, tool=tool, tools=tools, pitch=PITCH, history=h)
            times[h].append(run.summary["seconds"])
            runs[h] = run
    # the paper's own treap update: traversal from the roots pruned by conditions (1), (2)
    r0 = runs["treap"]
    t_trav = []
    for _ in range(repeat):
        t = time.perf_counter()
        it = simulate_treap(r0.stock, r0.pieces, r0.cutters, r0.slot)
        t_trav.append(time.perf_counter() - t)
    n = runs["none"].n_stages
    stages = [int(round(f * n)) for f in FRACTIONS]
    tr, zt, tt = runs["treap"], runs["ztrace"], runs["ttrace"]
    out = {
        "moves": int(len(prog.moves)),
        "positions": int(n),
        "rays": int(tr.stock.n_rays),
        "stages": stages,
        "seconds_parse": round(t_parse, 3),
        "seconds_positions": round(t_dda, 3),
    }
    for h in KINDS:
        out[f"time_{h}"] = round(min(times[h]), 4)
    out["time_treap_traversal"] = round(min(t_trav), 4)
    out["treap_traversal_same_nodes"] = bool(np.array_equal(it.kids, r0.structure.kids))
    for h in ("ztrace", "ttrace", "treap"):
        out[f"bytes_{h}"] = int(runs[h].summary["history_bytes"])
    out["elements_ztrace"] = int(zt.summary["history_elements"])
    out["elements_ttrace"] = int(tt.summary["history_elements"])
    out["nodes_treap"] = int(tr.summary["history_elements"])
    out["bytes_dexels_final"] = int(tr.final.nbytes)
    out["dexels_created"] = int(tr.summary["dexels_created"])
    out["dexels_deleted"] = int(tr.summary["dexels_deleted"])
    out["reconstruct_ms"] = [_best_ms(lambda k=k: tr.reconstruct(k)) for k in stages]
    out["display_ms"] = [_best_ms(lambda k=k: tr.display(k)) for k in stages]
    out["reconstruct_ms_ztrace"] = [_best_ms(lambda k=k: zt.reconstruct(k)) for k in stages]
    out["display_ms_ztrace"] = [_best_ms(lambda k=k: zt.display(k)) for k in stages]
    out["display_ms_ttrace"] = [_best_ms(lambda k=k: tt.display(k)) for k in stages]
    out["replay_ms_none"] = [_best_ms(lambda k=k: runs["none"].reconstruct(k), 1) for k in stages[:-1]]
    # exactness at the sampled stages: every history agrees with the replay
    out["histories_agree"] = bool(all(
        tr.reconstruct(k).same_as(zt.reconstruct(k)) and tr.reconstruct(k).same_as(runs["none"].reconstruct(k))
        and np.array_equal(tr.display(k), tt.display(k), equal_nan=True) for k in stages))
    out["treap_height"] = tr.structure.heights()
    none = out["time_none"]
    out["ratios"] = {
        "ztrace_over_none": round(out["time_ztrace"] / none, 3),
        "ttrace_over_none": round(out["time_ttrace"] / none, 3),
        "treap_over_none": round(out["time_treap"] / none, 3),
        "treap_traversal_over_none": round(out["time_treap_traversal"] / none, 3),
        "treap_bytes_over_traces": round(out["bytes_treap"] / (out["bytes_ztrace"] + out["bytes_ttrace"]), 3),
    }
    return out


def _cutters(numbers, tools, default) -> list:
    return [tools.get(int(n), default) for n in numbers]


def exact_figures(program_path: str | Path, stock, tool, tools, *, n_rays: int = EXACT_RAYS,
                  n_uncut: int = 300, seed: int = 0, pitch: float = PITCH) -> dict:
    """How close the simulated final stock is to the exact sweep, at random rays.

    The rays are drawn (seeded) from those the simulation cut; ``n_uncut`` more from those
    it left uncut though a cutting move's box grown by the tool's radius holds them (a
    missed cut shows there). The reference is :class:`exact_sweep.RayReference`.
    """
    tools = dict(tools or {})
    default = parse_tool_spec(tool) if isinstance(tool, str) else tool
    prog = parse(program_path, tool_table=tools or None)
    z1 = float(stock[5])
    run = simulate(prog, stock, tool=default, tools=tools, pitch=pitch, history="none")
    run_move = simulate(prog, stock, tool=default, tools=tools, pitch=pitch, history="none", stages="move")
    wp = run.final
    top = wp.top().ravel()
    top_move = run_move.final.top().ravel()
    ref = RayReference(prog.moves, tools, default, stock)
    rng = np.random.default_rng(seed)
    cut = np.flatnonzero(top < z1)
    pick = np.sort(rng.choice(cut, min(n_rays, cut.size), replace=False))
    # uncut rays within reach of a cutting move
    reach = np.zeros((wp.nx, wp.ny), dtype=bool)
    box = ref.box
    ia = np.clip(np.ceil((box[:, 0] - wp.x0) / wp.pitch), 0, wp.nx).astype(int)
    ib = np.clip(np.floor((box[:, 2] - wp.x0) / wp.pitch) + 1, 0, wp.nx).astype(int)
    ja = np.clip(np.ceil((box[:, 1] - wp.y0) / wp.pitch), 0, wp.ny).astype(int)
    jb = np.clip(np.floor((box[:, 3] - wp.y0) / wp.pitch) + 1, 0, wp.ny).astype(int)
    for a, b, c, d in zip(ia, ib, ja, jb):
        reach[a:b, c:d] = True
    uncut = np.flatnonzero(reach.ravel() & ~(top < z1))
    pick_uncut = np.sort(rng.choice(uncut, min(n_uncut, uncut.size), replace=False))
    t = time.perf_counter()
    rays = np.concatenate([pick, pick_uncut])
    i, j = np.divmod(rays, wp.ny)
    qx, qy = wp.x0 + i * wp.pitch, wp.y0 + j * wp.pitch
    got = [ref.top(x, y) for x, y in zip(qx, qy)]
    t_ref = time.perf_counter() - t
    zref = np.array([g[0] for g in got])
    line = np.array([g[1] for g in got])
    # the same rays of a float64 height field cut along the same pieces
    t = time.perf_counter()
    pos = positions(prog, pitch=pitch)
    numbers = np.unique(pos.tool)
    slot = np.searchsorted(numbers, pos.tool).astype(np.int32)
    hf = HeightField(ZMap(wp.x0, wp.y0, wp.pitch, wp.pitch, np.full((wp.nx, wp.ny), z1)))
    hf.cut(Pieces.of(pos), _cutters(numbers, tools, default), slot)
    t_hf = time.perf_counter() - t

    def diff(a, b):  # a - b, NaN (no material left) equal to NaN
        d = a - b
        both = np.isnan(a) & np.isnan(b)
        return np.where(both, 0.0, np.where(np.isnan(d), np.inf, d))

    n = pick.size
    err = diff(top[rays], zref)
    err64 = diff(hf.z.ravel()[rays], zref)
    deeper = -err[:n]
    out = {
        "exact_tool": tool if isinstance(tool, str) else None,
        "exact_tools": {str(k): f"{c.kind}:{c.diameter:g}" + (f":{c.corner_radius:g}" if c.kind == "bull" else "")
                        for k, c in tools.items()},
        "exact_pitch": pitch,
        "exact_rays_checked": int(n),
        "exact_max_err_mm": float(np.abs(err[:n]).max()),
        "exact_share_over_1um": round(float(np.mean(np.abs(err[:n]) > 1e-3)), 6),
        "exact_max_deeper_mm": float(max(deeper.max(), 0.0)),
        "exact_max_err_f64_mm": float(np.abs(err64[:n]).max()),
        "exact_max_deeper_f64_mm": float(max((-err64[:n]).max(), 0.0)),
        "exact_uncut_rays_checked": int(pick_uncut.size),
        "exact_uncut_max_err_mm": float(np.abs(err[n:]).max()) if pick_uncut.size else 0.0,
        "exact_move_stages_max_diff_mm": float(np.abs(diff(top_move, top)).max()),
        "exact_seconds_reference": round(t_ref, 2),
        "exact_seconds_heightfield": round(t_hf, 2),
    }
    k = int(np.argmax(np.abs(err)))
    out["exact_worst"] = {"x": round(float(qx[k]), 4), "y": round(float(qy[k]), 4), "sim": float(top[rays[k]]),
                          "ref": float(zref[k]), "line": int(line[k])}
    bad = np.flatnonzero(-err > 1e-6)
    bad = bad[np.argsort(err[bad])][:5]
    out["exact_deeper_rays"] = [{"x": round(float(qx[b]), 4), "y": round(float(qy[b]), 4),
                                 "deeper_mm": float(-err[b]), "ref_line": int(line[b])} for b in bad]
    return out


def _fine_child(spec: dict) -> dict:
    """One fine case in this (fresh) process: seconds and peak memory of ``simulate``."""
    tools = {}
    if spec.get("camotics"):
        tools, _bounds, _units = load_camotics_project(spec["camotics"])
    if spec.get("tool_table"):
        tools = load_tool_table(spec["tool_table"])
    tool = spec.get("tool") or (tools[min(tools)] if tools else None)
    for st in ("pitch", "move"):  # JIT (compiled or from the cache) before timing
        simulate(WARM_PROGRAM, (0, 0, -2, 4, 3, 0), tool=tool or "ball:1", tools=tools, pitch=0.25,
                 history="treap", stages=st)
    prog = parse(spec["program"], tool_table=tools or None)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t = time.perf_counter()
    run = simulate(prog, spec["stock"], tool=tool, tools=tools, pitch=spec["pitch"], history="treap",
                   stages=spec["stages"])
    wall = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {"s": round(wall, 3), "cut_s": run.summary["seconds"], "peak_mb": round(peak, 1),
            "base_mb": round(base, 1), "history_mb": round(run.summary["history_bytes"] / 2**20, 1),
            "history_elements": int(run.summary["history_elements"]), "positions": int(run.n_stages),
            "rays": int(run.final.n_rays)}


def fine_figures(program: str | Path, stock, *, pitch: float, tool: str | None = None,
                 camotics: str | Path | None = None, tool_table: str | Path | None = None) -> dict:
    """The fine case in both stage modes, each in a child process (its own peak memory)."""
    out: dict = {"fine_pitch": pitch}
    for st, key in (("pitch", "fine"), ("move", "fine_move")):
        spec = {"program": str(program), "stock": list(stock), "pitch": pitch, "stages": st, "tool": tool,
                "camotics": str(camotics) if camotics else None,
                "tool_table": str(tool_table) if tool_table else None}
        done = subprocess.run([sys.executable, __file__, "--fine-child", json.dumps(spec)],
                              capture_output=True, text=True)
        if done.returncode != 0:
            out[f"{key}_error"] = done.stderr.strip().splitlines()[-1:] or [f"exit {done.returncode}"]
            continue
        got = json.loads(done.stdout.strip().splitlines()[-1])
        out.update({f"{key}_{k}": v for k, v in got.items()})
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--quick", action="store_true", help="a smoke run: the slow parts skipped or small")
    ap.add_argument("--fine-child", metavar="JSON", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.fine_child:
        got = _fine_child(json.loads(args.fine_child))
        print(json.dumps(got))
        return got
    if args.quick:
        args.repeat, args.no_real = 1, True
    _warm_up()
    with tempfile.TemporaryDirectory() as tmp:
        prog = write_mould_program(os.path.join(tmp, "mould.nc"))
        result = {"program": "bench/make_mould_program.py", "stock": list(STOCK), "tool": TOOL, "pitch": PITCH}
        result.update(figures(prog, STOCK, parse_tool_spec(TOOL), None, args.repeat))
        relief = write_relief_program(os.path.join(tmp, "relief.nc"), tool_table=os.path.join(tmp, "relief.toml"))
        relief_tools = load_tool_table(os.path.join(tmp, "relief.toml"))
        flower, flower_project = DATA / "flower_mold.nc", DATA / "flower_mold.camotics"
        _tools, flower_stock, _units = load_camotics_project(flower_project)
        n_rays = 200 if args.quick else EXACT_RAYS
        result["relief"] = {"program": "bench/make_relief_program.py", "stock": list(RELIEF_STOCK),
                            "tools": {str(k): v for k, v in RELIEF_TOOLS.items()},
                            "moves": int(parse(relief, tool_table=relief_tools).n_moves)}
        result["exact"] = {
            "flower_mold": exact_figures(flower, flower_stock, FLOWER_BALL, None, n_rays=n_rays),
            "relief": exact_figures(relief, RELIEF_STOCK, None, relief_tools, n_rays=n_rays),
        }
        fine_pitch = PITCH if args.quick else FINE_PITCH
        relief_pitch = PITCH if args.quick else RELIEF_FINE_PITCH
        result["fine"] = {
            "flower_mold": fine_figures(flower, flower_stock, pitch=fine_pitch, camotics=flower_project),
            "relief": {"relief_fine_pitch": relief_pitch,
                       **fine_figures(relief, RELIEF_STOCK, pitch=relief_pitch,
                                      tool_table=os.path.join(tmp, "relief.toml"))},
        }
        if not args.quick:
            result["fine"]["relief"]["relief_fine_note"] = (
                f"at {RELIEF_FINE_PITCH} mm, not {FINE_PITCH} mm: {FINE_PITCH} mm has 4x the rays and "
                "2x the stages, estimated at about 8x the time at 0.1 mm (over the 60 s budget)")
    r = result["ratios"]
    result["targets"] = {
        "time_none<=3s": result["time_none"] <= 3.0,
        "time_ztrace<=1.2x": r["ztrace_over_none"] <= 1.2,
        "time_ttrace<=1.2x": r["ttrace_over_none"] <= 1.2,
        "time_treap<=1.5x": r["treap_over_none"] <= 1.5,
        "reconstruct_ms<=50": max(result["reconstruct_ms"]) <= 50,
        "display_ms<=20": max(result["display_ms"]) <= 20,
        "bytes_treap<=0.65x": r["treap_bytes_over_traces"] <= 0.65,
    }
    if not args.no_real:
        result["real"] = {}
        for name in ("flower_mold", "cameo"):
            nc, project = DATA / f"{name}.nc", DATA / f"{name}.camotics"
            if not nc.exists():
                result["real"][name] = {"error": f"{nc} not found"}
                continue
            tools, bounds, _units = load_camotics_project(project)
            default = tools[min(tools)] if tools else None
            result["real"][name] = figures(nc, bounds, default, tools, args.repeat)
    print(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
