"""What the G-code reader returns: the moves array, its row kinds and planes, and Program.

The interpreter appends one tuple per motion (a *row*, see :data:`ROW_FIELDS`) while it runs;
:func:`moves_from_rows` turns them into the ``MOVE_DTYPE`` array of a :class:`Program` once
the program has run, the start of each move being the end of the one before.

Examples
--------
>>> nan = float("nan")
>>> rows = [(RAPID, 1.0, 2.0, 3.0, nan, nan, nan, PLANE_XY, 0, nan, 0, 1, nan)]
>>> m = moves_from_rows(rows, [0, 0, None])
>>> m["start"].tolist(), m["end"].tolist(), m["known"].tolist()
([[0.0, 0.0, 0.0]], [[1.0, 2.0, 3.0]], [3])
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple, Sequence

import numpy as np

__all__ = [
    "RAPID",
    "LINEAR",
    "ARC_CW",
    "ARC_CCW",
    "MOVE_DTYPE",
    "KNOWN_X",
    "KNOWN_Y",
    "KNOWN_Z",
    "KNOWN_ALL",
    "PLANE_XY",
    "PLANE_ZX",
    "PLANE_YZ",
    "PLANE_AXES",
    "ROW_FIELDS",
    "plane_axes",
    "ToolChange",
    "Program",
    "moves_from_rows",
]

RAPID, LINEAR, ARC_CW, ARC_CCW = 0, 1, 2, 3

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

#: MOVE_DTYPE's ``plane``: the number of the G code that selects it
PLANE_XY, PLANE_ZX, PLANE_YZ = 17, 18, 19

#: (first, second, normal) axis indices of each plane, right-handed as LinuxCNC: G18 is (Z, X).
PLANE_AXES = {PLANE_XY: (0, 1, 2), PLANE_ZX: (2, 0, 1), PLANE_YZ: (1, 2, 0)}

#: The interpreter's row: the fields of MOVE_DTYPE but ``start`` and ``known``, with ``end``
#: and ``center`` spread over three columns each (X, Y, Z). Cutter compensation
#: (:mod:`zmap.sim.cutter_comp`) makes rows of the same layout.
ROW_FIELDS = ("kind", "end_x", "end_y", "end_z", "center_x", "center_y", "center_z", "plane",
              "turns", "feed", "tool", "line", "sweep")


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
        return PLANE_AXES[int(plane)]
    except KeyError:
        raise ValueError(f"plane={_plain(plane)!r} is not one of 17, 18, 19") from None


def _plain(v: Any) -> Any:
    """A numpy scalar as the Python number it holds (messages print 17, not np.int8(17))."""
    return v.item() if isinstance(v, np.generic) else v


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
        The tool table passed to :func:`zmap.sim.gcode.parse`.
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
        >>> from zmap.sim.gcode import parse
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
        for plane in PLANE_AXES:
            sel = arcs[m["plane"][arcs] == plane]
            if sel.size == 0:
                continue
            a, b, _ = PLANE_AXES[plane]
            s, c = m["start"][sel], m["center"][sel]
            sweep = m["sweep"][sel]
            r = np.hypot(s[:, a] - c[:, a], s[:, b] - c[:, b])
            a0 = np.arctan2(s[:, b] - c[:, b], s[:, a] - c[:, a])
            lo_ang = np.minimum(a0, a0 + sweep)
            hi_ang = np.maximum(a0, a0 + sweep)
            # each quarter angle the arc passes is an extreme of the two plane axes
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


def moves_from_rows(rows: Sequence[tuple], known_from: Sequence[int | None]) -> np.ndarray:
    """The moves array of the rows the interpreter made.

    Parameters
    ----------
    rows : sequence of tuple
        One row per motion, laid out as :data:`ROW_FIELDS`.
    known_from : sequence of 3 (int or None)
        Per axis (X, Y, Z), the index of the first row that starts with the axis set by the
        program; None if the program never sets it.

    Returns
    -------
    ndarray of MOVE_DTYPE, shape (len(rows),)
        The first move starts at the origin, each other at the end of the one before.
    """
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
        if known_from[i] is not None:
            moves["known"][known_from[i]:] |= 1 << i
    return moves
