"""A reader for 3-axis milling programs (RS274/NGC as CAM systems and people write them).

:func:`parse` turns a program into a :class:`Program`: one row per elementary motion (rapid,
feed, clockwise or counter-clockwise arc) in a numpy structured array, in millimetres whatever
the program's units, with the active work offset (G54-G59.3, G10 L2) applied. Canned drilling
cycles (G81, G82, G83 with G98/G99, L repeats, G91 incremental semantics) are expanded into
the rapids and feeds LinuxCNC's interpreter would command. Positions are tool-tip positions:
G43 H shifts the tip's programmed Z by the tool's length offset, as LinuxCNC does.

Supported beyond that: arcs in G17/G18/G19 (I J K or R, helical, P turns), G20/G21, G90/G91,
G90.1/G91.1, G53, rigid tapping (G33.1), tools (T, M6, G43 H, G49, a tool table), cutter
radius compensation (G40, G41/G42 D, G41.1/G42.1 D) in G17 and G18 as LinuxCNC's
interpreter performs it (:mod:`zmap.sim.cutter_comp`), LinuxCNC's ``#`` parameters,
``[...]`` expressions and O-word control flow (``sub``/``call``/``return``, ``while``,
``do``, ``repeat``, ``if``/``elseif``/``else``, subroutines from ``<name>.ngc`` files; see
:mod:`zmap.sim.ngc`) and Fanuc-style ``M98 P L`` / ``O<n>`` ... ``M99`` subprograms.

Refused, with :class:`zmap.errors.GCodeError` naming ``file:line:column`` and the word:
cutter compensation in G19, G5.x splines, G7/G8, G28/G30, G33, G38.x, G43.1/G43.2, G73,
G74, G76, G84-G89, G92, G93, G95, G10 other than L2, any other unknown G or M code, axes
other than X Y Z, and invalid blocks (compensation errors such as an inside corner the tool
cannot cut included). With ``lenient=True`` such blocks are skipped and counted in
:attr:`Program.warnings`. See ``docs/gcode.md`` for the full list.

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

import copy
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, NamedTuple, Sequence

import numpy as np

from ..errors import GCodeError
from ._arcs import arc_sweep
from .cutter_comp import CompError, CutterComp
from .ngc import NgcError, OWord, Parameters, compact, program_structure, scan_line

__all__ = [
    "parse",
    "Program",
    "ToolChange",
    "MOVE_DTYPE",
    "KNOWN_ALL",
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
#: lines. ``known`` is the bitmask of the axes (X=1, Y=2, Z=4) whose position the program had
#: set before the move starts (7: the start is fully known; see :class:`Program`).
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
        ("known", np.int8),
    ]
)

#: bits of MOVE_DTYPE's ``known``
KNOWN_X, KNOWN_Y, KNOWN_Z = 1, 2, 4
KNOWN_ALL = 7

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
_OWORD_HEAD = re.compile(
    r"(?:N\d+(?:\.\d*)?)?O(?:<([^>]*)>|(\d+))(ENDSUB|ENDWHILE|ENDREPEAT|ENDIF|ELSEIF|ELSE|SUB|"
    r"CALL|DO|WHILE|IF|BREAK|CONTINUE|RETURN|REPEAT)?")
_OWORD_EXPR_HEAD = re.compile(r"(?:N\d+(?:\.\d*)?)?O\[")
_M99 = re.compile(r"M0*99(?![\d.])")
#: default limits of one parse: blocks run again by loops and calls (beyond one pass through the
#: file's lines, so a long plain program is never cut) and moves made
MAX_BLOCKS = 100_000
MAX_MOVES = 20_000_000
#: the work envelope: no machine coordinate, offset or arc centre beyond this (mm)
MAX_COORD_MM = 1.0e6
#: largest tool number (T, H, D words): the moves' tool column is int32
MAX_TOOL = 2**31 - 1
#: largest number of turns of one arc (P word of G2/G3)
MAX_TURNS = 10_000

# G codes (x10) and their modal groups.
_G_GROUP = {
    0: 1, 10: 1, 20: 1, 30: 1, 331: 1, 800: 1, 810: 1, 820: 1, 830: 1,
    170: 2, 180: 2, 190: 2,
    900: 3, 910: 3,
    901: 4, 911: 4,
    940: 5,
    200: 6, 210: 6,
    400: 7, 410: 7, 420: 7, 411: 7, 421: 7,
    430: 8, 490: 8,
    980: 10, 990: 10,
    540: 12, 550: 12, 560: 12, 570: 12, 580: 12, 590: 12, 591: 12, 592: 12, 593: 12,
    610: 13, 611: 13, 640: 13,
    40: 0, 100: 0, 530: 0,
}
_G_UNSUPPORTED = {
    431: "dynamic tool length offset (G43.1) is not supported",
    432: "additional tool length offset (G43.2) is not supported",
    330: "spindle-synchronised motion (G33) is not supported",
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
# group 10 is ours: M98/M99 (Fanuc-style subprogram call and return, as LinuxCNC runs them)
_M_GROUP = {0: 4, 1: 4, 2: 4, 30: 4, 3: 7, 4: 7, 5: 7, 6: 6, 7: 8, 8: 8, 9: 8, 98: 10, 99: 10}
_M_UNSUPPORTED: dict[int, str] = {}
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
        raise ValueError(f"plane={_plain(plane)!r} is not one of 17, 18, 19") from None


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
        ``known`` (int8) is the bitmask of the axes, X=1, Y=2, Z=4, whose position the
        program had set before the row starts: by an axis word of a move (absolute, or
        incremental), ``G53``, or a canned cycle (its R plane sets the drilling axis). Until
        a program has set all three (``known == 7``) the tool's position is unknown, and the
        reader stands in 0 for each unknown coordinate of ``start`` and ``end``. A simulator
        should start the tool clear above the stock and not cut with moves whose start is not
        fully known (see ``docs/gcode.md``, "Tool start"). Rows with ``known == 7`` are
        exactly the moves from a known start.
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


def _split_lines(text: str) -> list[str]:
    """Lines as an editor shows them: a UTF-8 BOM dropped, LF, CRLF, CR and ``\\r\\r\\n`` ends."""
    if text.startswith("\ufeff"):
        text = text[1:]
    lines = _LINE_END.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


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
        self.tlo = 0.0  # active tool length offset (G43), mm
        self.speed = 0.0  # spindle speed (S), rev/min
        self.cycle_il = math.nan  # initial level of the canned cycles in a row (LinuxCNC)
        self.comp = None  # CutterComp while G41/G42 is on
        self.call: tuple[int, int] | None = None  # M98 P L of the block just run
        self.max_moves = MAX_MOVES
        self.m99 = False
        self.stop: tuple[str, int] | None = None  # word and column of the block's M2/M30/M99
        self.known = 0  # axes set by the program so far (X=1, Y=2, Z=4)
        self.known_from: list[int | None] = [None, None, None]  # first row that starts known
        self.params = Parameters()
        self._install_system_parameters()

    def _install_system_parameters(self) -> None:
        """Read-only parameters that report the machine state (in program units)."""
        def prog(i: int) -> Callable[[], float]:
            return lambda: (self.pos[i] - self.offsets[self.cs][i]) / self.scale()

        sysp = self.params.system
        for i, name in enumerate("XYZ"):
            sysp[5420 + i] = sysp["_" + name] = prog(i)
        sysp[5400] = sysp["_CURRENT_TOOL"] = lambda: float(self.tool)
        sysp["_SELECTED_TOOL"] = lambda: float(self.selected_tool)
        sysp[5220] = lambda: float(self.cs + 1)
        sysp["_COORD_SYSTEM"] = lambda: float(540 + 10 * self.cs if self.cs < 6 else 590 + self.cs - 5)
        sysp["_METRIC"] = lambda: float(self.units == "mm")
        sysp["_IMPERIAL"] = lambda: float(self.units == "inch")
        sysp["_ABSOLUTE"] = lambda: float(self.absolute)
        sysp["_INCREMENTAL"] = lambda: float(not self.absolute)
        sysp["_FEED"] = lambda: 0.0 if math.isnan(self.feed) else self.feed / self.scale()
        sysp[5410] = lambda: self.tool_diameter(self.tool) / self.scale()
        # LinuxCNC's return value of the last subroutine: 0 until a return or endsub sets it
        self.params.globals["_VALUE"] = 0.0
        self.params.globals["_VALUE_RETURNED"] = 0.0
        for cs in range(9):  # #5221-#5229 G54 ... #5381-#5389 G59.3 (X Y Z of each)
            for i in range(3):
                sysp[5221 + 20 * cs + i] = (lambda cs=cs, i=i: self.offsets[cs][i] / self.scale())

    def mark(self, axes: int, at: int) -> None:
        """The program set ``axes`` (bitmask): rows from index ``at`` on start with them known."""
        new = axes & ~self.known
        if new:
            for i in range(3):
                if new >> i & 1:
                    self.known_from[i] = at
            self.known |= new

    def scale(self) -> float:
        """mm per program unit."""
        return MM_PER_INCH if self.units == "inch" else 1.0

    def tool_entry(self, number: int) -> Any:
        return None if self.tool_table is None else self.tool_table.get(number)

    def tool_diameter(self, number: int) -> float:
        """Diameter of a tool in the table, mm (0 if unknown)."""
        return float(getattr(self.tool_entry(number), "diameter", 0.0))

    # -- state snapshot for lenient mode ---------------------------------------------------
    def snapshot(self, params: bool = True) -> tuple:
        # scalars are immutable: a shallow copy, then fresh copies of the few mutable fields
        state = dict(self.__dict__)
        for k in ("rows", "tool_changes", "tool_table", "params"):
            del state[k]
        state["pos"] = list(self.pos)
        state["known_from"] = list(self.known_from)
        state["offsets"] = [list(o) for o in self.offsets]
        if self.comp is not None:
            state["comp"] = copy.deepcopy(self.comp)
        # parameters change only on lines with #, [ or O: the caller says whether to copy them
        return (len(self.rows), len(self.tool_changes), state,
                self.params.snapshot() if params else None)

    def restore(self, snap: tuple) -> None:
        n, nt, state, params = snap
        self.__dict__.update(state)
        if params is not None:
            self.params.restore(params)
        del self.rows[n:]
        del self.tool_changes[nt:]


def _err(file: str, line: int, col: int | None, word: str, problem: str) -> GCodeError:
    """A GCodeError at a 1-based column (1 if unknown)."""
    return GCodeError(file, line, col or 1, word, problem)


def parse(
    source: str | os.PathLike,
    *,
    lenient: bool = False,
    tool_table: Mapping[int, Any] | str | os.PathLike | None = None,
    filename: str | None = None,
    block_delete: bool = True,
    max_blocks: int = MAX_BLOCKS,
    max_moves: int = MAX_MOVES,
    subroutine_path: str | os.PathLike | Sequence[str | os.PathLike] | None = None,
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
        block is appended to :attr:`Program.warnings`. Cutter-compensation errors count as the
        block's (a corner the tool cannot cut is found by the block after it, or by G40);
        when compensation is still on as the program ends and its held-back move cannot be
        cut, the error names the ``M2``/``M30``/``M99`` block or the file's last line, and
        under ``lenient`` those held-back moves are dropped. Only the limits
        (``max_blocks``, ``max_moves``) and unreadable files stop a lenient parse.
    tool_table : mapping of int to Cutter, or path of a TOML tool table, optional
        When given, every tool loaded by M6 must be in it (T0, no tool, always may be).
    filename : str, optional
        Name used in messages (default: the path, or ``"<string>"`` for text).
    block_delete : bool, keyword-only
        True (default): lines starting with ``/`` are skipped, as with the block-delete
        switch on. False: the ``/`` is ignored and the block runs.
    max_blocks, max_moves : int, keyword-only
        Limits of one parse: blocks run beyond one pass through the file's lines (each
        pass through a loop or a subroutine counts) and moves made. A program beyond
        either stops with GCodeError at the block
        that crossed it, before memory runs out (an endless ``while`` loop, ``L1000000000``).
    subroutine_path : str, path-like or sequence of them, keyword-only
        Folders searched first for ``<name>.ngc`` when ``O<name> call`` names a subroutine
        the program does not define (LinuxCNC's ``[RS274NGC]SUBROUTINE_PATH``; a string may
        list several, separated by ``:``). Relative folders are taken from the program's
        folder. The program's folder and the folders below it are searched after them.

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

    lines = _split_lines(text)
    n_lines = len(lines)

    st = _Interp(fname, table)
    warnings: list[str] = []
    src = _Source.from_lines(lines, fname, block_delete, lenient, warnings)
    runner = _Runner(st, src, lenient, warnings, max_blocks, max_moves, block_delete)
    runner.sub_dirs = _subroutine_dirs(subroutine_path, fname)
    runner.run()
    if st.comp is not None:
        _end_compensation(st, runner.end_at, lenient, warnings)

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
    moves["known"] = 0
    for i in range(3):
        if st.known_from[i] is not None:
            moves["known"][st.known_from[i]:] |= 1 << i
    return Program(
        moves=moves,
        units_input=st.units_seen or "mm",
        warnings=warnings,
        tool_changes=st.tool_changes,
        n_lines=n_lines,
        filename=fname,
        tool_table=table,
    )




def _end_compensation(st: _Interp, end_at: tuple[str, int, int, str], lenient: bool,
                      warnings: list[str]) -> None:
    """Flush cutter compensation left on when the program ends (as LinuxCNC at M2).

    A move held back that cannot be cut raises GCodeError at the block that ended the program
    (``M2``, ``M30``, ``M99``) or at the last line of the file; under ``lenient`` it becomes a
    warning and the held-back moves are dropped, as a skipped block's would be.
    """
    try:
        st.comp.flush()
    except CompError as e:
        file, line, col, word = end_at
        err = GCodeError(file, line, col, word,
                         f"{_comp_problem(e, line)}; cutter compensation was still on when the "
                         f"program ended (G40 ends it)")
        if not lenient:
            raise err from None
        warnings.append(str(err))
        st.comp.discard()
    st.comp = None


def _comp_problem(e: CompError, lineno: int) -> str:
    """A CompError's problem, naming the held-back move's line when it is not ``lineno``."""
    if e.line and e.line != lineno:
        return f"{e.problem}; the move is on line {e.line}"
    return e.problem


def _subroutine_dirs(path: Any, fname: str) -> list[Path]:
    """The folders of ``parse(subroutine_path=...)``, relative ones from the program's folder."""
    if path is None:
        return []
    if isinstance(path, (str, os.PathLike)):
        items = str(path).split(":") if isinstance(path, str) else [path]
    else:
        items = list(path)
    base = Path(fname).parent if os.path.isfile(fname) else Path.cwd()
    out = []
    for item in items:
        if not isinstance(item, (str, os.PathLike)):
            raise TypeError(f"subroutine_path must hold folder names, got {item!r}")
        if str(item):
            d = Path(item)
            out.append(d if d.is_absolute() else base / d)
    return out


