"""A reader for 3-axis milling programs (RS274/NGC as CAM systems and people write them).

:func:`parse` turns a program into a :class:`Program`: one row per elementary motion (rapid,
feed, clockwise or counter-clockwise arc) in a numpy structured array, in millimetres whatever
the program's units, with the active work offset (G54-G59.3, G10 L2) applied. Canned drilling
cycles (G81, G82, G83 with G98/G99, L repeats, G91 incremental semantics) are expanded into
the rapids and feeds LinuxCNC's interpreter would command. Positions are tool-tip positions:
G43 H is recorded but does not move the tip.

Anything the reader does not support (cutter compensation, O-word subroutines, ``#``
parameters, expressions, unknown G or M codes, extra axes) raises
:class:`zmap.errors.GCodeError` naming ``file:line:column`` and the word; with
``lenient=True`` such blocks are skipped and counted in :attr:`Program.warnings`. See
``docs/gcode.md`` for the full list.

Examples
--------
>>> from zmap.sim.gcode import parse
>>> prog = parse("G21 G90\\nG0 X0 Y0 Z5\\nG1 Z-1 F100\\nG2 X10 I5\\n")
>>> prog.moves["kind"].tolist()
[0, 1, 2]
>>> prog.moves["end"][-1].tolist()
[10.0, 0.0, -1.0]
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, NamedTuple

import numpy as np

from ..errors import GCodeError

__all__ = [
    "parse",
    "Program",
    "ToolChange",
    "MOVE_DTYPE",
    "RAPID",
    "LINEAR",
    "ARC_CW",
    "ARC_CCW",
    "MM_PER_INCH",
    "arc_sweep",
    "plane_axes",
]

RAPID, LINEAR, ARC_CW, ARC_CCW = 0, 1, 2, 3
MM_PER_INCH = 25.4

#: One row per motion. ``sweep`` (added to the contract) is the signed angle of an arc in
#: radians about the plane normal (positive counter-clockwise, full turns included), NaN for
#: lines.
MOVE_DTYPE = np.dtype(
    [
        ("kind", np.int8),
        ("start", np.float64, (3,)),
        ("end", np.float64, (3,)),
        ("center", np.float64, (3,)),
        ("plane", np.int8),
        ("turns", np.int32),
        ("feed", np.float64),
        ("tool", np.int32),
        ("line", np.int32),
        ("sweep", np.float64),
    ]
)

# (first, second, normal) axis indices of each plane, right-handed as LinuxCNC: G18 is (Z, X).
_PLANE_AXES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
_IJK = "IJK"
_XYZ = "XYZ"

# Arc end-point tolerance (LinuxCNC): absolute 0.002 in or 0.05 mm, or relative 0.1 %.
_ARC_ABS_TOL_MM = {"inch": 0.002 * MM_PER_INCH, "mm": 0.05}
_ARC_REL_TOL = 0.001
_G83_RAPID_DELTA_MM = 0.010 * MM_PER_INCH  # LinuxCNC G83_RAPID_DELTA, 0.010 in

_TOKEN = re.compile(r"([A-Z])[ \t]*([-+]?(?:\d+\.?\d*|\.\d+))|(\S)")
_COMMENT = re.compile(r"\([^)]*\)|;.*")
_LINE_END = re.compile(r"\r*\n|\r")
_JUNK_WORD = re.compile(r"#<[^>]*>|#\d*|O<[^>]*>\w*|\S[^\s()]*")

# G codes (x10) and their modal groups.
_G_GROUP = {
    0: 1, 10: 1, 20: 1, 30: 1, 800: 1, 810: 1, 820: 1, 830: 1,
    170: 2, 180: 2, 190: 2,
    900: 3, 910: 3,
    901: 4, 911: 4,
    940: 5,
    200: 6, 210: 6,
    400: 7,
    430: 8, 490: 8,
    980: 10, 990: 10,
    540: 12, 550: 12, 560: 12, 570: 12, 580: 12, 590: 12, 591: 12, 592: 12, 593: 12,
    610: 13, 611: 13, 640: 13,
    40: 0, 100: 0, 530: 0,
}
_G_UNSUPPORTED = {
    410: "cutter radius compensation (G41) is not supported",
    420: "cutter radius compensation (G42) is not supported",
    411: "dynamic cutter compensation (G41.1) is not supported",
    421: "dynamic cutter compensation (G42.1) is not supported",
    431: "dynamic tool length offset (G43.1) is not supported",
    432: "additional tool length offset (G43.2) is not supported",
    330: "spindle-synchronised motion (G33) is not supported",
    331: "rigid tapping (G33.1) is not supported",
    930: "inverse-time feed (G93) is not supported",
    950: "feed per revolution (G95) is not supported",
    920: "G92 offsets are not supported",
    280: "G28 return to home is not supported",
    300: "G30 return to home is not supported",
    50: "splines (G5) are not supported",
    51: "splines (G5.1) are not supported",
    52: "NURBS (G5.2) are not supported",
    70: "lathe diameter mode (G7) is not supported",
    80: "lathe radius mode (G8) is not supported",
    730: "chip-break drilling (G73) is not supported",
    740: "left-hand tapping (G74) is not supported",
    760: "threading cycle (G76) is not supported",
    840: "tapping cycle (G84) is not supported",
    850: "boring cycle (G85) is not supported",
    860: "boring cycle (G86) is not supported",
    870: "back boring cycle (G87) is not supported",
    880: "boring cycle (G88) is not supported",
    890: "boring cycle (G89) is not supported",
    381: "probing (G38.x) is not supported",
    382: "probing (G38.x) is not supported",
    383: "probing (G38.x) is not supported",
    384: "probing (G38.x) is not supported",
    385: "probing (G38.x) is not supported",
}
_M_GROUP = {0: 4, 1: 4, 2: 4, 30: 4, 3: 7, 4: 7, 5: 7, 6: 6, 7: 8, 8: 8, 9: 8}
_M_UNSUPPORTED = {
    98: "subprogram calls (M98) are not supported",
    99: "subprogram returns (M99) are not supported",
}
_AXES_EXTRA = "ABCUVW"
_WORD_LETTERS = set("FSTHPQRLIJKXYZD")


def plane_axes(plane: int) -> tuple[int, int, int]:
    """Axis indices ``(first, second, normal)`` of an arc plane (17, 18 or 19).

    The frame is right-handed as in LinuxCNC: G17 is (X, Y, Z), G18 is (Z, X, Y) and G19 is
    (Y, Z, X); counter-clockwise (G3) is positive about the normal.

    Examples
    --------
    >>> plane_axes(18)
    (2, 0, 1)
    """
    try:
        return _PLANE_AXES[int(plane)]
    except KeyError:
        raise ValueError(f"plane={plane!r} is not one of 17, 18, 19") from None


def arc_sweep(a0: float, b0: float, a1: float, b1: float, ca: float, cb: float,
              ccw: bool, turns: int = 0) -> float:
    """Signed swept angle of an arc (radians, positive counter-clockwise), as LinuxCNC.

    Parameters
    ----------
    a0, b0, a1, b1 : float
        Start and end in plane coordinates (mm).
    ca, cb : float
        Centre in plane coordinates (mm).
    ccw : bool
        True for G3, False for G2.
    turns : int
        Extra full turns (P word minus one).

    Returns
    -------
    float
        In ``(0, 2*pi*(turns+1)]`` for G3, in ``[-2*pi*(turns+1), 0)`` for G2; an arc whose
        end angle equals its start angle is a full circle.

    Examples
    --------
    >>> round(arc_sweep(1, 0, 0, 1, 0, 0, True), 6)
    1.570796
    >>> round(arc_sweep(1, 0, 1, 0, 0, 0, False), 6)
    -6.283185
    """
    alpha = math.atan2(b0 - cb, a0 - ca)
    beta = math.atan2(b1 - cb, a1 - ca)
    if ccw:
        if beta <= alpha:
            beta += 2.0 * math.pi
        return (beta - alpha) + turns * 2.0 * math.pi
    if alpha <= beta:
        alpha += 2.0 * math.pi
    return (beta - alpha) - turns * 2.0 * math.pi


class ToolChange(NamedTuple):
    """A tool change (M6): the first move made with ``tool`` and its source line."""

    move: int
    tool: int
    line: int


@dataclass
class Program:
    """A parsed NC program.

    Attributes
    ----------
    moves : ndarray of MOVE_DTYPE, shape (n_moves,)
        One row per motion, in mm, tool-tip positions after work offsets; ``start`` of a row
        is the ``end`` of the previous one (the first starts at the origin).
    units_input : {"mm", "inch"}
        Length units the program was written in (its first G20/G21; "mm" if none).
    warnings : list of str
        ``file:line:column: word: problem`` for each block skipped under ``lenient=True``.
    tool_changes : list of ToolChange
        Each M6, with the index of the first move made with the new tool.
    n_lines : int
        Lines in the source, counted as an editor shows them.
    filename : str
        The name used in messages.
    tool_table : dict of int to Cutter, or None
        The tool table passed to :func:`parse`.
    """

    moves: np.ndarray
    units_input: str = "mm"
    warnings: list[str] = field(default_factory=list)
    tool_changes: list[ToolChange] = field(default_factory=list)
    n_lines: int = 0
    filename: str = "<string>"
    tool_table: dict[int, Any] | None = None

    @property
    def n_moves(self) -> int:
        """Number of motions."""
        return int(self.moves.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box of the tool-tip path, arcs included exactly.

        Returns
        -------
        lo, hi : ndarray of shape (3,), float64
            Minimum and maximum tip coordinates in mm; NaN when there are no moves.

        Examples
        --------
        >>> lo, hi = parse("G0 X1 Y0\\nG3 X-1 Y0 I-1 J0 F10\\n").bounds()
        >>> hi.tolist(), lo.tolist()
        ([1.0, 1.0, 0.0], [-1.0, 0.0, 0.0])
        """
        m = self.moves
        if m.shape[0] == 0:
            nan = np.full(3, np.nan)
            return nan, nan.copy()
        pts = [m["start"], m["end"]]
        arcs = np.flatnonzero(m["kind"] >= ARC_CW)
        for plane in (17, 18, 19):
            sel = arcs[m["plane"][arcs] == plane]
            if sel.size == 0:
                continue
            a, b, _ = _PLANE_AXES[plane]
            s, c = m["start"][sel], m["center"][sel]
            sweep = m["sweep"][sel]
            r = np.hypot(s[:, a] - c[:, a], s[:, b] - c[:, b])
            a0 = np.arctan2(s[:, b] - c[:, b], s[:, a] - c[:, a])
            lo_ang = np.minimum(a0, a0 + sweep)
            hi_ang = np.maximum(a0, a0 + sweep)
            for q in range(4):
                ang = q * np.pi / 2
                k = np.ceil((lo_ang - ang) / (2 * np.pi))
                hit = ang + 2 * np.pi * k <= hi_ang
                if not hit.any():
                    continue
                p = s[hit].copy()
                p[:, a] = c[hit, a] + r[hit] * np.cos(ang)
                p[:, b] = c[hit, b] + r[hit] * np.sin(ang)
                pts.append(p)
        allp = np.concatenate(pts)
        return allp.min(axis=0), allp.max(axis=0)


