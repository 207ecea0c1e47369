"""Benchmark of zmap.verify and zmap.cam; prints one JSON object.

* ``cl_pps``: drop-cutter CL points per second on a 1000 x 1000 axis grid, 6 mm ball, over the
  EZ precision model (tol 0.01, base grid 0.5 mm) of a window of a real die (OCCT's
  ``bug27693_cornetta-step.stp``, walls and edges inside), the model sampled every 0.1 mm
  (``pitch``), JIT warm; the time includes sampling the model (``cl_bounds_s`` alone: its
  bounding surface of :mod:`zmap.cam.bounds`); ``cl_discrete_pps``: the discrete drop alone
  (``refine=False``) on the same grid;
  ``cl_max_err``: largest |ours - reference| on random points of the grid and on points whose
  contact is off-axis by more than 1 mm (walls and edges), the reference being
  ``tests.reference.cam.drop_cutter_reference_dense`` (a 0.02 mm lattice on the whole disk and
  the rim as a curve at 0.005 mm, refinement around every candidate within its bound) on the same
  model's ``PrecisionModel.height``; signed: ``cl_max_below_ref`` (ours low: the tool would
  gouge; the certified drop is never low) and ``cl_max_above_ref`` (ours high: beside a wall,
  a sampled design's bound on its safe side, or the reference missing a maximum).
* OpenCAMLib (``pip install '.[bench]'``): ``BatchDropCutter`` with a 6 mm ``BallCutter`` on the
  same part's triangles (BRepMesh at 0.01 mm deflection, the faces in the window), 1 and 2
  threads, in the same run; ``cl_vs_ocl2``: ``cl_pps`` over OCL's 2-thread rate;
  ``ocl_max_diff``: its largest difference from our CL heights on those points.
* ``cl_part_max_gouge_mm`` / ``ocl_part_max_gouge_mm``: on ``part_points`` of those points, how
  far the ball at our CL / OCL's enters the exact part (the ball's radius less OCC's distance
  from its centre to the B-rep): speed and truth side by side (ours is dropped on the EZ model,
  within its tolerance of the part; OCL on a 0.01 mm mesh).
* ``finish_die_s``: ``zmap toolpath data/step/bug27693_cornetta-step.stp --tool ball:6
  --stepover 0.5 --tol 0.002`` (the whole die, 280 x 160 mm, from the STEP part itself), timed
  as a command; ``finish_die_max_gouge_mm``: the same OCC check on ``finish_die_checked_points``
  of its CL points (random ones and the steepest); ``finish_die_max_below_mm`` and
  ``finish_die_above_p50/75/90_mm``: its CL heights less a brute force on the part's exact
  heights (0.02 mm lattice on the disk, 0.002 mm around the best) on ``finish_die_truth_points``.
* ``compare_s``: a full :func:`zmap.verify.compare` (deviation, classes, regions, first
  offending stage and line of every gouge ray) of ``flower_mold.nc``'s stock at the end
  (CAMotics stock and tool, 0.26 mm rays, treap history) against a design z-map at the same
  0.26 mm rays: the stock as it stood half way (everything cut after it is a gouge);
  ``first_gouge_ms``: the first offending stage of one ray from the history.

Run: ``.venv/bin/python bench/verify.py [--n 1000] [--no-die]``. The figures depend on the machine and
its load; the README quotes one run.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DIE = ROOT / "data" / "step" / "bug27693_cornetta-step.stp"
FLOWER = ROOT / "data" / "gcode" / "flower_mold.nc"
FLOWER_PROJECT = ROOT / "data" / "gcode" / "flower_mold.camotics"
WINDOW = (-45.0, -25.0, 5.0, 25.0)  # half the handset: relief, the pocket and its walls


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def die_model():
    import cad_io
    from cad_io.refine import RefineOptions, refine_models

    part = cad_io.read_step(DIE)
    w = WINDOW
    base = cad_io.sample(part, 0.5, bounds=(w[0] - 5, w[1] - 5, w[2] + 5, w[3] + 5))
    model = refine_models(part, base, RefineOptions(0.01, ("ez",)))["ez"][0]
    return part, model


def ocl_rates(part, xs, ys, cl_ours):
    try:
        import opencamlib as ocl
    except ImportError:
        return {"ocl": "opencamlib not installed (pip install '.[bench]')"}
    from cad_io.mesh import triangulate

    triangulate(part, 0.01)
    surf = ocl.STLSurf()
    w = WINDOW
    n_tri = 0
    for f in part.faces:
        m = f.mesh
        if m is None:
            continue
        P = m.nodes[m.triangles]
        keep = ((P[:, :, 0].max(axis=1) >= w[0] - 4) & (P[:, :, 0].min(axis=1) <= w[2] + 4)
                & (P[:, :, 1].max(axis=1) >= w[1] - 4) & (P[:, :, 1].min(axis=1) <= w[3] + 4))
        for t in P[keep]:
            surf.addTriangle(ocl.Triangle(ocl.Point(*t[0]), ocl.Point(*t[1]), ocl.Point(*t[2])))
            n_tri += 1
    out = {"ocl_version": str(ocl.version()), "ocl_triangles": n_tri, "ocl_points": int(xs.size)}
    for threads in (1, 2):
        bdc = ocl.BatchDropCutter()
        bdc.setSTL(surf)
        bdc.setCutter(ocl.BallCutter(6.0, 50.0))
        bdc.setThreads(threads)
        for x, y in zip(xs, ys):
            bdc.appendPoint(ocl.CLPoint(float(x), float(y), -100.0))
        t = time.perf_counter()
        bdc.run()
        dt = time.perf_counter() - t
        out[f"ocl_pps_{threads}thread"] = round(xs.size / dt, 1)
        z = np.array([p.z for p in bdc.getCLPoints()])
    out["ocl_max_diff"] = float(np.max(np.abs(z - cl_ours)))
    out["ocl_cl"] = z.tolist()
    return out


def part_gouge(part, cutter, x, y, cl) -> np.ndarray:
    """How far a ball at each CL point enters the exact part, mm (0: clear): the ball's radius
    less OCC's distance (``BRepExtrema_DistShapeShape``) from its centre to the part's faces."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt

    from cad_io.distance import faces_compound

    faces = faces_compound(part.shape)
    R = cutter.radius
    out = np.zeros(len(x))
    for k in range(len(x)):
        if not np.isfinite(cl[k]):
            continue
        v = BRepBuilderAPI_MakeVertex(gp_Pnt(float(x[k]), float(y[k]), float(cl[k]) + R)).Vertex()
        ext = BRepExtrema_DistShapeShape(faces, v)
        out[k] = max(0.0, R - ext.Value()) if ext.IsDone() else np.nan
    return out