class _LimitError(GCodeError):
    """A limit of the whole parse was crossed: fatal even under ``lenient=True``."""


@dataclass
class _Source:
    """One program file prepared for the runner: cleaned lines and paired O-words."""

    name: str
    lines: list  # per line: upper-cased comment-free text, a GCodeError to raise, or None
    special: list[bool]  # the line needs the LinuxCNC scanner (#, [ or O in it)
    owords: dict[int, OWord]
    structure: Any

    @classmethod
    def from_lines(cls, lines: list[str], fname: str, block_delete: bool, lenient: bool,
                   warnings: list[str]) -> "_Source":
        out: list = [None] * len(lines)
        special = [False] * len(lines)
        percent_open = False
        seen_block = False
        comment_sub = _COMMENT.sub
        for idx, raw in enumerate(lines):
            if not raw or raw.isspace():
                continue
            s = raw
            if "(" in s or ";" in s or ")" in s:
                s = comment_sub(lambda mt: " " * len(mt.group()), s)
                if "(" in s or ")" in s:
                    col = s.find("(") if "(" in s else s.find(")")
                    out[idx] = GCodeError(fname, idx + 1, col + 1, s[col],
                                          "unbalanced comment parenthesis")
                    continue
            s = s.upper()
            stripped = s.strip()
            if not stripped:
                continue
            if stripped == "%":
                if not seen_block and not percent_open:
                    percent_open = True
                    continue
                if percent_open:
                    del out[idx:], special[idx:]  # the closing tape mark ends the program
                    break
                continue
            seen_block = True
            if stripped[0] == "/":
                if block_delete:
                    continue
                s = s.replace("/", " ", 1)
            out[idx] = s
            special[idx] = "#" in s or "[" in s or "O" in s
        src = cls(fname, out, special, {}, None)
        src._pair_owords(lenient, warnings)
        return src

    def _pair_owords(self, lenient: bool, warnings: list[str]) -> None:
        m99: list[int] = []
        for idx, s in enumerate(self.lines):
            if not isinstance(s, str):
                continue
            if "O" in s:
                c, cols = compact(s)
                m = _OWORD_HEAD.match(c)
                if m:
                    label = f"<{m.group(1)}>" if m.group(1) is not None else str(int(m.group(2)))
                    self.owords[idx] = OWord(label, m.group(3) or "", (), cols[0])
                elif _OWORD_EXPR_HEAD.match(c):
                    # O[expression]: LinuxCNC's computed label (the runner evaluates it); the
                    # text pairs statements that share it
                    label, kw = _bracketed_label(c)
                    if label is not None:
                        self.owords[idx] = OWord(label, kw, (), cols[0])
            if "M" in s and "99" in s and _M99.search(compact(s)[0]):
                m99.append(idx)
        while True:
            try:
                self.structure = program_structure(self.owords, m99)
                return
            except NgcError as e:
                ow = self.owords[e.pos]
                err = GCodeError(self.name, e.pos + 1, ow.col, e.word, e.problem)
                if not lenient:
                    raise err from None
                warnings.append(str(err))
                del self.owords[e.pos]
                self.lines[e.pos] = None


