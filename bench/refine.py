"""Benchmark of the precision refinements (paper 004 §3) on the bundled pocket and boss.

Prints one JSON object: for data/pocket.step the PrecisionModel query rate (EZ model, JIT
warmed up), the largest 3D distance to the B-rep of the EZ, CZ and base models at 10^5
random points, the EZ memory over the base's, and the bytes of a plain z-map at the e-map
interval; the same for data/boss.step under "boss".

    python bench/refine.py [--grid 0.5] [--tol 0.01] [--points 100000]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "data"


def run(path: Path, grid: float, tol: float, points: int) -> dict:
    from cad_io.refine import RefineOptions, ReportOptions, refine_models, report_rows
    from cad_io.sampler import sample
    from cad_io.step import read_step

    part = read_step(path)
    base = sample(part, grid)
    models = refine_models(part, base, RefineOptions(tol, ("ez", "cz")))
    rep = report_rows(part, ReportOptions(grid, tol, n_points=points), models=models, base=base)
    ez = models["ez"][0]
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = base.bounds
    xs = rng.uniform(x0, x1, 2_000_000)
    ys = rng.uniform(y0, y1, 2_000_000)
    ez.height(xs[:100], ys[:100])
    best = np.inf
    for _ in range(3):
        t = time.perf_counter()
        ez.height(xs, ys)
        best = min(best, time.perf_counter() - t)
    r = rep["rows"]
    return {"model_qps": round(xs.size / best),
            "ez_max_dist": r["ez"]["max_dist"], "base_max_dist": r["base"]["max_dist"],
            "cz_max_dist": r["cz"]["max_dist"], "cz_max_dist_in_domains": r["cz"].get("max_dist_in_cz"),
            "ez_p999_dist": r["ez"]["p999_dist"],
            "memory_ratio": r["ez"]["total_bytes"] / r["base"]["total_bytes"],
            "cz_memory_ratio": r["cz"]["total_bytes"] / r["base"]["total_bytes"],
            "plain_fine_bytes": rep["plain_fine_bytes"],
            "ez_total_bytes": r["ez"]["total_bytes"], "emap_ratio": r["ez"]["emap_ratio"],
            "ez_facet_points": r["ez"].get("facet_points"), "grid": grid, "tol": tol, "points": points}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=float, default=0.5)
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--points", type=int, default=100_000)
    a = ap.parse_args()
    out = run(DATA / "pocket.step", a.grid, a.tol, a.points)
    out["boss"] = run(DATA / "boss.step", a.grid, a.tol, a.points)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
