"""``zmap compare`` end to end: report formats, pictures, regions, collisions, bad input."""

from __future__ import annotations

import json

import pytest

from zmap import ZMap
from zmap.cli import main
from zmap.sim import simulate


@pytest.fixture()
def files(tmp_path):
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X5 Y5 Z2\nG1 Z-0.5 F50\nG1 X8\nG0 Z-1\nG0 Z2\n")
    run = simulate(prog, (0, 0, -3, 12, 10, 0), tool="ball:2", pitch=0.2)
    run.save(tmp_path / "r.zsim")
    ZMap.from_function(lambda x, y: 0 * x - 0.3, (-1, -1, 13, 11), 0.5).save(tmp_path / "d.zmap.npz")
    return tmp_path, prog


@pytest.mark.slow
def test_compare_writes_reports_pictures_regions(files, capsys):
    d, prog = files
    rc = main(["compare", str(d / "r.zsim"), str(d / "d.zmap.npz"), "--tol", "0.01", "--format", "json",
               "-o", str(d / "rep.md"), "--png", str(d / "dev.png"), "--regions", str(d / "reg.csv"),
               "--program", str(prog), "--collisions", "--no-holder"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["totals"]["gouge_regions"] >= 1
    # the first gouge: the feed down to -0.5 on line 3
    assert out["totals"]["first_gouge_line"] == 3
    assert [c["line"] for c in out["collisions"] if c["kind"] == "rapid"] == [5]
    md = (d / "rep.md").read_text()
    assert "| first_gouge_line | 3 |" in md and "G1 Z-0.5" in md and "rapid" in md
    assert (d / "reg.csv").read_text().startswith("kind,rays,area_mm2")
    assert (d / "dev.png").stat().st_size > 10_000


@pytest.mark.parametrize("args, needle", [
    (["--tol", "-0.01"], "tolerance must be >= 0"),
    (["--collisions"], "--program"),
    (["--stage", "99999"], "out of range"),
])
def test_compare_bad_input_one_line(files, capsys, args, needle):
    d, _prog = files
    rc = main(["compare", str(d / "r.zsim"), str(d / "d.zmap.npz"), *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and err[-1].startswith("zmap: error:") and needle in err[-1]


@pytest.mark.slow
def test_compare_missing_holder_data(files, capsys):
    d, prog = files
    rc = main(["compare", str(d / "r.zsim"), str(d / "d.zmap.npz"), "--program", str(prog), "--collisions"])
    err = capsys.readouterr().err
    assert rc == 1 and "holder data" in err
    # the message names both ways out: a holder table, or no holder check
    last = err.strip().splitlines()[-1]
    assert "--no-holder" in last and "--holders FILE" in last
    assert main(["compare", str(d / "r.zsim"), str(d / "d.zmap.npz"), "--program", str(prog),
                 "--collisions", "--no-holder"]) == 0


def test_compare_missing_design(files, capsys):
    d, _prog = files
    assert main(["compare", str(d / "r.zsim"), str(d / "nope.zpm")]) == 1
    assert "no such file" in capsys.readouterr().err