def _bracketed_label(c: str) -> tuple[str | None, str]:
    """``("[expr]", keyword)`` of a compact ``O[expr] keyword`` line (None if unbalanced)."""
    i = c.index("[")
    depth = 0
    for k in range(i, len(c)):
        depth += (c[k] == "[") - (c[k] == "]")
        if depth == 0:
            m = re.match(r"ENDSUB|ENDWHILE|ENDREPEAT|ENDIF|ELSEIF|ELSE|SUB|CALL|DO|WHILE|IF|BREAK|"
                         r"CONTINUE|RETURN|REPEAT", c[k + 1:])
            return c[i:k + 1], (m.group() if m else "")
    return None, ""


@dataclass
class _Frame:
    """A subroutine call in progress: where to return, and what kind of call."""

    source: _Source
    return_idx: int
    kind: str  # "sub" (O-word call: own #1-#30 and locals) or "m98" (shares parameters)
    start: int  # index of the sub or program header line
    remaining: int = 1  # M98 L repeats still to run
    label: str = ""


class _Runner:
    """Runs a program's lines through the interpreter, with O-word control flow and calls."""

    def __init__(self, st: _Interp, main: _Source, lenient: bool, warnings: list[str],
                 max_blocks: int, max_moves: int, block_delete: bool = True):
        self.st = st
        self.main = main
        self.lenient = lenient
        self.block_delete = block_delete  # subroutine files read later follow the program
        self.warnings = warnings
        self.max_blocks = max_blocks
        self.max_moves = max_moves
        st.max_moves = max_moves
        self.files: dict[str, _Source | None] = {}
        self.sub_dirs: list[Path] = []
        #: where the program ended: (file, line, column, word) of its M2/M30/M99, or the end
        #: of the file
        self.end_at: tuple[str, int, int, str] = (main.name, max(len(main.lines), 1), 1,
                                                  "end of file")

    def run(self) -> None:
        st = self.st
        src, i = self.main, 0
        frames: list[_Frame] = []
        repeats: dict[tuple[int, int], int] = {}
        jumped = False
        executed = 0
        budget = self.max_blocks + len(src.lines)
        while not st.ended:
            if i >= len(src.lines):
                if frames:
                    f = frames[-1]
                    err = GCodeError(src.name, max(len(src.lines), 1), 1, f"O{f.label}",
                                     "subroutine runs off the end of the file")
                    if not self.lenient:
                        raise err
                    self.warnings.append(str(err) + "; the program ends here")
                self.end_at = (src.name, max(len(src.lines), 1), 1, "end of file")
                return
            item = src.lines[i]
            if item is None:
                i += 1
                continue
            executed += 1
            if executed > budget:
                raise _LimitError(src.name, i + 1, 1, "block",
                                 f"more than {self.max_blocks} blocks executed (an endless "
                                 f"loop?); parse(max_blocks=...) or zmap simulate "
                                 f"--max-blocks allows more")
            st.file = src.name
            st.stop = None
            was_jumped, jumped = jumped, False
            snap = st.snapshot(src.special[i]) if self.lenient else None
            try:
                if isinstance(item, GCodeError):
                    raise item
                ow = src.owords.get(i)
                if ow is not None:
                    src, i, jumped = self._oword(src, i, ow, frames, repeats, was_jumped)
                    continue
                self._line(src, i, item)
                if len(st.rows) > self.max_moves:
                    raise _LimitError(src.name, i + 1, 1, "block",
                                     f"the program makes more than {self.max_moves} moves; "
                                     f"parse(max_moves=...) allows more")
            except GCodeError as e:
                if not self.lenient or isinstance(e, _LimitError):
                    raise
                st.restore(snap)
                self.warnings.append(str(e))
                st.call, st.m99 = None, False
                i += 1
                continue
            if st.stop is not None:
                self.end_at = (src.name, i + 1, st.stop[1], st.stop[0])
            i += 1
            if st.call is not None:
                p, count = st.call
                st.call = None
                if count > 0:
                    tsrc, tidx = self._find(src, f"P{p}", i)
                    frames.append(_Frame(src, i, "m98", tidx, count, str(p)))
                    src, i = tsrc, tidx + 1
            elif st.m99:
                st.m99 = False
                if not frames or frames[-1].kind != "m98":
                    st.ended = True  # M99 in the main program ends it, as LinuxCNC by default
                    continue
                f = frames[-1]
                f.remaining -= 1
                if f.remaining > 0:
                    i = f.start + 1
                else:
                    frames.pop()
                    src, i = f.source, f.return_idx

    def _line(self, src: _Source, i: int, s: str) -> None:
        st = self.st
        lineno = i + 1
        if src.special[i]:
            try:
                line = scan_line(s, st.params)
            except NgcError as e:
                raise GCodeError(src.name, lineno, e.pos, e.word, e.problem) from None
            if line.oword is not None:
                ow = line.oword
                raise GCodeError(src.name, lineno, ow.col, f"O{ow.label}",
                                 "an O-word must start the line")
            for key, v in line.assigns:
                st.params.set(key, v)
            if line.words:
                _block(st, line.words, s, lineno)
            return
        toks = _TOKEN.findall(s)
        if _fast_block(st, toks, lineno):
            return
        _block(st, _plain_words(src.name, lineno, s), s, lineno)

    def _find(self, src: _Source, label: str, i: int) -> tuple[_Source, int]:
        """The source and line index of subroutine ``label``: defined in this file, the main
        file or a file already read, else in ``<name>.ngc`` (LinuxCNC's find_ngc_file): in a
        folder of ``subroutine_path``, beside the main file, or in a folder below it."""
        for cand in (src, self.main, *(f for f in self.files.values() if f is not None)):
            idx = cand.structure.subs.get(label)
            if idx is not None:
                return cand, idx
        if not label.startswith("P"):
            name = label.strip("<>").lower()  # LinuxCNC reads the line in lower case
            if name not in self.files:
                path = self._sub_file(name)
                cand = None
                if path is not None:
                    text, fname = _read_source(path, None)
                    cand = _Source.from_lines(_split_lines(text), fname, self.block_delete,
                                              self.lenient, self.warnings)
                self.files[name] = cand
            cand = self.files[name]
            if cand is not None and label in cand.structure.subs:
                return cand, cand.structure.subs[label]
        shown = f"O{label}" if not label.startswith("P") else f"program O{label[1:]}"
        raise GCodeError(src.name, i, 1, shown, f"{shown} is not defined"
                         + ("" if label.startswith("P") else
                            " in the file, nor in a file beside it or in subroutine_path"))

    def _sub_file(self, name: str) -> Path | None:
        """``<name>.ngc`` in the subroutine folders, beside the main file, or below it."""
        fname = f"{name}.ngc"
        dirs = list(self.sub_dirs)
        if self.main.name != "<string>" and os.path.isfile(self.main.name):
            dirs.append(Path(self.main.name).parent)
        for d in dirs:
            for cand in (d / fname, d / fname.upper()):
                if cand.is_file():
                    return cand
        if len(dirs) > len(self.sub_dirs):  # LinuxCNC's findFile: the folders below, in turn
            root = dirs[-1]
            for top, subdirs, files in os.walk(root):
                subdirs[:] = sorted(x for x in subdirs if not x.startswith("."))
                if len(Path(top).relative_to(root).parts) >= 4:
                    subdirs[:] = []
                if top != str(root) and fname in files:
                    return Path(top) / fname
        return None

    def _oword(self, src: _Source, i: int, ow: OWord, frames: list[_Frame],
               repeats: dict[tuple[int, int], int], jumped: bool) -> tuple[_Source, int, bool]:
        """Run one O-word statement; return where to go on (source, index, jumped)."""
        st = self.st
        S = src.structure
        kw = ow.keyword
        if kw == "SUB" or i in S.fanuc:  # a definition met in the flow is skipped
            return src, S.end[i] + 1, False
        try:
            line = scan_line(src.lines[i], st.params)
        except NgcError as e:
            raise GCodeError(src.name, i + 1, e.pos, e.word, e.problem) from None
        args = line.oword.args if line.oword is not None else ()
        word = f"O{ow.label}"

        def cond() -> bool:
            if not args:
                raise GCodeError(src.name, i + 1, ow.col, word,
                                 f"{kw.lower()} needs a condition in [brackets]")
            return args[0] != 0.0

        if kw == "CALL":
            label = line.oword.label if line.oword is not None else ow.label  # O[expr]: evaluated
            tsrc, tidx = self._find(src, label, i + 1)
            if len(frames) >= 100:
                raise GCodeError(src.name, i + 1, ow.col, word, "subroutine calls nested "
                                                                "more than 100 deep")
            frames.append(_Frame(src, i + 1, "sub", tidx, 1, label))
            st.params.push(args)
            return tsrc, tidx + 1, False
        if kw in ("ENDSUB", "RETURN"):
            if not frames or frames[-1].kind != "sub":
                raise GCodeError(src.name, i + 1, ow.col, word,
                                 f"{kw.lower()} without a call in progress")
            f = frames.pop()
            st.params.pop()
            # LinuxCNC's read_o: a value sets #<_value> and #<_value_returned>; none clears both
            st.params.set("<_VALUE_RETURNED>", 1.0 if args else 0.0)
            st.params.set("<_VALUE>", args[0] if args else 0.0)
            return f.source, f.return_idx, False
        if kw == "WHILE":
            if i in S.start:  # the while that closes a do-loop
                return src, (S.start[i] + 1 if cond() else i + 1), False
            return src, (i + 1 if cond() else S.end[i] + 1), False
        if kw == "ENDWHILE":
            return src, S.start[i], False
        if kw == "DO":
            return src, i + 1, False
        if kw == "REPEAT":
            if not args:
                raise GCodeError(src.name, i + 1, ow.col, word, "repeat needs a count in "
                                                                "[brackets]")
            n = round(args[0])
            repeats[(id(src), i)] = n
            return src, (i + 1 if n > 0 else S.end[i] + 1), False
        if kw == "ENDREPEAT":
            s0 = S.start[i]
            left = repeats.get((id(src), s0), 1) - 1
            repeats[(id(src), s0)] = left
            return src, (s0 + 1 if left > 0 else i + 1), False
        if kw == "IF":
            return (src, i + 1, False) if cond() else (src, S.end[i], True)
        if kw == "ELSEIF":
            if not jumped:
                return src, S.endif[i] + 1, False
            return (src, i + 1, False) if cond() else (src, S.end[i], True)
        if kw == "ELSE":
            return src, (i + 1 if jumped else S.endif[i] + 1), False
        if kw == "ENDIF":
            return src, i + 1, False
        if kw in ("BREAK", "CONTINUE"):
            loop = S.loop[i]
            lkw = src.owords[loop].keyword
            if lkw == "REPEAT":  # LinuxCNC's convert_control_functions accepts while/do only
                raise GCodeError(src.name, i + 1, ow.col, word,
                                 f"{kw.lower()} works in while and do loops only, not in "
                                 f"repeat O{ow.label}")
            if kw == "BREAK":
                return src, S.end[loop] + 1, False
            return src, (loop if lkw == "WHILE" else S.end[loop]), False
        raise GCodeError(src.name, i + 1, ow.col, word,
                         f"O-word {kw.lower() or 'program number'} cannot be run here")