def finish_die(args, res) -> None:
    """``zmap toolpath`` on the whole die from its STEP file, timed as a user runs it, and the
    gouge of a sample of its CL points against the exact part."""
    import subprocess
    import tempfile

    import cad_io
    from zmap.sim.tools import parse_tool_spec

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "die.nc"
        cmd = [sys.executable, "-m", "zmap.cli", "toolpath", str(DIE), "--tool", "ball:6", "--stepover", "0.5",
               "--tol", "0.002", "-o", str(out)]
        log("whole die from the STEP file: " + " ".join(cmd[2:]))
        t = time.perf_counter()
        subprocess.run(cmd, check=True, cwd=ROOT)
        res["finish_die_s"] = round(time.perf_counter() - t, 1)
        pts = np.array([[float(w[1:]) for w in ln.split()[1:4]] for ln in out.read_text().splitlines()
                        if ln.startswith("G1 X") and " Y" in ln and " Z" in ln])
    res["finish_die_cl_points_kept"] = int(len(pts))
    rng = np.random.default_rng(1)
    pick = rng.choice(len(pts), min(args.die_check, len(pts)), replace=False)
    # and as many of the steepest (the largest climb to the next point: walls and edges)
    climb = np.abs(np.diff(pts[:, 2])) / np.maximum(np.hypot(*np.diff(pts[:, :2], axis=0).T), 1e-9)
    pick = np.unique(np.r_[pick, np.argsort(climb)[-min(args.die_check, len(climb)):]])
    part = cad_io.read_step(DIE)
    ball = parse_tool_spec("ball:6")
    g = part_gouge(part, ball, pts[pick, 0], pts[pick, 1], pts[pick, 2])
    res["finish_die_checked_points"] = int(pick.size)
    res["finish_die_max_gouge_mm"] = float(np.nanmax(g))
    # signed error against a brute force on the part's exact heights (how high the program
    # runs: the certified drop is never low, and high beside walls)
    some = rng.choice(len(pts), min(args.die_truth, len(pts)), replace=False)
    ref = brute_cl(part, ball.radius, pts[some, 0], pts[some, 1])
    d = (pts[some, 2] - ref)[np.isfinite(ref)]
    res["finish_die_truth_points"] = int(d.size)
    res["finish_die_max_below_mm"] = float(max(0.0, -d.min()))
    for q in (50, 75, 90):
        res[f"finish_die_above_p{q}_mm"] = round(float(np.percentile(d, q)), 5)


