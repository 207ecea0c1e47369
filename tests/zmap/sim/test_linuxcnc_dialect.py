"""The reader's LinuxCNC dialect, checked against what LinuxCNC's rs274ngc interpreter does.

Each program here is our own, small, with its moves worked out by hand; the comment names the
LinuxCNC behaviour (its source file or its tests/interp/ directory) that it pins down.
"""

from __future__ import annotations

import numpy as np
import pytest

from zmap.errors import GCodeError
from zmap.sim.gcode import parse


def ends(prog) -> list[list[float]]:
    return np.round(prog.moves["end"], 6).tolist()


# ---------------------------------------------------------------- parameters -------------------
def test_exists_numbered_parameters():
    # tests/interp/exists: EXISTS[#n] is 1 for a number in range, also through ## indirection
    p = parse("#1=2\n#2=99999\nG0 X EXISTS[#1] Y EXISTS[#99999] Z EXISTS[##1]\n"
              "G0 X EXISTS[##2] Y EXISTS[#<nope>]\n")
    assert ends(p) == [[1, 0, 1], [0, 0, 1]]


def test_value_starts_at_zero_and_endsub_without_value_clears_it():
    # #<_value> and #<_value_returned> exist before any call; a bare endsub sets both to 0
    p = parse("G0 X#<_value> Y#<_value_returned>\n"
              "o<a> sub\no<a> return [7]\no<a> endsub\n"
              "o<b> sub\no<b> endsub\n"
              "o<a> call\nG0 X#<_value> Y#<_value_returned>\n"
              "o<b> call\nG0 X#<_value> Y#<_value_returned>\n")
    assert ends(p) == [[0, 0, 0], [7, 1, 0], [0, 0, 0]]


def test_numbered_parameters_1_to_30_come_back_after_a_call_but_31_does_not():
    # interp_o_word.cc execute_call/execute_return save and restore #1-#30 only;
    # tests/interp/m98m99/02-variables: an argument-less call starts with #1-#30 at 0
    p = parse("#1=1\n#30=30\n#31=31\n"
              "o<s> sub\nG0 X#1 Y#30 Z#31\n#1=10\n#30=300\n#31=310\no<s> endsub\n"
              "o<s> call\nG0 X#1 Y#30 Z#31\no<s> call [5]\n")
    assert ends(p) == [[0, 0, 31], [1, 30, 310], [5, 0, 310]]


def test_local_named_parameter_of_the_main_program_is_not_seen_in_a_sub():
    # named parameters without a leading _ live in their call level only
    with pytest.raises(GCodeError, match="not defined") as info:
        parse("#<a>=5\no<s> sub\nG0 X#<a>\no<s> endsub\no<s> call\n")
    assert info.value.line == 3
    p = parse("#<a>=5\no<s> sub\n#<a>=7\nG0 Y#<a>\no<s> endsub\no<s> call\nG0 X#<a>\n")
    assert ends(p) == [[0, 7, 0], [5, 7, 0]]


# ---------------------------------------------------------------- O-words ----------------------
def test_call_of_a_sub_defined_after_the_call():
    p = parse("o<s> call [3]\nM2\no<s> sub\nG0 X#1\no<s> endsub\n")
    assert ends(p) == [[3, 0, 0]]


def test_computed_o_word_labels_for_call_and_m98():
    # tests/interp/m98m99/14-o-expression-call: O[expr] call and M98 P[expr]
    p = parse("#2=10\nO[#2*10] call [4]\nM98 P[5*5*2*2+100]\nM30\n"
              "O100 sub\nG0 X#1\nO100 endsub\nO200\nG0 Y2\nM99\n")
    assert ends(p) == [[4, 0, 0], [4, 2, 0]]


def test_repeat_nested_in_a_while_counts_afresh_each_time():
    p = parse("#1=0\no1 while [#1 LT 2]\no100 repeat [3]\nG91 G0 X1\no100 endrepeat\n"
              "#1=[#1+1]\nG90\no1 endwhile\n")
    assert [e[0] for e in ends(p)] == [1, 2, 3, 4, 5, 6]


def test_break_and_continue_in_a_do_while_loop():
    # interp_o_word.cc: continue skips to the closing while, which tests the condition
    p = parse("#1=0\no1 do\n#1=[#1+1]\no2 if [#1 EQ 2]\no1 continue\no2 endif\n"
              "o3 if [#1 EQ 4]\no1 break\no3 endif\nG0 X#1\no1 while [#1 LT 10]\nG0 Y1\n")
    assert ends(p) == [[1, 0, 0], [3, 0, 0], [3, 1, 0]]
    # a continue whose condition is then false leaves the loop
    p = parse("#1=0\no1 do\n#1=[#1+1]\no1 continue\nG0 X9\no1 while [#1 LT 3]\nG0 Y#1\n")
    assert ends(p) == [[0, 3, 0]]


