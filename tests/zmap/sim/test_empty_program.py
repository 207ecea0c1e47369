"""A program without moves: the run is the stock alone, said once (API warning, CLI line)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from zmap.cli import main
from zmap.sim import simulate
from zmap.sim.gcode import parse
from zmap.sim.session import Run

EMPTY = "%\nG21 G90 (set-up only)\nT1 M6\nM2\n%\n"


def test_simulate_warns_on_a_program_without_moves(tmp_path):
    nc = tmp_path / "empty.nc"
    nc.write_text(EMPTY)
    with pytest.warns(UserWarning, match=r"empty\.nc has no moves; the run is the stock alone") as rec:
        run = simulate(parse(nc), "box:0,0,-2,3,2,0", tool="ball:1", pitch=0.25)
    assert len(rec) == 1 and str(nc) in str(rec[0].message)
    assert run.n_stages == 0 and run.summary["moves"] == 0
    with pytest.warns(UserWarning, match="empty.nc has no moves"):
        simulate(str(nc), "box:0,0,-2,3,2,0", tool="ball:1", pitch=0.25)


@pytest.mark.parametrize("program", [EMPTY, np.zeros((0, 3))])
def test_simulate_warns_on_text_and_empty_positions(program):
    with pytest.warns(UserWarning, match="^the program has no moves; the run is the stock alone$"):
        simulate(program, (0, 0, -2, 3, 2, 0), tool="ball:1", pitch=0.25, history="ttrace")


def test_no_warning_with_moves():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run = simulate(np.array([[1.0, 1.0, -0.5]]), (0, 0, -2, 3, 2, 0), tool="ball:1", pitch=0.25)
    assert run.n_stages == 1


def test_cli_warns_in_one_line_and_writes_the_run(tmp_path, capsys):
    nc = tmp_path / "empty.nc"
    nc.write_text(EMPTY)
    out = tmp_path / "e.zsim"
    assert main(["simulate", str(nc), "--stock", "box:5x5x2", "--tool", "ball:1", "-o", str(out),
                 "--no-progress"]) == 0
    cap = capsys.readouterr()
    assert cap.err == f"warning: {nc} has no moves; the run is the stock alone\n"
    assert "moves            0" in cap.out
    assert Run.load(out).n_stages == 0


def test_cli_is_silent_with_moves(tmp_path, capsys):
    nc = tmp_path / "t.nc"
    nc.write_text("G21 G90\nG0 X1 Y1 Z1\nG1 Z-0.5 F100\nX2\nM2\n")
    assert main(["simulate", str(nc), "--stock", "box:5x5x2", "--tool", "ball:1", "-o", str(tmp_path / "t.zsim"),
                 "--no-progress"]) == 0
    assert capsys.readouterr().err == ""
