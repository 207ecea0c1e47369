"""zmap refine / zmap report: bad input and one end-to-end run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cad_io.refine import OptionError, RefineOptions, ReportOptions
from zmap.cli import main
from zmap.model import PrecisionModel

DATA = Path(__file__).resolve().parents[2] / "data"


@pytest.fixture(scope="module")
def boss_zmap(tmp_path_factory):
    out = tmp_path_factory.mktemp("z") / "boss.zmap.npz"
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1.0", "-o", str(out), "--no-progress"]) == 0
    return out


def test_refine_needs_part(boss_zmap, tmp_path, capsys):
    assert main(["refine", str(boss_zmap), "--tol", "0.01", "-o", str(tmp_path / "a.zpm")]) != 0
    assert "exact surface" in capsys.readouterr().err
    assert main(["refine", str(boss_zmap), "--part", str(tmp_path / "nope.step"), "--tol", "0.01",
                 "-o", str(tmp_path / "a.zpm")]) != 0
    assert "exact surface" in capsys.readouterr().err


def test_refine_tol_not_below_grid(boss_zmap, tmp_path, capsys):
    assert main(["refine", str(boss_zmap), "--part", str(DATA / "boss.step"), "--tol", "1.0",
                 "-o", str(tmp_path / "a.zpm")]) != 0
    err = capsys.readouterr().err
    assert "1 mm" in err and "dx=1" in err


@pytest.mark.slow
def test_refine_ez_and_report(boss_zmap, tmp_path, capsys):
    out = tmp_path / "boss.zpm"
    assert main(["refine", str(boss_zmap), "--part", str(DATA / "boss.step"), "--tol", "0.05",
                 "--method", "ez", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "facet heights" in text
    m = PrecisionModel.load(out)
    assert m.ez is not None and m.nbytes["ez"] > 0
    assert main(["report", str(DATA / "boss.step"), "--grid", "1.0", "--tol", "0.05", "--points", "2000",
                 "--method", "ez", "--format", "json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert set(rep["rows"]) == {"base", "ez"}
    assert rep["plain_fine_bytes"] > rep["rows"]["ez"]["total_bytes"]


@pytest.fixture(scope="module")
def boss_zmap_y(tmp_path_factory):
    out = tmp_path_factory.mktemp("zy") / "boss_y.zmap.npz"
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1.0", "--axis", "+y", "-o", str(out),
                 "--no-progress"]) == 0
    return out


@pytest.mark.slow
def test_refine_a_zmap_seen_from_plus_y(boss_zmap_y, tmp_path, capsys):
    out = tmp_path / "boss_y.zpm"
    assert main(["refine", str(boss_zmap_y), "--part", str(DATA / "boss.step"), "--tol", "0.05",
                 "--method", "ez", "-o", str(out)]) == 0
    assert "e-points" in capsys.readouterr().out
    m = PrecisionModel.load(out)
    assert m.base.meta["axis"] == "+y" and m.ez.n_points > 0


def test_refine_rejects_a_zmap_of_another_part_or_axis(tmp_path, capsys):
    far = tmp_path / "far.zmap.npz"
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1.0", "--bounds", "500", "500", "510", "510",
                 "-o", str(far), "--no-progress"]) == 0
    assert main(["refine", str(far), "--part", str(DATA / "boss.step"), "--tol", "0.05",
                 "-o", str(tmp_path / "a.zpm")]) != 0
    assert "misses boss.step seen from +z" in capsys.readouterr().err


def test_refine_rejects_an_unknown_axis_in_the_zmap(boss_zmap, tmp_path, capsys):
    from zmap.grid import ZMap

    zm = ZMap.load(boss_zmap)
    zm.meta["axis"] = "up"
    bad = tmp_path / "bad.zmap.npz"
    zm.save(bad)
    assert main(["refine", str(bad), "--part", str(DATA / "boss.step"), "--tol", "0.05",
                 "-o", str(tmp_path / "a.zpm")]) != 0
    assert "axis 'up' is not one of" in capsys.readouterr().err


@pytest.mark.slow
def test_report_seen_from_plus_y(capsys):
    # the part and its OCP shape are rotated together: were OCC measuring in the world frame,
    # the base's distances would be tens of mm, not within a grid interval
    assert main(["report", str(DATA / "boss.step"), "--axis", "+y", "--grid", "1.0", "--tol", "0.05",
                 "--points", "1000", "--method", "ez", "--format", "json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["axis"] == "+y"
    rows = rep["rows"]
    assert 0 < rows["base"]["max_dist"] < 1.0
    assert rows["ez"]["max_dist"] < rows["base"]["max_dist"]


def test_report_bad_deflection(capsys):
    assert main(["report", str(DATA / "boss.step"), "--grid", "1.0", "--tol", "0.05", "--deflection", "-1"]) != 0
    assert "--deflection" in capsys.readouterr().err


@pytest.mark.parametrize("make, field", [
    (lambda: RefineOptions(0.0), "tol"),
    (lambda: RefineOptions(float("nan")), "tol"),
    (lambda: RefineOptions(0.01, ("ez", "xz")), "methods"),
    (lambda: RefineOptions(0.01, deflection=-0.1), "deflection"),
    (lambda: RefineOptions(0.01, theta_x=0.0), "theta_x"),
    (lambda: ReportOptions(-1.0, 0.01), "grid"),
    (lambda: ReportOptions(1.0, 1.0), "tol"),
    (lambda: ReportOptions(1.0, 0.05, n_points=0), "n_points"),
    (lambda: ReportOptions(1.0, 0.05, n_points=2.5), "n_points"),
    (lambda: ReportOptions(1.0, 0.05, distance_deflection=float("inf")), "distance_deflection"),
])
def test_refine_and_report_options_name_the_field_at_fault(make, field):
    with pytest.raises(OptionError) as err:
        make()
    assert err.value.option == field and isinstance(err.value, ValueError)


def test_report_options_take_a_method_name_and_default_their_deflections_to_half_tol():
    o = ReportOptions(2.0, 0.02, methods="ez")
    assert o.methods == ("ez",) and o.height_deflection == o.distance_mesh_deflection == 0.01
    assert o.refine_options() == RefineOptions(0.02, ("ez",), deflection=0.01)


def test_report_bad_points_is_named_as_the_option(capsys):
    assert main(["report", str(DATA / "boss.step"), "--grid", "1.0", "--tol", "0.05", "--points", "0"]) != 0
    assert "--points" in capsys.readouterr().err


@pytest.mark.slow
def test_report_rows_deflection_and_reference_facet_count():
    from cad_io.refine import ReportOptions, report_rows
    from cad_io.step import read_step

    part = read_step(DATA / "boss.step")
    rep = report_rows(part, ReportOptions(1.0, 0.05, n_points=500, methods=("ez",)))
    assert (rep["deflection"], rep["distance_deflection"]) == (0.025, 0.025)  # tol / 2 by default
    assert rep["reference_facet_points"] == 0 and rep["reference_empty_points"] == 0
    fine = report_rows(part, ReportOptions(1.0, 0.05, n_points=500, methods=("ez",), deflection=0.005,
                                           distance_deflection=0.005))
    assert fine["deflection"] == 0.005
    # the exact heights (Newton) and NURBS feet do not depend on the mesh
    for name in ("base", "ez"):
        assert fine["rows"][name]["max_dist"] == pytest.approx(rep["rows"][name]["max_dist"], abs=1e-9)
        assert fine["rows"][name]["max_vertical_flat"] == pytest.approx(rep["rows"][name]["max_vertical_flat"],
                                                                       abs=1e-9)
    with pytest.raises(ValueError, match="distance_deflection must be a positive"):
        ReportOptions(1.0, 0.05, n_points=10, methods=(), distance_deflection=0.0)


def test_skirt_bound_under_an_overhang(tmp_path):
    """A mushroom (a 30 mm cap on a 10 mm stem over a base plate) seen from +z: the top-most
    height jumps from the cap (22 mm) to the base (2 mm) with no wall below the cap's rim.
    A point on that jump is 8 mm from the B-rep but on the top-most surface's skirt."""
    cq = pytest.importorskip("cadquery")
    import numpy as np

    from cad_io.refine import _skirt_bound
    from cad_io.distance import distance_to_part
    from cad_io.sampler import sample_points
    from cad_io.step import read_step

    shape = (cq.Workplane("XY").box(40, 40, 2, centered=(True, True, False))
             .union(cq.Workplane("XY").workplane(offset=2).box(10, 10, 18, centered=(True, True, False)))
             .union(cq.Workplane("XY").workplane(offset=20).box(30, 30, 2, centered=(True, True, False))))
    path = tmp_path / "mushroom.step"
    cq.exporters.export(shape, str(path))
    part = read_step(path)
    tol = 0.01
    x = np.array([15.001, 15.003, 17.0, 0.0])  # just off the cap's rim (x = 15), on the base, on the cap
    y = np.zeros(4)
    h = np.array([10.0, 21.0, 2.004, 22.0])
    z0 = sample_points(part, x, y, deflection=tol / 2)[0]
    assert np.allclose(z0, [2.0, 2.0, 2.0, 22.0])
    d = distance_to_part(part, np.c_[x, y, h], deflection=tol / 2)
    assert d[0] > 7.9 and abs(d[1] - 0.003) < 1e-6
    b = _skirt_bound(part, x, y, h, z0, tol / 2, tol, 0.5)
    assert b[0] <= 0.0025 and b[1] <= 0.005  # the cap's edge bracket the heights within r
    assert b[2] == np.inf and b[3] == np.inf  # within tol of the exact height: the B-rep distance stands
