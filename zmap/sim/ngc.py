"""The LinuxCNC (rs274ngc) language layer of the G-code reader: parameters, expressions, O-words.

:mod:`zmap.sim.gcode` hands every line that holds a ``#``, a ``[`` or an ``O`` to
:func:`scan_line`, which turns it into words with numeric values, parameter assignments and an
O-word statement. Parameters live in a :class:`Parameters` store (numbered ``#1``-``#5602``,
local ``#<name>`` per subroutine call, global ``#<_name>``); expressions follow LinuxCNC's
``read_real_expression``: operators ``** * / MOD + - EQ NE GT GE LT LE AND OR XOR`` with its
precedence, left to right within a level, and the functions ``ABS ACOS ASIN ATAN[y]/[x] COS
EXP FIX FUP LN ROUND SIN SQRT TAN EXISTS`` (angles in degrees). A value is compiled into a
postfix program and run on a stack, both without recursion, so nesting depth and length are
bounded by memory only (``[[[...1...]]]`` 5,000 deep, a sum of 5,000 terms are tested).
:func:`program_structure` pairs the O-word statements of a file (``sub/endsub``, ``while/endwhile``, ``do/while``,
``repeat/endrepeat``, ``if/elseif/else/endif``) before anything runs.

Everything works on the *compact* line: upper case, comments blanked, blanks removed (as
LinuxCNC reads a line), with a map back to the columns of the source line for messages.

Examples
--------
>>> p = Parameters()
>>> line = scan_line("#1 = [2 ** 3 MOD 5]  G1 X[#2 + 1] Y-#1", p)
>>> [(w.letter, w.value) for w in line.words], line.assigns
([('G', 1.0), ('X', 1.0), ('Y', -0.0)], [(1, 3.0)])
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Callable, NamedTuple

__all__ = [
    "NgcError",
    "Word",
    "OWord",
    "Line",
    "Parameters",
    "compact",
    "scan_line",
    "evaluate",
    "program_structure",
    "Structure",
    "MAX_PARAMETER",
]

#: highest numbered parameter (LinuxCNC RS274NGC_MAX_PARAMETERS - 1)
MAX_PARAMETER = 5602
#: ``EQ``, ``NE``, ``LE``, ``GE`` compare within this, as LinuxCNC's TOLERANCE_EQUAL
TOLERANCE_EQUAL = 0.0001
#: a number or expression beyond this magnitude is refused (no machine needs it; 1e300 * 1e300
#: would otherwise become infinity silently)
MAX_MAGNITUDE = 1e100

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)")
_NAME = re.compile(r"<([^>]*)>")
_UNARY = ("ABS", "ACOS", "ASIN", "ATAN", "COS", "EXISTS", "EXP", "FIX", "FUP", "LN", "ROUND",
          "SIN", "SQRT", "TAN")
# operator, precedence (LinuxCNC's precedence(): AND OR XOR 2, comparisons 3, + - 4, * / MOD 5,
# ** 6); longer spellings first so that "**" is not read as "*".
_OPERATORS = (("**", 6), ("*", 5), ("/", 5), ("MOD", 5), ("+", 4), ("-", 4), ("EQ", 3),
              ("NE", 3), ("GT", 3), ("GE", 3), ("LT", 3), ("LE", 3), ("AND", 2), ("OR", 2),
              ("XOR", 2))
_OPERATOR_RE = re.compile("|".join(re.escape(op) for op, _ in _OPERATORS))
_PRECEDENCE = dict(_OPERATORS)
_KEYWORDS = ("ENDSUB", "ENDWHILE", "ENDREPEAT", "ENDIF", "ELSEIF", "ELSE", "SUB", "CALL", "DO",
             "WHILE", "IF", "BREAK", "CONTINUE", "RETURN", "REPEAT")


class NgcError(Exception):
    """A problem at index ``pos`` of the compact line (turned into GCodeError by the reader)."""

    def __init__(self, pos: int, word: str, problem: str):
        super().__init__(problem)
        self.pos = pos
        self.word = word
        self.problem = problem


class Word(NamedTuple):
    """A word of a block: letter, value (program units) and 1-based source column."""

    letter: str
    value: float
    col: int


class OWord(NamedTuple):
    """An O-word statement: label (``"<name>"`` or the number as text), keyword, arguments."""

    label: str
    keyword: str
    args: tuple[float, ...]
    col: int


@dataclass
class Line:
    """A scanned line: words in order, parameter assignments, an O-word statement or None."""

    words: list[Word] = field(default_factory=list)
    assigns: list[tuple[int | str, float]] = field(default_factory=list)
    oword: OWord | None = None


@lru_cache(maxsize=8192)  # lines inside loops and subroutines are scanned again and again
def compact(s: str) -> tuple[str, tuple[int, ...]]:
    """Drop blanks from an (upper-cased, comment-free) line; map each kept char to its column.

    Examples
    --------
    >>> compact("G1 X [1 + 2]")
    ('G1X[1+2]', (1, 2, 4, 6, 7, 9, 11, 12))
    """
    cols = tuple(i + 1 for i, ch in enumerate(s) if ch not in " \t\r\n\f\v")
    return "".join(s[i - 1] for i in cols), cols


class Parameters:
    """Numbered, local named and global named parameters, with a call stack for subroutines.

    ``system`` maps read-only names or numbers (``"_X"``, ``5420``, ...) to callables that give
    the machine's current value; the reader installs them.

    Examples
    --------
    >>> p = Parameters()
    >>> p.set(1, 2.5); p.set("<_G>", 1.0); p.get(1), p.get("<_G>"), p.get(7)
    (2.5, 1.0, 0.0)
    """

    def __init__(self) -> None:
        self.numbered: dict[int, float] = {}
        self.globals: dict[str, float] = {}
        self.frames: list[dict[str, float]] = [{}]
        self.saved: list[dict[int, float]] = []
        self.system: dict[int | str, Callable[[], float]] = {}

    # names are stored without the angle brackets, upper case (the line is upper-cased)
    def get(self, key: int | str) -> float:
        """Value of ``#n`` or ``#<name>``; KeyError for an undefined named parameter."""
        if isinstance(key, int):
            if key in self.system:
                return float(self.system[key]())
            return self.numbered.get(key, 0.0)
        name = key.strip("<>")
        if name in self.system:
            return float(self.system[name]())
        if name.startswith("_"):
            return self.globals[name]
        return self.frames[-1][name]

    def exists(self, key: str) -> bool:
        """Whether a named parameter is defined (EXISTS[#<name>])."""
        name = key.strip("<>")
        if name in self.system:
            return True
        return name in (self.globals if name.startswith("_") else self.frames[-1])

    def set(self, key: int | str, value: float) -> None:
        """Assign ``#n`` or ``#<name>``."""
        if isinstance(key, int):
            self.numbered[key] = value
            return
        name = key.strip("<>")
        if name.startswith("_"):
            self.globals[name] = value
        else:
            self.frames[-1][name] = value

    def push(self, args: tuple[float, ...]) -> None:
        """Enter a subroutine: #1-#30 saved and set from ``args`` (the rest 0), new locals."""
        self.saved.append({k: self.numbered[k] for k in range(1, 31) if k in self.numbered})
        for k in range(1, 31):
            self.numbered.pop(k, None)
        for k, v in enumerate(args[:30], 1):
            self.numbered[k] = v
        self.frames.append({})

    def pop(self) -> None:
        """Leave a subroutine: #1-#30 and the caller's locals come back."""
        for k in range(1, 31):
            self.numbered.pop(k, None)
        self.numbered.update(self.saved.pop())
        self.frames.pop()

    def snapshot(self) -> tuple:
        return (dict(self.numbered), dict(self.globals), [dict(f) for f in self.frames],
                [dict(s) for s in self.saved])

    def restore(self, snap: tuple) -> None:
        n, g, f, s = snap
        self.numbered, self.globals = dict(n), dict(g)
        self.frames, self.saved = [dict(x) for x in f], [dict(x) for x in s]


