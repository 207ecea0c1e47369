"""`zmap simulate` and `zmap replay`, end to end through zmap.cli.main."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from zmap.cli import main
from zmap.sim.session import Run

ROOT = Path(__file__).resolve().parents[3]
DEMO = ROOT / "data" / "demo_pocket.nc"
TOOLS = ROOT / "data" / "tools.toml"

PROGRAM = """%
G21 G90 G17
T1 M6
G0 X2 Y2 Z2
G1 Z-1 F300
G1 X8 Y2
G2 X8 Y6 I0 J2
G1 X2 Y6 Z-1.5
M30
%
"""


@pytest.fixture()
def small_run(tmp_path, capsys):
    nc = tmp_path / "p.nc"
    nc.write_text(PROGRAM)
    out = tmp_path / "p.zsim"
    rc = main(["simulate", str(nc), "--stock", "box:12x10x4", "--tool", "ball:2", "--pitch", "0.3",
               "--history", "treap", "-o", str(out), "--no-progress"])
    assert rc == 0
    capsys.readouterr()
    return out


def test_simulate_prints_summary_and_writes_run(tmp_path, capsys):
    nc = tmp_path / "p.nc"
    nc.write_text(PROGRAM)
    out = tmp_path / "p.zsim"
    assert main(["simulate", str(nc), "--stock", "box:12x10x4", "--tool", "ball:2", "--pitch", "0.3",
                 "-o", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    for word in ("moves", "positions", "rays", "dexels created", "dexels deleted", "history", "seconds"):
        assert word in text
    run = Run.load(out)
    assert run.history == "treap" and run.n_stages > 0
    # box:LxWxH is centred on the tool path's xy extent, top at z = 0
    lo, hi = run.xyz.min(axis=0), run.xyz.max(axis=0)
    assert np.isclose(run.stock.x0, (lo[0] + hi[0]) / 2 - 6.0) and np.isclose(run.stock.y0, (lo[1] + hi[1]) / 2 - 5.0)
    assert np.nanmax(run.display(0)) == 0.0 and np.nanmin(run.display(0)) == 0.0


def test_replay_png_and_gif(small_run, tmp_path, capsys):
    png = tmp_path / "half.png"
    assert main(["replay", str(small_run), "--stage", "1/2", "--png", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    gif = tmp_path / "a.gif"
    assert main(["replay", str(small_run), "--animate", "end:0", "--gif", str(gif), "--frames", "5"]) == 0
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames >= 2
    assert main(["replay", str(small_run)]) == 0
    assert '"n_stages"' in capsys.readouterr().out


def test_replay_errors_are_one_line(small_run, tmp_path, capsys):
    n = Run.load(small_run).n_stages
    capsys.readouterr()
    assert main(["replay", str(small_run), "--stage", str(n + 5), "--png", str(tmp_path / "x.png")]) != 0
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"out of range 0..{n}" in err
    assert not (tmp_path / "x.png").exists()
    bad = tmp_path / "bad.zsim"
    bad.write_bytes(b"garbage")
    assert main(["replay", str(bad), "--stage", "end"]) != 0
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.zsim" in err and "corrupt" in err


def test_simulate_errors_are_one_line(tmp_path, capsys):
    nc = tmp_path / "t.nc"
    nc.write_text("G21 G90\nT9 M6\nG0 X1 Y1 Z1\nG1 Z-1 F100\nM2\n")
    out = tmp_path / "t.zsim"
    assert main(["simulate", str(nc), "--stock", "box:5x5x2", "--tools", str(TOOLS), "-o", str(out),
                 "--no-progress"]) != 0
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "T9" in err
    assert not out.exists()
    assert main(["simulate", str(nc), "--stock", "box:5x5x2", "--tool", "ball:2", "--history", "trap",
                 "-o", str(out)]) != 0
    assert "trap" in capsys.readouterr().err
    nc.write_text("G21\nG41 X1\n")
    assert main(["simulate", str(nc), "--stock", "box:5x5x2", "--tool", "ball:2", "-o", str(out),
                 "--no-progress"]) != 0
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "t.nc:2:" in err


def test_demo_program_with_tool_table(tmp_path, capsys):
    out = tmp_path / "demo.zsim"
    assert main(["simulate", str(DEMO), "--stock", "box:0,0,-10,40,30,0", "--tools", str(TOOLS),
                 "-o", str(out), "--no-progress", "--history", "ttrace"]) == 0
    run = Run.load(out)
    assert run.tool_numbers == [1, 2] and run.summary["dexels_deleted"] > 0  # holes drilled through
    top = run.display("end")
    assert np.isnan(top).any()  # the through holes show the background


@pytest.mark.slow
def test_run_demo_end_to_end(tmp_path):
    from zmap.sim.demo import run_demo

    written = run_demo(tmp_path / "out", echo=None)
    assert [p.name for p in written] == ["demo_pocket.zsim", "demo_pocket_half.png", "demo_pocket_end.png",
                                         "demo_pocket.gif"]
    assert all(p.stat().st_size > 0 for p in written)
    # the GIF shows the whole program: its first frame the uncut stock, its last the finished part
    from PIL import Image

    run = Run.load(written[0])
    with Image.open(written[3]) as gif:
        assert gif.n_frames >= 40
        gif.seek(0)
        first = np.asarray(gif.convert("RGB"), dtype=float)
        gif.seek(gif.n_frames - 1)
        last = np.asarray(gif.convert("RGB"), dtype=float)
    assert np.abs(first - last).mean() > 5  # the pocket, ring and holes are cut between them
    assert run.n_stages == run.stage("end")


@pytest.mark.slow
def test_real_program_with_camotics_project(tmp_path, sample_data):
    gdir = sample_data / "gcode"
    out = tmp_path / "flower.zsim"
    assert main(["simulate", str(gdir / "flower_mold.nc"), "--camotics", str(gdir / "flower_mold.camotics"),
                 "-o", str(out), "--no-progress"]) == 0
    run = Run.load(out)
    assert run.n_stages > 50_000
    k = run.stage("1/2")
    assert np.array_equal(run.display(k), run.reconstruct(k).top(), equal_nan=True)


def test_simulate_max_blocks_limits_loops(tmp_path, capsys):
    prog = tmp_path / "loop.ngc"
    prog.write_text("G21 G90 G0 X0 Y0 Z1\n#1=0\nO1 while [#1 LT 300]\nG1 X[#1/10] F100\n"
                    "#1=[#1+1]\nO1 endwhile\nM2\n")
    args = ["simulate", str(prog), "--stock", "box:50x10x5", "--tool", "flat:2", "--no-progress",
            "-o", str(tmp_path / "l.zsim")]
    assert main(args + ["--max-blocks", "100"]) == 1
    err = capsys.readouterr().err
    assert "loop.ngc:4:1" in err and "--max-blocks" in err and err.count("\n") == 1
    assert not (tmp_path / "l.zsim").exists()
    assert main(args + ["--max-blocks", "5000"]) == 0
    assert (tmp_path / "l.zsim").exists()