def _read_source(source: str | os.PathLike, filename: str | None) -> tuple[str, str]:
    if isinstance(source, os.PathLike) or (
        isinstance(source, str) and "\n" not in source and "\r" not in source
        and len(source) < 4096 and os.path.isfile(source)
    ):
        path = Path(source)
        with open(path, encoding="utf-8", errors="replace", newline="") as fh:
            text = fh.read()
        return text, filename if filename is not None else str(path)
    if not isinstance(source, str):
        raise TypeError(f"source must be a path or G-code text, got {type(source).__name__}")
    return source, filename if filename is not None else "<string>"


class _Interp:
    """Modal state of the interpreter; moves are appended as float rows."""

    def __init__(self, filename: str, tool_table: Mapping[int, Any] | None):
        self.file = filename
        self.tool_table = tool_table
        self.rows: list[tuple] = []
        self.pos = [0.0, 0.0, 0.0]  # machine coordinates, mm
        self.plane = 17
        self.units = "mm"
        self.units_seen: str | None = None
        self.absolute = True
        self.ijk_absolute = False
        self.motion = 800  # G80: no motion mode
        self.retract_r = False  # G98 (old Z) by default, as LinuxCNC
        self.offsets = [[0.0, 0.0, 0.0] for _ in range(9)]
        self.cs = 0
        self.feed = math.nan
        self.selected_tool = 0
        self.tool = 0
        self.tool_changes: list[ToolChange] = []
        self.cycle_r = math.nan
        self.cycle_z = math.nan
        self.cycle_q = math.nan
        self.ended = False

    # -- state snapshot for lenient mode ---------------------------------------------------
    def snapshot(self) -> tuple:
        return (
            len(self.rows), list(self.pos), self.plane, self.units, self.units_seen,
            self.absolute, self.ijk_absolute, self.motion, self.retract_r,
            [list(o) for o in self.offsets], self.cs, self.feed, self.selected_tool,
            self.tool, len(self.tool_changes), self.cycle_r, self.cycle_z, self.cycle_q,
            self.ended,
        )

    def restore(self, s: tuple) -> None:
        (n, self.pos, self.plane, self.units, self.units_seen, self.absolute,
         self.ijk_absolute, self.motion, self.retract_r, self.offsets, self.cs, self.feed,
         self.selected_tool, self.tool, nt, self.cycle_r, self.cycle_z, self.cycle_q,
         self.ended) = s
        del self.rows[n:]
        del self.tool_changes[nt:]