@pytest.mark.parametrize("kw", ["break", "continue"])
def test_break_and_continue_in_repeat_are_errors_as_in_linuxcnc(kw):
    # convert_control_functions accepts break/continue only for while and do labels
    with pytest.raises(GCodeError, match="while and do loops only") as info:
        parse(f"o1 repeat [3]\nG0 X1\no1 {kw}\no1 endrepeat\n")
    assert (info.value.line, info.value.word) == (3, "O1")


# ---------------------------------------------------------------- subroutine files -------------
def test_subroutine_files_beside_below_and_on_the_subroutine_path(tmp_path):
    # tests/interp/sub-call-from-sub: subs in their own files, calling each other
    (tmp_path / "subs").mkdir()
    (tmp_path / "lib").mkdir()
    (tmp_path / "subs" / "caller.ngc").write_text(
        "o<caller> sub\nG0 X#1\no<helper> call [#2]\no<caller> endsub\nM2\n")
    (tmp_path / "subs" / "helper.ngc").write_text("o<helper> sub\nG0 Y#1\no<helper> endsub\n")
    (tmp_path / "beside.ngc").write_text("o<beside> sub\nG0 Z#1\no<beside> endsub\n")
    (tmp_path / "lib" / "beside.ngc").write_text("o<beside> sub\nG0 Z[#1*10]\no<beside> endsub\n")
    (tmp_path / "100.ngc").write_text("o100 sub\nG0 X100\no100 endsub\n")
    main = tmp_path / "main.ngc"
    main.write_text("o<Caller> call [1] [2]\no<beside> call [3]\no100 call\nM2\n")
    assert ends(parse(main)) == [[1, 0, 0], [1, 2, 0], [1, 2, 3], [100, 2, 3]]
    # subroutine_path comes first
    p = parse(main, subroutine_path="lib")
    assert ends(p)[2] == [1, 2, 30]
    p = parse(main, subroutine_path=[tmp_path / "lib"])
    assert ends(p)[2] == [1, 2, 30]
    with pytest.raises(GCodeError, match="subroutine_path"):
        parse("o<caller> call\n")


# ---------------------------------------------------------------- cutter compensation ----------
def test_negative_compensation_diameter_cuts_on_the_other_side():
    # tests/interp/crazy-paths: G41.1 D-0.5 is compensation on the right, radius 0.25
    body = "G21 G0 X0 Y0\n{comp}\nG1 F100 Y-2\nG1 X10\nG40\nG1 X20\n"
    neg = parse(body.format(comp="G41.1 D-0.5"))
    pos = parse(body.format(comp="G42.1 D0.5"))
    np.testing.assert_array_equal(neg.moves["end"], pos.moves["end"])
    np.testing.assert_array_equal(neg.moves["kind"], pos.moves["kind"])
    assert neg.moves["end"][1].tolist() == [-0.25, -2, 0]  # right of a -Y move is -X


def test_compensation_in_the_g18_plane_is_the_g17_one_with_z_x_for_x_y():
    # tests/interp/inside-corners: the same outline in G17 (X, Y) and in G18 (Z, X) gives the
    # same compensated numbers, Z for X and X for Y
    g17 = parse("G21 G17 G0 X0 Y0\nG41.1 D1\nG1 F100 X5 Y1\nG3 X8 Y4 I3 J0\nG1 Y8\nG40\nG1 X0\n")
    g18 = parse("G21 G18 G0 Z0 X0\nG41.1 D1\nG1 F100 Z5 X1\nG3 Z8 X4 K3 I0\nG1 X8\nG40\nG1 Z0\n")
    np.testing.assert_array_equal(g17.moves["kind"], g18.moves["kind"])
    np.testing.assert_allclose(g18.moves["end"][:, [2, 0, 1]], g17.moves["end"], atol=1e-12)
    arcs = g17.moves["kind"] >= 2
    np.testing.assert_allclose(g18.moves["center"][arcs][:, [2, 0]],
                               g17.moves["center"][arcs][:, [0, 1]], atol=1e-12)
    np.testing.assert_allclose(g18.moves["sweep"], g17.moves["sweep"], atol=1e-12)
    assert set(g18.moves["plane"].tolist()) == {18}
    with pytest.raises(GCodeError, match="G19 plane"):
        parse("G21 G19 G0 Y0 Z0\nG41.1 D1\nG1 F100 Y5\n")


def test_nested_subroutine_definition_is_an_error(tmp_path):
    # tests/interp/nested-sub-error: a sub defined inside another sub (here in its own file)
    (tmp_path / "nested.ngc").write_text(
        "o<nested> sub\no100 sub\nG0 X#1\no100 endsub\no100 call [4]\no<nested> endsub\n")
    main = tmp_path / "main.ngc"
    main.write_text("o<nested> call [7]\nM2\n")
    with pytest.raises(GCodeError, match="nested") as info:
        parse(main)
    assert (info.value.file, info.value.line, info.value.word) == (
        str(tmp_path / "nested.ngc"), 2, "O100")
