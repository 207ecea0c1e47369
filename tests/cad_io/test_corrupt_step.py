"""Corrupt STEP files: a crash of OCC's reader is contained and reported in one line; lost
entities and faces are counted, warned about, refused under ``--strict``; OCC's messages
never reach our stdout."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from zmap.errors import StepImportError

pytest.importorskip("OCP")

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "data" / "step" / "bm2_ec_t4-A.stp"  # 13 B-spline faces, 136 KiB


def _corrupt(tmp_path: Path, n_bytes: int, seed: int) -> Path:
    """A copy of bm2_ec_t4-A.stp with ``n_bytes`` printable bytes changed in its DATA section
    (seeded): 20 bytes (seed 0) make OCC's reader segfault; 5 bytes (seed 8) lose 2 faces."""
    data = SOURCE.read_bytes()
    start = data.index(b"DATA;") + 5
    rng = np.random.default_rng(seed)
    b = bytearray(data)
    for p in rng.integers(start, len(b) - 20, n_bytes):
        b[p] = int(rng.integers(33, 127))
    out = tmp_path / f"bm2_{n_bytes}_{seed}.stp"
    out.write_bytes(bytes(b))
    return out


def _cli(capfd, *args: str) -> SimpleNamespace:
    """``zmap ARGS`` with stdout and stderr caught at the file-descriptor level, where OCC writes."""
    from zmap.cli import main

    capfd.readouterr()
    code = main(list(args))
    got = capfd.readouterr()
    return SimpleNamespace(returncode=code, stdout=got.out, stderr=got.err)


def test_reader_crash_is_one_line_naming_the_file(tmp_path, capfd):
    from cad_io.step import read_step

    bad = _corrupt(tmp_path, 20, 0)
    with pytest.raises(StepImportError, match="crashed") as info:
        read_step(bad)
    assert str(bad) in str(info.value) and "\n" not in str(info.value)
    # the command answers in one line and writes nothing
    out = tmp_path / "x.zmap.npz"
    r = _cli(capfd, "convert", str(bad), "--grid", "2", "-o", str(out), "--no-progress")
    assert r.returncode != 0, r
    err = r.stderr.strip()
    assert err.startswith("zmap: error:") and "\n" not in err and bad.name in err and "crashed" in err, err
    assert r.stdout == "" and not out.exists()


@pytest.mark.slow
def test_lost_faces_are_counted_warned_and_refused_under_strict(tmp_path, capfd):
    from cad_io.step import read_step

    bad = _corrupt(tmp_path, 5, 8)
    part = read_step(bad)
    assert len(part.faces) == 11
    msg = [w for w in part.warnings if "damaged" in w]
    assert len(msg) == 1 and "2 of the file's 13 faces are missing" in msg[0], part.warnings
    assert "entities failed to load or transfer" in msg[0] and "Line 488" in msg[0]
    with pytest.raises(StepImportError, match="strict"):
        read_step(bad, strict=True)
    out = tmp_path / "x.zmap.npz"
    r = _cli(capfd, "convert", str(bad), "--grid", "2", "-o", str(out), "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "2 of the file's 13 faces are missing" in r.stderr
    # stdout holds our summary only: OCC's reader messages ('*** ERR StepReaderData ***', coloured) stay out
    lines = r.stdout.splitlines()
    assert lines and all(line.split()[0] in ("wrote", "part", "grid", "method", "time", "memory") for line in lines), \
        r.stdout
    out2 = tmp_path / "y.zmap.npz"
    r = _cli(capfd, "convert", str(bad), "--grid", "2", "-o", str(out2), "--no-progress", "--strict")
    assert r.returncode != 0 and "strict" in r.stderr and not out2.exists()
    assert r.stderr.strip().count("\n") == 0, r.stderr


@pytest.mark.parametrize("name", ["bm2_ec_t4-A.stp", "trj7_c2-td-203.stp", "nist_ftc_08_asme1_ap242-2.stp",
                                  "featuretype.STEP"])
def test_sound_files_have_no_damage_report(name):
    """AP242 files whose presentation/PMI records OCC rejects (trj7, nist_ftc_08) are not damaged:
    read under ``strict`` (which refuses any damage report), with no damage warning."""
    from cad_io.step import read_step

    told = []
    part = read_step(ROOT / "data" / "step" / name, strict=True, warn=told.append)
    assert not part.shape.IsNull() and len(part.faces) > 0
    assert not any("damaged" in w for w in told + part.warnings), told


def test_in_process_read_agrees_and_stays_quiet(tmp_path, capfd):
    """Without the child process (no fork) the same damage is found, and OCC's output is caught."""
    from cad_io.step import _load_shape

    bad = _corrupt(tmp_path, 5, 8)
    _, msg_child = _load_shape(bad)
    _, msg_here = _load_shape(bad, isolate=False)
    assert msg_here == msg_child and "2 of the file's 13 faces" in msg_here
    assert capfd.readouterr().out == ""
