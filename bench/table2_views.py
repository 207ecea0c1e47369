"""Table 2 over every real part of data/step, seen from +z and from one side: memory and distance.

For each STEP file in data/step with an exact B-rep (nist_ftc_08 has tessellated faces only),
from +z and from ``--side`` (default +y), builds the base z-map and its EZ model at ``--grid``
and ``--tol`` and measures them at ``--points`` random points with
:func:`cad_io.refine.report_rows` (each view in a child process of ``bench/table2.py``, under
``--timeout``). Prints one JSON object; ``--markdown FILE`` also writes the table.

The distances are in mm: ``max_dist_topmost`` (to the top-most surface seen along the view
axis, which is what a z-map holds), its value within the file's own tolerances, and the
largest 3D distance to the nominal B-rep; every distance above tol/2 is measured again by OCC.

    python bench/table2_views.py [--grid 2] [--large-grid 4] [--tol 0.02] [--points 5000] [--side +y]
                                 [--only NAME ...] [--timeout 900] [--markdown FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import table2  # noqa: E402  (bench/table2.py: the per-part child)

#: files of data/step without an exact B-rep: nothing to refine from
NO_EXACT = {"nist_ftc_08_asme1_ap242-2.stp"}
#: the sheets over a metre long, on ``--large-grid``
LARGE = {"bm2_ec_t4-A.stp", "trj7_c2-td-203.stp"}


def _row(name: str, axis: str, r: dict, tol: float) -> str:
    if "error" in r:
        return f"| {name} | {axis} | – | – | – | – | – | – | – | {r['error']} |"
    ok = all(v is not None and v <= tol for v in (r["max_dist_topmost_own_tolerance"]["ez"],))
    return (f"| {name} | {axis} | {r['base_shape'][0]:,} x {r['base_shape'][1]:,} | {r['zmap_kb']:,.1f} "
            f"| {r['emap_kb']:,.1f} | {r['ez_over_base']:.2f} | {r['max_dist_topmost']['ez']:.4f} "
            f"| {r['max_dist_topmost_own_tolerance']['ez']:.4f} | {r['max_dist']['ez']:.4f} "
            f"| {'yes' if ok else '**no**'} ({r['seconds']:.0f} s) |")


def markdown(res: dict) -> str:
    lines = [f"grid {res['grid']:g} mm ({res['large_grid']:g} mm on the sheets over a metre long: "
             f"{', '.join(sorted(n.split('.')[0] for n in LARGE))}), tol {res['tol']:g} mm, {res['points']:,} "
             f"random points a view; distances in mm",
             "",
             "| part | view | base nodes | base KB | e-map KB | EZ / base | to the top-most surface "
             "| top-most, within the file's tolerances | to the nominal B-rep | <= tol (time) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for name, views in res["parts"].items():
        for axis, r in views.items():
            lines.append(_row(name.split(".")[0], axis, r, res["tol"]))
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=float, default=2.0)
    ap.add_argument("--large-grid", type=float, default=4.0, help="grid of the sheets over a metre long")
    ap.add_argument("--tol", type=float, default=0.02)
    ap.add_argument("--points", type=int, default=5000)
    ap.add_argument("--side", default="+y", choices=("+x", "-x", "+y", "-y"))
    ap.add_argument("--only", nargs="*", default=None, help="substrings of the part file names to run")
    ap.add_argument("--views", nargs="*", default=None, help="view axes to run (default +z and --side)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per view (child process)")
    ap.add_argument("--markdown", type=Path, default=None)
    a = ap.parse_args()
    paths = [p for p in sorted((ROOT / "data" / "step").iterdir()) if p.name not in NO_EXACT]
    if a.only:
        paths = [p for p in paths if any(o in p.name for o in a.only)]
    res = {"grid": a.grid, "large_grid": a.large_grid, "tol": a.tol, "points": a.points, "side": a.side,
           "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "parts": {}}
    for path in paths:
        res["parts"][path.name] = {}
        for axis in a.views or ("+z", a.side):
            grid = a.large_grid if path.name in LARGE else a.grid
            plan = {"grid": grid, "axis": axis, "methods": ("ez",), "points": a.points}
            print(f"[{time.strftime('%H:%M:%S')}] {path.name} from {axis}", file=sys.stderr, flush=True)
            r = table2._child(path, plan, a.tol, a.points, a.timeout)
            res["parts"][path.name][axis] = r
            print(f"[{time.strftime('%H:%M:%S')}]   " + (r.get("error") or
                  f"{r['seconds']:.0f} s, top-most {r['max_dist_topmost']['ez']:.4f} mm, "
                  f"EZ/base {r['ez_over_base']:.2f}"), file=sys.stderr, flush=True)
            if a.markdown:
                a.markdown.write_text(markdown(res))
    ok = [r["max_dist_topmost_own_tolerance"]["ez"] <= a.tol for v in res["parts"].values() for r in v.values()
          if "error" not in r]
    res["all_within_tol"] = bool(ok) and all(ok) and len(ok) == sum(len(v) for v in res["parts"].values())
    print(json.dumps(res))


if __name__ == "__main__":
    main()
