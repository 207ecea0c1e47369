"""CZ against EZ: what a CZ model must store on each real part.

A CZ-map (paper 004 §3.1) holds a wall or sharp edge to ``tol`` by sampling a band along
the feature curve on a rotated grid ``delta_y = tol`` across the curve and
``delta_x = tol / tan(theta_x)`` along it: the curve, within ``theta_x`` of the domain's
axis, moves at most ``delta_y`` sideways over one ``delta_x``. Both intervals follow from
the tolerance alone, so its memory grows with the features' length over ``tol^2``, where
the EZ-map's grows with the number of base grid edges the features cross.

For each part this prints (one JSON object, and a markdown table with ``--markdown``):

- ``curve_mm``: length of the feature curves that ``refine_models`` lays CZ domains along
  (VW curves traced on the base map and SE curves from the part's sharp and open edges);
- ``paper_kb``: the CZ model that ``refine_models(..., ("cz",))`` builds (the layout of
  :func:`zmap.refine.cz.cz_layout`: margin of 2 base intervals each side, 8 bytes a node),
  and ``paper_over_base``;
- ``least_kb``: a floor under any CZ that holds ``tol`` on these curves, as generous to the
  CZ as the geometry allows: a band of one base interval ``h`` each side of the curve (the
  least that covers the cells a crossing spoils), ``delta_y = tol`` across it, and along it
  ``delta_x = h`` (as if every run were straight and on its domain's axis: a CZ-map coarser
  than the base map along the curve would refine nothing there), 2 bytes a node (a 16-bit
  code, where the base map is stored at 8), no overlap between domains:
  ``curve_mm / h * (2 h / tol) * 2 = 4 curve_mm / tol`` bytes; ``least_over_base`` the same
  over the base map. With the paper's ``delta_x = tol / tan(20 deg)`` instead of ``h`` it
  is ``h tan(20 deg) / tol`` times more (``paper_dx_kb``);
- ``ez_kb`` (with ``--ez``): the EZ model's e-map as stored, for the same base map, and
  ``least_over_ez``.

Usage::

    python bench/cz_vs_ez.py [--grid 0.5] [--tol 0.01] [--only NAME ...] [--ez] [--markdown FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: the parts the issue names for CZ (deliverable 3) and the two bundled samples
DEFAULT_PARTS = ("data/step/bug27693_cornetta-step.stp", "data/step/bug27453_165-174_piattello.stp",
                 "data/step/featuretype.STEP", "data/step/Ventilator.stp", "data/pocket.step", "data/boss.step")
THETA_X = math.radians(20.0)


def curve_length(curves) -> float:
    """Total xy length (mm) of a list of polylines."""
    import numpy as np

    total = 0.0
    for c in curves:
        c = np.asarray(c, dtype=np.float64).reshape(-1, 2)
        c = c[np.all(np.isfinite(c), axis=1)]
        if len(c) > 1:
            total += float(np.hypot(*np.diff(c, axis=0).T).sum())
    return total


def one_part(path: Path, grid: float, tol: float, with_ez: bool) -> dict:
    """CZ plan, CZ floor and (optionally) EZ bytes of one part."""
    from cad_io.refine import CZ_DELTA_Y_SHARE, cz_curves
    from cad_io.sampler import sample
    from cad_io.step import read_step
    from zmap.features import default_eps_r, sharp_edge_curves
    from zmap.refine.cz import cz_intervals, cz_layout

    t0 = time.perf_counter()
    part = read_step(path)
    base = sample(part, grid, progress=False)
    base_bytes = int(base.z.nbytes)  # the heights, as PrecisionModel.nbytes counts the base
    eps_r = default_eps_r(tol, base.dx, base.dy)
    curves = cz_curves(base, eps_r, sharp_edge_curves(part.edges))  # refine_models' CZ curves
    length = curve_length(curves)
    lay = cz_layout(base, tol=CZ_DELTA_Y_SHARE * tol, curves=curves, theta_x=THETA_X)
    paper_bytes = 8 * int(lay.prod(axis=1).sum()) if lay.size else 0
    ddx, ddy = cz_intervals(tol, THETA_X)
    h = max(base.dx, base.dy)
    least_bytes = 2.0 * (length / h) * (2.0 * h / ddy)
    paper_dx_bytes = 2.0 * (length / ddx) * (2.0 * h / ddy)
    out = {"part": path.name, "grid": grid, "tol": tol, "base_kb": round(base_bytes / 1024, 1),
           "curves": len(curves), "curve_mm": round(length, 1), "paper_domains": int(lay.shape[0]),
           "paper_kb": round(paper_bytes / 1024, 1), "paper_over_base": round(paper_bytes / base_bytes, 1),
           "least_kb": round(least_bytes / 1024, 1), "least_over_base": round(least_bytes / base_bytes, 1),
           "paper_dx_kb": round(paper_dx_bytes / 1024, 1)}
    if with_ez:
        from cad_io.refine import RefineOptions, refine_models

        model, info = refine_models(part, base, RefineOptions(tol, ("ez",)))["ez"]
        ez_bytes = model.ez.nbytes
        out.update({"ez_kb": round(ez_bytes / 1024, 1), "ez_over_base": round(1 + ez_bytes / base_bytes, 2),
                    "least_over_ez": round(least_bytes / ez_bytes, 1), "ez_seconds": round(info["seconds"], 1)})
    out["seconds"] = round(time.perf_counter() - t0, 1)
    return out


def markdown(rows: list[dict]) -> str:
    cols = [("part", "part"), ("curve_mm", "feature curves (mm)"), ("base_kb", "base (KB)"),
            ("paper_kb", "CZ as built (KB)"), ("paper_over_base", "CZ as built / base"),
            ("paper_dx_kb", "band +-h at the paper's intervals, 16 bit (KB)"),
            ("least_kb", "CZ floor (KB)"), ("least_over_base", "CZ floor / base"),
            ("ez_kb", "e-map (KB)"), ("ez_over_base", "EZ / base"), ("least_over_ez", "CZ floor / e-map")]
    cols = [c for c in cols if any(c[0] in r for r in rows)]
    lines = ["| " + " | ".join(h for _, h in cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(f"{r[k]:,}" if isinstance(r.get(k), (int, float)) else str(r.get(k, "–"))
                                       for k, _ in cols) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grid", type=float, default=0.5)
    ap.add_argument("--tol", type=float, default=0.01)
    ap.add_argument("--only", nargs="*", default=None, help="parts whose file name contains one of these")
    ap.add_argument("--ez", action="store_true", help="also build the EZ model of each part and compare")
    ap.add_argument("--markdown", type=Path, default=None)
    a = ap.parse_args()
    paths = [ROOT / p for p in DEFAULT_PARTS]
    if a.only:
        paths = [p for p in paths if any(s in p.name for s in a.only)]
    rows = []
    for p in paths:
        print(f"{p.name} ...", file=sys.stderr, flush=True)
        rows.append(one_part(p, a.grid, a.tol, a.ez))
        print(f"  {rows[-1]}", file=sys.stderr, flush=True)
    print(json.dumps({"grid": a.grid, "tol": a.tol, "theta_x_deg": 20.0, "parts": rows}))
    if a.markdown:
        a.markdown.write_text(markdown(rows))


if __name__ == "__main__":
    main()
