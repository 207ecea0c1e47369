"""Finishing programs on the z-maps of the nine real parts of data/step, and the loop on them.

The maps (tests/data/part_maps, written by tests/data/make_part_maps.py with the project's own
sampler) are the designs. On a window of each, a raster program's CL points must all lie at or
above an independent brute force (every node under the cutter and the Bezier surface on a
lattice over the disk and its rim, :mod:`tests.zmap.cam.brute`); and the loop, program ->
simulation on a stock of design + 0.3 mm -> compare, must show no gouge, while a feed lowered
by 0.3 mm is found at its line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from tests.zmap.cam.brute import brute_zmap
from zmap import ZMap
from zmap.cam.raster import raster_program
from zmap.interpolate import bezier
from zmap.sim.tools import parse_tool_spec

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("cam")

MAPS = sorted((Path(__file__).resolve().parents[2] / "data" / "part_maps").glob("*.zmap.npz"))
TOL = 0.01


def _setup(path):
    """The design, a cutter to its scale (a 6 mm ball, larger on coarse maps), and a window of
    about 30 x 30 nodes in the middle of the map."""
    zm = ZMap.load(path)
    g = zm.dx
    D = max(6.0, round(4 * g))
    nx, ny = zm.z.shape
    i0, j0 = max(0, nx // 2 - 15), max(0, ny // 2 - 15)
    i1, j1 = min(nx - 1, i0 + 30), min(ny - 1, j0 + 30)
    win = (zm.x0 + i0 * g, zm.y0 + j0 * g, zm.x0 + i1 * g, zm.y0 + j1 * g)
    # CL points close enough that a feed's sag over a convex edge, step^2 / (8 R), stays < TOL / 2
    step = min(g / 2, math.sqrt(4 * (D / 2) * TOL))
    return zm, parse_tool_spec(f"ball:{D:g}"), win, step


def test_the_nine_parts_are_there():
    assert len(MAPS) == 9


@pytest.mark.parametrize("path", MAPS, ids=lambda p: p.name.split(".")[0])
@pytest.mark.slow
def test_program_never_below_the_brute_force(path):
    zm, cut, win, step = _setup(path)
    prog = raster_program(zm, cut, stepover=2 * zm.dx, step=step, bounds=win, tol=0.002)
    pts = np.concatenate(prog.passes)
    ends = np.concatenate([np.stack([p[0], p[-1]]) for p in prog.passes])
    rng = np.random.default_rng(0)
    pick = np.concatenate([pts[rng.choice(len(pts), min(150, len(pts)), replace=False)], ends[:100]])
    ref = brute_zmap(zm, cut, pick[:, 0], pick[:, 1], h=zm.dx / 20)
    ok = np.isfinite(ref)
    assert ok.all()  # every CL point of the program stands over the design
    below = ref - pick[:, 2]
    assert below.max() <= 1e-4, (below.max(), pick[np.argmax(below)])


@pytest.mark.slow
@pytest.mark.parametrize("path", MAPS, ids=lambda p: p.name.split(".")[0])
def test_loop_clean_and_planted_fault(path, tmp_path):
    from zmap.sim import simulate
    from zmap.verify import compare

    zm, cut, win, step = _setup(path)
    prog = raster_program(zm, cut, stepover=2 * zm.dx, step=step, bounds=win, tol=0.002, name=path.name)
    nc = prog.save(tmp_path / "finish.nc")
    # the stock: the design + 0.3 mm over the window and the cutter's reach, rays 1 mm apart or
    # a quarter of a coarse map's grid (its nodes alone would straddle a planted dip)
    p = min(zm.dx, max(1.0, zm.dx / 4))
    pad = cut.radius + zm.dx
    xs = np.arange(max(win[0] - pad, zm.x0), min(win[2] + pad, zm.bounds[2]) + 1e-9, p)
    ys = np.arange(max(win[1] - pad, zm.y0), min(win[3] + pad, zm.bounds[3]) + 1e-9, p)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    stock = ZMap(xs[0], ys[0], p, p, bezier(zm, X, Y) + 0.3)
    run = simulate(nc, stock, tool=f"ball:{cut.diameter:g}", pitch=p)
    c = compare(run, zm, tol=TOL)
    assert c.totals["gouge_regions"] == 0, c.totals
    # one feed lowered by 0.3 mm, the one nearest the middle of the program whose contact lies
    # under the cutter's axis (on a steep wall the dip would stay between the rays): found, at
    # its line
    lines = nc.read_text().splitlines()
    feeds, gap = [], []
    for i, t in enumerate(lines):
        if t.startswith("G1 ") and " X" in t and "F" not in t:
            x, y, z = (float(re.search(a + r"(-?\d+\.\d+)", t).group(1)) for a in "XYZ")
            feeds.append(i)
            gap.append(abs(float(bezier(zm, x, y)) - z))  # NaN off the design
    gap = np.nan_to_num(np.array(gap), nan=np.inf)
    under = np.flatnonzero(gap < 1e-3)
    k = feeds[under[len(under) // 2]] if under.size else feeds[int(np.argmin(gap))]
    m = re.search(r"Z(-?\d+\.\d+)", lines[k])
    lines[k] = lines[k][:m.start(1)] + f"{float(m.group(1)) - 0.3:.5f}" + lines[k][m.end(1):]
    bad = tmp_path / "finish_bad.nc"
    bad.write_text("\n".join(lines) + "\n")
    c = compare(simulate(bad, stock, tool=f"ball:{cut.diameter:g}", pitch=p), zm, tol=TOL)
    assert c.totals["gouge_regions"] >= 1
    assert c.totals["first_gouge_line"] == k + 1