def _err(file: str, line: int, text: str, k: int | None, word: str, problem: str) -> GCodeError:
    """A GCodeError at the k-th token of ``text`` (column 1-based; 1 if unknown)."""
    col = 1
    if k is not None:
        for i, mt in enumerate(_TOKEN.finditer(text)):
            if i == k:
                col = mt.start() + 1
                break
    return GCodeError(file, line, col, word, problem)


def parse(
    source: str | os.PathLike,
    *,
    lenient: bool = False,
    tool_table: Mapping[int, Any] | str | os.PathLike | None = None,
    filename: str | None = None,
    block_delete: bool = True,
) -> Program:
    """Read a 3-axis milling program into moves in millimetres.

    Parameters
    ----------
    source : str or path-like
        A path to a program file, or the program text itself (text is recognised by a line
        break, or by not naming an existing file).
    lenient : bool, keyword-only
        False (default): the first unsupported or invalid block raises
        :class:`~zmap.errors.GCodeError`. True: such blocks are skipped, the machine state is
        left as before the block, and one ``file:line:column: word: problem`` line per skipped
        block is appended to :attr:`Program.warnings`.
    tool_table : mapping of int to Cutter, or path of a TOML tool table, optional
        When given, every tool loaded by M6 must be in it (T0, no tool, always may be).
    filename : str, optional
        Name used in messages (default: the path, or ``"<string>"`` for text).
    block_delete : bool, keyword-only
        True (default): lines starting with ``/`` are skipped, as with the block-delete
        switch on. False: the ``/`` is ignored and the block runs.

    Returns
    -------
    Program
        Moves (``MOVE_DTYPE``), units, warnings, tool changes.

    Raises
    ------
    GCodeError
        Unsupported or invalid input, located by file, line, column and word.

    Examples
    --------
    >>> p = parse("G20 G90 G0 X1 Y2 Z0.5\\nG1 Z0 F10\\n")
    >>> p.units_input, p.moves["end"].tolist()
    ('inch', [[25.4, 50.8, 12.7], [25.4, 50.8, 0.0]])
    >>> p.moves["feed"].tolist()[1]
    254.0
    """
    if not isinstance(lenient, bool):
        raise TypeError(f"lenient must be a bool, got {lenient!r}")
    if not isinstance(block_delete, bool):
        raise TypeError(f"block_delete must be a bool, got {block_delete!r}")
    text, fname = _read_source(source, filename)
    table: dict[int, Any] | None
    if tool_table is None:
        table = None
    elif isinstance(tool_table, (str, os.PathLike)):
        from .tools import load_tool_table

        table = load_tool_table(tool_table)
    else:
        table = dict(tool_table)

    if text.startswith("\ufeff"):
        text = text[1:]
    lines = _LINE_END.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    n_lines = len(lines)

    st = _Interp(fname, table)
    warnings: list[str] = []
    percent_open = False
    seen_block = False
    tok_findall = _TOKEN.findall
    comment_sub = _COMMENT.sub

    for lineno, raw in enumerate(lines, 1):
        if not raw or raw.isspace():
            continue
        s = raw
        if "(" in s or ";" in s or ")" in s:
            s = comment_sub(lambda mt: " " * len(mt.group()), s)
            if "(" in s or ")" in s:
                col = s.find("(") if "(" in s else s.find(")")
                e = GCodeError(fname, lineno, col + 1, s[col], "unbalanced comment parenthesis")
                if lenient:
                    warnings.append(str(e))
                    continue
                raise e
        s = s.upper()
        stripped = s.strip()
        if not stripped:
            continue
        if stripped == "%":
            if not seen_block and not percent_open:
                percent_open = True
                continue
            if percent_open:
                break  # the closing tape mark ends the program
            continue
        seen_block = True
        if stripped[0] == "/":
            if block_delete:
                continue
            s = s.replace("/", " ", 1)
        toks = tok_findall(s)
        if _fast_block(st, toks, lineno):
            continue
        if lenient:
            snap = st.snapshot()
            try:
                _block(st, toks, s, lineno)
            except GCodeError as e:
                st.restore(snap)
                warnings.append(str(e))
        else:
            _block(st, toks, s, lineno)
        if st.ended:
            break

    rows = st.rows
    moves = np.empty(len(rows), dtype=MOVE_DTYPE)
    if rows:
        arr = np.array(rows, dtype=np.float64)
        moves["kind"] = arr[:, 0]
        moves["end"] = arr[:, 1:4]
        moves["start"][0] = 0.0
        moves["start"][1:] = arr[:-1, 1:4]
        moves["center"] = arr[:, 4:7]
        moves["plane"] = arr[:, 7]
        moves["turns"] = arr[:, 8]
        moves["feed"] = arr[:, 9]
        moves["tool"] = arr[:, 10]
        moves["line"] = arr[:, 11]
        moves["sweep"] = arr[:, 12]
    return Program(
        moves=moves,
        units_input=st.units_seen or "mm",
        warnings=warnings,
        tool_changes=st.tool_changes,
        n_lines=n_lines,
        filename=fname,
        tool_table=table,
    )


