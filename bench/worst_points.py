"""The worst points of a part's EZ model: where its heights are farthest from the B-rep.

Builds the base z-map and the EZ model of one STEP part (as ``bench/table2.py`` does, EZ only)
and prints one JSON object: the ``--top`` random points (of ``--points``, seeded) farthest from
the part's faces (:func:`cad_io.distance.distance_to_part`), each with the model's and the exact
height, the distance and the base cell, and the EZ cell check's counts.

    python bench/worst_points.py data/step/Ventilator.stp --grid 2 --tol 0.02 [--axis +z] [--points 5000]
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part")
    ap.add_argument("--grid", type=float, required=True)
    ap.add_argument("--tol", type=float, required=True)
    ap.add_argument("--axis", default="+z")
    ap.add_argument("--points", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--top", type=int, default=5)
    a = ap.parse_args()
    from cad_io.refine import RefineOptions, refine_models
    from cad_io.distance import distance_to_part
    from cad_io.sampler import sample, sample_points
    from cad_io.step import read_step
    from cad_io.view import view_part

    part = view_part(read_step(a.part), a.axis)
    base = sample(part, a.grid)
    defl = a.tol / 2
    model = refine_models(part, base, RefineOptions(a.tol, ("ez",), deflection=defl))["ez"][0]
    rng = np.random.default_rng(a.seed)
    x0, y0, x1, y1 = base.bounds
    xs, ys = rng.uniform(x0, x1, a.points), rng.uniform(y0, y1, a.points)
    h = model.height(xs, ys)
    zex = sample_points(part, xs, ys, deflection=defl)[0]
    ok = np.flatnonzero(np.isfinite(h))
    d = distance_to_part(part, np.c_[xs[ok], ys[ok], h[ok]], deflection=defl)
    worst = []
    for k in np.argsort(-d)[: a.top]:
        j = ok[k]
        worst.append({"x": round(float(xs[j]), 4), "y": round(float(ys[j]), 4), "model": round(float(h[j]), 4),
                      "exact": round(float(zex[j]), 4), "distance": round(float(d[k]), 4),
                      "cell": [int((xs[j] - x0) // base.dx), int((ys[j] - y0) // base.dy)]})
    print(json.dumps({"part": a.part, "axis": a.axis, "grid": a.grid, "tol": a.tol, "points": a.points,
                      "seed": a.seed, "worst": worst, "ez_patches": int(model.ez.n_patches),
                      "ez_unresolved": int(model.ez.unresolved)}))


if __name__ == "__main__":
    main()
