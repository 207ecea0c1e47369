"""Exit status and one-line messages of every ``zmap`` subcommand on bad input and failures.

1: bad input (missing or unreadable file, bad option value, G-code or STEP error) and any
other failure; 2: a malformed command line (click's usage errors); 130: interrupted.
"""

from __future__ import annotations

import numpy as np
import pytest

from zmap import ZMap
from zmap.cli import main


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert "Traceback" not in err
    return err.strip()


@pytest.fixture
def small_zmap(tmp_path):
    return ZMap(0, 0, 1, 1, np.zeros((4, 4))).save(tmp_path / "m.zmap.npz")


@pytest.fixture
def nc(tmp_path):
    p = tmp_path / "t.nc"
    p.write_text("G21 G90\nG0 X1 Y1 Z1\nG1 Z-0.5 F100\nX2\nM2\n")
    return p


def _missing_cases(tmp_path, small_zmap, nc):
    nope = tmp_path / "nope"
    out = str(tmp_path / "out")
    return {
        "simulate": (["simulate", f"{nope}.nc", "--stock", "box:5x5x2", "--tool", "ball:1", "-o", out], f"{nope}.nc"),
        "simulate --tools": (["simulate", str(nc), "--stock", "box:5x5x2", "--tools", f"{nope}.toml", "-o", out],
                             f"{nope}.toml"),
        "simulate --camotics": (["simulate", str(nc), "--camotics", f"{nope}.camotics", "-o", out],
                                f"{nope}.camotics"),
        "simulate --stock": (["simulate", str(nc), "--stock", f"{nope}.zmap.npz", "--tool", "ball:1", "-o", out,
                              "--no-progress"], f"{nope}.zmap.npz"),
        "replay": (["replay", f"{nope}.zsim"], f"{nope}.zsim"),
        "info": (["info", f"{nope}.zmap.npz"], f"{nope}.zmap.npz"),
        "convert": (["convert", f"{nope}.step", "--grid", "1", "-o", out], f"{nope}.step"),
        "refine": (["refine", f"{nope}.zmap.npz", "--part", f"{nope}.step", "--tol", "0.1", "-o", out],
                   f"{nope}.zmap.npz"),
        "refine --part": (["refine", str(small_zmap), "--part", f"{nope}.step", "--tol", "0.1", "-o", out],
                          f"{nope}.step"),
        "report": (["report", f"{nope}.step", "--grid", "1", "--tol", "0.1"], f"{nope}.step"),
    }


@pytest.mark.parametrize("case", ["simulate", "simulate --tools", "simulate --camotics", "simulate --stock", "replay",
                                  "info", "convert", "refine", "refine --part", "report"])
def test_missing_file_exits_1_naming_it(case, tmp_path, small_zmap, nc, capsys):
    argv, missing = _missing_cases(tmp_path, small_zmap, nc)[case]
    assert main(argv) == 1
    err = one_line(capsys)
    assert err == f"zmap: error: {missing}: no such file" or (
        err.startswith(f"zmap: error: {missing}: no such file") and case == "refine --part"), err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, needle", [
    (["convert", "PART", "--grid", "-1", "-o", "OUT"], "--grid"),          # the command refuses the value
    (["convert", "PART", "--grid", "x", "-o", "OUT"], "'x' is not a valid float"),  # click refuses it
    (["convert", "PART", "--grid", "1", "--axis", "z", "-o", "OUT"], "'z' is not one of"),
    (["accuracy", "--surface", "cone"], "cone"),
    (["simulate", "NC", "--stock", "box:5x5x2", "--tool", "ball:1", "--history", "trap", "-o", "OUT"], "trap"),
    (["simulate", "NC", "--stock", "box:5x5x2", "--tool", "ball:1", "--pitch", "-1", "-o", "OUT",
      "--no-progress"], "pitch"),
    (["simulate", "NC", "--stock", "box:5x5x2", "--tool", "cone:1", "-o", "OUT", "--no-progress"], "cone"),
    (["info", "TMP"], "is a directory"),
])
def test_bad_option_value_exits_1(argv, needle, tmp_path, nc, capsys):
    from pathlib import Path

    data = Path(__file__).resolve().parents[2] / "data"
    sub = {"PART": str(data / "boss.step"), "OUT": str(tmp_path / "out"), "NC": str(nc), "TMP": str(tmp_path)}
    assert main([sub.get(a, a) for a in argv]) == 1
    err = one_line(capsys)
    assert err.startswith("zmap: error: ") and needle in err


