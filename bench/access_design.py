"""Tool access of a design that gives heights against the same part's exact faces.

For each STEP part, the access pipeline runs three times with the same voxel, direction set
and ball: on the part's exact faces (``cad_io.access.analyse``, the material its shell or
surface gives), and as a design that gives heights (``zmap.access.analyse_design``, the
material below the top-most surface): on the part's exact top-most heights, and on a z-map
sampled from it (``cad_io.sample`` at ``--pitch``). On a lattice of nodes ``--margin`` mm
inside the part's xy box, 1 mm apart, each answers whether the ball reaches the node's
top-most voxel from +z (:func:`zmap.access.node_directions`).

Per part and design: ``same_share``, the share of nodes where the design and the faces give
the same answer; ``design_only``, nodes the design says the ball reaches from +z and the faces
say it does not; ``faces_only``, the other way (a height field's wall is a steep stretch
between two samples, where the design is the more cautious); ``seconds`` of each pipeline.

The truth for every answer "reached" (``faces`` and each design): the ball touching the
node's top-most point p (the part's exact heights) along its normal n has its centre at
c = p + a n, and ``ball_overlap`` measures how deep it then overlaps the material below the
top-most surface (on a 0.02 mm lattice of columns, so to about 0.02 mm).
``reached_but_blocked``: smooth nodes (``smooth_nodes``: the surface rises less than a voxel
over a voxel either way along x, y and the diagonals, away from walls, where a node's top-most point and normal are well
defined and its voxel column holds no wall) answered "reached" where the ball overlaps by more than 0.02 mm;
``max_overlap_mm``: the largest. The voxel map decides at its resolution: its capsule test
frees a direction when no material voxel centre is nearer the ball's centre than a less half
a voxel diagonal, so overlaps up to half a voxel diagonal (``half_diagonal_mm``) are within
its stated accuracy.

Usage: ``python bench/access_design.py [PARTS ...] [--voxel 1] [--q 2] [--tool 6] [--pitch 0.25]
[--margin 3]``; prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
PARTS = [os.path.join(HERE, "..", "data", n) for n in ("pocket.step", "freeform_die.step", "boss.step")]


def ball_overlap(part, a: float, x: np.ndarray, y: np.ndarray, e: float = 0.01, h: float = 0.02) -> np.ndarray:
    """How deep (mm, >= 0) a ball of radius ``a`` overlaps the part when it touches the part's
    top-most point at each (x, y) along its normal, the material being all below the top-most
    surface (NaN: no surface).

    The centre is c = p + a n (n from the exact heights' central differences, ``e``); the
    overlap is a less the distance from c to the material, the least over the columns (u, v)
    within a of c of ``hypot(|(u, v) - c|, max(0, c_z - h(u, v)))`` on an ``h`` lattice. The
    certified drop-cutter (:func:`zmap.cam.drop_cutter`, never low) first clears the columns
    where the ball lowered from +z stops no higher than c."""
    from zmap.cam import drop_cutter
    from zmap.design import as_design

    hf = as_design(part).heights
    z = hf(x, y)
    p = (hf(x + e, y) - hf(x - e, y)) / (2 * e)
    q = (hf(x, y + e) - hf(x, y - e)) / (2 * e)
    w = np.sqrt(1 + p * p + q * q)
    cx, cy, cz = x - a * p / w, y - a * q / w, z + a / w
    out = np.where(np.isfinite(z), 0.0, np.nan)
    tip = drop_cutter(part, f"ball:{2 * a:g}", cx, cy)
    g = np.arange(-a, a + h / 2, h)
    U, V = np.meshgrid(g, g, indexing="ij")
    disk = np.hypot(U, V) <= a
    U, V, R = U[disk], V[disk], np.hypot(U[disk], V[disk])
    for k in np.flatnonzero(tip + a - cz > 1e-6):
        top = hf(cx[k] + U, cy[k] + V)
        dist = np.hypot(R, np.maximum(0.0, cz[k] - top))
        out[k] = max(0.0, a - float(np.nanmin(dist)))
    return out


def smooth_nodes(part, X: np.ndarray, Y: np.ndarray, d: float) -> np.ndarray:
    """Nodes whose surface rises less than a voxel over a voxel either way along x, y and the
    diagonals: away
    from walls, where a node's top-most point and its normal are well defined, and its voxel
    column holds no wall (the map answers for a column's top-most voxel, and a node on a voxel
    boundary beside a wall gets the wall's top)."""
    from zmap.design import as_design

    h = as_design(part).heights
    z = h(X, Y)
    ok = np.isfinite(z)
    for dx, dy in ((d, 0), (-d, 0), (0, d), (0, -d), (d, d), (d, -d), (-d, d), (-d, -d)):
        ok &= np.abs(h(X + dx, Y + dy) - z) < d
    return ok


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("parts", nargs="*", default=PARTS)
    ap.add_argument("--voxel", type=float, default=1.0)
    ap.add_argument("--q", type=int, default=2)
    ap.add_argument("--tool", type=float, default=6.0, help="ball diameter, mm")
    ap.add_argument("--pitch", type=float, default=0.25, help="the sampled z-map's pitch, mm")
    ap.add_argument("--margin", type=float, default=3.0, help="nodes this far inside the part's xy box, mm")
    args = ap.parse_args()

    import cad_io
    from cad_io.access import analyse
    from zmap.access import Tool, analyse_design, node_directions
    from zmap.access.directions import to_bool

    tool = Tool(args.tool)
    out = {"voxel": args.voxel, "q": args.q, "tool": args.tool, "pitch": args.pitch, "parts": {}}
    for path in args.parts:
        part = cad_io.read_step(path)
        b = part.bbox
        m = args.margin
        X, Y = np.meshgrid(np.arange(b[0] + m, b[3] - m, 1.0), np.arange(b[1] + m, b[4] - m, 1.0), indexing="ij")

        def from_above(result):
            vox, _ = node_directions(result.vm, result.amap, X, Y)
            up = result.vm.directions.index("+z")
            return (vox >= 0) & to_bool(result.amap, result.vm.directions.k)[np.maximum(vox, 0), up]

        # the faces first: the height sampler leaves a finer mesh on the part (see docs/access.md)
        t = time.perf_counter()
        faces = from_above(analyse(part, d=args.voxel, q=args.q, tool=tool))
        faces_seconds = round(time.perf_counter() - t, 2)
        overlap = ball_overlap(part, args.tool / 2, X.ravel(), Y.ravel()).reshape(X.shape)
        smooth = smooth_nodes(part, X, Y, args.voxel)

        def truth(reached):
            bad = reached & smooth & (overlap > 0.02)
            return {"reached_but_blocked": int(bad.sum()),
                    "max_overlap_mm": round(float(overlap[bad].max()), 4) if bad.any() else 0.0}

        row = {"nodes": int(X.size), "smooth_nodes": int(smooth.sum()),
               "half_diagonal_mm": round(0.5 * np.sqrt(3) * args.voxel, 4),
               "faces": {"seconds": faces_seconds, **truth(faces)}}
        for name, design in (("exact heights", part), ("z-map", cad_io.sample(part, args.pitch))):
            t = time.perf_counter()
            heights = from_above(analyse_design(design, d=args.voxel, q=args.q, tool=tool))
            row[name] = {"same_share": round(float((heights == faces).mean()), 4),
                         "design_only": int((heights & ~faces).sum()),
                         "faces_only": int((faces & ~heights).sum()),
                         "seconds": round(time.perf_counter() - t, 2), **truth(heights)}
        out["parts"][os.path.basename(path)] = row
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