_FAST_LETTERS = frozenset("XYZFN")


def _fast_block(st: _Interp, toks: list, lineno: int) -> bool:
    """Fast path for the common block: coordinates (and F) under modal G0/G1.

    Returns False, having changed nothing, for anything else (the full interpreter runs).
    """
    motion = st.motion
    vals: dict[str, float] = {}
    for letter, num, junk in toks:
        if junk or letter in vals:
            return False
        if letter == "G":
            v = float(num)
            if v == 0.0:
                motion = 0
            elif v == 1.0:
                motion = 10
            else:
                return False
            vals["G"] = v
        elif letter not in _FAST_LETTERS:
            return False
        elif letter != "N":
            vals[letter] = float(num)
    if motion != 0 and motion != 10:
        return False
    vals.pop("G", None)
    f = MM_PER_INCH if st.units == "inch" else 1.0
    feed = st.feed
    if "F" in vals:
        v = vals.pop("F")
        if v < 0:
            return False
        feed = v * f
    if not vals:
        st.feed = feed
        st.motion = motion
        return True
    if motion == 10 and not feed > 0:
        return False
    pos = st.pos
    if st.absolute:
        off = st.offsets[st.cs]
        x = vals["X"] * f + off[0] if "X" in vals else pos[0]
        y = vals["Y"] * f + off[1] if "Y" in vals else pos[1]
        z = vals["Z"] * f + off[2] if "Z" in vals else pos[2]
    else:
        x = pos[0] + vals["X"] * f if "X" in vals else pos[0]
        y = pos[1] + vals["Y"] * f if "Y" in vals else pos[1]
        z = pos[2] + vals["Z"] * f if "Z" in vals else pos[2]
    nan = math.nan
    if motion == 0:
        st.rows.append((0, x, y, z, nan, nan, nan, st.plane, 0, nan, st.tool, lineno, nan))
    else:
        st.rows.append((1, x, y, z, nan, nan, nan, st.plane, 0, feed, st.tool, lineno, nan))
    st.pos = [x, y, z]
    st.feed = feed
    st.motion = motion
    return True