def test_gcode_error_exits_1(tmp_path, capsys):
    bad = tmp_path / "bad.nc"
    bad.write_text("G21\nG1 X1 Q5\n")
    assert main(["simulate", str(bad), "--stock", "box:5x5x2", "--tool", "ball:1", "-o", str(tmp_path / "o.zsim"),
                 "--no-progress"]) == 1
    assert one_line(capsys).startswith(f"zmap: error: {bad}:2:")


@pytest.mark.parametrize("argv", [["convert", "x.step", "--bogus"], ["convert"], ["nosuchcommand"],
                                  ["simulate", "x.nc", "-o"]])
def test_usage_errors_stay_click_exit_2(argv, capsys):
    assert main(argv) == 2
    assert one_line(capsys).startswith("zmap: error: ")


def test_help_and_version_exit_0(capsys):
    assert main(["--help"]) == 0
    assert main(["--version"]) == 0
    assert main(["info", "--help"]) == 0


# ---- unexpected failures: one line, no traceback ---------------------------------------------

@pytest.mark.parametrize("exc, expect", [
    (MemoryError(), "zmap: error: out of memory while running 'zmap accuracy': MemoryError"),
    (MemoryError("Unable to allocate 8.00 GiB for an array"),
     "zmap: error: out of memory while running 'zmap accuracy' (Unable to allocate 8.00 GiB for an array): "
     "MemoryError"),
    (RuntimeError("boom\nsecond line"), "zmap: error: internal error while running 'zmap accuracy': RuntimeError: "
                                        "boom second line"),
    (KeyError("k"), "zmap: error: internal error while running 'zmap accuracy': KeyError: 'k'"),
])
def test_unexpected_failure_is_one_line(exc, expect, monkeypatch, capsys):
    import zmap.accuracy

    def fail(*args, **kwargs):
        raise exc

    monkeypatch.setattr(zmap.accuracy, "accuracy_rows", fail)
    monkeypatch.delenv("ZMAP_TRACEBACK", raising=False)
    assert main(["accuracy", "--points", "10"]) == 1
    err = one_line(capsys)
    assert err.startswith(expect), err


def test_memory_error_in_a_subcommand_module(monkeypatch, tmp_path, nc, capsys):
    import zmap.sim.session

    def fail(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(zmap.sim.session, "simulate", fail)
    out = tmp_path / "o.zsim"
    assert main(["simulate", str(nc), "--stock", "box:5x5x2", "--tool", "ball:1", "-o", str(out)]) == 1
    assert one_line(capsys) == "zmap: error: out of memory while running 'zmap simulate': MemoryError"
    assert not out.exists()


def test_eof_error_is_bad_input_not_abort(monkeypatch, capsys):
    import zmap.accuracy

    def fail(*args, **kwargs):
        raise EOFError("truncated")

    monkeypatch.setattr(zmap.accuracy, "accuracy_rows", fail)
    assert main(["accuracy", "--points", "10"]) == 1
    assert one_line(capsys) == "zmap: error: truncated"


def test_keyboard_interrupt_prints_interrupted_and_exits_130(monkeypatch, capsys):
    import zmap.accuracy

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(zmap.accuracy, "accuracy_rows", interrupt)
    assert main(["accuracy", "--points", "10"]) == 130
    assert one_line(capsys) == "zmap: interrupted"


def test_traceback_on_request(monkeypatch):
    import zmap.accuracy

    def fail(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(zmap.accuracy, "accuracy_rows", fail)
    monkeypatch.setenv("ZMAP_TRACEBACK", "1")
    with pytest.raises(RuntimeError, match="boom"):
        main(["accuracy", "--points", "10"])


def test_system_exit_is_not_swallowed(monkeypatch):
    import zmap.accuracy

    def leave(*args, **kwargs):
        raise SystemExit(7)

    monkeypatch.setattr(zmap.accuracy, "accuracy_rows", leave)
    with pytest.raises(SystemExit):
        main(["accuracy", "--points", "10"])
