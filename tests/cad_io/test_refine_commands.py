"""zmap refine / zmap report: bad input and one end-to-end run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

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
