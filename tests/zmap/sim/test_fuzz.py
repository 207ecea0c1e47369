"""Fuzzing the G-code reader and the path generator with mutants of real programs.

Property: reading a mutant either raises :class:`zmap.errors.GCodeError` located by
``file:line:column: word: problem``, or gives moves that are all finite (start, end; centre
and sweep of arcs; feed of feed moves) with tool numbers >= 0; and cutting those moves into
positions either gives finite positions or raises a located :class:`zmap.errors.PathError`.
Each reading runs under a wall-clock alarm so that a hang fails instead of blocking the run.
The bigger campaign (2,000 mutants of 8 programs, child processes, memory limits) is
``bench/fuzz_gcode.py``.
"""

from __future__ import annotations

import re
import signal

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from zmap.errors import GCodeError, PathError
from zmap.sim.gcode import parse
from zmap.sim.path import positions

from tests.conftest import GCODE_DATA as DATA

PROGRAMS = ("flower_mold.nc", "g17-g99-g81.ngc", "tort.ngc", "rgh.ngc")
N_LINES = 40
D400 = "9" * 400
LOCATED = re.compile(r"^.+:\d+:\d+: .+: .+")
NUMBERS = (D400, "-" + D400, "1" + "0" * 30, "1E308", "1e400", "INF", "-INF", "NAN", "0", "-0",
           "0.0000001", "-0.0000001", "1000000000", "99999999999", "2147483648", "-1", ".", "")
BLOCKS = (
    "G91 G81 X1 Z-1 R1 F100 L1000000000",
    "G83 X1 Y1 Z-1 R1 Q0.0000001 F100",
    f"G83 X1 Y1 Z-{D400} R1 Q1 F100",
    "G2 X1 I1 P1000000000 F100",
    "G0 X1000000000",
    "T99999999999 M6",
    f"G{D400}",
    f"M{D400}",
    f"G43 H{D400}",
    f"G10 L2 P{D400} X1",
    f"G10 L2 P1 X{D400}",
    f"G1 X1 F{D400}",
    f"G2 X1 R{D400} F100",
    "#1=[1/0]",
    "O100 while [1]",
    "G91",
    "G20",
)
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)")
ALARM_S = 1.5


def _lines(name: str) -> list[str]:
    with open(DATA / name, encoding="utf-8", errors="replace", newline="") as fh:
        return fh.read().splitlines()[:N_LINES]


SOURCES = {name: _lines(name) for name in PROGRAMS if (DATA / name).exists()}


class Hang(Exception):
    """A reading that did not finish within the alarm."""


def _within(seconds: float, what: str, f, *args, **kw):
    """``f(*args, **kw)``, or AssertionError when it runs past ``seconds`` (SIGALRM). The
    hung call's frames (and what they hold: a runaway list of moves) are dropped before the
    failure is raised, so that a report keeping the traceback does not keep gigabytes."""

    def _raise(signum, frame):
        raise Hang()

    old = signal.signal(signal.SIGALRM, _raise)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    hung = False
    try:
        return f(*args, **kw)
    except Hang:
        hung = True
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    if hung:
        raise AssertionError(f"{what} did not finish in {seconds:g} s (a hang)")


def _moves_finite(moves: np.ndarray) -> str | None:
    """None when all is finite, else what is not."""
    arc = moves["kind"] >= 2
    checks = (
        ("end", np.isfinite(moves["end"]).all(axis=1)),
        ("center", ~arc | np.isfinite(moves["center"]).all(axis=1)),
        ("sweep", ~arc | np.isfinite(moves["sweep"])),
        ("feed", (moves["kind"] == 0) | np.isfinite(moves["feed"])),
        ("start", np.isfinite(moves["start"]).all(axis=1)),
        ("tool >= 0", moves["tool"] >= 0),
    )
    bad = ~np.logical_and.reduce([ok for _, ok in checks])
    if bad.any():  # the first bad move, and the first of its checks that fails
        i = int(np.argmax(bad))
        name = next(n for n, ok in checks if not ok[i])
        return f"move {i} (line {int(moves['line'][i])}): {name} fails: {moves[i]}"
    return None