def _block(st: _Interp, toks: list, s: str, lineno: int) -> None:
    """Interpret one block (tokens of one line) in LinuxCNC's order of execution."""
    file = st.file
    gcodes: list[tuple[int, int]] = []
    mcodes: list[tuple[int, int]] = []
    words: dict[str, float] = {}
    widx: dict[str, int] = {}
    for k, (letter, num, junk) in enumerate(toks):
        if junk:
            _junk_error(st, s, lineno, k, junk)
        if letter == "G":
            v = float(num)
            code = round(v * 10)
            if abs(v * 10 - code) > 1e-6 or code not in _G_GROUP:
                problem = _G_UNSUPPORTED.get(code, f"G{num} is not a supported G code")
                raise _err(file, lineno, s, k, f"G{num}", problem)
            gcodes.append((code, k))
        elif letter == "M":
            v = float(num)
            code = int(v)
            if code != v or code not in _M_GROUP:
                problem = _M_UNSUPPORTED.get(code, f"M{num} is not a supported M code")
                raise _err(file, lineno, s, k, f"M{num}", problem)
            mcodes.append((code, k))
        elif letter == "N":
            continue
        elif letter in _WORD_LETTERS:
            if letter in words:
                raise _err(file, lineno, s, k, f"{letter}{num}",
                           f"{letter} word appears twice in the block")
            words[letter] = float(num)
            widx[letter] = k
        elif letter == "O":
            raise _err(file, lineno, s, k, f"O{num}",
                       "O-word subroutines and control flow are not supported")
        elif letter in _AXES_EXTRA:
            raise _err(file, lineno, s, k, f"{letter}{num}",
                       f"axis {letter} is not supported (3-axis XYZ only)")
        else:
            raise _err(file, lineno, s, k, f"{letter}{num}", f"word {letter} is not supported")

    # Modal groups: at most one code per group (G80 may join a motion code: it runs first).
    groups: dict[int, int] = {}
    gk: dict[int, int] = {}
    cancel_cycle = False
    for code, k in gcodes:
        grp = _G_GROUP[code]
        if code == 800:
            cancel_cycle = True
            if 1 in groups:
                continue
        if grp in groups and not (grp == 1 and groups[grp] == 800):
            raise _err(file, lineno, s, k, _gname(code),
                       f"{_gname(groups[grp])} and {_gname(code)} are in the same modal group")
        groups[grp] = code
        gk[code] = k
    mgroups: dict[int, int] = {}
    for code, k in mcodes:
        grp = _M_GROUP[code]
        if grp in mgroups and {mgroups[grp], code} != {7, 8}:  # mist and flood may combine
            raise _err(file, lineno, s, k, f"M{code}",
                       f"M{mgroups[grp]} and M{code} are in the same modal group")
        mgroups[grp] = code

    def werr(letter: str, problem: str) -> GCodeError:
        v = words[letter]
        return _err(file, lineno, s, widx[letter], f"{letter}{_fmt(v)}", problem)

    def gerr(code: int, problem: str) -> GCodeError:
        return _err(file, lineno, s, gk.get(code), _gname(code), problem)

    used = set()
    # -- units first of all (values of this block are read in the new units) --------------
    units = st.units
    if 6 in groups:
        units = "inch" if groups[6] == 200 else "mm"
    f = MM_PER_INCH if units == "inch" else 1.0

    # 3. feed, 4. spindle speed
    feed = st.feed
    if "F" in words:
        if words["F"] < 0:
            raise werr("F", "feed rate must not be negative")
        feed = words["F"] * f
        used.add("F")
    if "S" in words:
        if words["S"] < 0:
            raise werr("S", "spindle speed must not be negative")
        used.add("S")
    # 5. tool select, 6. tool change
    selected = st.selected_tool
    if "T" in words:
        t = words["T"]
        if t < 0 or t != int(t):
            raise werr("T", "tool number must be a non-negative integer")
        selected = int(t)
        used.add("T")
        if st.tool_table is not None and selected != 0 and selected not in st.tool_table:
            have = ", ".join(str(x) for x in sorted(st.tool_table)) or "none"
            raise werr("T", f"tool {selected} is not in the tool table (tools: {have})")
    tool = st.tool
    tool_changed = False
    if mgroups.get(6) == 6:
        tool = selected
        tool_changed = True
    # 10. dwell
    nonmodal = groups.get(0)
    if nonmodal == 40:
        if "P" not in words:
            raise gerr(40, "G4 dwell needs a P word (seconds)")
        if words["P"] < 0:
            raise werr("P", "dwell time must not be negative")
        used.add("P")
    # 11. plane, 12. units (done), 14. tool length
    plane = groups.get(2, st.plane * 10) // 10
    if groups.get(8) == 430:
        if "H" in words:
            h = words["H"]
            if h < 0 or h != int(h):
                raise werr("H", "H must be a non-negative integer")
            used.add("H")
    # 15. coordinate system
    cs = st.cs
    if 12 in groups:
        cs = {540: 0, 550: 1, 560: 2, 570: 3, 580: 4, 590: 5, 591: 6, 592: 7, 593: 8}[groups[12]]
    # 16. path control: G64 P Q accepted and ignored
    if groups.get(13) == 640:
        for w in "PQ":
            if w in words and nonmodal != 40:
                used.add(w)
    # 17. distance modes, 18. retract mode
    absolute = st.absolute if 3 not in groups else groups[3] == 900
    ijk_absolute = st.ijk_absolute if 4 not in groups else groups[4] == 901
    retract_r = st.retract_r if 10 not in groups else groups[10] == 990
    # 19. G10 L2
    offsets = st.offsets
    axis_present = [w in words for w in _XYZ]
    any_axis = any(axis_present)
    if nonmodal == 100:
        if "L" not in words or words["L"] != 2:
            raise gerr(100, "only G10 L2 (set a work offset) is supported"
                       + (f", got L{_fmt(words['L'])}" if "L" in words else ", L word missing"))
        if "P" not in words:
            raise gerr(100, "G10 L2 needs a P word (0 = current, 1-9 = G54-G59.3)")
        p = words["P"]
        if p != int(p) or not 0 <= p <= 9:
            raise werr("P", f"G10 L2 P must be an integer 0..9, got {_fmt(p)}")
        if "R" in words:
            raise werr("R", "rotated coordinate systems (G10 L2 R) are not supported")
        idx = cs if p == 0 else int(p) - 1
        offsets = [list(o) for o in offsets]
        for i, w in enumerate(_XYZ):
            if w in words:
                offsets[idx][i] = words[w] * f
        used.update(("L", "P", "X", "Y", "Z"))
        any_axis = False  # consumed by G10

    # 20. motion
    motion = st.motion
    if cancel_cycle:
        motion = 800
    if 1 in groups and groups[1] != 800:
        motion = groups[1]
    pos = st.pos
    rows = st.rows
    n_before = len(rows)
    new_pos = pos
    g53 = nonmodal == 530
    if g53:
        if not absolute:
            raise gerr(530, "G53 needs absolute distance mode (G90)")
        if motion not in (0, 10):
            raise gerr(530, "G53 must be used with G0 or G1")
    off = [0.0, 0.0, 0.0] if g53 else offsets[cs]
    cycle_r, cycle_z, cycle_q = st.cycle_r, st.cycle_z, st.cycle_q
    explicit_motion = 1 in groups and groups[1] != 800
    if any_axis or (explicit_motion and motion in (810, 820, 830) and ("R" in words or "Z" in words)):
        if motion == 800:
            w = next(w for w in _XYZ if w in words)
            raise werr(w, "axis word with no active motion mode (G80 in effect)")
        if nonmodal == 40:
            raise gerr(40, "axis words cannot be used with G4")
        if motion in (0, 10, 20, 30):
            end = list(pos)
            for i in range(3):
                w = _XYZ[i]
                if w in words:
                    end[i] = words[w] * f + off[i] if absolute else pos[i] + words[w] * f
            feed_v = math.nan if motion == 0 else feed
            if motion != 0 and not (feed_v > 0):
                raise _err(file, lineno, s, gk.get(motion), _gname(motion),
                           "feed move with no feed rate (F word) set")
            if motion in (0, 10):
                rows.append((0 if motion == 0 else 1, end[0], end[1], end[2],
                             math.nan, math.nan, math.nan, plane, 0, feed_v, tool, lineno,
                             math.nan))
            else:
                _arc(st, words, widx, gk, s, lineno, motion, plane, pos, end, f, off,
                     ijk_absolute, units, feed_v, tool, used)
            new_pos = end
        else:
            new_pos, cycle_r, cycle_z, cycle_q = _cycle(
                st, words, widx, gk, s, lineno, motion, plane, pos, f, off, absolute,
                retract_r, feed, tool, cycle_r, cycle_z, cycle_q, used)
        used.update(("X", "Y", "Z"))
    elif explicit_motion and motion in (20, 30) and any(w in words for w in "IJKR"):
        raise gerr(motion, f"{_gname(motion)} needs at least one axis word")
    # 21. stop
    ended = mgroups.get(4) in (2, 30)

    unused = [w for w in words if w not in used]
    if unused:
        w = min(unused, key=lambda x: widx[x])
        raise werr(w, f"{w} word is not used by any code in the block")

    # commit
    st.pos = list(new_pos)
    st.units = units
    if 6 in groups and st.units_seen is None:
        st.units_seen = units
    st.feed = feed
    st.selected_tool = selected
    if tool_changed:
        st.tool = tool
        st.tool_changes.append(ToolChange(n_before, tool, lineno))
    st.plane = plane
    st.cs = cs
    st.absolute = absolute
    st.ijk_absolute = ijk_absolute
    st.retract_r = retract_r
    st.offsets = offsets
    st.motion = motion
    st.cycle_r, st.cycle_z, st.cycle_q = cycle_r, cycle_z, cycle_q
    if ended:
        st.ended = True


