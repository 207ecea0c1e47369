"""Interpolation throughput and accuracy on a 1000x1000 sphere-cap z-map.

Every zmap scheme and two SciPy references (RectBivariateSpline kx=ky=3 and
RegularGridInterpolator method="cubic") on the same grid and the same 10^7 random points,
in one run. RegularGridInterpolator's cubic method is far slower, so it is timed on the
first ``--rgi-points`` points (reported). Prints one JSON object.

    .venv/bin/python bench/interpolate.py [--points 10000000]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numba
import numpy as np
from scipy.interpolate import RectBivariateSpline, RegularGridInterpolator

from zmap.accuracy import zmap_of
from zmap.interpolate import bezier, bilinear
from zmap.surfaces import sphere_cap


def timed(fn, *args, repeat: int = 1):
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn(*args)
        best = min(best, time.perf_counter() - t)
    return out, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10_000_000)
    ap.add_argument("--rgi-points", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    surf = sphere_cap(half_width=50.0)  # corners at r = 70.7: the whole square is on the cap
    grid = 100.0 / 999.0  # 1000 x 1000 grid points over [-50, 50]^2
    zm = zmap_of(surf, grid, margin=0)
    assert zm.shape == (1000, 1000), zm.shape
    rng = np.random.default_rng(args.seed)
    x = rng.uniform(zm.x0, zm.x1, args.points)
    y = rng.uniform(zm.y0, zm.y1, args.points)
    exact = surf.height(x, y)
    # Points two cells or more from the edge, where every stencil is complete.
    inner = (np.abs(x) <= 50.0 - 2 * grid) & (np.abs(y) <= 50.0 - 2 * grid)

    result: dict = {"grid": list(zm.shape), "grid_interval": grid, "points": args.points,
                    "threads": numba.get_num_threads(), "cpus": os.cpu_count(), "machine": platform.machine()}
    schemes = {
        "bezier": lambda: bezier(zm, x, y, tangent="circle"),
        "bezier_central": lambda: bezier(zm, x, y, tangent="central"),
        "bezier_quartic": lambda: bezier(zm, x, y, tangent="quartic"),
        "bezier_quartic_onesided": lambda: bezier(zm, x, y, tangent="quartic", boundary="one-sided"),
        "bilinear": lambda: bilinear(zm, x, y),
    }
    for name, fn in schemes.items():
        if name.startswith("bezier"):
            bezier(zm, x[:10], y[:10], tangent="circle")  # JIT warm-up
        bilinear(zm, x[:10], y[:10])
        h, sec = timed(fn, repeat=3)
        result[f"{name}_qps"] = args.points / sec
        result[f"{name}_max_err"] = float(np.nanmax(np.abs(h - exact)))
        result[f"{name}_interior_max_err"] = float(np.nanmax(np.abs(h - exact)[inner]))

    spline, build = timed(lambda: RectBivariateSpline(zm.x, zm.y, zm.z, kx=3, ky=3))
    h, sec = timed(spline.ev, x, y)
    result["spline_build_s"] = build
    result["spline_qps"] = args.points / sec
    result["spline_max_err"] = float(np.abs(h - exact).max())
    result["spline_interior_max_err"] = float(np.abs(h - exact)[inner].max())

    n = min(args.rgi_points, args.points)
    rgi, build = timed(lambda: RegularGridInterpolator((zm.x, zm.y), zm.z, method="cubic"))
    h, sec = timed(rgi, np.column_stack([x[:n], y[:n]]))
    result["rgi_cubic_build_s"] = build
    result["rgi_cubic_points"] = n
    result["rgi_cubic_qps"] = n / sec
    result["rgi_cubic_max_err"] = float(np.abs(h - exact[:n]).max())
    result["bezier_over_spline_qps"] = result["bezier_qps"] / result["spline_qps"]
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
