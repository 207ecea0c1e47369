"""The loop on a window of the cornetta die from its STEP file: program, simulation, compare.

``zmap.cam.raster_program`` over x -45..5, y -25..25 mm of ``data/step/bug27693_cornetta-step.stp``
(6 mm ball, stepover 0.5, chord tol 0.002, the design being the STEP part), simulated on a stock
of the part's exact z-map + 0.3 mm (0.1 mm rays, its interior: 3 mm in from the window) and
compared with that z-map at tol 0.01. Prints one JSON object: the program's figures, the gouge
and excess totals, and the deviation's percentiles (mm above the design).

Run: ``.venv/bin/python bench/die_window_loop.py``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DIE = ROOT / "data" / "step" / "bug27693_cornetta-step.stp"
WINDOW = (-45.0, -25.0, 5.0, 25.0)


def main() -> None:
    import cad_io
    from zmap import ZMap
    from zmap.cam import raster_program
    from zmap.sim import simulate
    from zmap.verify import compare

    part = cad_io.read_step(DIE)
    res: dict = {"window": WINDOW}
    t = time.perf_counter()
    prog = raster_program(part, "ball:6", stepover=0.5, tol=0.002, bounds=WINDOW, name="cornetta")
    res["toolpath_s"] = round(time.perf_counter() - t, 2)
    res["program"] = prog.stats
    p = 0.1
    W = WINDOW
    design = cad_io.sample(part, p, bounds=(W[0] + 3, W[1] + 3, W[2] - 3, W[3] - 3))
    stock = ZMap(design.x0, design.y0, p, p, design.z + 0.3)
    with tempfile.TemporaryDirectory() as tmp:
        path = prog.save(Path(tmp) / "window.nc")
        t = time.perf_counter()
        run = simulate(path, stock, tool="ball:6", pitch=p)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # rays beyond the design's outline, said in totals
            c = compare(run, design, tol=0.01)
        res["simulate_compare_s"] = round(time.perf_counter() - t, 2)
    res["totals"] = {k: v for k, v in c.totals.items() if "gouge" in k or "excess" in k}
    d = c.deviation[np.isfinite(c.deviation)]
    res["deviation_mm"] = {f"p{q}": round(float(np.percentile(d, q)), 5) for q in (50, 75, 90, 99)}
    res["deviation_mm"].update(min=round(float(d.min()), 5), max=round(float(d.max()), 5))
    print(json.dumps(res, indent=1, default=float))


if __name__ == "__main__":
    main()
