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
1/10, 1/4, 1/2, 3/4 and the end, best of 5. Prints one JSON object.

Usage: ``python bench/simulate.py [--repeat N] [--no-real]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from make_mould_program import STOCK, TOOL, write_mould_program  # noqa: E402

from zmap.sim.gcode import parse  # noqa: E402
from zmap.sim.history.treap import simulate_treap  # noqa: E402
from zmap.sim.path import positions  # noqa: E402
from zmap.sim.session import simulate  # noqa: E402
from zmap.sim.tools import load_camotics_project, parse_tool_spec  # noqa: E402

PITCH = 0.26
FRACTIONS = (0.1, 0.25, 0.5, 0.75, 1.0)
KINDS = ("none", "ztrace", "ttrace", "treap")
DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"


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
        it = simulate_treap(r0.stock, r0.xyz, r0.cutters, r0.slot)
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


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-real", action="store_true")
    args = ap.parse_args(argv)
    _warm_up()
    with tempfile.TemporaryDirectory() as tmp:
        prog = write_mould_program(os.path.join(tmp, "mould.nc"))
        result = {"program": "bench/make_mould_program.py", "stock": list(STOCK), "tool": TOOL, "pitch": PITCH}
        result.update(figures(prog, STOCK, parse_tool_spec(TOOL), None, args.repeat))
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
