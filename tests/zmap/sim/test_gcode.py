"""Tests of the G-code reader (zmap.sim.gcode)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.errors import GCodeError
from zmap.sim.canon import expected_moves, program_moves
from zmap.sim.gcode import MOVE_DTYPE, Program, arc_sweep, parse
from zmap.sim.tools import Cutter

from tests.conftest import GCODE_DATA as DATA

# Every sample program: None if it parses, else (line, column, word, keyword of the problem).
REAL = {
    "Gates_combined_R12.nc": None,
    "ShapeOko_Calibration_Pattern_01b.ngc": None,
    "botomata_bottom.nc": None,
    "cam-nisley_cam.ngc": None,
    "cameo.nc": None,
    "flower_mold.nc": None,
    "g17-g18-g19.gcode": None,
    "g17-g99-g81.ngc": None,
    "m98m99-05-loops.ngc": None,
    "mmount.ngc": None,
    "rgh.ngc": None,
    "tort.ngc": None,
}


# ---------------------------------------------------------------- real programs ----------
def test_every_sample_is_listed():
    found = {p.name for p in DATA.iterdir() if p.suffix in (".nc", ".ngc", ".gcode")}
    assert found == set(REAL)


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_programs_strict(name):
    path = DATA / name
    want = REAL[name]
    if want is None:
        prog = parse(path)
        assert prog.n_moves > 0
        assert prog.warnings == []
        assert np.isfinite(prog.moves["end"]).all()
        # moves chain: each starts where the previous ended
        np.testing.assert_array_equal(prog.moves["start"][1:], prog.moves["end"][:-1])
    else:
        line, col, word, key = want
        with pytest.raises(GCodeError, match=key) as info:
            parse(path)
        e = info.value
        assert (e.line, e.column, e.word) == (line, col, word)
        assert str(e).startswith(f"{path}:{line}:{col}: {word}: ")


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_programs_lenient(name):
    prog = parse(DATA / name, lenient=True)
    if REAL[name] is None:
        assert prog.warnings == []
        strict = parse(DATA / name)
        for name_ in prog.moves.dtype.names:
            np.testing.assert_array_equal(prog.moves[name_], strict.moves[name_])
    else:
        line, col, word, _ = REAL[name]
        assert prog.warnings, name
        assert prog.warnings[0].startswith(f"{DATA / name}:{line}:{col}: {word}: ")
        assert all(re.match(r".+:\d+:\d+: \S+: ", w) for w in prog.warnings)


def test_real_program_facts():
    flower = parse(DATA / "flower_mold.nc")
    assert flower.units_input == "inch"
    assert flower.n_lines == 16562
    shapeoko = parse(DATA / "ShapeOko_Calibration_Pattern_01b.ngc")  # \r\r\n line ends
    assert shapeoko.n_lines == 4610
    assert shapeoko.moves["line"].max() <= 4610
    cameo = parse(DATA / "cameo.nc")
    assert cameo.units_input == "mm"
    assert [tc.tool for tc in cameo.tool_changes] == [1]
    assert (cameo.moves["tool"] == 1).all()
    bot = parse(DATA / "botomata_bottom.nc")
    assert [tc.tool for tc in bot.tool_changes] == [1, 1, 2, 3]
    planes = parse(DATA / "g17-g18-g19.gcode")
    assert set(np.unique(planes.moves["plane"][planes.moves["kind"] >= 2])) == {17, 18, 19}


@pytest.mark.parametrize("name", ["flower_mold.nc", "cameo.nc", "rgh.ngc", "tort.ngc"])
@pytest.mark.slow
def test_fast_path_equals_full_interpreter(name, monkeypatch):
    import zmap.sim.gcode as gcode

    fast = parse(DATA / name)
    monkeypatch.setattr(gcode, "_fast_block", lambda *args: False)
    slow = parse(DATA / name)
    for field_ in MOVE_DTYPE.names:
        np.testing.assert_array_equal(fast.moves[field_], slow.moves[field_])


def _canon_moves(path: Path) -> list[tuple[str, tuple[str, ...]]]:
    """STRAIGHT_TRAVERSE / STRAIGHT_FEED / ARC_FEED end points from an rs274 -g listing."""
    out = []
    for raw in path.read_text().splitlines():
        m = re.search(r"\b(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED)\((.*)\)\s*$", raw)
        if not m:
            continue
        args = [a.strip() for a in m.group(2).split(",")]
        if m.group(1) == "ARC_FEED":
            # ARC_FEED(first_end, second_end, first_axis, second_axis, rotation, axis_end, ...)
            out.append(("ARC_FEED", (args[0], args[1], args[5])))
        else:
            out.append((m.group(1), tuple(args[:3])))
    return out


def _my_moves(prog: Program) -> list[tuple[str, tuple[str, ...]]]:
    scale = 25.4 if prog.units_input == "inch" else 1.0
    names = {0: "STRAIGHT_TRAVERSE", 1: "STRAIGHT_FEED", 2: "ARC_FEED", 3: "ARC_FEED"}
    out = []
    for m in prog.moves:
        e = m["end"] / scale
        if m["kind"] >= 2:
            a, b, n = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[int(m["plane"])]
            e = e[[a, b, n]]
        out.append((names[int(m["kind"])], tuple(f"{v + 0.0:.4f}" for v in e)))
    return out


def test_linuxcnc_expected_g17_g99_g81():
    expected = _canon_moves(DATA / "g17-g99-g81.expected")
    mine = _my_moves(parse(DATA / "g17-g99-g81.ngc"))
    assert len(expected) == 37
    assert mine == expected
    full = expected_moves(DATA / "g17-g99-g81.expected")
    np.testing.assert_allclose([m[1] for m in program_moves(parse(DATA / "g17-g99-g81.ngc"))],
                               [e[1] for e in full], rtol=0, atol=0.5e-4 + 1e-9)


@pytest.mark.parametrize("name,table,count", [("cam-nisley_cam", "cam-nisley_test.tbl", 317),
                                              ("m98m99-05-loops", None, 51)])
def test_linuxcnc_expected_parameters_subroutines_and_compensation(name, table, count):
    # O-word loops and ifs, # parameters and expressions, M98/M99 and G42 with the .tbl
    # (read in inches, as LinuxCNC's standalone rs274 does): every move as LinuxCNC prints it
    expected = expected_moves(DATA / f"{name}.expected")
    prog = parse(DATA / f"{name}.ngc", tool_table=DATA / table if table else None)
    mine = program_moves(prog)
    assert len(expected) == count
    assert [m[0] for m in mine] == [e[0] for e in expected]  # move kinds, arc directions
    # the reference prints 4 decimals: equal within its rounding
    np.testing.assert_allclose(np.concatenate([m[1] for m in mine]),
                               np.concatenate([e[1] for e in expected]), rtol=0, atol=0.5e-4 + 1e-9)


# ---------------------------------------------------------------- syntax ---------------------
def test_words_without_spaces_lower_case_and_modal_motion():
    p = parse("g90g21g1x1.5y-.5z0f100\nx2\n y3 \nG0Z5\nX0Y0\n")
    np.testing.assert_array_equal(p.moves["kind"], [1, 1, 1, 0, 0])
    np.testing.assert_array_equal(
        p.moves["end"], [[1.5, -0.5, 0], [2, -0.5, 0], [2, 3, 0], [2, 3, 5], [0, 0, 5]])
    np.testing.assert_array_equal(p.moves["line"], [1, 2, 3, 4, 5])
    assert p.moves.dtype == MOVE_DTYPE


def test_comments_n_numbers_block_delete_and_tape_marks():
    text = "%\nN10 G0 X1 (move; here) ; trailing\n/G0 X9\n(only a comment)\nN20 Y2\n%\nG0 X99\n"
    p = parse(text)
    np.testing.assert_array_equal(p.moves["end"], [[1, 0, 0], [1, 2, 0]])
    p2 = parse(text, block_delete=False)
    np.testing.assert_array_equal(p2.moves["end"][:, 0], [1, 9, 9])


@pytest.mark.parametrize("eol", ["\n", "\r\n", "\r\r\n", "\r"])
def test_line_numbers_for_every_line_end(eol):
    text = eol.join(["G21 G90", "G0 X1", "G0 X2 G33", "G0 X3"]) + eol
    with pytest.raises(GCodeError, match="spindle-synchronised") as info:
        parse(text, filename="prog.nc")
    e = info.value
    assert (e.file, e.line, e.column, e.word) == ("prog.nc", 3, 7, "G33")
    assert str(e).startswith("prog.nc:3:7: G33: ")


@pytest.mark.parametrize(
    "text,word,col,key",
    [
        ("G0 X1\nG42.1 X2\n", "G42.1", 1, "D word"),
        ("G0 X1\no100 sub\n", "O100", 1, "never closed"),
        ("G0 X1\nG0 X#<nope>\n", "#<NOPE>", 5, "not defined"),
        ("G0 X1\nG0 X[1+2\n", "[1+2", 5, "expression"),
        ("G0 X1\nG33.1 Z-1\n", "G33.1", 1, "K word"),
        ("G0 X1\nG12 X1\n", "G12", 1, "not a supported G code"),
        ("G0 X1\nM98 P1\n", "program O1", 1, "not defined"),
        ("G0 X1\nM101\n", "M101", 1, "not a supported M code"),
        ("G0 X1\nG0 A10\n", "A10", 4, "3-axis"),
        ("G0 X1\nG0 X1 X2\n", "X2", 7, "twice"),
        ("G0 X1\nG0 G1 X2\n", "G1", 4, "same modal group"),
        ("G0 X1\nG1 X2\n", "G1", 1, "feed rate"),
        ("G80\nX2\n", "X2", 1, "no active motion"),
        ("G0 X1\nG0 X1 (open comment\n", "(", 7, "parenthesis"),
        ("G0 X1\nG1 X2 I1 F10\n", "I1", 7, "not used"),
        ("G0 X1\nG0 X\n", "X", 4, "no number"),
    ],
)
def test_unsupported_and_invalid_blocks(text, word, col, key):
    with pytest.raises(GCodeError, match=key) as info:
        parse(text)
    e = info.value
    assert (e.line, e.column, e.word) == (2, col, word)


def test_x_units_are_millimetres():
    p = parse("G20 G90\nG1 X1 Y-2 Z0.5 F10\nG21\nG1 X1\n")
    assert p.units_input == "inch"
    np.testing.assert_allclose(p.moves["end"], [[25.4, -50.8, 12.7], [1.0, -50.8, 12.7]])
    np.testing.assert_allclose(p.moves["feed"], [254.0, 254.0])


def test_incremental_and_arc_distance_modes():
    p = parse("G21 G90 G0 X1 Y1\nG91 G1 X1 Y2 F50\nX-1\nG90.1 G90 G2 X7 Y3 I4 J1\n")
    np.testing.assert_allclose(p.moves["end"][:3], [[1, 1, 0], [2, 3, 0], [1, 3, 0]])
    np.testing.assert_allclose(p.moves["center"][3], [4, 1, 0])  # absolute I J (G90.1)


def test_work_offsets_g10_l2_and_g53():
    p = parse("G21 G90\nG10 L2 P2 X10 Y20 Z-5\nG55 G0 X1 Y1 Z1\nG53 G0 X0 Y0 Z0\nG54 G0 X1\n")
    np.testing.assert_allclose(p.moves["end"], [[11, 21, -4], [0, 0, 0], [1, 0, 0]])
    with pytest.raises(GCodeError, match="L2"):
        parse("G10 L20 P1 X0\n")


def test_lenient_skips_whole_block_and_keeps_state():
    p = parse("G21 G90 G0 X1\nG91 G33 X5\nG0 X2\n#1=[1/0]\nG0 Y1\n", lenient=True)
    np.testing.assert_allclose(p.moves["end"], [[1, 0, 0], [2, 0, 0], [2, 1, 0]])  # still G90
    assert len(p.warnings) == 2
    assert p.warnings[0].startswith("<string>:2:5: G33: ")
    assert "division by zero" in p.warnings[1]


def test_program_end_stops_reading():
    p = parse("G0 X1\nM30\nG33 X3\n")
    assert p.n_moves == 1


def test_tools_and_tool_table():
    table = {1: Cutter("ball", 3), 2: Cutter("flat", 6)}
    p = parse("T1 M6\nG43 H1 G0 Z5\nG0 X1\nT2\nG0 X2\nM6\nG0 X3\n", tool_table=table)
    np.testing.assert_array_equal(p.moves["tool"], [1, 1, 1, 2])
    assert [(tc.move, tc.tool, tc.line) for tc in p.tool_changes] == [(0, 1, 1), (3, 2, 6)]
    with pytest.raises(GCodeError, match="not in the tool table") as info:
        parse("G0 X1\nT7 M6\n", tool_table=table)
    assert (info.value.line, info.value.word) == (2, "T7")
    toml = Path(__file__).resolve().parents[3] / "data" / "tools.toml"
    q = parse("T4 M6\nG0 X1\n", tool_table=toml)
    assert q.tool_table[4].kind == "flat" and q.moves["tool"].tolist() == [4]


def test_dwell_path_modes_and_misc_codes_are_accepted():
    p = parse("G17 G21 G40 G49 G54 G64 P0.01 Q0.01 G80 G90 G94 G98\nM3 S1000 M8\nG4 P1.5\n"
              "G61\nM7 M8\nM9 M5 M0\nG0 X1\nM2\n")
    assert p.n_moves == 1
    with pytest.raises(GCodeError, match="P word"):
        parse("G4\n")


# ---------------------------------------------------------------- arcs -----------------------
def test_full_circle_helix_and_turns():
    p = parse("G21 G90 G0 X10 Y0 Z0\nG3 X10 Y0 Z-2 I-10 J0 F100\nG2 X10 Y0 Z-4 I-10 P3\n")
    m = p.moves
    np.testing.assert_allclose(m["center"][1], [0, 0, 0])
    assert m["sweep"][1] == pytest.approx(2 * math.pi)
    assert m["sweep"][2] == pytest.approx(-6 * math.pi)
    assert m["turns"][2] == 2
    assert m["start"][1][2] != m["end"][1][2]  # helical


def test_r_form_both_ways_and_planes():
    # G17: quarter circle either side; negative R takes the long way
    p = parse("G21 G0 X1 Y0\nG3 X0 Y1 R1 F10\nG0 X1 Y0\nG3 X0 Y1 R-1\n")
    np.testing.assert_allclose(p.moves["center"][1][:2], [0, 0], atol=1e-12)
    np.testing.assert_allclose(p.moves["center"][3][:2], [1, 1], atol=1e-12)
    assert p.moves["sweep"][1] == pytest.approx(math.pi / 2)
    assert p.moves["sweep"][3] == pytest.approx(3 * math.pi / 2)
    # G18 (first axis Z, second X): G3 is counter-clockwise about +Y
    q = parse("G21 G18 G0 X1 Z0\nG3 X0 Z-1 I-1 K0 F10\n")
    assert q.moves["sweep"][1] == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(q.moves["center"][1], [0, 0, 0])
    # G19 (first axis Y, second Z): G2 is clockwise about +X
    r = parse("G21 G19 G0 Y1 Z0\nG2 Y0 Z-1 J-1 K0 F10\n")
    assert r.moves["sweep"][1] == pytest.approx(-math.pi / 2)


def test_arc_radius_mismatch_is_an_error():
    with pytest.raises(GCodeError, match="differs") as info:
        parse("G21 G0 X0 Y0\nG2 X10 Y0 I5.2 J0 F100\n")
    assert (info.value.line, info.value.column, info.value.word) == (2, 11, "I5.2")
    # within 0.05 mm (metric) it is accepted; in inches 0.002 in
    parse("G21 G0 X0 Y0\nG2 X10 Y0 I5.02 J0 F100\n")
    parse("G20 G0 X0 Y0\nG2 X1 Y0 I0.5009 J0 F100\n")
    with pytest.raises(GCodeError, match="differs"):
        parse("G20 G0 X0 Y0\nG2 X0.1 Y0 I0.0525 J0 F100\n")
    # relative 0.1 % lets a large arc through
    parse("G21 G0 X0 Y0\nG2 X1000 Y0 I500.2 J0 F100\n")
    with pytest.raises(GCodeError, match="too small"):
        parse("G21 G0 X0 Y0\nG2 X10 Y0 R4 F100\n")
    with pytest.raises(GCodeError, match="cannot be used for an arc"):
        parse("G21 G0 X0 Y0\nG2 X10 Y0 I5 K1 F100\n")


@settings(max_examples=60, deadline=None)
@given(
    cx=st.floats(-50, 50), cy=st.floats(-50, 50), r=st.floats(0.5, 40),
    a0=st.floats(-math.pi, math.pi), a1=st.floats(-math.pi, math.pi), ccw=st.booleans(),
)
def test_random_ijk_arcs_round_trip(cx, cy, r, a0, a1, ccw):
    sx, sy = cx + r * math.cos(a0), cy + r * math.sin(a0)
    ex, ey = cx + r * math.cos(a1), cy + r * math.sin(a1)
    text = (f"G21 G90 G0 X{sx:.6f} Y{sy:.6f}\n"
            f"G{3 if ccw else 2} X{ex:.6f} Y{ey:.6f} I{cx - sx:.6f} J{cy - sy:.6f} F100\n")
    m = parse(text).moves[1]
    np.testing.assert_allclose(m["center"][:2], [cx, cy], atol=2e-6)
    sw = m["sweep"]
    assert (0 < sw <= 2 * math.pi + 1e-12) if ccw else (-2 * math.pi - 1e-12 <= sw < 0)
    # the end angle is the start angle plus the sweep
    s = m["start"]
    ang = math.atan2(s[1] - m["center"][1], s[0] - m["center"][0]) + sw
    e = m["end"]
    rr = math.hypot(s[0] - m["center"][0], s[1] - m["center"][1])
    assert m["center"][0] + rr * math.cos(ang) == pytest.approx(e[0], abs=1e-5)
    assert m["center"][1] + rr * math.sin(ang) == pytest.approx(e[1], abs=1e-5)


def test_arc_sweep_matches_linuxcnc_find_turn():
    assert arc_sweep(1, 0, 0, 1, 0, 0, True) == pytest.approx(math.pi / 2)
    assert arc_sweep(1, 0, 0, 1, 0, 0, False) == pytest.approx(-3 * math.pi / 2)
    assert arc_sweep(1, 0, 1, 0, 0, 0, True, 1) == pytest.approx(4 * math.pi)


# ---------------------------------------------------------------- canned cycles --------------
def test_g81_g98_returns_to_old_z_and_modal_repeat():
    p = parse("G21 G90 G98 G0 X0 Y0 Z10\nG81 X1 Y1 Z-2 R2 F50\nX2\nG80\nG0 Z20\n")
    ends = p.moves["end"].tolist()
    assert ends == [[0, 0, 10], [1, 1, 10], [1, 1, 2], [1, 1, -2], [1, 1, 10],
                    [2, 1, 10], [2, 1, 2], [2, 1, -2], [2, 1, 10], [2, 1, 20]]
    np.testing.assert_array_equal(p.moves["kind"], [0, 0, 0, 1, 0, 0, 0, 1, 0, 0])


def test_g83_pecks_as_linuxcnc():
    p = parse("G21 G90 G99 G0 X0 Y0 Z5\nG83 X3 Y4 Z-2.5 R1 Q1 F50\n")
    z = p.moves["end"][1:, 2].tolist()
    d = 0.254
    assert z == pytest.approx([5, 1, 0, 1, 0 + d, -1, 1, -1 + d, -2, 1, -2 + d, -2.5, 1])
    kinds = p.moves["kind"][1:].tolist()
    assert kinds == [0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0]


def test_g82_and_cycle_errors():
    p = parse("G21 G90 G0 Z5\nG82 X1 Z-1 R1 P0.5 F10\n")
    assert p.moves["end"][-1].tolist() == [1, 0, 5]
    with pytest.raises(GCodeError, match="below the hole bottom"):
        parse("G21 G90 G0 Z5\nG81 X1 Z2 R1 F10\n")
    with pytest.raises(GCodeError, match="Q word"):
        parse("G21 G90 G0 Z5\nG83 X1 Z-2 R1 F10\n")
    with pytest.raises(GCodeError, match="R word"):
        parse("G21 G90 G0 Z5\nG81 X1 Z-2 F10\n")


def test_bounds_cover_arc_extremes():
    p = parse("G21 G0 X10 Y0\nG3 X-10 Y0 I-10 J0 F10\n")
    lo, hi = p.bounds()
    np.testing.assert_allclose(hi, [10, 10, 0])
    np.testing.assert_allclose(lo, [-10, 0, 0])


def test_source_as_path_and_text(tmp_path):
    f = tmp_path / "a.nc"
    f.write_bytes(b"G0 X1\r\nG0 X2 G33\r\n")
    with pytest.raises(GCodeError) as info:
        parse(f)
    assert info.value.file == str(f) and info.value.line == 2
    with pytest.raises(GCodeError) as info:
        parse(str(f), filename="shown.nc")
    assert info.value.file == "shown.nc"
    with pytest.raises(TypeError, match="lenient"):
        parse("G0 X1", lenient="yes")


# ------------------------------------------------------------------ deep expressions --------
def test_deeply_nested_and_long_expressions_in_a_block():
    # beyond Python's recursion limit: the reader's expression evaluator uses explicit stacks
    p = parse("G0 X" + "[" * 400 + "1" + "]" * 400)
    assert p.moves["end"].tolist() == [[1.0, 0.0, 0.0]]
    p = parse("G0 X[" + "+".join(["1"] * 1000) + "]")
    assert p.moves["end"].tolist() == [[1000.0, 0.0, 0.0]]
    p = parse("#1=[" + "+".join(["0.5"] * 4000) + "]\nG0 Y[#1 - " + "[" * 3000 + "1"
              + "]" * 3000 + "]\n")
    assert p.moves["end"].tolist() == [[0.0, 1999.0, 0.0]]


def test_deeply_nested_expression_errors_are_located():
    with pytest.raises(GCodeError, match="expected, got end of line") as info:
        parse("G0 X1\nG0 X" + "[" * 3000 + "1" + "]" * 2999 + "\n")
    assert (info.value.line, info.value.column) == (2, 5)
    p = parse("G0 X1\nG0 X" + "[" * 3000 + "1/0" + "]" * 3000 + "\nG0 X2\n", lenient=True)
    assert p.moves["end"][:, 0].tolist() == [1.0, 2.0]
    assert len(p.warnings) == 1 and p.warnings[0].startswith("<string>:2:")
    assert "division by zero" in p.warnings[0]


_LOCATED = re.compile(r"^.+:\d+:\d+: .+: .+")
_EXPR_PIECES = ("[", "]", "[", "]", "1", "0", "2.5", "-", "+", "*", "/", "**", " MOD ", " GT ",
                " OR ", "#", "#1", "#<_a>", "#<b>", "ABS[", "COS[", "ATAN[", "]/[", "EXISTS[",
                "LN[", ".", "<", ">", "=", "X", "G", "O", "(", ")")


@settings(max_examples=150, deadline=None)
@given(st.lists(st.sampled_from(_EXPR_PIECES), max_size=50), st.integers(0, 2500),
       st.integers(0, 2500), st.sampled_from(["G0 X", "#1=", "G1 F100 Y", "O1 if "]),
       st.booleans())
def test_random_nested_expressions_raise_only_gcode_errors(pieces, opening, closing, head,
                                                           lenient):
    body = "[" * opening + "".join(pieces) + "]" * closing
    text = f"#<_a>=1\n{head}{body}\n" + ("O1 endif\n" if head.startswith("O1") else "")
    try:
        p = parse(text, lenient=lenient)
    except GCodeError as e:
        assert not lenient, f"lenient parse raised {e}"
        assert _LOCATED.match(str(e)), str(e)
    else:
        assert np.isfinite(p.moves["end"]).all()
        assert all(_LOCATED.match(w) for w in p.warnings)


def test_lenient_subprogram_running_off_the_end_warns_and_ends():
    # the M99 block is skipped: O7 runs off the end of the file
    text = "G0 X1\nM98 P7\nG0 X3\nM2\nO7\nG0 X2\nM99 X\n"
    with pytest.raises(GCodeError, match="no number"):
        parse(text)
    p = parse(text, lenient=True)
    assert p.moves["line"].tolist() == [1, 6]
    assert p.warnings[0].startswith("<string>:7:5: X: ")
    assert p.warnings[1].startswith("<string>:7:1: O7: subroutine runs off the end of the file")


# ------------------------------------------------------------------ known start --------------
@pytest.mark.parametrize("text,known", [
    ("G0 Z30\nG0 X1 Y2\nG1 Z-1 F100\n", [0, 4, 7]),
    ("G1 X1 F10\nG2 Y2 J1\nG0 Z[1]\nG0 X0\n", [0, 1, 3, 7]),              # full interpreter
    ("G91 G0 X1\nG0 Y1 Z1\nG0 X1\n", [0, 1, 7]),                          # incremental words
    ("G53 G0 X0 Y0 Z0\nG0 X1\n", [0, 7]),
    ("G81 X1 Y2 Z-1 R1 F100\nG0 X0\n", [0, 4, 7, 7, 7]),                  # rise to R, then over
    ("G0 Z5\nG81 X1 Z-1 R1 F100\nY3\nG80 G0 X0\n", [0, 4, 5, 5, 5, 5, 7, 7, 7, 7]),
    ("G0 X1 Y1\nG41.1 D2\nG1 X5 F10\nG1 Z-1\nG1 Y5\nG40\nG0 X0\n", [0, 3, 3, 7, 7]),
])
def test_known_axes_before_each_move(text, known):
    p = parse(text)
    assert p.moves["known"].tolist() == known
    assert p.moves.dtype == MOVE_DTYPE and MOVE_DTYPE["known"] == np.int8


def test_known_is_kept_across_skipped_blocks():
    # the skipped block's axis is not set; the block after sets it
    p = parse("G0 X1 Y1\nG0 Z1 Q1\nG0 Z2\nG0 X3\n", lenient=True)
    assert p.moves["known"].tolist() == [0, 3, 7]
    assert len(p.warnings) == 1