def _plain_words(fname: str, lineno: int, s: str) -> list[tuple[str, float, int]]:
    """Words of a line with plain numbers only: (letter, value, column)."""
    out = []
    for mt in _TOKEN.finditer(s):
        letter, num, junk = mt.groups()
        col = mt.start() + 1
        if junk:
            problem = (f"word {junk} has no number" if junk.isalpha()
                       else f"unexpected character {junk!r}")
            raise GCodeError(fname, lineno, col, junk, problem)
        v = float(num)
        if not math.isfinite(v) or abs(v) > 1e100:
            raise GCodeError(fname, lineno, col, f"{letter}{num[:20]}" + ("..." if len(num) > 20 else ""),
                             "number out of range")
        out.append((letter, v, col))
    return out


_FAST_LETTERS = frozenset("XYZFN")


def _fast_block(st: _Interp, toks: list, lineno: int) -> bool:
    """Fast path for the common block: coordinates (and F) under modal G0/G1.

    Returns False, having changed nothing, for anything else (the full interpreter runs).
    """
    if st.comp is not None:
        return False
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
    for v in vals.values():
        if not abs(v) <= 1e100:  # huge or not finite: the full interpreter says why
            return False
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
        st.cycle_il = math.nan
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
    if not (abs(x) <= MAX_COORD_MM and abs(y) <= MAX_COORD_MM and abs(z) <= MAX_COORD_MM):
        return False
    nan = math.nan
    if motion == 0:
        st.rows.append((0, x, y, z, nan, nan, nan, st.plane, 0, nan, st.tool, lineno, nan))
    else:
        st.rows.append((1, x, y, z, nan, nan, nan, st.plane, 0, feed, st.tool, lineno, nan))
    if st.known != KNOWN_ALL:
        st.mark(("X" in vals) | ("Y" in vals) << 1 | ("Z" in vals) << 2, len(st.rows))
    st.pos = [x, y, z]
    st.feed = feed
    st.motion = motion
    st.cycle_il = math.nan
    return True


