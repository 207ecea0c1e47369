"""The vocabulary of the G-code dialect: codes and their modal groups, word letters, limits.

G codes are kept as ten times their number, so that a decimal code is an exact integer
(``G33.1`` is 331, ``G59.3`` is 593); M codes as their number. The modal groups are
LinuxCNC's (rs274ngc's ``gees`` and ``ems`` tables), whose numbers the interpreter keeps: two
codes of one group in a block are an error, and each group has its step in the order of
execution (:mod:`zmap.sim._gcode_modal`). The module also reads the words of a plain line
(numbers only, no parameters) and names a word or a code in a message.

Examples
--------
>>> G_GROUP[G_TOOL_LENGTH_OFFSET] == MODAL_GROUP_TOOL_LENGTH
True
>>> g_name(G_RIGID_TAP), g_name(G_DWELL)
('G33.1', 'G4')
>>> plain_words("x.nc", 1, "G1 X-1.5 F100")
[('G', 1.0, 1), ('X', -1.5, 4), ('F', 100.0, 10)]
"""

from __future__ import annotations

import math
import re

from ..errors import GCodeError
from .cutter_comp import CompError
from .ngc import MAX_MAGNITUDE

__all__ = [
    "MM_PER_INCH", "MAX_BLOCKS", "MAX_MOVES", "MAX_COORD_MM", "MAX_TOOL", "MAX_TURNS",
    "MODAL_GROUP_NON_MODAL", "MODAL_GROUP_MOTION", "MODAL_GROUP_PLANE", "MODAL_GROUP_DISTANCE",
    "MODAL_GROUP_ARC_DISTANCE", "MODAL_GROUP_FEED_RATE_MODE", "MODAL_GROUP_UNITS",
    "MODAL_GROUP_CUTTER_COMP", "MODAL_GROUP_TOOL_LENGTH", "MODAL_GROUP_RETURN_MODE",
    "MODAL_GROUP_COORD_SYSTEM", "MODAL_GROUP_PATH_CONTROL",
    "G_RAPID", "G_LINEAR", "G_ARC_CW", "G_ARC_CCW", "G_RIGID_TAP", "G_CANCEL_CYCLE",
    "G_DRILL", "G_DRILL_DWELL", "G_PECK_DRILL", "STRAIGHT_MOTIONS", "ARC_MOTIONS",
    "CANNED_CYCLES", "G_PLANE_XY", "G_PLANE_ZX", "G_PLANE_YZ", "G_ABSOLUTE", "G_INCREMENTAL",
    "G_ARC_ABSOLUTE", "G_ARC_INCREMENTAL", "G_FEED_PER_MINUTE", "G_INCH", "G_MM",
    "G_COMP_OFF", "G_COMP_LEFT", "G_COMP_RIGHT", "G_COMP_LEFT_DIAMETER",
    "G_COMP_RIGHT_DIAMETER", "G_TOOL_LENGTH_OFFSET", "G_TOOL_LENGTH_CANCEL",
    "G_RETURN_OLD_Z", "G_RETURN_R", "G_COORD_SYSTEMS", "G_EXACT_PATH", "G_EXACT_STOP",
    "G_BLENDING", "G_DWELL", "G_SET_OFFSETS", "G_MACHINE_COORDS",
    "M_GROUP_STOP", "M_GROUP_TOOL_CHANGE", "M_GROUP_SPINDLE", "M_GROUP_COOLANT",
    "M_GROUP_SUBPROGRAM", "M_END", "M_END_REWIND", "M_TOOL_CHANGE", "M_MIST", "M_FLOOD",
    "M_CALL", "M_RETURN",
    "G_GROUP", "G_UNSUPPORTED", "M_GROUP", "M_UNSUPPORTED", "AXES_EXTRA", "WORD_LETTERS",
    "XYZ", "IJK", "TOKEN",
    "plain_words", "gcode_error", "g_name", "fmt_number", "comp_problem",
]

MM_PER_INCH = 25.4

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