def brute_cl(part, R: float, x: np.ndarray, y: np.ndarray, h: float = 0.02) -> np.ndarray:
    """A ball's CL height at each (x, y) by brute force on the part's exact top-most heights:
    every point of an ``h`` lattice on the disk, then a 0.002 mm lattice around the best; NaN
    where no part lies under the disk. Shares no code with zmap.cam."""
    from cad_io.sampler import height_function

    hf = height_function(part)
    g = np.arange(-R, R + h / 2, h)
    f = np.arange(-0.04, 0.0401, 0.002)
    out = np.full(len(x), np.nan)
    for k in range(len(x)):
        best = -np.inf
        for cx, cy, grid in ((x[k], y[k], g), (None, None, f)):
            if cx is None:
                if not np.isfinite(best):
                    break
                cx, cy = bx, by
            U, V = np.meshgrid(cx + grid, cy + grid, indexing="ij")
            d = np.hypot(U - x[k], V - y[k])
            m = d <= R
            cl = hf(U[m], V[m]) - (R - np.sqrt(R * R - d[m] ** 2))
            if np.isfinite(cl).any() and np.nanmax(cl) > best:
                i = int(np.nanargmax(cl))
                best, bx, by = float(cl[i]), U[m][i], V[m][i]
        out[k] = best if np.isfinite(best) else np.nan
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1000, help="CL grid side (n x n)")
    ap.add_argument("--ref-points", type=int, default=30)
    ap.add_argument("--ocl-points", type=int, default=2000)
    ap.add_argument("--ref-h", type=float, default=0.02, help="the reference's lattice spacing on the disk, mm")
    ap.add_argument("--discrete-n", type=int, default=1000,
                    help="grid side (n x n) of the discrete-phase figure cl_discrete_pps")
    ap.add_argument("--part-points", type=int, default=200,
                    help="CL points checked against the exact part (OCC distance), ours and OpenCAMLib's")
    ap.add_argument("--die-check", type=int, default=500,
                    help="random CL points of the whole-die program checked against the part by OCC distance, "
                         "and as many of the steepest")
    ap.add_argument("--die-truth", type=int, default=100,
                    help="random CL points of the whole-die program against a brute force on the part's exact heights")
    ap.add_argument("--only-die", action="store_true", help="the whole-die program alone")
    ap.add_argument("--no-die", action="store_true", help="skip the whole-die program (finish_die_s)")
    args = ap.parse_args()
    from zmap.cam import drop_cutter
    from tests.reference.cam import drop_cutter_reference_dense
    from zmap.sim.tools import parse_tool_spec

    res: dict = {"machine_cpus": os.cpu_count()}
    if args.only_die:
        finish_die(args, res)
        print(json.dumps(res, indent=1))
        return
    log("building the die's precision model ...")
    t = time.perf_counter()
    part, model = die_model()
    res["model_s"] = round(time.perf_counter() - t, 2)
    res["model"] = repr(model)
    ball = parse_tool_spec("ball:6")
    w = WINDOW
    xs = np.linspace(w[0], w[2], args.n)
    ys = np.linspace(w[1], w[3], args.n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    drop_cutter(model, ball, X[:20, :20], Y[:20, :20], pitch=0.1)  # JIT warm-up
    # the bounding surface the drop samples (part of cl_s: timed alone here, then dropped)
    import zmap.cam.drop as D

    D._BOUNDS.clear()
    t = time.perf_counter()
    R = ball.radius
    bs = D.bounding_surface(model, (w[0] - R - 0.1, w[1] - R - 0.1, w[2] + R + 0.2, w[3] + R + 0.2), pitch=0.1)
    res["cl_bounds_s"] = round(time.perf_counter() - t, 3)
    res["cl_bounds_nodes"] = int(bs.z.size)
    D._BOUNDS.clear()
    del bs
    log(f"drop-cutter on {X.size} points ...")
    t = time.perf_counter()
    cl, cx, cy, _cz = drop_cutter(model, ball, X, Y, pitch=0.1, return_contact=True)
    dt = time.perf_counter() - t
    res["cl_points"] = int(X.size)
    res["cl_s"] = round(dt, 3)
    res["cl_pps"] = round(X.size / dt, 1)
    # where the time goes: the discrete drop alone (sampling the model, the pyramid drop),
    # and the share of points whose contact the exact refinement searches for
    nd = args.discrete_n
    XD, YD = np.meshgrid(np.linspace(w[0], w[2], nd), np.linspace(w[1], w[3], nd), indexing="ij")
    t = time.perf_counter()
    drop_cutter(model, ball, XD, YD, pitch=0.1, refine=False)
    res["cl_discrete_s"] = round(time.perf_counter() - t, 3)
    res["cl_discrete_points"] = int(XD.size)
    res["cl_discrete_pps"] = round(XD.size / res["cl_discrete_s"], 1)
    del XD, YD
    # error against the brute force: random points and points with off-axis contacts
    rng = np.random.default_rng(0)
    flat = rng.choice(X.size, args.ref_points // 2, replace=False)
    off = np.flatnonzero((np.hypot(cx - X, cy - Y) > 1.0).ravel())
    walls = rng.choice(off, min(off.size, args.ref_points - flat.size), replace=False) if off.size else flat[:0]
    pick = np.r_[flat, walls]
    log(f"brute-force reference on {pick.size} points ...")
    t = time.perf_counter()
    ref = np.empty(pick.size)
    for q, k in enumerate(pick):
        t1 = time.perf_counter()
        ref[q] = drop_cutter_reference_dense(model.height, ball, X.ravel()[k], Y.ravel()[k], h=args.ref_h)[0]
        log(f"  reference {q + 1}/{pick.size}: {time.perf_counter() - t1:.1f} s, ours - ref "
            f"{cl.ravel()[k] - ref[q]:+.3g} mm")
    res["cl_ref_s"] = round(time.perf_counter() - t, 1)
    res["cl_ref_h"] = args.ref_h
    err = cl.ravel()[pick] - ref
    res["cl_max_err"] = float(np.max(np.abs(err)))
    # signed: below the reference is a missed maximum (the tool would gouge); above it, the
    # reference missed a maximum that ours, an exact contact of the model, found
    res["cl_max_below_ref"] = float(max(0.0, -np.min(err)))
    res["cl_max_above_ref"] = float(max(0.0, np.max(err)))
    res["cl_max_err_random"] = float(np.max(np.abs(err[:flat.size])))
    res["cl_max_err_offaxis"] = float(np.max(np.abs(err[flat.size:]))) if walls.size else None
    res["cl_ref_points"] = int(pick.size)
    res["cl_offaxis_share"] = round(off.size / X.size, 4)
    # OpenCAMLib on the same part's triangles, same run
    # one sample for both: OpenCAMLib's points first, the exact-part check on its first ones
    sel = rng.choice(X.size, max(args.ocl_points, args.part_points), replace=False)
    if args.ocl_points:  # --ocl-points 0 skips OpenCAMLib
        log("OpenCAMLib BatchDropCutter ...")
        o = sel[:args.ocl_points]
        res.update(ocl_rates(part, X.ravel()[o], Y.ravel()[o], cl.ravel()[o]))
    if "ocl_pps_2thread" in res:
        res["cl_vs_ocl2"] = round(res["cl_pps"] / res["ocl_pps_2thread"], 1)
    # truth side by side: both against the exact part (the design the model stands for)
    k = min(args.part_points, sel.size)
    if args.ocl_points:
        k = min(k, args.ocl_points)  # OpenCAMLib's heights exist only at its points
    log(f"OCC distance from the ball to the part at {k} CL points, ours and OpenCAMLib's ...")
    res["part_points"] = k
    res["cl_part_max_gouge_mm"] = None if k == 0 else float(np.nanmax(part_gouge(part, ball, X.ravel()[sel[:k]], Y.ravel()[sel[:k]],
                                                             cl.ravel()[sel[:k]])))
    if "ocl_cl" in res and k:
        z = np.asarray(res.pop("ocl_cl"))[:k]
        res["ocl_part_max_gouge_mm"] = float(np.nanmax(part_gouge(part, ball, X.ravel()[sel[:k]],
                                                                  Y.ravel()[sel[:k]], z)))
    # compare on flower_mold.nc
    log("flower_mold.nc: simulate and compare ...")
    from zmap import ZMap
    from zmap.sim import simulate
    from zmap.sim.tools import load_camotics_project
    from zmap.verify import compare, first_offending

    tools, box, _u = load_camotics_project(FLOWER_PROJECT)
    run = simulate(FLOWER, box, tools=tools, tool=tools[1], pitch=0.26)
    s = run.stock
    half = run.display(run.n_stages // 2)
    design = ZMap(s.x0, s.y0, s.pitch, s.pitch, np.where(np.isnan(half), float(s.to_csr()[1].min()), half))
    compare(run, design, tol=0.01)  # warm
    times = []
    for _ in range(3):
        t = time.perf_counter()
        c = compare(run, design, tol=0.01)
        times.append(time.perf_counter() - t)
    res["compare_s"] = round(float(np.median(times)), 4)
    res["compare_rays"] = int(s.n_rays)
    res["compare_gouge_rays"] = c.totals["gouge_rays"]
    res["compare_regions"] = len(c.regions)
    res["compare_first_gouge_line"] = c.totals.get("first_gouge_line")
    g = c.gouges[0]
    i = int(round((g.deepest[0] - s.x0) / s.pitch))
    j = int(round((g.deepest[1] - s.y0) / s.pitch))
    ray = np.array([i * s.ny + j])
    lev = np.array([design.z[i, j] - 0.01])
    first_offending(run, ray, lev)
    ts = []
    for _ in range(50):
        t = time.perf_counter()
        first_offending(run, ray, lev)
        ts.append(time.perf_counter() - t)
    res["first_gouge_ms"] = round(1000 * float(np.median(ts)), 4)
    if not args.no_die:
        finish_die(args, res)
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
