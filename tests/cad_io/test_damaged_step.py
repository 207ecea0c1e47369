"""Damaged STEP files as they come: damage told first and by its effect, absurd faces refused,
a file that lost most of its faces refused, harmless faults only noted, the same for every
command that reads STEP, and a bar that moves while OCC reads. The damaged copies are made
by the seeded functions of ``tests/cad_io/corrupt.py``."""

from __future__ import annotations

import io
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tests.cad_io import corrupt
from zmap.errors import GridTooLargeError

pytest.importorskip("OCP")

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "data"


def _cli(capfd, *args: str) -> SimpleNamespace:
    from zmap.cli import main

    capfd.readouterr()
    code = main(list(args))
    got = capfd.readouterr()
    return SimpleNamespace(returncode=code, stdout=got.out, stderr=got.err)


@pytest.fixture(scope="module")
def faults(tmp_path_factory):
    return corrupt.harmless_faults(DATA / "torus.step", tmp_path_factory.mktemp("harmless"))


@pytest.fixture(scope="module")
def torus_map(tmp_path_factory):
    from zmap.cli import main
    from zmap.grid import ZMap

    out = tmp_path_factory.mktemp("torus") / "torus.zmap.npz"
    assert main(["convert", str(DATA / "torus.step"), "--grid", "2", "-o", str(out), "--no-progress"]) == 0
    return ZMap.load(out)


# ---- harmless is not damaged -------------------------------------------------------------------

@pytest.mark.parametrize("kind, words", [("seam", "Seam Curve with twice the same geom"),
                                         ("name", "(name) not a quoted String")])
def test_faults_that_change_no_face_are_notes_not_damage(faults, torus_map, tmp_path, capfd, kind, words):
    from cad_io.step import read_step
    from zmap.grid import ZMap

    part = read_step(faults[kind], strict=True)  # refused as "damaged" before
    assert part.warnings == [] and not part.damaged
    assert len(part.notes) == 1 and words in part.notes[0] and "no face lost or changed" in part.notes[0]
    out = tmp_path / f"{kind}.zmap.npz"
    r = _cli(capfd, "convert", str(faults[kind]), "--grid", "2", "-o", str(out), "--no-progress", "--strict")
    assert r.returncode == 0, r.stderr
    assert "damaged" not in r.stderr and r.stderr.startswith("note: 1 entity with harmless faults"), r.stderr
    zm = ZMap.load(out)
    # the map is the clean file's (to 2e-11 mm where OCC rebuilds the seam's pcurve)
    assert np.array_equal(np.isnan(zm.z), np.isnan(torus_map.z))
    assert np.nanmax(np.abs(zm.z - torus_map.z)) < 1e-9


# ---- damage told first; absurd faces refused ----------------------------------------------------

@pytest.fixture(scope="module")
def unbounded(tmp_path_factory):
    """cornetta with 20 bytes changed (seed 4): 49 entities fail, two planes lose their wires
    (OCC boxes them at +-1e100 mm), one face its pcurves (OCC's adaptor crashed the process)."""
    return corrupt.flip_bytes(DATA / "step" / "bug27693_cornetta-step.stp", tmp_path_factory.mktemp("flip"), 20, 4)


@pytest.mark.slow
def test_damage_is_told_first_and_unbounded_faces_are_refused(unbounded, tmp_path, capfd):
    """Before: a segfault of the whole process; then a grid-size refusal of 10^100-digit numbers."""
    out = tmp_path / "c.zmap.npz"
    r = _cli(capfd, "convert", str(unbounded), "--grid", "4", "-o", str(out), "--no-progress")
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert lines[0].startswith("warning: 49 entities failed to load or transfer"), lines
    assert "3 of the file's 110 faces are missing" in lines[0] and "damaged" in lines[0]
    assert lines[1].startswith("warning: faces 103, 105 of the 107 read refused: extent absurd"), lines
    assert "1e+100" in lines[1] and "x -140 .. 140" in lines[1]
    assert any("face 63 (bspline)" in w and "no curve on its surface" in w for w in lines[2:]), lines
    from zmap.grid import ZMap

    zm = ZMap.load(out)
    assert zm.x0 == pytest.approx(-140, abs=4) and zm.x1 == pytest.approx(140, abs=4)
    assert np.isfinite(zm.z).mean() > 0.5