def _arc(st, words, widx, gk, s, lineno, motion, plane, pos, end, f, off, ijk_absolute,
         units, feed, tool, used) -> None:
    file = st.file
    a, b, n = _PLANE_AXES[plane]
    ccw = motion == 30

    def werr(letter: str, problem: str) -> GCodeError:
        return _err(file, lineno, s, widx[letter], f"{letter}{_fmt(words[letter])}", problem)

    name = _gname(motion)
    bad = _IJK[n]
    if bad in words:
        raise werr(bad, f"{bad} word cannot be used for an arc in the G{plane} plane")
    turns = 0
    if "P" in words:
        p = words["P"]
        if p != int(p) or p < 1:
            raise werr("P", f"P (number of turns) must be a positive integer, got {_fmt(p)}")
        turns = int(p) - 1
        used.add("P")
    tol = max(_ARC_ABS_TOL_MM[units], 0.0)
    a0, b0, a1, b1 = pos[a], pos[b], end[a], end[b]
    ia, ib = _IJK[a], _IJK[b]
    if "R" in words:
        if ia in words or ib in words:
            w = ia if ia in words else ib
            raise werr(w, f"{name} cannot have both R and {w} words")
        radius = words["R"] * f
        used.add("R")
        if a1 == a0 and b1 == b0:
            raise werr("R", "R-form arc whose end point is its start point (use I J K)")
        abs_r = abs(radius)
        mid_a, mid_b = (a0 + a1) / 2.0, (b0 + b1) / 2.0
        half = math.hypot(mid_a - a1, mid_b - b1)
        if half - abs_r > tol:
            raise werr("R", f"radius {abs_r / f:.6g} is too small to reach the end point "
                            f"(half chord {half / f:.6g})")
        if abs_r == 0.0:
            raise werr("R", "zero radius arc")
        if half / abs_r > 1.0 - 1e-12:
            half = abs_r
        if (not ccw and radius > 0) or (ccw and radius < 0):
            theta = math.atan2(b1 - b0, a1 - a0) - math.pi / 2
        else:
            theta = math.atan2(b1 - b0, a1 - a0) + math.pi / 2
        offset = abs_r * math.cos(math.asin(half / abs_r))
        ca = mid_a + offset * math.cos(theta)
        cb = mid_b + offset * math.sin(theta)
    else:
        if ia not in words and ib not in words:
            raise _err(file, lineno, s, gk.get(motion), name,
                       f"{name} in the G{plane} plane needs {ia}/{ib} or R words")
        vi = words.get(ia, 0.0) * f
        vj = words.get(ib, 0.0) * f
        if ijk_absolute:
            ca, cb = vi + off[a], vj + off[b]
        else:
            ca, cb = a0 + vi, b0 + vj
        used.update((ia, ib))
        r1 = math.hypot(ca - a0, cb - b0)
        r2 = math.hypot(ca - a1, cb - b1)
        w = ia if ia in words else ib
        if r1 < 1e-9 or r2 < 1e-9:
            raise werr(w, "zero radius arc")
        d = abs(r1 - r2)
        if d > tol and d > _ARC_REL_TOL * r1:
            raise werr(w, f"radius to end of arc differs from radius to start: "
                          f"r1={r1 / f:.6g} r2={r2 / f:.6g} (difference {d / f:.3g} exceeds "
                          f"{tol / f:.3g} and {_ARC_REL_TOL:.1%})")
    sweep = arc_sweep(a0, b0, a1, b1, ca, cb, ccw, turns)
    c = [0.0, 0.0, 0.0]
    c[a], c[b], c[n] = ca, cb, pos[n]
    st.rows.append((2 if motion == 20 else 3, end[0], end[1], end[2], c[0], c[1], c[2],
                    plane, turns, feed, tool, lineno, sweep))