def _checked(v: float, pos: int, word: str) -> float:
    if not math.isfinite(v) or abs(v) > MAX_MAGNITUDE:
        raise NgcError(pos, word, f"value {v:.6g} is out of range (|value| <= {MAX_MAGNITUDE:.0e})")
    return v


#: a compiled value: called with the parameters, gives the number
Value = Callable[["Parameters"], float]


def _const(v: float) -> Value:
    return lambda P: v


# Opcodes of a compiled value: a postfix program run on a stack by _run (no recursion, so a
# value nested 10,000 brackets deep or a sum of 10,000 terms compiles and runs like any other).
_CONST = 0  # (op, value)
_PARAM = 1  # (op, number): #n with a literal n, checked at compile time
_PARAM_EXPR = 2  # (op, pos, word): #<value on the stack>
_NAMED = 3  # (op, name, pos, word): #<name>
_NEG = 4  # (op,)
_BINARY = 5  # (op, operator, pos, word)
_FUNCTION = 6  # (op, name, pos, word)
_ATAN = 7  # (op,): ATAN[y]/[x] of the two values on the stack
_EXISTS_NAMED = 8  # (op, name)
_EXISTS_NUM = 9  # (op,): whether the value on the stack is a valid parameter number


class _Group:
    """An open ``[`` while compiling: a plain expression, a function's argument, EXISTS."""

    __slots__ = ("kind", "pos", "fpos", "_word", "_c")

    def __init__(self, kind: str, pos: int, fpos: int, c: str):
        self.kind = kind  # "[" (plain), a function name, "ATAN2" (its second argument), "EXISTS"
        self.pos = pos  # index of the "["
        self.fpos = fpos  # index of the function name (pos for a plain group)
        self._word: str | None = None
        self._c = c

    @property
    def word(self) -> str:
        """The group's text (at most 40 characters), named by messages of its operators."""
        if self._word is None:
            self._word = _snippet(self._c, self.pos)
        return self._word


