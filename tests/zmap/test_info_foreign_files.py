"""``zmap info`` (and every loader through ``zmap._npzfile.read_npz``) on files that are not
z-maps: a STEP file, a text file, a .zsim; one line naming the file and what it holds, exit 1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from zmap import ZMap
from zmap.cli import main
from zmap.errors import ZMapFileError

DATA = Path(__file__).resolve().parents[2] / "data"


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert "Traceback" not in err
    return err.strip()


def test_info_on_a_step_file(capsys):
    step = DATA / "boss.step"
    assert main(["info", str(step)]) == 1
    err = one_line(capsys)
    assert err == f"zmap: error: {step}: not a zmap file (a STEP file)"


@pytest.mark.parametrize("content, what", [
    (b"G21 G90\nG0 X1\n", "a text file starting 'G21 G90'"),
    (b"", "an empty file"),
    (b"\x00\x01\x02garbage", "a binary file of 10 bytes"),
])
def test_info_on_text_empty_and_binary_files(content, what, tmp_path, capsys):
    p = tmp_path / "x.zmap.npz"
    p.write_bytes(content)
    assert main(["info", str(p)]) == 1
    err = one_line(capsys)
    assert err.startswith(f"zmap: error: {p}: not a zmap file") and what in err
    assert "pickle" not in err


def test_info_on_npy_and_foreign_npz(tmp_path, capsys):
    npy = tmp_path / "a.npy"
    np.save(npy, np.zeros(3))
    assert main(["info", str(npy)]) == 1
    assert "a single .npy array" in one_line(capsys)
    foreign = tmp_path / "f.npz"
    np.savez(foreign, a=np.zeros(3))
    assert main(["info", str(foreign)]) == 1
    assert "not a zmap file (arrays ['a'], no 'header')" in one_line(capsys)
    objects = tmp_path / "o.npz"
    np.savez(objects, header=np.array(json.dumps({"format": "zmap.ZMap", "version": 1})),
             z=np.array([None, 1], dtype=object))
    assert main(["info", str(objects)]) == 1
    err = one_line(capsys)
    assert "array 'z' cannot be read (it holds Python objects)" in err and "allow_pickle" not in err


def test_info_on_a_zsim_says_what_it_is(tmp_path, capsys):
    from zmap.sim import simulate

    xyz = np.array([[1.0, 1.0, -0.5], [2.0, 1.0, -0.5]])
    run = simulate(xyz, (0, 0, -2, 3, 2, 0), tool="ball:1", pitch=0.25, history="none")
    p = run.save(tmp_path / "r.zsim")
    assert main(["info", str(p)]) == 1
    err = one_line(capsys)
    assert err.startswith(f"zmap: error: {p}: not a zmap file: it holds a simulation run")
    assert "zmap replay" in err


def test_loaders_name_the_kind_of_zmap_file(tmp_path):
    from zmap.sim.session import Run

    zm = ZMap(0, 0, 1, 1, np.zeros((3, 3))).save(tmp_path / "m.zmap.npz")
    with pytest.raises(ZMapFileError, match="not a .zsim file: it holds a z-map"):
        Run.load(zm)
    with pytest.raises(ZMapFileError, match="not a precision model file: it holds a z-map"):
        from zmap.model import PrecisionModel

        PrecisionModel.load(zm)


def test_unreadable_file(tmp_path):
    import os

    p = ZMap(0, 0, 1, 1, np.zeros((3, 3))).save(tmp_path / "m.zmap.npz")
    os.chmod(p, 0)
    try:
        if os.access(p, os.R_OK):
            pytest.skip("running as a user who reads every file")
        with pytest.raises(ZMapFileError, match="cannot be read"):
            ZMap.load(p)
    finally:
        os.chmod(p, 0o644)


def test_truncated_zmap_is_corrupt(tmp_path):
    p = ZMap(0, 0, 1, 1, np.random.default_rng(0).random((50, 50))).save(tmp_path / "m.zmap.npz")
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(ZMapFileError, match="corrupt"):
        ZMap.load(p)