# -- modal groups of G codes (LinuxCNC's numbers) -------------------------------------------
MODAL_GROUP_NON_MODAL = 0  # G4, G10, G53: this block only
MODAL_GROUP_MOTION = 1
MODAL_GROUP_PLANE = 2
MODAL_GROUP_DISTANCE = 3
MODAL_GROUP_ARC_DISTANCE = 4  # of I J K
MODAL_GROUP_FEED_RATE_MODE = 5
MODAL_GROUP_UNITS = 6
MODAL_GROUP_CUTTER_COMP = 7
MODAL_GROUP_TOOL_LENGTH = 8
MODAL_GROUP_RETURN_MODE = 10  # of the canned cycles
MODAL_GROUP_COORD_SYSTEM = 12
MODAL_GROUP_PATH_CONTROL = 13

# -- G codes (x10) ------------------------------------------------------------------------
G_RAPID, G_LINEAR, G_ARC_CW, G_ARC_CCW = 0, 10, 20, 30
G_RIGID_TAP = 331
G_CANCEL_CYCLE = 800  # G80: no motion mode
G_DRILL, G_DRILL_DWELL, G_PECK_DRILL = 810, 820, 830
STRAIGHT_MOTIONS = (G_RAPID, G_LINEAR)
ARC_MOTIONS = (G_ARC_CW, G_ARC_CCW)
CANNED_CYCLES = (G_DRILL, G_DRILL_DWELL, G_PECK_DRILL)
G_PLANE_XY, G_PLANE_ZX, G_PLANE_YZ = 170, 180, 190
G_ABSOLUTE, G_INCREMENTAL = 900, 910
G_ARC_ABSOLUTE, G_ARC_INCREMENTAL = 901, 911
G_FEED_PER_MINUTE = 940
G_INCH, G_MM = 200, 210
G_COMP_OFF, G_COMP_LEFT, G_COMP_RIGHT = 400, 410, 420
G_COMP_LEFT_DIAMETER, G_COMP_RIGHT_DIAMETER = 411, 421  # G41.1/G42.1: D is the diameter
G_TOOL_LENGTH_OFFSET, G_TOOL_LENGTH_CANCEL = 430, 490
G_RETURN_OLD_Z, G_RETURN_R = 980, 990
#: G54 ... G59.3, in the order of their work offsets (index 0-8, LinuxCNC's P1-P9)
G_COORD_SYSTEMS = (540, 550, 560, 570, 580, 590, 591, 592, 593)
G_EXACT_PATH, G_EXACT_STOP, G_BLENDING = 610, 611, 640
G_DWELL, G_SET_OFFSETS, G_MACHINE_COORDS = 40, 100, 530