class _Prefix(NamedTuple):
    """A prefix waiting for its value: ``-`` or ``+``, ``#`` (parameter), or EXISTS's ``#``."""

    kind: str  # "-", "+", "#", "E"
    pos: int


class _Operator(NamedTuple):
    """A binary operator waiting for its right operand."""

    op: str
    prec: int
    group: _Group


def _snippet(c: str, i: int, j: int | None = None) -> str:
    """The text of ``c`` from ``i``: to ``j``, or a whole ``[...]`` group, at most 40 characters."""
    limit = i + 40
    if i < len(c) and c[i] == "[":
        depth = 0
        for k in range(i, min(len(c), limit)):
            depth += (c[k] == "[") - (c[k] == "]")
            if depth == 0:
                j = max(j or 0, k + 1)
                break
        else:
            j = limit
    return c[i:min(j if j is not None else i + 20, limit)] or "end of line"


class _Compiler:
    """LinuxCNC's read_real_value / read_real_expression over one compact line, compiled once.

    Each value becomes a postfix program over the parameters (run by :func:`_run`), so a line
    inside a loop is read once and evaluated on every pass. Reading and running use explicit
    stacks, never recursion: any nesting depth and any number of terms is taken. Syntax
    errors raise at compile time, arithmetic errors (division by zero, an undefined parameter)
    when the value is evaluated; both carry the index into the compact line.
    """

    def __init__(self, c: str):
        self.c = c

    def _snippet(self, i: int, j: int | None = None) -> str:
        return _snippet(self.c, i, j)

    def _name(self, i: int) -> tuple[str, int]:
        """``#<name>`` at ``c[i] == '#'``: ``"<NAME>"`` and the index after the ``>``."""
        m = _NAME.match(self.c, i + 1)
        if not m:
            raise NgcError(i, self._snippet(i), "named parameter without a closing '>'")
        if not m.group(1):
            raise NgcError(i, self._snippet(i), "empty parameter name")
        return "<" + m.group(1) + ">", m.end()

    def value(self, i: int) -> tuple[Value, int]:
        """The value at ``c[i]``: a number, ``#parameter``, ``[expression]``, a function or a
        signed value; returns it compiled and the index after it.

        Operators follow LinuxCNC's precedence (``**`` 6; ``* / MOD`` 5; ``+ -`` 4;
        comparisons 3; ``AND OR XOR`` 2), left to right within a level; a sign or a ``#``
        applies to the value right after it.
        """
        c = self.c
        n = len(c)
        code: list[tuple] = []
        stack: list[Any] = []  # _Group, _Prefix and _Operator entries, innermost last
        groups: list[_Group] = []
        while True:
            # -- a value starts at i ---------------------------------------------------------
            if i >= n:
                raise NgcError(max(i - 1, 0), self._snippet(max(i - 1, 0)), "a value is missing")
            ch = c[i]
            nxt = c[i + 1] if i + 1 < n else ""
            if ch == "[":
                g = _Group("[", i, i, c)
                stack.append(g)
                groups.append(g)
                i += 1
                continue
            if ch == "#":
                if nxt == "<":
                    name, j = self._name(i)
                    code.append((_NAMED, name, i, self._snippet(i, j)))
                    i = j
                else:
                    stack.append(_Prefix("#", i))
                    i += 1
                    continue
            elif ch in "+-" and nxt and not (nxt.isdigit() or nxt == "."):
                stack.append(_Prefix(ch, i))
                i += 1
                continue
            elif ch.isalpha():
                name = next((u for u in _UNARY if c.startswith(u, i)), None)
                if name is None:
                    m = re.match(r"[A-Z]+", c[i:i + 40])
                    word = m.group() if m else ch
                    raise NgcError(i, word, f"unknown function or word {word!r} in a value")
                j = i + len(name)
                if j >= n or c[j] != "[":
                    raise NgcError(i, name, f"{name} needs its argument in [brackets]")
                if name != "EXISTS":
                    g = _Group(name, j, i, c)
                    stack.append(g)
                    groups.append(g)
                    i = j + 1
                    continue
                k = j + 1
                if not (k < n and c[k] == "#"):
                    raise NgcError(i, name, "EXISTS needs a parameter: EXISTS[#<name>] or EXISTS[#n]")
                if k + 1 < n and c[k + 1] == "<":
                    key, k2 = self._name(k)
                    if not (k2 < n and c[k2] == "]"):
                        raise NgcError(i, name, "EXISTS needs a parameter: EXISTS[#<name>] or "
                                                "EXISTS[#n]")
                    code.append((_EXISTS_NAMED, key))
                    i = k2 + 1
                else:  # a numbered parameter exists when its number is in range (LinuxCNC)
                    g = _Group("EXISTS", j, i, c)
                    stack.append(g)
                    groups.append(g)
                    stack.append(_Prefix("E", k))
                    i = k + 1
                    continue
            else:
                m = _NUMBER.match(c, i)
                if not m:
                    raise NgcError(i, self._snippet(i), f"a number, #parameter or [expression] "
                                                        f"was expected, got {ch!r}")
                code.append((_CONST, _checked(float(m.group()), i, m.group()[:40])))
                i = m.end()
            # -- a value ends at i: apply its prefixes, then an operator or a "]" ------------
            while True:
                while stack and type(stack[-1]) is _Prefix:
                    self._prefix(stack.pop(), code, i)
                if not stack:
                    return _finish(code), i
                g = groups[-1]
                if g.kind == "EXISTS":
                    if not (i < n and c[i] == "]"):
                        raise NgcError(g.fpos, "EXISTS", "EXISTS needs a parameter: "
                                                         "EXISTS[#<name>] or EXISTS[#n]")
                    stack.pop()
                    groups.pop()
                    i += 1
                    continue
                m = _OPERATOR_RE.match(c, i)
                if m is not None:
                    op = m.group()
                    prec = _PRECEDENCE[op]
                    while type(stack[-1]) is _Operator and stack[-1].prec >= prec:
                        top = stack.pop()
                        code.append((_BINARY, top.op, g.pos, g.word))
                    stack.append(_Operator(op, prec, g))
                    i = m.end()
                    break  # its right operand starts at i
                if not (i < n and c[i] == "]"):
                    what = repr(c[i]) if i < n else "end of line"
                    raise NgcError(g.pos, self._snippet(g.pos, i + 1), f"expression: ']' or an "
                                                                       f"operator was expected, "
                                                                       f"got {what}")
                while type(stack[-1]) is _Operator:
                    top = stack.pop()
                    code.append((_BINARY, top.op, g.pos, g.word))
                stack.pop()
                groups.pop()
                i += 1
                if g.kind == "ATAN":
                    word = c[g.fpos:i][:40]
                    if i >= n or c[i] != "/":
                        raise NgcError(g.fpos, word, "ATAN needs two arguments: ATAN[y]/[x]")
                    if i + 1 >= n or c[i + 1] != "[":
                        raise NgcError(i, word, "ATAN's second argument must be in [brackets]")
                    g2 = _Group("ATAN2", i + 1, g.fpos, c)
                    stack.append(g2)
                    groups.append(g2)
                    i += 2
                    break  # its second argument starts at i
                if g.kind == "ATAN2":
                    code.append((_ATAN,))
                elif g.kind != "[":
                    code.append((_FUNCTION, g.kind, g.fpos, c[g.fpos:i][:40]))

    def _prefix(self, p: _Prefix, code: list[tuple], j: int) -> None:
        """Apply a prefix to the value just compiled (it ends at ``j``)."""
        if p.kind == "-":
            code.append((_NEG,))
        elif p.kind == "E":
            code.append((_EXISTS_NUM,))
        elif p.kind == "#":
            word = self._snippet(p.pos, j)
            if self.c[p.pos + 1].isdigit():  # a literal number (the last constant): check it once
                code[-1] = (_PARAM, _parameter_number(code[-1][1], p.pos, word))
            else:
                code.append((_PARAM_EXPR, p.pos, word))

    def parameter(self, i: int) -> tuple[str | Callable[["Parameters"], int], int]:
        """``#n``, ``#<name>``, ``##n`` or ``#[expr]`` at ``c[i] == '#'``: the name, or a
        function of the parameters that gives the (checked) number."""
        c = self.c
        if i + 1 < len(c) and c[i + 1] == "<":
            return self._name(i)
        number, j = self.value(i + 1)
        word = self._snippet(i, j)

        if c[i + 1].isdigit():  # a literal number: check it now, once
            n = _parameter_number(number(Parameters()), i, word)
            return (lambda P: n), j
        return (lambda P: _parameter_number(number(P), i, word)), j

    def expression(self, i: int) -> tuple[Value, int]:
        """``[ ... ]`` at ``c[i] == '['``: the value and the index after the closing bracket."""
        return self.value(i)