@pytest.mark.slow
def test_warnings_are_told_as_soon_as_the_file_is_read(unbounded, monkeypatch):
    """The damage line reaches the caller before any face is converted (a damaged face can
    take long; the user must know why first)."""
    import cad_io.step as step

    told: list[str] = []
    seen_at_convert: list[int] = []
    real = step._convert

    def spy(faces, kinds):
        seen_at_convert.append(len(told))
        return real(faces, kinds)

    monkeypatch.setattr(step, "_convert", spy)
    part = step.read_step(unbounded, warn=told.append)
    assert seen_at_convert[0] >= 2 and "entities failed" in told[0] and "refused" in told[1]
    assert told == part.warnings and part.damaged


def test_absurd_extent_of_a_damaged_part_is_said_with_its_damage():
    from cad_io.part import Face, Part
    from cad_io.reading import explain_extent

    faces = [Face(0, "plane", None, bbox=(0, 0, 0, 10, 10, 1)), Face(1, "bspline", None, bbox=(0, 0, 0, 8.9e98, 10, 1))]
    part = Part(faces, source="/x/mould.stp", warnings=["3 entities failed to load or transfer (#12 ...)"],
                damaged=True)
    err = explain_extent(part, GridTooLargeError("grid of 8.9e98 x 11 points needs ..."))
    msg = str(err)
    assert isinstance(err, GridTooLargeError) and "\n" not in msg
    assert msg.startswith("mould.stp: the part's extent (x 0 .. 8.9e+98") and "absurd" in msg
    assert "3 entities failed" in msg
    part.damaged = False
    plain = GridTooLargeError("grid too large")
    assert explain_extent(part, plain) is plain


# ---- a map that lost the part is not a result ---------------------------------------------------

def test_a_file_that_lost_most_of_its_faces_is_refused(tmp_path, capfd):
    """Before: convert wrote an all-empty map and exited 0."""
    bad = corrupt.shell_cut(DATA / "step" / "featuretype.STEP", tmp_path, 1, 0)
    out = tmp_path / "f.zmap.npz"
    r = _cli(capfd, "convert", str(bad), "--grid", "2", "-o", str(out), "--no-progress")
    assert r.returncode != 0 and not out.exists()
    err = r.stderr.strip()
    assert "\n" not in err and err.startswith("zmap: error:") and bad.name in err, err
    assert "95 of the file's 96 faces are lost (99 %)" in err and "--partial" in err, err
    r = _cli(capfd, "convert", str(bad), "--grid", "2", "-o", str(out), "--no-progress", "--partial")
    assert r.returncode == 0 and out.exists(), r.stderr
    assert r.stderr.startswith("warning: 95 of the file's 96 faces are missing"), r.stderr


# ---- report and refine read STEP as convert does ------------------------------------------------

@pytest.mark.slow
def test_report_and_refine_warn_and_refuse_as_convert(tmp_path, capfd, faults, unbounded):
    from zmap.cli import main

    zmap_path = tmp_path / "torus.zmap.npz"
    assert main(["convert", str(DATA / "torus.step"), "--grid", "2", "-o", str(zmap_path), "--no-progress"]) == 0
    lost = corrupt.shell_cut(DATA / "step" / "featuretype.STEP", tmp_path, 1, 0)
    for args in (["report", "--grid", "2", "--tol", "0.05", "--points", "50", "--method", "ez"],
                 ["refine", str(zmap_path), "--tol", "0.05", "-o", str(tmp_path / "t.zpm"), "--part"]):
        for bad, extra, words in ((unbounded, ["--strict"], "refused: strict"),
                                  (lost, [], "95 of the file's 96 faces are lost")):
            where = args.index("--part") + 1 if "--part" in args else 1
            argv = args[:where] + [str(bad)] + args[where:] + extra
            r = _cli(capfd, *argv)
            assert r.returncode != 0, (argv, r.stderr)
            assert r.stderr.strip().count("\n") == 0 and words in r.stderr, (argv, r.stderr)
        assert not (tmp_path / "t.zpm").exists()
    # a harmless fault: a note, and --strict passes
    r = _cli(capfd, "refine", str(zmap_path), "--part", str(faults["seam"]), "--tol", "0.05", "-o",
             str(tmp_path / "s.zpm"), "--strict")
    assert r.returncode == 0 and r.stderr.startswith("note: 1 entity with harmless faults"), r.stderr


