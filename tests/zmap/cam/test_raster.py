"""Raster finishing programs: format, chord tolerance, safe links, and ``zmap toolpath``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zmap import ZMap
from zmap.cam import drop_cutter
from zmap.cam.raster import raster_program, scallop_height, simplify_chords
from zmap.cli import main
from zmap.sim.gcode import LINEAR, RAPID, parse

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("cam")


def _dome():
    return ZMap.from_function(lambda x, y: 5 - 0.02 * (x * x + y * y) + np.where(x > 4, 2.0, 0.0),
                              (-12, -12, 12, 12), 0.2)


def test_scallop_formulas():
    assert scallop_height("ball:6", 0.4) == pytest.approx(3 - math.sqrt(9 - 0.04))
    assert scallop_height("flat:6", 5.9) == 0.0
    assert scallop_height("bull:10:1", 7.0) == 0.0  # within the 8 mm flat bottom
    assert scallop_height("bull:10:1", 9.0) == pytest.approx(1 - math.sqrt(1 - 0.25))
    with pytest.raises(ValueError, match="more than the cutter diameter"):
        scallop_height("ball:6", 7)


def test_simplify_chords_keeps_every_point_within_tol():
    rng = np.random.default_rng(0)
    u = np.linspace(0, 10, 400)
    z = np.sin(u) + 0.01 * rng.standard_normal(400)
    keep = simplify_chords(u, z, 0.02)
    interp = np.interp(u, u[keep], z[keep])
    assert np.abs(interp - z).max() <= 0.02 + 1e-12
    assert keep.size < 200


def test_program_is_plain_gcode_our_reader_parses(tmp_path):
    m = _dome()
    prog = raster_program(m, "ball:6", stepover=1.0, tol=0.005, bounds=(-1, -5, 7, 5), angle=math.radians(30))
    text = prog.text
    assert "G21 G90 G17" in text and "M3" in text and text.rstrip().endswith("M2")
    assert "(predicted scallop height 0.041960 mm on a flat floor)" in text
    assert "ball end mill D6" in text and "stepover 1 mm" in text and "angle 30 deg" in text
    for line in text.splitlines():
        assert line.startswith(("(", "G0 ", "G1 ", "G21", "S", "M5", "M2")), line
    p = prog.save(tmp_path / "f.nc")
    pr = parse(p)
    kinds = set(pr.moves["kind"].tolist())
    assert kinds <= {RAPID, LINEAR}
    feeds = pr.moves[pr.moves["kind"] == LINEAR]
    # every feed end point is on the CL surface: the tool never sits below it
    end = feeds["end"]
    cl = drop_cutter(m, "ball:6", end[:, 0], end[:, 1])
    assert np.all(end[:, 2] >= cl - 1e-4)
    # rapids only at the clearance height or above the next feed's start
    rap = pr.moves[pr.moves["kind"] == RAPID]
    assert np.all(rap["end"][:, 2] >= np.nanmin(cl))
    assert prog.stats["passes"] >= 10 and prog.stats["kept_points"] < prog.stats["cl_points"]


def test_chord_tolerance_bounds_the_linearised_cl():
    m = _dome()
    tol = 0.003
    prog = raster_program(m, "ball:6", stepover=2.0, tol=tol, bounds=(0, -4, 8, 4), step=0.05)
    t = np.linspace(0, 1, 9)[1:-1]
    mids = []
    for pts in prog.passes:
        a, b = pts[:-1], pts[1:]
        mids.append((a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3))
    mid = np.vstack(mids)
    cl = drop_cutter(m, "ball:6", mid[:, 0], mid[:, 1])
    worst = float(np.max(cl - mid[:, 2]))
    # between CL samples 0.05 mm apart the curvature adds little beyond the chord tolerance
    assert worst <= tol + 2e-4


def test_bad_parameters():
    m = _dome()
    for kw, needle in (({"stepover": -1}, "stepover"), ({"stepover": 1, "tol": 0}, "tol"),
                       ({"stepover": 1, "bounds": (1, 1, 0, 0)}, "bounds")):
        with pytest.raises(ValueError, match=needle):
            raster_program(m, "ball:6", **kw)
    with pytest.raises(ValueError, match="no surface"):
        raster_program(m, "ball:6", stepover=1, bounds=(100, 100, 110, 110))


def test_toolpath_command(tmp_path, capsys):
    d = tmp_path / "dome.zmap.npz"
    _dome().save(d)
    out = tmp_path / "finish.nc"
    rc = main(["toolpath", str(d), "--tool", "ball:6", "--stepover", "1.5", "--angle", "90", "--tol", "0.005",
               "--bounds", "-5", "-5", "5", "5", "-o", str(out)])
    assert rc == 0, capsys.readouterr().err
    assert "predicted scallop" in out.read_text()
    assert len(parse(out).moves) > 10
    rc = main(["toolpath", str(d), "--tool", "ball:6", "--stepover", "-1", "-o", str(out)])
    assert rc == 1 and "stepover" in capsys.readouterr().err
    rc = main(["toolpath", str(tmp_path / "none.zpm"), "--tool", "ball:6", "--stepover", "1", "-o", str(out)])
    assert rc == 1 and "no such file" in capsys.readouterr().err


def test_passes_are_linked_along_the_cl_surface_without_retracts():
    # a dome and a step: every pass end lies over design, so every link is a feed; no point
    # of any feed (links included) passes under the CL surface by more than the sag test's 1e-3
    zm = ZMap.from_function(lambda x, y: 5 - 0.02 * (x * x + y * y) + np.where(y > 1.3, 1.0, 0.0),
                            (-10, -10, 10, 10), 0.25)
    prog = raster_program(zm, "ball:6", stepover=0.7, tol=0.002, bounds=(-4, -4, 4, 4))
    assert prog.stats["retracts"] == 0 and prog.stats["links"] == prog.stats["passes"] - 1
    pr = parse(prog.text)
    feeds = pr.moves[pr.moves["kind"] == LINEAR]
    a, b = feeds["start"][1:], feeds["end"][1:]   # after the plunge
    t = np.linspace(0, 1, 11)
    pts = (a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3)
    cl = drop_cutter(zm, "ball:6", pts[:, 0], pts[:, 1])
    assert np.max(cl - pts[:, 2]) <= 1e-3 + 1e-6
    # the step's edge is crossed by the links too (the first passes lie below it)
    assert (b[:, 1] - a[:, 1] > 0).any()
