"""Table 2 analogue (paper 004 §4): EZ/CZ refinements of the bundled samples and the real parts.

For data/pocket.step, data/boss.step and every STEP file in data/step, builds the
base z-map, the EZ model and (where practical) the CZ model at ``--tol`` and a base grid
chosen per part, and measures them with :func:`cad_io.refine.report_rows`. Each part runs
in a child process under a time limit, so one slow or failing part is recorded (with its
error message) and the run goes on. Progress goes to stderr; stdout gets one JSON object.

Parts whose top is not +z are rotated into their view frame first (:func:`cad_io.view.view_part`:
the NURBS, meshes and the OCP shape, so that OCC's distance check measures in that frame too),
as ``zmap report --axis`` and ``zmap refine`` (on a z-map converted with ``--axis``) do.

    python bench/table2.py [--tol 0.01] [--points 100000] [--parts DIR] [--timeout 300]
                           [--only NAME ...] [--jobs N] [--markdown FILE]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data"
PARTS = DATA / "step"

NO_EXACT = "no exact surface: refinement needs the NURBS B-rep"

# Per-part settings: base grid (mm), view axis, refinements, random points, note.
# Grids: 0.5 mm up to ~300 mm, coarser above, so each part stays within minutes on 2 cores.
# CZ on the real parts is too heavy at tol 0.01 mm: its domains are sampled at delta_y = tol
# and delta_x = k * tol along every VW/SE curve (cornetta, grid 0.5: 118.7 M points sampled
# in 257 s, EZ 3.4 M points in 17 s, and the report then ran past 300 s), so they get EZ only.
_EZ_ONLY = "EZ only: CZ too heavy at tol 0.01 (CZ domains sampled at tol x 3 tol along every feature curve)"
PLAN: dict[str, dict] = {
    "pocket.step": {"grid": 0.5},
    "boss.step": {"grid": 0.5},
    "Ventilator.stp": {"grid": 0.5, "methods": ("ez",), "note": _EZ_ONLY},
    "featuretype.STEP": {"grid": 0.5, "methods": ("ez",), "note": _EZ_ONLY},
    "bug27453_165-174_piattello.stp": {"grid": 0.5, "methods": ("ez",), "note": _EZ_ONLY},
    "bug27693_cornetta-step.stp": {"grid": 0.5, "methods": ("ez",), "note": _EZ_ONLY},
    "trj8_b1-ec-214.stp": {"grid": 0.5, "methods": ("ez",), "note": _EZ_ONLY},
    "trj7_c2-td-203.stp": {"grid": 1.0, "methods": ("ez",),
                           "note": "4 loose B-spline faces, 1100 mm long: grid 1 mm; " + _EZ_ONLY},
    "nist_ctc_02_asme1_ap242-1.stp": {"grid": 2.0, "axis": "+y", "methods": ("ez",), "points": 20_000,
                                      "note": "y-up part: seen from +y (part and OCP shape rotated into the "
                                              "view frame); 680 x 400 mm, 487 faces: grid 2 mm, 2*10^4 points; "
                                              + _EZ_ONLY},
    "bm2_ec_t4-A.stp": {"grid": 2.0, "methods": ("ez",), "points": 20_000,
                        "note": "open B-spline sheets ~1.2 m, top direction not known: +z view, grid 2 mm, "
                                "2*10^4 points; " + _EZ_ONLY},
    "nist_ftc_08_asme1_ap242-2.stp": {"skip": NO_EXACT},
}


def _default_plan(path: Path) -> dict:
    return {"grid": 0.5, "note": "no entry in PLAN: default 0.5 mm, +z"}


def run_one(path: Path, grid: float, tol: float, points: int, axis: str, methods: tuple,
            deflection: float | None = None) -> dict:
    """Report of one part (called in the child process); ``deflection`` None: tol/2 (report_rows')."""
    from cad_io.refine import ReportOptions, refine_models, report_rows
    from cad_io.sampler import sample
    from cad_io.step import read_step
    from cad_io.view import view_part

    t0 = time.perf_counter()
    part = read_step(path)
    if not part.faces:
        raise ValueError("no faces in the file")
    if not any(f.surface is not None for f in part.faces):
        raise ValueError(NO_EXACT)
    part = view_part(part, axis)
    t_read = time.perf_counter() - t0
    base = sample(part, grid, progress=False) if _takes_progress() else sample(part, grid)
    t_base = time.perf_counter() - t0 - t_read
    print(f"  base {base.nx} x {base.ny} in {t_base:.1f} s", file=sys.stderr, flush=True)
    options = ReportOptions(grid, tol, n_points=points, methods=methods, deflection=deflection,
                            distance_deflection=deflection)
    models = refine_models(part, base, options.refine_options())
    cz_plan = _cz_plan(part, base, tol) if "cz" not in methods else None
    for m, (_, info) in models.items():
        print(f"  {m}: {info['seconds']:.1f} s, {info['sampled']:,} points sampled", file=sys.stderr, flush=True)
    rep = report_rows(part, options, models=models, base=base)
    x0, y0, x1, y1 = base.bounds
    r = rep["rows"]
    kb = lambda b: round(b / 1024, 1)
    out = {
        "axis": axis, "methods": list(methods), "grid": grid, "tol": tol, "points": points,
        "xy_dimension_mm": [round(x1 - x0, 3), round(y1 - y0, 3)], "base_shape": [base.nx, base.ny],
        "emap_interval": float(models["ez"][0].ez.interval) if "ez" in models else None,
        "zmap_kb": kb(r["base"]["total_bytes"]),
        "emap_kb": kb(r["ez"]["extra_bytes"]) if "ez" in r else None,
        "ez_total_kb": kb(r["ez"]["total_bytes"]) if "ez" in r else None,
        "cz_kb": kb(r["cz"]["extra_bytes"]) if "cz" in r else None,
        "cz_total_kb": kb(r["cz"]["total_bytes"]) if "cz" in r else None,
        "n_cz": r["cz"]["n_cz"] if "cz" in r else None,
        "cz_planned": cz_plan,
        "emap_ratio_pct": round(100 * r["ez"]["emap_ratio"], 3) if "ez" in r else None,
        "ez_over_base": round(r["ez"]["total_bytes"] / r["base"]["total_bytes"], 3) if "ez" in r else None,
        "plain_fine_kb": kb(rep["plain_fine_bytes"]), "plain_fine_shape": rep["plain_fine_shape"],
        "ez_over_plain_fine": (round(r["ez"]["total_bytes"] / rep["plain_fine_bytes"], 5) if "ez" in r else None),
        "max_dist": {k: v["max_dist"] for k, v in r.items()},
        "max_dist_own_tolerance": {k: v.get("max_dist_own_tolerance") for k, v in r.items()},
        "largest_tolerance_used": {k: v.get("largest_tolerance_used") for k, v in r.items()},
        "p999_dist": {k: v["p999_dist"] for k, v in r.items()},
        "max_dist_topmost": {k: v.get("max_dist_topmost") for k, v in r.items()},
        "max_dist_topmost_own_tolerance": {k: v.get("max_dist_topmost_own_tolerance") for k, v in r.items()},
        "ez_patches": r["ez"].get("ez_patches") if "ez" in r else None,
        "ez_lattices": r["ez"].get("ez_lattices") if "ez" in r else None,
        "ez_unresolved": r["ez"].get("ez_unresolved") if "ez" in r else None,
        "ez_pruned": r["ez"].get("ez_pruned") if "ez" in r else None,
        "ez_bytes_by_part": _ez_bytes(models["ez"][0].ez) if "ez" in models else None,
        "max_vertical_flat": {k: v["max_vertical_flat"] for k, v in r.items()},
        "max_dist_in_cz": r["cz"].get("max_dist_in_cz") if "cz" in r else None,
        "facet_points": {k: v.get("facet_points") for k, v in r.items() if k != "base"},
        "build_seconds": {k: v.get("build_seconds") for k, v in r.items() if k != "base"},
        "occ_confirmed": {k: [v["occ_confirmed"], v["above_half_tol_unconfirmed"]] for k, v in r.items()},
        "deflection": [rep.get("deflection"), rep.get("distance_deflection")],
        "reference_facet_points": rep.get("reference_facet_points"),
        "points_with_height": r["base"]["points_with_height"],
        "base_seconds": round(t_base, 2),
        "seconds": round(time.perf_counter() - t0, 2),
    }
    return out


def _ez_bytes(ez) -> dict:
    """Where the stored e-map's bytes go (KB): e-point codes of the windowed wall edges and of
    the other e-edges, their scales, the edge bits and counts, the windows, and the cell
    patches' codes, nodes, counts and sub-lattices; with the counts of edges and windows.
    Format 5 stores each edge's (patch's, sub-lattice's) codes in the bits its range needs
    or as second differences (``*_codes_bits``, widths in ``*_codes_w4`` and ``*_codes_r4``):
    the edges' share is split by those widths; a patch's nodes and codes by its plain width
    (its sub-edges are stored as differences from their chords: the split is approximate)."""
    import numpy as np

    a = ez.to_arrays()
    kb = lambda *names: round(sum(a[n].nbytes for n in names if n in a) / 1024, 1)

    def widths(w4, count):
        w = np.empty(2 * w4.size, dtype=np.int64)
        w[0::2], w[1::2] = w4 & 15, w4 >> 4
        return w[:count] + 1

    n = np.diff(ez.offsets)
    if "codes_bits" in a:
        bits = n * widths(a["codes_w4"], ez.n_edges)
        if "codes_mode" in a:  # differenced edges: two plain codes, then the differences' widths
            md = np.unpackbits(a["codes_mode"], count=ez.n_edges).astype(bool)
            rw = widths(a["codes_r4"], int(md.sum()))
            w = widths(a["codes_w4"], ez.n_edges)[md]
            bits[md] = np.minimum(n[md], 2) * w + (n[md] - 2) * rw
        win = bits[ez.win >= 0].sum() / 8
        other = bits[ez.win < 0].sum() / 8 + sum(a[k].nbytes for k in ("codes_w4", "codes_mode", "codes_r4") if k in a)
    else:
        win, other = 2 * n[ez.win >= 0].sum(), 2 * n[ez.win < 0].sum()
    patch_codes, patch_nodes = kb("patch_codes"), kb("patch_node_codes")
    p = ez.patches
    if "patch_codes_bits" in a and p is not None and p.n_patches:
        w = widths(a["patch_codes_w4"], p.n_patches)
        patch_nodes = round(float((np.diff(p.node_off) * w).sum()) / 8 / 1024, 1)
        patch_codes = round(float((np.diff(p.code_off) * w).sum()) / 8 / 1024 + a["patch_codes_w4"].nbytes / 1024, 1)
    return {"codes_windowed_edges": round(float(win) / 1024, 1),
            "codes_other_edges": round(float(other) / 1024, 1),
            "lo_step": kb("lo", "lo_k", "lo_lattice", "step", "step_common", "step_is_common"), "edge_bits_counts": kb("edge_bits", "counts"),
            "windows": kb("win_bits", "win_b", "win_nl", "win_kink", "win_forced"),
            "patch_codes": patch_codes, "patch_nodes": patch_nodes,
            "patch_counts": kb("patch_counts", "patch_counts4", "patch_counts_nz", "patch_counts4nz",
                                               "patch_counts8nz", "patch_countsbnz", "patch_counts_bw"),
            "patch_cells_levels_scales": kb("patch_cells", "patch_level", "patch_lo", "patch_step"),
            "sub_lattices": kb(*[k for k in a if k.startswith("patch_sub_")]),
            "n_edges": ez.n_edges, "n_windows": ez.n_windows, "n_patches": ez.n_patches}


def _cz_plan(part, base, tol: float) -> dict:
    """What the CZ model of ``refine_models`` would sample and store on this part, from its
    domain layout (:func:`zmap.refine.cz.cz_layout`), without sampling: points, KB, domains."""
    import math

    from cad_io.refine import CZ_DELTA_Y_SHARE, cz_curves
    from zmap.features import default_eps_r, sharp_edge_curves
    from zmap.refine.cz import cz_layout

    eps_r = default_eps_r(tol, base.dx, base.dy)
    curves = cz_curves(base, eps_r, sharp_edge_curves(part.edges))
    lay = cz_layout(base, tol=CZ_DELTA_Y_SHARE * tol, curves=curves, theta_x=math.radians(20.0))
    n = int(lay.prod(axis=1).sum()) if lay.size else 0
    return {"points": n, "kb": round(8 * n / 1024, 1), "domains": int(lay.shape[0])}


def _takes_progress() -> bool:
    import inspect

    from cad_io.sampler import sample

    return "progress" in inspect.signature(sample).parameters


def _parts(parts_dir: Path, only: list[str] | None) -> list[Path]:
    paths = [DATA / "pocket.step", DATA / "boss.step"]
    if parts_dir.is_dir():
        paths += sorted(p for p in parts_dir.iterdir() if p.suffix.lower() in (".stp", ".step"))
    if only:
        paths = [p for p in paths if any(o in p.name for o in only)]
    return paths


def _child(path: Path, plan: dict, tol: float, points: int, timeout: float) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--one", str(path), "--grid", str(plan["grid"]),
           "--axis", plan.get("axis", "+z"), "--methods", ",".join(plan.get("methods", ("ez", "cz"))),
           "--tol", str(tol), "--points", str(plan.get("points", points))]
    if plan.get("deflection") is not None:
        cmd += ["--deflection", str(plan["deflection"])]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=None, text=True, timeout=timeout, cwd=ROOT, check=False)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:g} s", "seconds": round(time.perf_counter() - t0, 1)}
    try:
        return json.loads(p.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        why = (f"child killed by signal {-p.returncode}" + (" (out of memory?)" if p.returncode == -9 else "")
               if p.returncode < 0 else f"child exited with {p.returncode}")
        return {"error": f"{why} and no result", "seconds": round(time.perf_counter() - t0, 1)}


def _fmt(v, n=4) -> str:
    return "–" if v is None else f"{v:.{n}f}"


def markdown(res: dict) -> str:
    """Table 2 shaped: rows are quantities, columns the models."""
    names = list(res["parts"])
    P = res["parts"]

    def cell(name, fn):
        r = P[name]
        if "skipped" in r:
            return "skipped" if fn is _first else ""
        if "error" in r:
            return "failed" if fn is _first else ""
        try:
            return fn(r)
        except (KeyError, TypeError):
            return "–"

    kb = lambda v: "–" if v is None else f"{v:,.0f}" if v >= 100 else f"{v:,.1f}"
    rows = [
        ("XY-dimension (mm)", "", _first),
        ("View axis", "", lambda r: r["axis"]),
        ("Grid-interval (mm)", "Z-map", lambda r: f"{r['grid']:g}"),
        ("", "E-map", lambda r: _fmt(r["emap_interval"], 3) if r["emap_interval"] else "–"),
        ("Memory (KB)", "Z-map", lambda r: kb(r["zmap_kb"])),
        ("", "E-map", lambda r: kb(r["emap_kb"])),
        ("", "EZ-map", lambda r: kb(r["ez_total_kb"])),
        ("", "CZ-maps", lambda r: kb(r["cz_kb"]) + (f" ({r['n_cz']})" if r["n_cz"] is not None else "")),
        ("", "CZ-maps planned, not built", lambda r: "–" if not r.get("cz_planned") else
         f"{r['cz_planned']['kb']:,.0f} ({r['cz_planned']['domains']:,})"),
        ("CZ / base memory (planned)", "", lambda r: "–" if not r.get("cz_planned") else
         _fmt(1 + r["cz_planned"]["kb"] / r["zmap_kb"], 1)),
        ("E-map ratio (%)", "", lambda r: _fmt(r["emap_ratio_pct"], 2)),
        ("EZ / base memory", "", lambda r: _fmt(r["ez_over_base"], 2)),
        ("Plain z-map at tol (KB)", "", lambda r: kb(r["plain_fine_kb"])),
        ("EZ / plain z-map at tol", "", lambda r: "1/" + f"{1 / r['ez_over_plain_fine']:,.0f}"),
        ("Max 3D distance (mm)", "base", lambda r: _fmt(r["max_dist"]["base"])),
        ("", "EZ", lambda r: _fmt(r["max_dist"].get("ez"))),
        ("", "CZ", lambda r: _fmt(r["max_dist"].get("cz"))),
        ("", "CZ inside domains", lambda r: _fmt(r["max_dist_in_cz"])),
        ("Max 3D distance, edges at the file's tolerance (mm)", "EZ",
         lambda r: _fmt(r["max_dist_own_tolerance"].get("ez")) + (
             f" (edges up to {r['largest_tolerance_used']['ez']:.4f})"
             if (r["largest_tolerance_used"].get("ez") or 0.0) > 1e-5 else "")),
        ("Max distance to the top-most surface (mm)", "base", lambda r: _fmt(r["max_dist_topmost"]["base"])),
        ("", "EZ", lambda r: _fmt(r["max_dist_topmost"].get("ez"))),
        ("", "CZ", lambda r: _fmt(r["max_dist_topmost"].get("cz"))),
        ("Max distance to the top-most surface, edges at the file's tolerance (mm)", "EZ",
         lambda r: _fmt((r.get("max_dist_topmost_own_tolerance") or {}).get("ez"))),
        ("99.9 % 3D distance (mm)", "base", lambda r: _fmt(r["p999_dist"]["base"])),
        ("", "EZ", lambda r: _fmt(r["p999_dist"].get("ez"))),
        ("", "CZ", lambda r: _fmt(r["p999_dist"].get("cz"))),
        ("Max vertical dev, not steep (mm)", "base", lambda r: _fmt(r["max_vertical_flat"]["base"])),
        ("", "EZ", lambda r: _fmt(r["max_vertical_flat"].get("ez"))),
        ("E-map bytes (KB)", "codes on windowed edges", lambda r: kb(r["ez_bytes_by_part"]["codes_windowed_edges"])),
        ("", "codes on other e-edges", lambda r: kb(r["ez_bytes_by_part"]["codes_other_edges"])),
        ("", "edge scales, bits, counts, windows", lambda r: kb(sum(
            r["ez_bytes_by_part"][k] for k in ("lo_step", "edge_bits_counts", "windows")))),
        ("", "cell patches", lambda r: kb(sum(
            r["ez_bytes_by_part"][k] for k in ("patch_codes", "patch_nodes", "patch_counts",
                                               "patch_cells_levels_scales")))),
        ("", "sub-lattices", lambda r: kb(r["ez_bytes_by_part"]["sub_lattices"])),
        ("", "windowed / all e-edges", lambda r: f"{r['ez_bytes_by_part']['n_windows']:,} / "
                                                  f"{r['ez_bytes_by_part']['n_edges']:,}"),
        ("EZ cell check", "patched cells", lambda r: f"{r['ez_patches']:,}"),
        ("", "of them lattices", lambda r: f"{r['ez_lattices']:,}"),
        ("", "still off", lambda r: f"{r['ez_unresolved']:,}"),
        ("", "edges dropped", lambda r: f"{r['ez_pruned']:,}"),
        ("Random points", "", lambda r: f"{r['points']:,}"),
        ("Seconds", "base z-map", lambda r: f"{r['base_seconds']:.1f}"),
        ("", "EZ build", lambda r: _fmt(r["build_seconds"].get("ez"), 1)),
        ("", "CZ build", lambda r: _fmt(r["build_seconds"].get("cz"), 1)),
        ("", "total", lambda r: f"{r['seconds']:.0f}"),
    ]
    short = [n.replace(".stp", "").replace(".step", "").replace(".STEP", "") for n in names]
    out = ["| Model | | " + " | ".join(short) + " |", "|---|---|" + "---:|" * len(names)]
    for label, sub, fn in rows:
        out.append(f"| {label} | {sub} | " + " | ".join(cell(n, fn) for n in names) + " |")
    notes = []
    for n in names:
        r = P[n]
        if "skipped" in r:
            notes.append(f"- **{n}**: skipped: {r['skipped']}")
        elif "error" in r:
            notes.append(f"- **{n}**: failed: {r['error']}" + (f" ({r['note']})" if r.get("note") else ""))
        elif r.get("note"):
            notes.append(f"- **{n}**: {r['note']}")
    return "\n".join(out + [""] + notes) + "\n"


def _first(r) -> str:
    a, b = r["xy_dimension_mm"]
    return f"{a:g} × {b:g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--parts", type=Path, default=PARTS, help="folder of the real parts (STEP)")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per part (child process)")
    ap.add_argument("--only", nargs="*", default=None, help="substrings of the part file names to run")
    ap.add_argument("--markdown", type=Path, default=None, help="also write the table as markdown here")
    ap.add_argument("--json-out", type=Path, default=None, help="also write (and update per part) the JSON here")
    ap.add_argument("--jobs", type=int, default=1, help="parts run at once (child processes)")
    ap.add_argument("--one", type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--grid", type=float, default=None,
                    help="base grid (mm) for every part instead of the plan's (e.g. 1 or 2 for the large sheets)")
    ap.add_argument("--axis", default="+z", help=argparse.SUPPRESS)
    ap.add_argument("--methods", default="ez,cz", help=argparse.SUPPRESS)
    ap.add_argument("--deflection", type=float, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one is not None:
        t0 = time.perf_counter()
        try:
            res = run_one(a.one, a.grid, a.tol, a.points, a.axis, tuple(a.methods.split(",")), a.deflection)
        except Exception as err:  # noqa: BLE001 (recorded in the table, the run goes on)
            import traceback

            traceback.print_exc(file=sys.stderr)
            res = {"error": f"{type(err).__name__}: {' '.join(str(err).split())}",
                   "seconds": round(time.perf_counter() - t0, 1)}
        print(json.dumps(res))
        return
    res = {"tol": a.tol, "points": a.points, "grid": a.grid, "timeout_s": a.timeout, "parts_dir": str(a.parts),
           "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "parts": {}}
    paths = _parts(a.parts, a.only)
    for path in paths:  # table order, filled in as the parts finish
        res["parts"][path.name] = {"error": "not run (interrupted)"}

    def one(path: Path) -> None:
        plan = dict(PLAN.get(path.name) or _default_plan(path))
        if a.grid is not None and "skip" not in plan:
            plan["grid"] = a.grid
        print(f"[{time.strftime('%H:%M:%S')}] {path.name}: {plan}", file=sys.stderr, flush=True)
        if "skip" in plan:
            row = {"skipped": plan["skip"]}
        else:
            row = _child(path, plan, a.tol, a.points, a.timeout)
            if plan.get("note"):
                row["note"] = plan["note"]
            if "error" in row:
                row.update({"grid": plan["grid"], "axis": plan.get("axis", "+z"),
                            "methods": list(plan.get("methods", ("ez", "cz")))})
        with lock:
            res["parts"][path.name] = row
            print(f"[{time.strftime('%H:%M:%S')}] {path.name}: "
                  + (row.get("skipped") or row.get("error") or
                     f"{row['seconds']:.0f} s, max dist {row['max_dist']}"), file=sys.stderr, flush=True)
            if a.json_out:
                a.json_out.write_text(json.dumps(res, indent=1))
            if a.markdown:
                a.markdown.write_text(markdown(res))

    import threading
    from concurrent.futures import ThreadPoolExecutor

    lock = threading.Lock()
    with ThreadPoolExecutor(max_workers=max(a.jobs, 1)) as ex:
        list(ex.map(one, paths))
    print(json.dumps(res))


if __name__ == "__main__":
    main()
