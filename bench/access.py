"""Benchmark of tool access directions from a visibility voxel map (paper 002).

A real part (default ``data/step/featuretype.STEP``, a machined part with pockets and
bores), voxel d = 0.5 mm, q = 4 (k = 320 directions), a 6 mm ball with a 20 x 40 mm holder at
25 mm stick-out. The pipeline runs once to compile the kernels on a small part (the
``data/boss.step`` sample at d = 2 mm), then is timed on the part from reading the faces'
samples to the set-ups (``seconds``; the STEP reading is apart, ``read_seconds``).

``pairs_per_s``: boundary voxels x k directions decided per second of the decisions (the
visibility and access stages; comparable to the anchor's Embree rays/s, which leaves out
building the scene); ``pairs_per_s_pipeline``: the same pairs per second of the whole pipeline
(``seconds``: sampling, voxel map, visibility, access, set-ups). ``tool_stats``: shank and
holder tests decided by the dilated buffers as clear, as blocked, and by a disc scan.
``refine``: the refinement's figures (``global_visibility(refine=True)``: half-voxel pieces,
those cast again, the (piece, direction) pairs cast again and freed, voxel and piece pairs
freed). ``agree_share``: share of (point, direction) pairs where the map's V'_g (the point's
half-voxel piece's, ``cad_io.access.point_visibility``) agrees with OCC thin
rays (``cad_io.access.reference_visibility``) on ``--points`` random surface points x all k
directions (the same answer for the same pair; nothing is counted as agreeing for being near
a silhouette); ``voxel_only_far``: pairs the map calls free that OCC finds blocked more than a
voxel diagonal away (non-conservative answers), ``voxel_only_near`` within it;
``disagree_near_silhouette``: disagreements where OCC gives the other answer for the same
direction from a point one voxel diagonal away (a silhouette within one voxel);
``tool_agree_share`` the same for the ball-end map A' (the point's piece's where faces meet,
``cad_io.access.point_access``) against ``reference_tool`` (BRepExtrema on the tool's axis;
``--tool-points`` points); ``tool_voxel_only_far``: pairs the map frees that OCC blocks even
with the shank and holder a voxel diagonal thinner. ``peak_mb``: peak resident memory
of the process (ru_maxrss). ``map_mb``: the voxel map's arrays.

``rays``: casting lines per voxel edge (``--rays``, 2 as in ``analyse``).

Usage: ``python bench/access.py [PART] [--voxel 0.5] [--q 4] [--points 60] [--tool-points 6] [--seed 0]
[--rays 2]``; prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("part", nargs="?", default=str(ROOT / "data" / "step" / "featuretype.STEP"))
    ap.add_argument("--voxel", type=float, default=0.5)
    ap.add_argument("--q", type=int, default=4)
    ap.add_argument("--points", type=int, default=60)
    ap.add_argument("--tool-points", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0, help="seed of the agreement sample points")
    ap.add_argument("--rays", type=int, default=2, help="casting lines per voxel edge")
    args = ap.parse_args()

    from cad_io.access import agreement, analyse
    from cad_io.step import read_step
    from zmap.access.voxelmap import Tool

    tool = Tool(6.0, stickout=25.0, holder_diameter=20.0, holder_length=40.0)
    warm = read_step(ROOT / "data" / "boss.step")
    analyse(warm, d=2.0, q=args.q, tool=tool, rays=args.rays)  # compile the kernels

    t = time.perf_counter()
    part = read_step(args.part)
    read_s = time.perf_counter() - t
    res = analyse(part, d=args.voxel, q=args.q, tool=tool, rays=args.rays)
    vm = res.vm
    pairs = vm.n_boundary * vm.directions.k
    ag = agreement(part, res, n_points=args.points, seed=args.seed, explain=True) if args.points else None
    out = {
        "part": Path(args.part).name, "seed": args.seed, "d": args.voxel, "q": args.q, "rays": args.rays,
        "k": vm.directions.k,
        "tool": "ball 6 mm, holder 20 x 40 mm at 25 mm stick-out",
        "voxels": vm.n_voxels, "boundary_voxels": vm.n_boundary, "interior_voxels": vm.n_interior,
        "samples": vm.n_samples, "read_seconds": round(read_s, 2),
        "seconds": round(res.seconds["total"], 2),
        "stage_seconds": {k: round(v, 2) for k, v in res.seconds.items()},
        "pairs_per_s": round(pairs / (res.seconds["visibility"] + res.seconds["access"])),
        "pairs_per_s_pipeline": round(pairs / res.seconds["total"]),
        "tool_stats": res.stats["tool"],
        "refine": res.stats["refine"],
        "three_axis_share": round(res.verdict["share"], 4),
        "area_inaccessible_mm2": round(res.verdict["area_inaccessible"], 1),
        "setups": len(res.setups),
        "map_mb": round(vm.nbytes / 2**20, 1),
    }
    if ag is not None:  # --points 0: no agreement with the OCC rays
        out.update({"agree_share": round(ag["agree_share"], 5), "agree_pairs": ag["pairs"],
                    "voxel_only_near": ag["voxel_only_near"], "voxel_only_far": ag["voxel_only_far"],
                    "reference_only": ag["reference_only"],
                    "disagree_near_silhouette": ag["disagree_near_silhouette"], "disagree": ag["disagree"]})
    if args.tool_points:
        t = time.perf_counter()
        agt = agreement(part, res, n_points=args.tool_points, seed=args.seed + 1, tool=True)
        out.update({"tool_agree_share": round(agt["agree_share"], 5), "tool_pairs": agt["pairs"],
                    "tool_voxel_only": agt["voxel_only"], "tool_voxel_only_far": agt["voxel_only_far"],
                    "tool_reference_only": agt["reference_only"],
                    "tool_reference_seconds": round(time.perf_counter() - t, 1)})
    out["peak_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
