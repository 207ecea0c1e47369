"""The LinuxCNC language layer (zmap.sim.ngc): expressions, parameters, line scanning, O-words."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.sim.ngc import (
    NgcError,
    OWord,
    Parameters,
    compact,
    evaluate,
    program_structure,
    scan_line,
)


# ------------------------------------------------------------------ expressions -------------
@pytest.mark.parametrize("text,want", [
    ("[1 + 2 * 3]", 7.0),
    ("[2 ** 3 ** 2]", 64.0),            # LinuxCNC: left to right within a level
    ("[1 - 2 - 3]", -4.0),
    ("[8 / 4 / 2]", 1.0),
    ("[7 MOD 3]", 1.0),
    ("[-7 MOD 3]", 2.0),                # always positive, as LinuxCNC's fmod + |b|
    ("[2 * 3 MOD 4]", 2.0),             # * and MOD share a level
    ("[1 + 2 EQ 3]", 1.0),              # arithmetic before comparisons
    ("[1 EQ 1.00009]", 1.0),            # EQ within 0.0001
    ("[1 NE 1.00009]", 0.0),
    ("[1 LE 1.00005]", 1.0),
    ("[2 GE 1]", 1.0),
    ("[1 GT 1]", 0.0),
    ("[1 LT 2 AND 2 LT 1]", 0.0),       # comparisons before AND/OR/XOR
    ("[0 OR 3]", 1.0),
    ("[1 XOR 1]", 0.0),
    ("[-[1 + 1]]", -2.0),
    ("-[2]", -2.0),
    ("ABS[-2.5]", 2.5),
    ("SIN[30]", 0.5),                   # degrees
    ("COS[60]", 0.5),
    ("TAN[45]", 1.0),
    ("ASIN[1]", 90.0),
    ("ACOS[0]", 90.0),
    ("ATAN[1]/[-1]", 135.0),
    ("SQRT[16]", 4.0),
    ("EXP[0]", 1.0),
    ("LN[1]", 0.0),
    ("FIX[-1.5]", -2.0),
    ("FUP[-1.5]", -1.0),
    ("ROUND[2.5]", 3.0),
    ("ROUND[-2.5]", -3.0),
    ("[ 1 +2 ]", 3.0),                  # blanks are dropped, as LinuxCNC reads a line
])
def test_operators_functions_and_precedence(text, want):
    assert evaluate(text) == pytest.approx(want, abs=1e-12)


@pytest.mark.parametrize("text,key", [
    ("[1 / 0]", "division by zero"),
    ("[1 MOD 0]", "MOD by zero"),
    ("SQRT[-1]", "SQRT"),
    ("LN[0]", "LN"),
    ("ASIN[2]", "ASIN"),
    ("ACOS[-1.5]", "ACOS"),
    ("[-8 ** 0.5]", "non-integer power"),
    ("[1 + 2", "expected"),
    ("[1 +]", "expected"),
    ("FOO[1]", "unknown function"),
    ("SIN 1", "brackets"),
    ("ATAN[1]", "two arguments"),
    ("[1e3]", "expected"),              # no exponents in G-code numbers
    ("[10 ** 400]", "out of range"),
    ("EXP[1000]", "out of range"),
    ("[" + "9" * 400 + "]", "out of range"),
])
def test_expression_errors_are_clean(text, key):
    with pytest.raises(NgcError, match=key):
        evaluate(text)


def _tree(depth: int):
    leaf = st.integers(-50, 50).map(float)
    if depth == 0:
        return leaf
    sub = _tree(depth - 1)
    return st.one_of(leaf, st.tuples(st.sampled_from(["+", "-", "*"]), sub, sub))


def _render(t) -> tuple[str, float]:
    if isinstance(t, float):
        return (f"{t:g}" if t >= 0 else f"[0 - {-t:g}]"), t
    op, a, b = t
    sa, va = _render(a)
    sb, vb = _render(b)
    v = {"+": va + vb, "-": va - vb, "*": va * vb}[op]
    return f"[{sa} {op} {sb}]", v


@settings(max_examples=200, deadline=None)
@given(_tree(4))
@pytest.mark.slow
def test_random_bracketed_expressions_equal_python(tree):
    text, want = _render(tree)
    if not text.startswith("["):
        text = f"[{text}]"
    assert evaluate(text) == want


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["+", "-", "*", "/"]), st.integers(1, 9)), min_size=1,
                max_size=6), st.integers(1, 9))
def test_flat_expressions_follow_usual_precedence(ops, first):
    # without brackets: * and / bind tighter than + and -, left to right
    text = f"{first}" + "".join(f" {op} {v}" for op, v in ops)
    terms: list[float] = [float(first)]  # a reference without eval: * and / fold into the last term
    for op, v in ops:
        if op == "*":
            terms[-1] *= v
        elif op == "/":
            terms[-1] /= v
        else:
            terms.append(float(v) if op == "+" else -float(v))
    want = math.fsum(terms)
    assert evaluate(f"[{text}]") == pytest.approx(want, rel=1e-12, abs=1e-12)


# ------------------------------------------------------------------ parameters --------------
def test_parameters_numbered_named_global_and_frames():
    p = Parameters()
    p.set(1, 5.0)
    p.set("<X>", 2.0)
    p.set("<_G>", 3.0)
    p.push((7.0, 8.0))
    assert p.get(1) == 7.0 and p.get(2) == 8.0 and p.get(3) == 0.0
    assert p.get("<_G>") == 3.0                     # globals are seen in a call
    with pytest.raises(KeyError):
        p.get("<X>")                                # locals of the caller are not
    p.set("<X>", 9.0)
    p.pop()
    assert p.get(1) == 5.0 and p.get(2) == 0.0 and p.get("<X>") == 2.0
    assert p.exists("<_G>") and not p.exists("<Y>")


def test_scan_line_reads_old_values_and_sets_after():
    p = Parameters()
    p.set(1, 1.0)
    line = scan_line("#1=[#1+1] #2=#1 G1 X#1 Y[#1*2] F100", p)
    assert [(w.letter, w.value) for w in line.words] == [("G", 1.0), ("X", 1.0), ("Y", 2.0),
                                                         ("F", 100.0)]
    assert line.assigns == [(1, 2.0), (2, 1.0)]     # both read #1 as it was


def test_scan_line_indirect_and_named_and_columns():
    p = Parameters()
    p.set(5, 3.0)
    p.set(3, 42.0)
    line = scan_line("G0   X##5", p)
    assert line.words[1].value == 42.0
    assert line.words[1].col == 6                   # column in the source line
    with pytest.raises(NgcError) as info:
        scan_line("G0 X1 Y#<nope>", p)
    assert info.value.pos == 8 and "not defined" in info.value.problem


@pytest.mark.parametrize("text,key", [
    ("#1", "'=' is"),
    ("#0=1", "out of range"),
    ("#6000=1", "out of range"),
    ("#1.5=1", "not an integer"),
    ("G1 X", "missing"),
    ("G1 X1 O100 IF [1]", "start the line"),
    ("G1 $", "unexpected character"),
    ("O100 WHILE 1", "unexpected text"),
])
def test_scan_line_errors(text, key):
    with pytest.raises(NgcError, match=key):
        scan_line(text, Parameters())


def test_compact_maps_columns():
    c, cols = compact("G1  X [ 1 ]")
    assert c == "G1X[1]" and cols == (1, 2, 5, 7, 9, 11)


# ------------------------------------------------------------------ O-word structure --------
def _ow(label: str, kw: str) -> OWord:
    return OWord(label, kw, (), 1)


def test_structure_pairs_loops_branches_and_subs():
    ow = {0: _ow("<S>", "SUB"), 2: _ow("<S>", "ENDSUB"),
          3: _ow("1", "WHILE"), 4: _ow("2", "IF"), 5: _ow("1", "BREAK"), 6: _ow("2", "ELSEIF"),
          7: _ow("2", "ELSE"), 8: _ow("2", "ENDIF"), 9: _ow("1", "ENDWHILE"),
          10: _ow("3", "DO"), 11: _ow("3", "CONTINUE"), 12: _ow("3", "WHILE"),
          13: _ow("4", "REPEAT"), 14: _ow("4", "ENDREPEAT"), 15: _ow("7", "")}
    s = program_structure(ow, m99_lines=[17])
    assert s.subs == {"<S>": 0, "P7": 15}
    assert s.end[0] == 2 and s.end[3] == 9 and s.start[9] == 3
    assert s.end[4] == 6 and s.end[6] == 7 and s.end[7] == 8
    assert s.endif == {4: 8, 6: 8, 7: 8}
    assert s.loop[5] == 3 and s.loop[11] == 10
    assert s.end[10] == 12 and s.start[12] == 10      # the while closes the do
    assert s.end[13] == 14 and s.end[15] == 17         # program O7 runs to its M99


@pytest.mark.parametrize("owords,key", [
    ({0: _ow("1", "WHILE")}, "never closed"),
    ({0: _ow("1", "ENDWHILE")}, "no matching while"),
    ({0: _ow("1", "IF"), 1: _ow("1", "ELSE"), 2: _ow("1", "ELSEIF"), 3: _ow("1", "ENDIF")},
     "after else"),
    ({0: _ow("1", "WHILE"), 1: _ow("2", "IF"), 2: _ow("1", "ENDWHILE"), 3: _ow("2", "ENDIF")},
     "not closed before"),
    ({0: _ow("1", "BREAK")}, "not inside loop"),
    ({0: _ow("1", "RETURN")}, "outside a subroutine"),
    ({0: _ow("<A>", "SUB"), 1: _ow("<A>", "ENDSUB"), 2: _ow("<A>", "SUB"),
      3: _ow("<A>", "ENDSUB")}, "defined twice"),
    ({0: _ow("5", "")}, "no M99"),
])
def test_structure_errors_name_the_statement(owords, key):
    with pytest.raises(NgcError, match=key) as info:
        program_structure(owords, m99_lines=[])
    assert info.value.pos in owords and info.value.word.startswith("O")


def test_math_functions_match_libm_in_degrees():
    for a in (-170.0, -33.3, 0.0, 12.5, 89.0, 271.0):
        assert evaluate(f"SIN[{a}]") == pytest.approx(math.sin(math.radians(a)), abs=1e-15)
        assert evaluate(f"COS[{a}]") == pytest.approx(math.cos(math.radians(a)), abs=1e-15)


# ------------------------------------------------------------------ depth and length --------
# Reading and running a value use explicit stacks: nesting and length are limited by memory
# only, far beyond Python's recursion limit (1,000 frames by default).
@pytest.mark.parametrize("text,want", [
    ("[" * 400 + "1" + "]" * 400, 1.0),
    ("[" * 5000 + "2" + "]" * 5000, 2.0),
    ("[" + "+".join(["1"] * 1000) + "]", 1000.0),
    ("[" + " - ".join(["1"] * 5000) + "]", -4998.0),          # left to right: 1 - 1 - ... - 1
    ("[" + "*".join(["1"] * 3000) + " + 1]", 2.0),
    ("[" + "1 + " * 2000 + "2 * 3]", 2006.0),                  # * before + at the end of a chain
    ("ABS[" * 2000 + "-3" + "]" * 2000, 3.0),
    ("-[" * 3001 + "1" + "]" * 3001, -1.0),                    # 3001 signs: odd, negative
    ("[" + "[1 + " * 1500 + "1" + "]" * 1500 + "]", 1501.0),   # right-nested sums
    ("ATAN[" * 500 + "1" + "]/[1]" * 500, 45.0),               # ATAN[ATAN[...]/[1]]/[1]...
])
def test_deep_and_long_expressions_evaluate(text, want):
    got = evaluate(text)
    if "ATAN" in text:  # ATAN[45]/[1] != 45: compare with the same fold in Python
        v = 1.0
        for _ in range(500):
            v = math.degrees(math.atan2(v, 1.0))
        want = v
    assert got == pytest.approx(want, rel=1e-12)


def test_deep_parameter_indirection_and_exists():
    p = Parameters()
    p.set(1, 1.0)  # #1 = 1: ##...#1 is 1 at any depth
    assert evaluate("#" * 3000 + "1", p) == 1.0
    assert evaluate("EXISTS[#" + "[" * 2000 + "1" + "]" * 2000 + "]") == 1.0
    assert evaluate("EXISTS[#" + "[" * 2000 + "0" + "]" * 2000 + "]") == 0.0


@pytest.mark.parametrize("text,key", [
    ("[" * 3000 + "1" + "]" * 2999, "expected, got end of line"),
    ("[" + "1+" * 3000 + "]", "expected"),
    ("[" + "[1/0]+" * 1000 + "1]", "division by zero"),
    ("EXISTS[#1+1]", "EXISTS needs a parameter"),
    ("ATAN[1]/2", "second argument"),
])
def test_deep_and_long_expression_errors_are_clean(text, key):
    with pytest.raises(NgcError, match=key):
        evaluate(text)


_PIECES = ("[", "]", "[", "]", "1", "2.5", "-", "+", "*", "/", "**", " MOD ", " EQ ", " AND ",
           "#", "#1", "#<_a>", "#<b>", "ABS[", "SIN[", "ATAN[", "]/[", "EXISTS[", "SQRT[",
           ".", "<", ">", "=", "X")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from(_PIECES), max_size=60), st.integers(0, 3000),
       st.integers(0, 3000))
@pytest.mark.slow
def test_random_expressions_raise_only_ngc_errors(pieces, opening, closing):
    text = "[" * opening + "".join(pieces) + "]" * closing
    p = Parameters()
    p.set("<_A>", 1.0)
    try:
        v = evaluate(text, p)
    except NgcError as e:
        assert 0 <= e.pos <= len(text) and e.word and e.problem
    else:
        assert math.isfinite(v)