#: the modal group of each G code the reader runs
G_GROUP = {
    **{code: MODAL_GROUP_MOTION for code in (*STRAIGHT_MOTIONS, *ARC_MOTIONS, G_RIGID_TAP,
                                             G_CANCEL_CYCLE, *CANNED_CYCLES)},
    **{code: MODAL_GROUP_PLANE for code in (G_PLANE_XY, G_PLANE_ZX, G_PLANE_YZ)},
    G_ABSOLUTE: MODAL_GROUP_DISTANCE, G_INCREMENTAL: MODAL_GROUP_DISTANCE,
    G_ARC_ABSOLUTE: MODAL_GROUP_ARC_DISTANCE, G_ARC_INCREMENTAL: MODAL_GROUP_ARC_DISTANCE,
    G_FEED_PER_MINUTE: MODAL_GROUP_FEED_RATE_MODE,
    G_INCH: MODAL_GROUP_UNITS, G_MM: MODAL_GROUP_UNITS,
    **{code: MODAL_GROUP_CUTTER_COMP for code in (G_COMP_OFF, G_COMP_LEFT, G_COMP_RIGHT,
                                                  G_COMP_LEFT_DIAMETER, G_COMP_RIGHT_DIAMETER)},
    G_TOOL_LENGTH_OFFSET: MODAL_GROUP_TOOL_LENGTH, G_TOOL_LENGTH_CANCEL: MODAL_GROUP_TOOL_LENGTH,
    G_RETURN_OLD_Z: MODAL_GROUP_RETURN_MODE, G_RETURN_R: MODAL_GROUP_RETURN_MODE,
    **{code: MODAL_GROUP_COORD_SYSTEM for code in G_COORD_SYSTEMS},
    **{code: MODAL_GROUP_PATH_CONTROL for code in (G_EXACT_PATH, G_EXACT_STOP, G_BLENDING)},
    **{code: MODAL_GROUP_NON_MODAL for code in (G_DWELL, G_SET_OFFSETS, G_MACHINE_COORDS)},
}
#: G codes LinuxCNC has and the reader refuses, with the reason (others: "not supported")
G_UNSUPPORTED = {
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

# -- modal groups of M codes (LinuxCNC's numbers; group 10 is ours) -------------------------
M_GROUP_STOP = 4
M_GROUP_TOOL_CHANGE = 6
M_GROUP_SPINDLE = 7
M_GROUP_COOLANT = 8
M_GROUP_SUBPROGRAM = 10  # M98/M99: Fanuc-style subprogram call and return, as LinuxCNC runs them

M_END, M_END_REWIND = 2, 30
M_TOOL_CHANGE = 6
M_MIST, M_FLOOD = 7, 8  # the one pair of codes that may share a block and a group
M_CALL, M_RETURN = 98, 99

#: the modal group of each M code the reader runs
M_GROUP = {0: M_GROUP_STOP, 1: M_GROUP_STOP, M_END: M_GROUP_STOP, M_END_REWIND: M_GROUP_STOP,
           3: M_GROUP_SPINDLE, 4: M_GROUP_SPINDLE, 5: M_GROUP_SPINDLE,
           M_TOOL_CHANGE: M_GROUP_TOOL_CHANGE,
           M_MIST: M_GROUP_COOLANT, M_FLOOD: M_GROUP_COOLANT, 9: M_GROUP_COOLANT,
           M_CALL: M_GROUP_SUBPROGRAM, M_RETURN: M_GROUP_SUBPROGRAM}
M_UNSUPPORTED: dict[int, str] = {}

#: axis letters of 4- and 5-axis machines: refused by name (3-axis XYZ only)
AXES_EXTRA = "ABCUVW"
#: letters of the words a block may hold besides G, M and N
WORD_LETTERS = set("FSTHPQRLIJKXYZD")
XYZ = "XYZ"
IJK = "IJK"

#: a word of a plain line (letter and number), or a character that starts no word
TOKEN = re.compile(r"([A-Z])[ \t]*([-+]?(?:\d+\.?\d*|\.\d+))|(\S)")


def plain_words(fname: str, lineno: int, s: str) -> list[tuple[str, float, int]]:
    """Words of a line with plain numbers only.

    Parameters
    ----------
    fname : str
        File name for messages.
    lineno : int
        1-based line number for messages.
    s : str
        The line, upper case, comments blanked.

    Returns
    -------
    list of (str, float, int)
        ``(letter, value, column)`` per word, the column 1-based.

    Raises
    ------
    GCodeError
        A letter with no number, a stray character, or a number beyond ``MAX_MAGNITUDE``.
    """
    out = []
    for mt in TOKEN.finditer(s):
        letter, num, junk = mt.groups()
        col = mt.start() + 1
        if junk:
            problem = (f"word {junk} has no number" if junk.isalpha()
                       else f"unexpected character {junk!r}")
            raise GCodeError(fname, lineno, col, junk, problem)
        v = float(num)
        if not math.isfinite(v) or abs(v) > MAX_MAGNITUDE:
            shown = f"{letter}{num[:20]}" + ("..." if len(num) > 20 else "")
            raise GCodeError(fname, lineno, col, shown, "number out of range")
        out.append((letter, v, col))
    return out


def gcode_error(file: str, line: int, col: int | None, word: str, problem: str) -> GCodeError:
    """A GCodeError at a 1-based column (1 if unknown)."""
    return GCodeError(file, line, col or 1, word, problem)


def g_name(code: int) -> str:
    """A G code (x10) as a program writes it: 20 is ``G2``, 331 is ``G33.1``."""
    return f"G{code // 10}" if code % 10 == 0 else f"G{code // 10}.{code % 10}"


def fmt_number(v: float) -> str:
    """A word's value for a message (10 significant digits)."""
    return f"{v:.10g}"


def comp_problem(e: CompError, lineno: int) -> str:
    """A CompError's problem, naming the held-back move's line when it is not ``lineno``."""
    if e.line and e.line != lineno:
        return f"{e.problem}; the move is on line {e.line}"
    return e.problem