def _parameter_number(v: float, pos: int, word: str) -> int:
    """The parameter number ``v`` names, checked: an integer in 1..MAX_PARAMETER."""
    n = round(v)
    if abs(v - n) > 1e-4:
        raise NgcError(pos, word, f"parameter number {v:.6g} is not an integer")
    if not 1 <= n <= MAX_PARAMETER:
        raise NgcError(pos, word, f"parameter number {n} is out of range (1..{MAX_PARAMETER})")
    return int(n)


def _run(code: tuple[tuple, ...], P: "Parameters") -> float:
    """Run a compiled value (postfix, on a stack) with the parameters ``P``."""
    s: list[float] = []
    push = s.append
    for ins in code:
        k = ins[0]
        if k == _CONST:
            push(ins[1])
        elif k == _BINARY:
            b = s.pop()
            v = _apply(ins[1], s[-1], b, ins[2], ins[3])
            if not abs(v) <= MAX_MAGNITUDE:
                _checked(v, ins[2], ins[3])
            s[-1] = v
        elif k == _PARAM:
            push(P.get(ins[1]))
        elif k == _NAMED:
            try:
                push(P.get(ins[1]))
            except KeyError:
                raise NgcError(ins[2], ins[3], f"named parameter #{ins[1]} is not "
                                               f"defined") from None
        elif k == _NEG:
            s[-1] = -s[-1]
        elif k == _FUNCTION:
            s[-1] = _checked(_function(ins[1], s[-1], ins[2], ins[3]), ins[2], ins[3])
        elif k == _PARAM_EXPR:
            s[-1] = P.get(_parameter_number(s[-1], ins[1], ins[2]))
        elif k == _ATAN:
            b = s.pop()
            s[-1] = math.degrees(math.atan2(s[-1], b))
        elif k == _EXISTS_NAMED:
            push(1.0 if P.exists(ins[1]) else 0.0)
        else:  # _EXISTS_NUM
            v = s[-1]
            n = round(v)
            s[-1] = 1.0 if abs(v - n) <= 1e-4 and 1 <= n <= MAX_PARAMETER else 0.0
    return s[-1]