def test_report_tells_the_damage_first(tmp_path, capfd, monkeypatch):
    """The report's damage line comes first, and its JSON carries the warnings (the
    measurement itself is stubbed: it is the same for a damaged part)."""
    import json

    import cad_io.commands as commands

    monkeypatch.setattr(commands, "report_rows", lambda part, *a, **k: {"rows": {}, "faces": len(part.faces)})
    bad = corrupt.flip_bytes(DATA / "step" / "bm2_ec_t4-A.stp", tmp_path, 5, 8)  # 2 of 13 faces lost
    r = _cli(capfd, "report", str(bad), "--grid", "4", "--tol", "0.1", "--method", "ez", "--format", "json")
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert lines[0].startswith("warning: ") and "2 of the file's 13 faces are missing" in lines[0], lines
    rep = json.loads(r.stdout)
    assert rep["faces"] == 11 and rep["warnings"][0] in lines[0]


# ---- the bar moves while OCC reads --------------------------------------------------------------

class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_bar_ticks_while_the_file_is_read(tmp_path, monkeypatch):
    """Before: 'reading: 0% 00:00' stayed frozen for the whole read (13 s on a large part)."""
    import cad_io.step as step
    from cad_io.commands import convert_cmd

    real = step.read_step

    def slow(*args, **kwargs):
        time.sleep(1.2)
        return real(*args, **kwargs)

    monkeypatch.setattr(step, "read_step", slow)
    err = _Tty()
    monkeypatch.setattr(sys, "stderr", err)
    convert_cmd.callback(str(DATA / "boss.step"), 4.0, None, "auto", "+z", None, str(tmp_path / "b.zmap.npz"),
                         True, False, False)
    text = err.getvalue()
    frames = [f for f in text.split("\r") if f.startswith("reading:")]
    assert any("00:01" in f for f in frames), frames  # the elapsed time moved during the read
    assert len(frames) >= 5, frames


# ---- no runaway on a damaged control point ------------------------------------------------------

@pytest.mark.slow
def test_a_spiked_face_is_refused_not_sampled_for_minutes(tmp_path, capfd):
    """cornetta with one control point's coordinate scaled by 100 (``E2`` appended, seed 0) and
    three CARTESIAN_POINT keywords broken: face 99's edges stay put (OCC boxes it 3 mm wide) while
    its surface spikes 1.2 m away. Before: the grid grew to 281 x 1,326 nodes and the sampler
    spent 110 s on the spike (12 s for the clean file); now the face is refused by its id."""
    from zmap.grid import ZMap

    bad = corrupt.scaled_control_point(DATA / "step" / "bug27693_cornetta-step.stp", tmp_path, 0, exponent="E2")
    out = tmp_path / "s.zmap.npz"
    t0 = time.perf_counter()
    r = _cli(capfd, "convert", str(bad), "--grid", "1", "-o", str(out), "--no-progress")
    seconds = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert lines[0].startswith("warning: 6 entities failed to load or transfer"), lines
    assert any(w.startswith("warning: face 99 (bspline) refused: its surface runs 1,") and "mm beyond" in w
               for w in lines), lines
    zm = ZMap.load(out)
    assert (zm.y0, zm.y1) == pytest.approx((-80, 80), abs=1)
    assert seconds < 90, seconds