def check_text(text: str, name: str = "mutant.nc") -> None:
    """The fuzz property for one text, both strict and lenient."""
    for lenient in (False, True):
        try:
            prog = _within(ALARM_S, f"parse(lenient={lenient})", parse, text, lenient=lenient,
                           filename=name)
        except GCodeError as e:
            assert LOCATED.match(str(e)), f"GCodeError without file:line:column: {e}"
            continue
        bad = _moves_finite(prog.moves)
        assert bad is None, f"parse(lenient={lenient}) returned {bad}"
        try:
            pos = _within(5 * ALARM_S, "positions", positions, prog, max_positions=2e6)
        except PathError as e:
            assert re.match(r"^.+:\d+: .+", str(e)), f"PathError without file:line: {e}"
            continue
        assert np.isfinite(pos.xyz).all()


@st.composite
def mutants(draw) -> tuple[str, list[str]]:
    name = draw(st.sampled_from(sorted(SOURCES)))
    lines = list(SOURCES[name])
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(("number", "number", "insert", "dup", "delete", "truncate",
                                   "text")))
        nums = list(_NUMBER.finditer(lines[i])) if i < len(lines) else []
        if op == "number" and nums:
            m = nums[draw(st.integers(0, len(nums) - 1))]
            new = draw(st.sampled_from(NUMBERS + ("-" + m.group().lstrip("+-"),)))
            lines[i] = lines[i][: m.start()] + new + lines[i][m.end():]
        elif op == "insert" or not lines:
            lines[i:i] = [draw(st.sampled_from(BLOCKS))]
        elif op == "dup":
            lines.insert(i, lines[i])
        elif op == "delete" and len(lines) > 1:
            del lines[i]
        elif op == "truncate":
            lines[i] = lines[i][: draw(st.integers(0, len(lines[i])))]
        else:
            k = draw(st.integers(0, len(lines[i])))
            junk = draw(st.text(st.characters(max_codepoint=255), min_size=1, max_size=4))
            lines[i] = lines[i][:k] + junk + lines[i][k:]
    return name, lines


def test_the_sources_parse_cleanly():
    assert len(SOURCES) >= 4, f"want 4 programs of {PROGRAMS} in {DATA}"
    for name, lines in SOURCES.items():
        check_text("\n".join(lines) + "\n", name)


@settings(max_examples=150, deadline=None, database=None,
          phases=(Phase.explicit, Phase.generate),  # no shrinking: a hang costs ALARM_S
          suppress_health_check=[HealthCheck.too_slow])
@given(mutants())
def test_mutants_raise_located_errors_or_give_finite_moves(mutant):
    name, lines = mutant
    check_text("\n".join(lines) + "\n", name)


# ------------------------------------------------------------------ the issue's cases

ISSUE_CASES = {
    "G 400 digits": f"G{D400} X1",
    "M 400 digits": f"M{D400}",
    "T 400 digits": f"T{D400} M6",
    "H 400 digits": f"G43 H{D400}",
    "L 400 digits": f"G91 G81 X1 Z-1 R1 F100 L{D400}",
    "arc P 400 digits": f"G2 X1 I1 F100 P{D400}",
    "G10 L2 P 400 digits": f"G10 L2 P{D400} X1",
    "X 400 digits": f"G0 X{D400}",
    "Y -400 digits": f"G1 Y-{D400} F100",
    "X1e400": "G0 X1e400",
    "X inf": "G0 XINF",
    "I 400 digits": f"G2 X1 I{D400} F100",
    "R 400 digits": f"G2 X1 R{D400} F100",
    "G10 offset 400 digits": f"G10 L2 P1 X{D400}\nG0 X1",
    "cycle R 400 digits": f"G81 X1 Z-1 R{D400} F100",
    "F 400 digits": f"G1 X1 F{D400}",
    "G81 L1000000000": "G91 G81 X1 Z-1 R1 F100 L1000000000",
    "G83 Q0.0000001": "G83 X1 Z-1 R1 Q0.0000001 F100",
    "G83 Z-400 digits": f"G83 X1 Z-{D400} R1 Q1 F100",
    "G2 P1000000000": "G2 X1 I1 F100 P1000000000",
    "G0 X1000000000": "G0 X1000000000",
    "T99999999999": "T99999999999 M6\nG0 X1",
}


@pytest.mark.parametrize("case", sorted(ISSUE_CASES))
def test_issue_case_raises_gcode_error_naming_its_line(case):
    text = "G21 G90 G0 X-1 Y0 Z5\n" + ISSUE_CASES[case] + "\n"
    with pytest.raises(GCodeError, match=r"^case\.nc:[23]:\d+: ") as info:
        _within(ALARM_S, f"parse of {case!r}", parse, text, filename="case.nc")
    assert info.value.line in (2, 3)