def _block(st: _Interp, toks: list, s: str, lineno: int) -> None:
    """Interpret one block (words of one line) in LinuxCNC's order of execution.

    ``toks`` is a list of ``(letter, value, column)``: values in program units, already read
    from numbers, parameters or expressions.
    """
    file = st.file
    gcodes: list[tuple[int, int]] = []
    mcodes: list[tuple[int, int]] = []
    words: dict[str, float] = {}
    widx: dict[str, int] = {}
    for letter, v, k in toks:
        if letter == "G":
            code = round(v * 10) if abs(v) < 1e4 else -1
            if abs(v * 10 - code) > 1e-6 or code not in _G_GROUP:
                problem = _G_UNSUPPORTED.get(code, f"G{_fmt(v)} is not a supported G code")
                raise _err(file, lineno, k, f"G{_fmt(v)}", problem)
            gcodes.append((code, k))
        elif letter == "M":
            code = int(v) if abs(v) < 1e4 else -1
            if code != v or code not in _M_GROUP:
                problem = _M_UNSUPPORTED.get(code, f"M{_fmt(v)} is not a supported M code")
                raise _err(file, lineno, k, f"M{_fmt(v)}", problem)
            mcodes.append((code, k))
        elif letter == "N":
            continue
        elif letter in _WORD_LETTERS:
            if letter in words:
                raise _err(file, lineno, k, f"{letter}{_fmt(v)}",
                           f"{letter} word appears twice in the block")
            words[letter] = v
            widx[letter] = k
        elif letter in _AXES_EXTRA:
            raise _err(file, lineno, k, f"{letter}{_fmt(v)}",
                       f"axis {letter} is not supported (3-axis XYZ only)")
        else:
            raise _err(file, lineno, k, f"{letter}{_fmt(v)}", f"word {letter} is not supported")

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
            raise _err(file, lineno, k, _gname(code),
                       f"{_gname(groups[grp])} and {_gname(code)} are in the same modal group")
        groups[grp] = code
        gk[code] = k
    mgroups: dict[int, int] = {}
    for code, k in mcodes:
        grp = _M_GROUP[code]
        if grp in mgroups and {mgroups[grp], code} != {7, 8}:  # mist and flood may combine
            raise _err(file, lineno, k, f"M{code}",
                       f"M{mgroups[grp]} and M{code} are in the same modal group")
        mgroups[grp] = code

    def werr(letter: str, problem: str) -> GCodeError:
        v = words[letter]
        return _err(file, lineno, widx[letter], f"{letter}{_fmt(v)}", problem)

    def gerr(code: int, problem: str) -> GCodeError:
        return _err(file, lineno, gk.get(code), _gname(code), problem)

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
    speed = st.speed
    if "S" in words:
        if words["S"] < 0:
            raise werr("S", "spindle speed must not be negative")
        speed = words["S"]
        used.add("S")
    # 5. tool select, 6. tool change
    selected = st.selected_tool
    if "T" in words:
        t = words["T"]
        if t < 0 or t != int(t) or t > MAX_TOOL:
            raise werr("T", f"tool number must be an integer 0..{MAX_TOOL}")
        selected = int(t)
        used.add("T")
        if st.tool_table is not None and selected != 0 and selected not in st.tool_table:
            have = ", ".join(str(x) for x in sorted(st.tool_table)) or "none"
            raise werr("T", f"tool {selected} is not in the tool table (tools: {have})")
    tool = st.tool
    tool_changed = False
    if mgroups.get(6) == 6:
        if st.comp is not None:
            raise _err(file, lineno, None, "M6", "tool change with cutter compensation on "
                                                 "(G40 first)")
        tool = selected
        tool_changed = True
    # M98 P L: call subprogram O<P> L times (the runner does it after the block); M99 returns
    call = None
    if mgroups.get(10) == 98:
        if "P" not in words:
            raise _err(file, lineno, None, "M98", "M98 needs a P word (the program number)")
        pv = words["P"]
        if pv < 0 or pv != int(pv) or pv > 99_999_999:
            raise werr("P", "M98 P must be a program number 0..99999999")
        count = 1
        if "L" in words:
            lv = words["L"]
            if lv < 0 or lv != int(lv) or lv > st.max_moves:
                raise werr("L", f"M98 L (repeats) must be an integer 0..{st.max_moves}")
            count = int(lv)
        call = (int(pv), count)
        used.update(("P", "L"))
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
    tlo = st.tlo
    if groups.get(8) == 430:
        h = tool
        if "H" in words:
            hv = words["H"]
            if hv < 0 or hv != int(hv) or hv > MAX_TOOL:
                raise werr("H", f"H must be an integer 0..{MAX_TOOL}")
            h = int(hv)
            used.add("H")
        entry = st.tool_entry(h)
        if entry is None and st.tool_table is not None and h != 0:
            w = "H" if "H" in words else None
            problem = f"tool {h} (G43 H) is not in the tool table"
            raise werr("H", problem) if w else gerr(430, problem)
        tlo = float(getattr(entry, "length_offset", 0.0))
    elif groups.get(8) == 490:
        tlo = 0.0
    # 13. cutter radius compensation (G40, G41, G42, G41.1, G42.1)
    comp = st.comp
    comp_code = groups.get(7)
    if comp_code in (410, 420, 411, 421):
        if comp is not None:
            raise gerr(comp_code, "cutter compensation is already on (G40 first)")
        if plane == 19:  # LinuxCNC: "radius compensation only in XY or XZ plane"
            raise gerr(comp_code, "cutter compensation in the G19 plane is not supported "
                                  "(G17 and G18 only, as LinuxCNC)")
        if comp_code in (410, 420):
            d = tool
            if "D" in words:
                dv = words["D"]
                if dv < 0 or dv != int(dv) or dv > MAX_TOOL:
                    raise werr("D", f"D (tool number) must be an integer 0..{MAX_TOOL}")
                d = int(dv)
            if st.tool_table is not None and d != 0 and st.tool_entry(d) is None:
                problem = f"tool {d} is not in the tool table"
                raise werr("D", problem) if "D" in words else gerr(comp_code, problem)
            radius = st.tool_diameter(d) / 2.0
        else:
            if "D" not in words:
                raise gerr(comp_code, f"{_gname(comp_code)} needs a D word (the diameter)")
            radius = words["D"] * f / 2.0  # negative: the other side, as LinuxCNC
        used.add("D")
        pos0 = list(st.pos)
        pos0[2] -= tlo - st.tlo
        side = "left" if comp_code in (410, 411) else "right"
        if radius < 0:  # LinuxCNC: a negative radius (D or table) cuts on the other side
            radius = -radius
            side = "right" if side == "left" else "left"
        if plane == 18:  # the XY engine in the (Z, X, Y) frame: G18 is right-handed as G17
            comp = CutterComp(side, radius, (pos0[2], pos0[0], pos0[1]),
                              _g18_rows(st.rows.append))
        else:
            comp = CutterComp(side, radius, tuple(pos0), st.rows.append)
    elif comp_code == 400 and comp is not None:
        try:
            comp.flush()
        except CompError as e:
            raise gerr(400, _comp_problem(e, lineno)) from None
        comp = None
    if st.comp is not None and comp is not None:
        if 12 in groups:
            raise gerr(groups[12], "coordinate system change with cutter compensation on")
        if plane != st.plane:
            raise gerr(groups[2], "plane change with cutter compensation on")
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
                if abs(words[w] * f) > MAX_COORD_MM:
                    raise werr(w, f"offset beyond the work envelope (|{w}| <= "
                                  f"{MAX_COORD_MM:g} mm)")
                offsets[idx][i] = words[w] * f
        used.update(("L", "P", "X", "Y", "Z"))
        any_axis = False  # consumed by G10

    # 20. motion
    motion = st.motion
    if cancel_cycle:
        motion = 800
    if 1 in groups and groups[1] != 800:
        motion = groups[1]
    # after G40 the tool sits at the compensated point (the next row starts there: rows chain),
    # while the program goes on from the programmed point, as in LinuxCNC
    pos = list(st.pos)
    pos[2] -= tlo - st.tlo  # G43/G49 move the tip's programmed Z, not the machine
    rows = st.rows
    n_before = len(rows)
    set_axes, set_at = 0, 0  # axes the block's move sets, and the first row that starts so
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
        if motion in (0, 10, 20, 30, 331):
            end = list(pos)
            for i in range(3):
                w = _XYZ[i]
                if w in words:
                    end[i] = words[w] * f + off[i] if absolute else pos[i] + words[w] * f
            feed_v = math.nan if motion == 0 else feed
            if motion not in (0, 331) and not (feed_v > 0):
                raise _err(file, lineno, gk.get(motion), _gname(motion),
                           "feed move with no feed rate (F word) set")
            _check_envelope(end, words, werr, gerr, motion)
            if motion == 331:
                if comp is not None:
                    raise gerr(331, "rigid tapping with cutter compensation on")
                new_pos = _rigid_tap(st, words, werr, gerr, pos, end, f, speed, feed, tool,
                                     plane, lineno, used)
            else:
                if motion == 0 or motion == 10:
                    row = (0 if motion == 0 else 1, end[0], end[1], end[2],
                           math.nan, math.nan, math.nan, plane, 0, feed_v, tool, lineno, math.nan)
                else:
                    row = _arc(st, words, widx, gk, s, lineno, motion, plane, pos, end, f, off,
                               ijk_absolute, units, feed_v, tool, used)
                    _check_envelope(row[4:7], words, werr, gerr, motion)
                set_axes = ("X" in words) | ("Y" in words) << 1 | ("Z" in words) << 2
                if comp is None:
                    rows.append(row)
                    set_at = len(rows)
                else:
                    if g53:
                        raise gerr(530, "G53 with cutter compensation on")
                    cend, ccen = tuple(end), (row[4], row[5])
                    if plane == 18:  # to the (Z, X, Y) frame of the engine
                        cend, ccen = (end[2], end[0], end[1]), (row[6], row[4])
                    try:
                        if motion in (0, 10):
                            comp.straight(row[0], cend, feed_v, tool, lineno)
                        else:
                            comp.arc(motion == 30, cend, ccen, row[8], feed_v, tool, lineno)
                    except CompError as e:
                        raise _err(file, lineno, gk.get(motion), _gname(motion),
                                   _comp_problem(e, lineno)) from None
                    set_at = len(rows) + comp.pending  # the rows held back come first
                new_pos = end
        else:
            if comp is not None:
                raise gerr(motion, f"canned cycle {_gname(motion)} with cutter compensation on")
            new_pos, cycle_r, cycle_z, cycle_q = _cycle(
                st, words, widx, gk, s, lineno, motion, plane, pos, f, off, absolute,
                retract_r, feed, tool, cycle_r, cycle_z, cycle_q, used)
            _check_envelope(new_pos, words, werr, gerr, motion)
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
    st.mark(set_axes, set_at)
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
    st.tlo = tlo
    st.speed = speed
    st.comp = comp
    if motion not in (810, 820, 830):
        st.cycle_il = math.nan
    st.call = call
    st.m99 = mgroups.get(10) == 99
    stop = mgroups.get(4) if ended else 99 if st.m99 else None
    if stop is not None:
        st.stop = (f"M{stop}", next(k for code, k in mcodes if code == stop))
    if ended:
        st.ended = True