_READS_PARAMETERS = frozenset((_PARAM, _PARAM_EXPR, _NAMED, _EXISTS_NAMED))


def _finish(code: list[tuple]) -> Value:
    """The compiled value as a function of the parameters (a constant folded once)."""
    if len(code) == 1:
        ins = code[0]
        if ins[0] == _CONST:
            return _const(ins[1])
        if ins[0] == _PARAM:
            n = ins[1]
            return lambda P: P.get(n)
    prog = tuple(code)
    if not any(ins[0] in _READS_PARAMETERS for ins in prog):
        try:  # no parameters: the value is known now (an error waits for the line to run)
            return _const(_run(prog, Parameters()))
        except NgcError:
            pass
    return lambda P: _run(prog, P)


def _function(name: str, a: float, pos: int, word: str) -> float:
    """LinuxCNC's execute_unary, angles in degrees."""
    if name in ("ASIN", "ACOS") and not -1.0 <= a <= 1.0:
        raise NgcError(pos, word, f"argument to {name} must be between -1 and 1, got {a:.6g}")
    if name == "SQRT" and a < 0:
        raise NgcError(pos, word, f"argument to SQRT must not be negative, got {a:.6g}")
    if name == "LN" and a <= 0:
        raise NgcError(pos, word, f"argument to LN must be positive, got {a:.6g}")
    if name == "ABS":
        return abs(a)
    if name == "ACOS":
        return math.degrees(math.acos(a))
    if name == "ASIN":
        return math.degrees(math.asin(a))
    if name == "COS":
        return math.cos(math.radians(a))
    if name == "SIN":
        return math.sin(math.radians(a))
    if name == "TAN":
        return math.tan(math.radians(a))
    if name == "EXP":
        return math.exp(a) if a < 709 else math.inf
    if name == "FIX":
        return float(math.floor(a))
    if name == "FUP":
        return float(math.ceil(a))
    if name == "LN":
        return math.log(a)
    if name == "ROUND":
        return float(math.trunc(a + (-0.5 if a < 0 else 0.5)))
    return math.sqrt(a)  # SQRT