def _cycle(st, words, widx, gk, s, lineno, motion, plane, pos, f, off, absolute, retract_r,
           feed, tool, cycle_r, cycle_z, cycle_q, used):
    """Expand G81/G82/G83 into moves as LinuxCNC's convert_cycle does."""
    file = st.file
    a, b, n = _PLANE_AXES[plane]
    name = _gname(motion)
    wn = _XYZ[n]

    def werr(letter: str, problem: str) -> GCodeError:
        return _err(file, lineno, s, widx[letter], f"{letter}{_fmt(words[letter])}", problem)

    def gerr(problem: str) -> GCodeError:
        return _err(file, lineno, s, gk.get(motion), name, problem)

    if "R" in words:
        cycle_r = words["R"] * f
        used.add("R")
    if wn in words:
        cycle_z = words[wn] * f
    if math.isnan(cycle_r):
        raise gerr(f"{name} needs an R word (retract plane)")
    if math.isnan(cycle_z):
        raise gerr(f"{name} needs a {wn} word (hole bottom)")
    if not (feed > 0):
        raise gerr(f"{name} with no feed rate (F word) set")
    repeats = 1
    if "L" in words:
        lv = words["L"]
        if lv != int(lv) or lv < 0:
            raise werr("L", f"L (repeats) must be a non-negative integer, got {_fmt(lv)}")
        repeats = int(lv)
        used.add("L")
    if motion == 820:
        if "P" in words:
            if words["P"] < 0:
                raise werr("P", "dwell time must not be negative")
            used.add("P")
    if motion == 830:
        if "Q" in words:
            cycle_q = words["Q"] * f
            used.add("Q")
        if math.isnan(cycle_q):
            raise gerr("G83 needs a Q word (peck depth)")
        if not cycle_q > 0:
            raise werr("Q", "Q (peck depth) must be positive") if "Q" in words else gerr(
                "Q (peck depth) must be positive")
    old_cc = pos[n]
    if absolute:
        aa = words[_XYZ[a]] * f + off[a] if _XYZ[a] in words else pos[a]
        bb = words[_XYZ[b]] * f + off[b] if _XYZ[b] in words else pos[b]
        aa_inc = bb_inc = 0.0
        r = cycle_r + off[n]
        cc = cycle_z + off[n]
    else:
        aa, bb = pos[a], pos[b]
        aa_inc = words[_XYZ[a]] * f if _XYZ[a] in words else 0.0
        bb_inc = words[_XYZ[b]] * f if _XYZ[b] in words else 0.0
        r = cycle_r + old_cc
        cc = r + cycle_z
    if r < cc:
        w = "R" if "R" in words else wn if wn in words else None
        problem = f"R ({_fmt(r / f)}) is below the hole bottom {wn} ({_fmt(cc / f)}) in {name}"
        raise werr(w, problem) if w else gerr(problem)
    rows = st.rows
    pl = plane

    def pt(u: float, v: float, w: float) -> tuple[float, float, float]:
        p = [0.0, 0.0, 0.0]
        p[a], p[b], p[n] = u, v, w
        return p[0], p[1], p[2]

    def trav(u, v, w):
        x, y, z = pt(u, v, w)
        rows.append((0, x, y, z, math.nan, math.nan, math.nan, pl, 0, math.nan, tool, lineno,
                     math.nan))

    def fd(u, v, w):
        x, y, z = pt(u, v, w)
        rows.append((1, x, y, z, math.nan, math.nan, math.nan, pl, 0, feed, tool, lineno,
                     math.nan))

    if old_cc < r:
        trav(pos[a], pos[b], r)
        old_cc = r
    clear_cc = r if retract_r else old_cc
    cur = list(pos)
    cur[n] = old_cc
    for _ in range(repeats):
        aa += aa_inc
        bb += bb_inc
        trav(aa, bb, old_cc)
        if old_cc != r:
            trav(aa, bb, r)
        if motion in (810, 820):
            fd(aa, bb, cc)
            trav(aa, bb, clear_cc)
        else:
            depth = r - cycle_q
            while depth > cc:
                fd(aa, bb, depth)
                trav(aa, bb, r)
                trav(aa, bb, depth + _G83_RAPID_DELTA_MM)
                depth -= cycle_q
            fd(aa, bb, cc)
            trav(aa, bb, clear_cc)
        old_cc = clear_cc
        cur = list(pt(aa, bb, clear_cc))
    return cur, cycle_r, cycle_z, cycle_q


def _junk_error(st: _Interp, s: str, lineno: int, k: int, junk: str) -> None:
    col = 1
    for i, mt in enumerate(_TOKEN.finditer(s)):
        if i == k:
            col = mt.start() + 1
            break
    if junk.isalpha():
        nxt = col
        while nxt < len(s) and s[nxt] in " \t":
            nxt += 1
        if nxt < len(s) and s[nxt] in "#[":
            col, junk = nxt + 1, s[nxt]
    mw = _JUNK_WORD.match(s, col - 1)
    word = mw.group() if mw else junk
    if junk == "#":
        problem = "# parameters are not supported"
    elif junk == "[":
        problem = "[expressions] are not supported"
    elif junk == "O":
        problem = "O-word subroutines and control flow are not supported"
    elif junk.isalpha():
        problem = f"word {junk} has no number"
    else:
        problem = f"unexpected character {junk!r}"
    raise GCodeError(st.file, lineno, col, word, problem)


def _gname(code: int) -> str:
    return f"G{code // 10}" if code % 10 == 0 else f"G{code // 10}.{code % 10}"


def _fmt(v: float) -> str:
    return f"{v:.10g}"