def _g18_rows(append: Callable[[tuple], None]) -> Callable[[tuple], None]:
    """Rows of the compensation engine run in the (Z, X, Y) frame, back in X Y Z, plane 18."""
    def emit(r: tuple) -> None:
        append((r[0], r[2], r[3], r[1], r[5], r[6], r[4], 18) + tuple(r[8:]))
    return emit


def _check_envelope(point, words: dict, werr, gerr, motion: int) -> None:
    """Refuse a position or centre outside the work envelope (|coordinate| <= MAX_COORD_MM)."""
    for i, v in enumerate(point):
        if abs(v) > MAX_COORD_MM:  # NaN (a line's centre) compares False
            problem = (f"{_XYZ[i]} = {v:.6g} mm is outside the work envelope "
                       f"(|coordinate| <= {MAX_COORD_MM:g} mm)")
            w = _XYZ[i] if _XYZ[i] in words else next((w for w in _XYZ if w in words), None)
            raise werr(w, problem) if w else gerr(motion, problem)


def _rigid_tap(st, words, werr, gerr, pos, end, f, speed, feed, tool, plane, lineno, used):
    """G33.1: feed to the hole bottom synchronised with the spindle, then back to the start.

    The feed is the pitch ``K`` times the spindle speed (the F word when S is not set).
    """
    if plane != 17:
        raise gerr(331, "rigid tapping is supported in the G17 plane only")
    if "K" not in words:
        raise gerr(331, "G33.1 needs a K word (the thread pitch)")
    if not words["K"] > 0:
        raise werr("K", "K (the thread pitch) must be positive")
    used.add("K")
    tap_feed = words["K"] * f * speed if speed > 0 else feed
    if not tap_feed > 0:
        raise gerr(331, "G33.1 with no spindle speed (S) and no feed rate (F) set")
    nan = math.nan
    st.rows.append((1, end[0], end[1], end[2], nan, nan, nan, plane, 0, tap_feed, tool, lineno, nan))
    st.rows.append((1, pos[0], pos[1], pos[2], nan, nan, nan, plane, 0, tap_feed, tool, lineno, nan))
    return list(pos)