def _apply(op: str, a: float, b: float, pos: int, word: str) -> float:
    """LinuxCNC's execute_binary1/2."""
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op == "/":
        if b == 0.0:
            raise NgcError(pos, word, "division by zero")
        return a / b
    if op == "MOD":
        if b == 0.0:
            raise NgcError(pos, word, "MOD by zero")
        r = math.fmod(a, b)
        return r + abs(b) if r < 0 else r
    if op == "**":
        if a < 0 and math.floor(b) != b:
            raise NgcError(pos, word, "a negative number raised to a non-integer power")
        if a == 0 and b < 0:
            raise NgcError(pos, word, "zero raised to a negative power")
        try:
            return math.pow(a, b)
        except OverflowError:
            return math.inf
    if op == "EQ":
        return 1.0 if abs(a - b) < TOLERANCE_EQUAL else 0.0
    if op == "NE":
        return 1.0 if abs(a - b) >= TOLERANCE_EQUAL else 0.0
    if op == "LT":
        return 1.0 if a < b else 0.0
    if op == "LE":
        return 1.0 if abs(a - b) < TOLERANCE_EQUAL or a <= b else 0.0
    if op == "GT":
        return 1.0 if a > b else 0.0
    if op == "GE":
        return 1.0 if abs(a - b) < TOLERANCE_EQUAL or a >= b else 0.0
    if op == "AND":
        return 0.0 if a == 0.0 or b == 0.0 else 1.0
    if op == "OR":
        return 1.0 if a != 0.0 or b != 0.0 else 0.0
    return 1.0 if (a == 0.0) != (b == 0.0) else 0.0  # XOR


def evaluate(expr: str, params: Parameters | None = None) -> float:
    """Value of one LinuxCNC expression, e.g. ``"[1 + 2 * 3]"`` or ``"SIN[30]"``.

    Examples
    --------
    >>> evaluate("[1 + 2 * 3 ** 2]"), evaluate("[-7 MOD 3]"), round(evaluate("ATAN[1]/[1]"), 9)
    (19.0, 2.0, 45.0)
    >>> evaluate("[1 LT 2 AND 3 EQ 3.00001]")
    1.0
    """
    c, _ = compact(expr.upper())
    v, j = _Compiler(c).value(0)
    if j != len(c):
        raise NgcError(j, c[j:j + 20], "unexpected text after the value")
    return v(params or Parameters())


class _CompiledLine(NamedTuple):
    words: tuple[tuple[str, Value, int], ...]  # letter, value, source column
    assigns: tuple[tuple[Any, Value, int, str], ...]  # key (name or number function), value, pos, text
    # label (text, or a Value for O[expr]), keyword, arguments, column
    oword: tuple[Any, str, tuple[Value, ...], int] | None
    cols: tuple[int, ...]


@lru_cache(maxsize=4096)  # lines inside loops and subroutines are read again and again
def _compile_line(s: str) -> _CompiledLine:
    c, cols = compact(s)
    cp = _Compiler(c)
    words: list[tuple[str, Value, int]] = []
    assigns: list[tuple[Any, Value, int, str]] = []
    i, n = 0, len(c)
    first = True
    while i < n:
        ch = c[i]
        if ch == "#":
            key, j = cp.parameter(i)
            if j >= n or c[j] != "=":
                raise NgcError(i, c[i:j], "a parameter outside a word must be set: '=' is missing")
            v, k = cp.value(j + 1)
            assigns.append((key, v, i, c[i:j]))
            i = k
            first = False
            continue
        if ch == "O":
            if not first:
                raise NgcError(i, c[i:i + 20], "an O-word must start the line")
            return _CompiledLine((), (), _compile_oword(cp, i, cols), cols)
        if not ch.isalpha():
            raise NgcError(i, ch, f"unexpected character {ch!r}")
        v, j = cp.value(i + 1)
        if ch != "N":
            words.append((ch, v, cols[i]))
        i = j
        first = False
    return _CompiledLine(tuple(words), tuple(assigns), None, cols)


