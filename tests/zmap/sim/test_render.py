"""Pictures of simulation stages: titles, PNG and GIF written by `zmap replay` (axes, colour bar, title)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from zmap.cli import main
from zmap.plot.stages import StageFigure, save_gif, stage_line, stage_title

PROGRAM = """%
G21 G90 G17
T1 M6
G0 X2 Y2 Z2
G1 Z-1 F300
G1 X8 Y2
G2 X8 Y6 I0 J2
G1 X2 Y6 Z-1.5
G0 Z5
G0 X9 Y9
M30
%
"""


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("render")
    nc = d / "p.nc"
    nc.write_text(PROGRAM)
    out = d / "p.zsim"
    assert main(["simulate", str(nc), "--stock", "box:12x10x4", "--tool", "ball:2", "--pitch", "0.3",
                 "--history", "treap", "-o", str(out), "--no-progress"]) == 0
    return nc, out


def _not_blank(path):
    a = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)
    return a.std() > 10.0


def test_stage_title_names_stage_line_and_text():
    assert stage_title("p.zsim", 5, 10, 7, "G1  X8 Y2 ") == "p.zsim: stage 5/10, line 7: G1 X8 Y2"
    assert stage_title("p.zsim", 5, 10, 7) == "p.zsim: stage 5/10, line 7"
    assert stage_title("p.zsim", 5, 10, 2, ["G21", "G1 X1"]) == "p.zsim: stage 5/10, line 2: G1 X1"
    assert stage_title("p.zsim", 5, 10, 9, ["G21"]) == "p.zsim: stage 5/10, line 9"
    assert stage_title("p.zsim", 0, 10, 3, "G1 X1") == "p.zsim: stage 0/10, stock"
    assert stage_title("p.zsim", 4, 10, 0) == "p.zsim: stage 4/10, line unknown"
    long = stage_title("r", 1, 2, 1, "G1 " + "X1 " * 50)
    assert long.endswith("...") and len(long) < 100


def test_stage_line_is_the_line_of_the_position_that_made_the_stage(small_run):
    from zmap.sim.session import Run

    run = Run.load(small_run[1])
    assert stage_line(run, 0) == 0
    assert stage_line(run, 1) == int(run.line[0]) and stage_line(run, run.n_stages) == int(run.line[-1])
    lines = PROGRAM.splitlines()
    assert all(lines[stage_line(run, k) - 1].startswith(("G0", "G1", "G2")) for k in range(1, run.n_stages + 1))


def test_stage_figure_frame_size_is_fixed_and_not_blank():
    fig = StageFigure(0.0, 0.0, 0.5, 40, 20, (-2.0, 0.0), scale=2)
    z = np.zeros((40, 20))
    a = fig.frame(z, "flat")
    z[10:20, 5:10] = -1.5
    z[0, 0] = np.nan
    b = fig.frame(z, "pocket")
    fig.close()
    assert a.shape == b.shape and a.dtype == np.uint8 and a.shape[2] == 3
    assert a.shape[1] >= 360 + 150  # plot area plus axis labels and colour bar
    assert not np.array_equal(a, b) and b.std() > 10


def test_replay_png_has_figure_size_and_is_not_blank(small_run, tmp_path, capsys):
    nc, zsim = small_run
    png = tmp_path / "half.png"
    assert main(["replay", str(zsim), "--stage", "1/2", "--png", str(png), "--program", str(nc)]) == 0
    assert "-> " in capsys.readouterr().out
    from zmap.sim.session import Run

    fig = StageFigure.for_run(Run.load(zsim))
    expect = fig.frame(np.zeros((Run.load(zsim).stock.nx, Run.load(zsim).stock.ny)), "").shape
    with Image.open(png) as im:
        assert im.size == (expect[1], expect[0])
    assert _not_blank(png)


def test_replay_stage_prints_title_with_gcode_text(small_run, capsys):
    nc, zsim = small_run
    from zmap.sim.session import Run

    run = Run.load(zsim)
    k = run.stage("1/2")
    assert main(["replay", str(zsim), "--stage", "1/2", "--program", str(nc)]) == 0
    out = capsys.readouterr().out
    line = stage_line(run, k)
    assert f"stage {k}/{run.n_stages}, line {line}: {PROGRAM.splitlines()[line - 1]}" in out
    assert main(["replay", str(zsim), "--stage", "1/2"]) == 0
    assert f"stage {k}/{run.n_stages}, line {line}:" in capsys.readouterr().out  # number alone


@pytest.mark.parametrize("span,frames", [("end:0", 7), ("0:end", 40)])
@pytest.mark.slow
def test_replay_gif_writes_every_frame_it_announces(small_run, tmp_path, capsys, span, frames):
    import re

    nc, zsim = small_run
    gif = tmp_path / "a.gif"
    assert main(["replay", str(zsim), "--animate", span, "--gif", str(gif), "--frames", str(frames),
                 "--no-progress"]) == 0
    announced = int(re.search(r"(\d+) frames", capsys.readouterr().out).group(1))
    from zmap.sim.session import Run

    n = Run.load(zsim).n_stages
    assert announced == min(frames, n + 1)
    with Image.open(gif) as im:
        assert im.n_frames == announced
        im.seek(im.n_frames // 2)
        assert np.asarray(im.convert("RGB")).std() > 10


def test_save_gif_keeps_identical_frames(tmp_path):
    f = np.full((20, 30, 3), 128, dtype=np.uint8)
    with Image.open(save_gif(tmp_path / "same.gif", [f] * 4)) as im:
        assert im.n_frames == 4
    with pytest.raises(ValueError, match="no frames"):
        save_gif(tmp_path / "none.gif", [])


def test_replay_3d_needs_png(small_run, capsys):
    assert main(["replay", str(small_run[1]), "--3d"]) != 0
    assert "--3d needs --png" in capsys.readouterr().err
