"""``zmap convert``: output, summary, one-line errors, nothing half-written."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from zmap import ZMap
from zmap.cli import main

DATA = Path(__file__).resolve().parents[2] / "data"


def _one_line_error(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert err.startswith("zmap: error:") and "\n" not in err, err
    for w in words:
        assert w in err, err
    return err


def test_convert_writes_map_and_summary(tmp_path, capsys):
    out = tmp_path / "pocket.zmap.npz"
    assert main(["convert", str(DATA / "pocket.step"), "--grid", "1", "-o", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    for word in ("23 faces", "jacobian", "facet", "empty", "points", " KB map", " s "):
        assert word in text, text
    zm = ZMap.load(out)
    assert zm.dx == 1.0 and zm.shape == (101, 81)
    assert set(zm.layers) == {"face", "method"}
    # block top and pocket floor; the outline (x = +-50, y = +-40) lies on grid lines and is kept
    assert abs(np.nanmax(zm.z) - 30.0) < 1e-9 and abs(np.nanmin(zm.z) - 15.0) < 1e-9
    assert np.isfinite(zm.z).all()
    assert zm.meta["source"] == "pocket.step"


def test_convert_bounds_method_axis(tmp_path, capsys):
    out = tmp_path / "b.zmap.npz"
    args = ["convert", str(DATA / "boss.step"), "--grid", "0.5", "--bounds", "-10", "-10", "10", "10",
            "--method", "facet", "--axis", "-z", "-o", str(out), "--no-progress"]
    assert main(args) == 0
    zm = ZMap.load(out)
    assert zm.shape == (41, 41) and zm.meta["axis"] == "-z" and zm.meta["method"] == "facet"
    assert set(np.unique(zm.layers["method"])) == {2}
    assert np.allclose(zm.z, 0.0, atol=1e-12)  # the plate's underside at world z = 0


def test_missing_file(tmp_path, capsys):
    out = tmp_path / "x.zmap.npz"
    assert main(["convert", str(tmp_path / "nope.step"), "--grid", "1", "-o", str(out)]) == 1
    _one_line_error(capsys, "nope.step")
    assert not out.exists()


def test_not_step(tmp_path, capsys):
    bad = tmp_path / "bad.step"
    bad.write_text("this is not a STEP file\n")
    out = tmp_path / "x.zmap.npz"
    assert main(["convert", str(bad), "--grid", "1", "-o", str(out)]) == 1
    _one_line_error(capsys, "bad.step")
    assert not out.exists()


def test_step_without_faces(tmp_path, capsys):
    empty = tmp_path / "empty.step"
    empty.write_text("ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION((''),'2;1');\n"
                     "FILE_NAME('empty','2026-01-01T00:00:00',(''),(''),'','','');\n"
                     "FILE_SCHEMA(('AUTOMOTIVE_DESIGN'));\nENDSEC;\nDATA;\n"
                     "#1=CARTESIAN_POINT('',(0.,0.,0.));\nENDSEC;\nEND-ISO-10303-21;\n")
    out = tmp_path / "x.zmap.npz"
    assert main(["convert", str(empty), "--grid", "1", "-o", str(out)]) == 1
    _one_line_error(capsys, "empty.step")
    assert not out.exists()


def test_grid_too_large(tmp_path, capsys):
    out = tmp_path / "x.zmap.npz"
    assert main(["convert", str(DATA / "freeform_die.step"), "--grid", "0.00001", "-o", str(out)]) == 1
    _one_line_error(capsys, "GB", " TB", "1e+14 points", "10,000,002 x")
    assert not out.exists() and not list(tmp_path.iterdir())


def test_bad_options(tmp_path, capsys):
    out = tmp_path / "x.zmap.npz"
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1", "--axis", "z", "-o", str(out)]) != 0
    assert "axis" in capsys.readouterr().err
    assert main(["convert", str(DATA / "boss.step"), "--grid", "-1", "-o", str(out)]) != 0
    assert "grid" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_convert_does_not_load_ocp_for_other_commands():
    import subprocess

    code = ("import sys, zmap.cli; zmap.cli.main(['accuracy', '--points', '100', '--surface', 'plane']); "
            "print(any(m.startswith(('OCP', 'cadquery')) for m in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert p.stdout.strip().endswith("False"), p.stdout + p.stderr


@pytest.mark.slow
def test_demo_writes_maps_and_pictures(tmp_path):
    from cad_io.demo import run_demo

    files = run_demo(tmp_path)
    names = {p.name for p in files}
    assert {"freeform_die.zmap.npz", "freeform_die.png", "pocket.zmap.npz", "pocket.png"} <= names
    assert all(p.exists() and p.stat().st_size > 0 for p in files)
    assert ZMap.load(tmp_path / "pocket.zmap.npz").layers["method"].max() >= 1