def scan_line(s: str, params: Parameters) -> Line:
    """Words, parameter assignments and O-word statement of one upper-cased, comment-free line.

    Values are read with the parameters as they stand *before* the line: LinuxCNC sets all the
    line's parameters after reading it. Raises :class:`NgcError` whose ``pos`` is the column
    in ``s`` (1-based). The line's syntax is compiled once and cached; only its values are
    evaluated on each call.
    """
    cols: tuple[int, ...] = ()
    try:
        cl = _compile_line(s)
        cols = cl.cols
        out = Line()
        if cl.oword is not None:
            label, keyword, args, col = cl.oword
            if not isinstance(label, str):
                v = label(params)
                if abs(v - round(v)) > 1e-4 or v < 0:
                    raise NgcError(0, _head(s), f"O-word number {v:.6g} is not a non-negative "
                                                 f"integer")
                label = str(int(round(v)))
            out.oword = OWord(label, keyword, tuple(a(params) for a in args), col)
            return out
        out.words = [Word(letter, v(params), col) for letter, v, col in cl.words]
        for key, v, pos, text in cl.assigns:
            if isinstance(key, str):
                if key.strip("<>") in params.system:
                    raise NgcError(pos, text, f"#{key} is read-only")
                out.assigns.append((key, v(params)))
            else:
                out.assigns.append((key(params), v(params)))
        return out
    except NgcError as e:
        if not cols:
            cols = compact(s)[1]
        e.pos = cols[min(e.pos, len(cols) - 1)] if cols else 1  # a source column from here on
        raise


def _head(s: str) -> str:
    """The first characters of a line's compact text (the word named in a message)."""
    return compact(s)[0][:20]


def _compile_oword(cp: _Compiler, i: int, cols: tuple[int, ...]) -> tuple:
    c = cp.c
    j = i + 1
    label: str | Value
    if j < len(c) and c[j] == "<":
        m = _NAME.match(c, j)
        if not m or not m.group(1):
            raise NgcError(i, c[i:i + 20], "O-word name without a closing '>'")
        label, j = "<" + m.group(1) + ">", m.end()
    elif j < len(c) and c[j] == "[":  # O[expression]: a number computed when the line runs
        label, j = cp.expression(j)
    else:
        m = re.compile(r"\d+").match(c, j)
        if not m:
            raise NgcError(i, c[i:i + 20], "O-word without a number or <name>")
        label, j = str(int(m.group())), m.end()
    keyword = next((k for k in _KEYWORDS if c.startswith(k, j)), "")
    j += len(keyword)
    args: list[Value] = []
    while j < len(c):
        if c[j] != "[":
            raise NgcError(j, c[j:j + 20], f"unexpected text after O{label} {keyword}".rstrip())
        v, j = cp.expression(j)
        args.append(v)
    return label, keyword, tuple(args), cols[i]


# --------------------------------------------------------------------- program structure ---
@dataclass
class Structure:
    """O-word pairing of one file, by line index (0-based).

    ``subs`` maps a label to the index of its ``sub`` line (``<name>`` or a number; Fanuc-style
    ``O1`` program headers too, under ``"P1"``); ``end`` maps the index of a ``sub``, ``while``,
    ``do``, ``repeat`` or ``if``/``elseif``/``else`` to the index of its closing statement
    (``endsub``, ``endwhile``, the ``while`` of a do-loop, ``endrepeat``, the next branch or
    ``endif``); ``start`` maps a closing loop statement back to its opening one; ``endif``
    maps every branch of an if to its ``endif``; ``loop`` maps ``break``/``continue`` to the
    opening statement of their loop.
    """

    subs: dict[str, int] = field(default_factory=dict)
    end: dict[int, int] = field(default_factory=dict)
    start: dict[int, int] = field(default_factory=dict)
    endif: dict[int, int] = field(default_factory=dict)
    loop: dict[int, int] = field(default_factory=dict)
    fanuc: set[int] = field(default_factory=set)