def _arc(st, words, widx, gk, s, lineno, motion, plane, pos, end, f, off, ijk_absolute,
         units, feed, tool, used) -> None:
    file = st.file
    a, b, n = _PLANE_AXES[plane]
    ccw = motion == 30

    def werr(letter: str, problem: str) -> GCodeError:
        return _err(file, lineno, widx[letter], f"{letter}{_fmt(words[letter])}", problem)

    name = _gname(motion)
    bad = _IJK[n]
    if bad in words:
        raise werr(bad, f"{bad} word cannot be used for an arc in the G{plane} plane")
    turns = 0
    if "P" in words:
        p = words["P"]
        if p != int(p) or p < 1 or p > MAX_TURNS:
            raise werr("P", f"P (number of turns) must be an integer 1..{MAX_TURNS}, "
                            f"got {_fmt(p)}")
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
            raise _err(file, lineno, gk.get(motion), name,
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
    return (2 if motion == 20 else 3, end[0], end[1], end[2], c[0], c[1], c[2],
            plane, turns, feed, tool, lineno, sweep)


def _cycle(st, words, widx, gk, s, lineno, motion, plane, pos, f, off, absolute, retract_r,
           feed, tool, cycle_r, cycle_z, cycle_q, used):
    """Expand G81/G82/G83 into moves as LinuxCNC's convert_cycle does."""
    file = st.file
    a, b, n = _PLANE_AXES[plane]
    name = _gname(motion)
    wn = _XYZ[n]

    def werr(letter: str, problem: str) -> GCodeError:
        return _err(file, lineno, widx[letter], f"{letter}{_fmt(words[letter])}", problem)

    def gerr(problem: str) -> GCodeError:
        return _err(file, lineno, gk.get(motion), name, problem)

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
    # LinuxCNC's initial level: the Z where the first block of this run of cycles began
    old_cc = pos[n] if math.isnan(st.cycle_il) else st.cycle_il
    st.cycle_il = old_cc
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
    pecks = 1 if motion != 830 else max(1.0, math.ceil((r - cc) / cycle_q))
    estimate = repeats * (3.0 + 3.0 * pecks)
    if len(rows) + estimate > st.max_moves:
        w = "Q" if motion == 830 and pecks > repeats and "Q" in words else (
            "L" if "L" in words else None)
        problem = (f"{name} would make {estimate:.3g} moves (limit {st.max_moves}; "
                   f"parse(max_moves=...) allows more)")
        raise werr(w, problem) if w else gerr(problem)

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

    # axes the cycle sets (MOVE_DTYPE's known): the drilling axis once at R, the plane axes
    # given by words once over the hole
    bit_n = 1 << n
    bits_ab = (_XYZ[a] in words) << a | (_XYZ[b] in words) << b
    if old_cc < r:
        trav(pos[a], pos[b], r)
        st.mark(bit_n, len(rows))
        old_cc = r
    clear_cc = r if retract_r else old_cc
    cur = list(pos)
    cur[n] = old_cc
    for _ in range(repeats):
        aa += aa_inc
        bb += bb_inc
        trav(aa, bb, old_cc)
        st.mark(bits_ab | (bit_n if old_cc == r else 0), len(rows))
        if old_cc != r:
            trav(aa, bb, r)
            st.mark(bit_n, len(rows))
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


def _plain(v: Any) -> Any:
    """A numpy scalar as the Python number it holds (messages print 17, not np.int8(17))."""
    return v.item() if isinstance(v, np.generic) else v


def _gname(code: int) -> str:
    return f"G{code // 10}" if code % 10 == 0 else f"G{code // 10}.{code % 10}"


def _fmt(v: float) -> str:
    return f"{v:.10g}"
