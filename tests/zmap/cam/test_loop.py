"""The loop: a real die -> precision model -> CL surface -> finishing program -> simulation on
a stock pre-cut to the design + 0.3 mm -> compare. And the same program with one block
dropped 0.2 mm, whose line compare names as the first gouge.

The die is OCCT's ``bug27693_cornetta-step.stp`` (a mould core, data/SOURCES.md); the window
x -20..20, y 14..22 mm is its B-spline relief where the slopes stay below about 10 degrees,
with the pocket's wall top 3-4 mm beside it (inside the cutter's reach).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from tests.conftest import STEP_DATA
from zmap import ZMap
from zmap.cam.raster import raster_program
from zmap.sim import simulate
from zmap.verify import compare

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("cam")

WIN = (-20.0, 14.0, 20.0, 22.0)
STEPOVER = 0.8
PITCH = 0.1


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    import cad_io
    from cad_io.refine import RefineOptions, refine_models

    part = cad_io.read_step(STEP_DATA / "bug27693_cornetta-step.stp")
    base = cad_io.sample(part, 0.5, bounds=(WIN[0] - 8, WIN[1] - 8, WIN[2] + 8, WIN[3] + 8))
    model = refine_models(part, base, RefineOptions(0.01, ("ez",)))["ez"][0]
    prog = raster_program(model, "ball:6", stepover=STEPOVER, tol=0.002, step=0.1,
                          bounds=(WIN[0] - 4, WIN[1] - STEPOVER, WIN[2] + 4, WIN[3] + STEPOVER),
                          name="cornetta")
    d = tmp_path_factory.mktemp("loop")
    path = prog.save(d / "finish.nc")
    xs = np.arange(WIN[0], WIN[2] + 1e-9, PITCH)
    ys = np.arange(WIN[1], WIN[3] + 1e-9, PITCH)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    stock = ZMap(xs[0], ys[0], PITCH, PITCH, model.height(X.ravel(), Y.ravel()).reshape(X.shape) + 0.3)
    return model, prog, path, stock, d


@pytest.mark.slow
def test_finishing_program_holds_the_design(loop):
    model, prog, path, stock, _d = loop
    run = simulate(path, stock, tool="ball:6", pitch=PITCH)
    c = compare(run, model, tol=0.005)
    dev = c.deviation
    assert np.isfinite(dev).all()
    max_gouge = max(0.0, -float(dev.min()))
    max_excess = float(dev.max())
    assert max_gouge <= 0.005
    assert c.totals["gouge_regions"] == 0
    # the cusps between passes: the flat-floor scallop, within 20 % (slopes <= ~10 degrees)
    assert abs(max_excess - prog.scallop) <= 0.2 * prog.scallop
    assert prog.scallop == pytest.approx(3 - np.sqrt(9 - 0.16))


@pytest.mark.slow
def test_deliberate_error_named_as_first_gouge(loop):
    model, prog, path, stock, d = loop
    lines = path.read_text().splitlines()
    feeds = [i for i, t in enumerate(lines) if t.startswith("G1 ") and "F" not in t]
    k = feeds[len(feeds) // 2]  # a block in the middle of a pass
    m = re.search(r"Z(-?\d+\.\d+)", lines[k])
    lines[k] = lines[k][:m.start(1)] + f"{float(m.group(1)) - 0.2:.5f}" + lines[k][m.end(1):]
    bad = d / "finish_bad.nc"
    bad.write_text("\n".join(lines) + "\n")
    run = simulate(bad, stock, tool="ball:6", pitch=PITCH)
    c = compare(run, model, tol=0.005)
    assert c.totals["gouge_regions"] >= 1
    assert c.totals["max_gouge_mm"] == pytest.approx(0.2, abs=0.03)
    assert c.totals["first_gouge_line"] == k + 1  # 1-based line of the dropped block
    assert c.first_gouge().first_line == k + 1