def program_structure(owords: dict[int, OWord], m99_lines: list[int]) -> Structure:
    """Pair the O-word statements of a file; raise NgcError(line index, ...) if unbalanced.

    Parameters
    ----------
    owords : dict of int to OWord
        The O-word statement of each line index that has one (arguments not needed).
    m99_lines : list of int
        Line indices that hold an M99 (the end of a Fanuc-style ``O<n>`` subprogram).
    """
    st = Structure()
    stack: list[tuple[int, OWord]] = []  # open sub/while/do/repeat/if statements
    branches: dict[int, list[int]] = {}  # if index -> its branch indices
    m99 = sorted(m99_lines)

    def fail(idx: int, ow: OWord, problem: str) -> NgcError:
        return NgcError(idx, f"O{ow.label}", problem)

    def close(idx: int, ow: OWord, opening: tuple[str, ...]) -> int:
        for k in range(len(stack) - 1, -1, -1):
            if stack[k][1].label == ow.label and stack[k][1].keyword in opening:
                if k != len(stack) - 1:
                    inner_idx, inner = stack[-1]
                    raise fail(inner_idx, inner, f"O{inner.label} {inner.keyword.lower()} is not "
                                                 f"closed before O{ow.label} {ow.keyword.lower()}")
                return stack.pop()[0]
        raise fail(idx, ow, f"O{ow.label} {ow.keyword.lower()} has no matching "
                            f"{' or '.join(o.lower() for o in opening)}")

    for idx in sorted(owords):
        ow = owords[idx]
        kw = ow.keyword
        if kw == "":
            # Fanuc-style program number: a subprogram that runs to the next M99
            st.subs.setdefault("P" + ow.label, idx)
            st.fanuc.add(idx)
            nxt = next((m for m in m99 if m > idx), None)
            if nxt is None:
                raise fail(idx, ow, f"subprogram O{ow.label} has no M99")
            st.end[idx] = nxt
        elif kw == "SUB":
            outer = next((o for _, o in stack if o.keyword == "SUB"), None)
            if outer is not None:  # LinuxCNC: NCE_NESTED_SUBROUTINE_DEFN
                raise fail(idx, ow, f"subroutine O{ow.label} is defined inside subroutine "
                                    f"O{outer.label} (nested definitions are not allowed)")
            if ow.label in st.subs and not st.subs[ow.label] in st.fanuc:
                raise fail(idx, ow, f"subroutine O{ow.label} is defined twice")
            st.subs[ow.label] = idx
            stack.append((idx, ow))
        elif kw in ("WHILE",):
            # the while of a do-loop closes it; otherwise it opens a while-loop
            if any(o.label == ow.label and o.keyword == "DO" for _, o in stack):
                s = close(idx, ow, ("DO",))
                st.end[s], st.start[idx] = idx, s
            else:
                stack.append((idx, ow))
        elif kw in ("DO", "REPEAT", "IF"):
            stack.append((idx, ow))
            if kw == "IF":
                branches[idx] = [idx]
        elif kw in ("ELSEIF", "ELSE"):
            if not stack or stack[-1][1].label != ow.label or stack[-1][1].keyword != "IF":
                raise fail(idx, ow, f"O{ow.label} {kw.lower()} has no matching if")
            br = branches[stack[-1][0]]
            if owords[br[-1]].keyword == "ELSE":
                raise fail(idx, ow, f"O{ow.label} {kw.lower()} after else")
            br.append(idx)
        elif kw in ("ENDSUB", "ENDWHILE", "ENDREPEAT", "ENDIF"):
            opening = {"ENDSUB": ("SUB",), "ENDWHILE": ("WHILE",), "ENDREPEAT": ("REPEAT",),
                       "ENDIF": ("IF",)}[kw]
            s = close(idx, ow, opening)
            st.end[s], st.start[idx] = idx, s
            if kw == "ENDIF":
                br = branches.pop(s) + [idx]
                for a, b in zip(br[:-1], br[1:]):
                    st.end[a] = b
                    st.endif[a] = idx
        elif kw in ("BREAK", "CONTINUE"):
            loop = next((k for k, o in reversed(stack)
                         if o.label == ow.label and o.keyword in ("WHILE", "DO", "REPEAT")), None)
            if loop is None:
                raise fail(idx, ow, f"O{ow.label} {kw.lower()} is not inside loop O{ow.label}")
            st.loop[idx] = loop
        elif kw == "RETURN":
            sub = next((k for k, o in reversed(stack) if o.keyword == "SUB"), None)
            if sub is None:
                raise fail(idx, ow, f"O{ow.label} return outside a subroutine")
            st.loop[idx] = sub
        # CALL needs no pairing
    if stack:
        idx, ow = stack[-1]
        raise fail(idx, ow, f"O{ow.label} {ow.keyword.lower()} is never closed")
    return st
