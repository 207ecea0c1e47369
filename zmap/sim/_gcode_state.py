"""The G-code interpreter's state: the modal state between blocks, and the block being run.

:class:`InterpState` is the machine as the program left it (position, modes, offsets, tool,
parameters) and the rows of the moves made so far. :class:`Block` is one block while it runs:
its words and codes, and the state it will leave, which the handlers of the modal groups
(:mod:`zmap.sim._gcode_modal`, :mod:`zmap.sim._gcode_motion`) fill in step by step from the
state before it and which is committed only when the whole block has been read without error.

Examples
--------
>>> from zmap.sim._gcode_program import KNOWN_X, KNOWN_Z
>>> st = InterpState("x.nc", None)
>>> st.mark(KNOWN_X | KNOWN_Z, 3)
>>> st.known, st.known_from
(5, [3, None, 3])
>>> st.params.get("<_METRIC>"), st.params.get(5220)
(1.0, 1.0)
"""

from __future__ import annotations

import copy
import math
from typing import Any, Callable, Mapping

from ..errors import GCodeError
from ._gcode_codes import (G_CANCEL_CYCLE, G_COORD_SYSTEMS, MAX_MOVES, MM_PER_INCH, fmt_number,
                           g_name, gcode_error)
from ._gcode_program import PLANE_XY, ToolChange
from .cutter_comp import CutterComp
from .ngc import Parameters

__all__ = ["InterpState", "Block"]


class InterpState:
    """Modal state of the interpreter; moves are appended to ``rows`` as float rows.

    Parameters
    ----------
    filename : str
        Name of the file being run, for messages (the runner changes it as calls go into
        other files).
    tool_table : mapping of int to Cutter, or None
        Tools that T, G43 H and G41/G42 D may name (any, when None).
    """

    def __init__(self, filename: str, tool_table: Mapping[int, Any] | None):
        self.file = filename
        self.tool_table = tool_table
        self.rows: list[tuple] = []  # laid out as _gcode_program.ROW_FIELDS
        self.pos = [0.0, 0.0, 0.0]  # machine coordinates, mm
        self.plane = PLANE_XY
        self.units = "mm"
        self.units_seen: str | None = None
        self.absolute = True
        self.ijk_absolute = False
        self.motion = G_CANCEL_CYCLE  # no motion mode until the program sets one
        self.retract_r = False  # G98 (old Z) by default, as LinuxCNC
        self.offsets = [[0.0, 0.0, 0.0] for _ in range(len(G_COORD_SYSTEMS))]
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
        self.comp: CutterComp | None = None  # while G41/G42 is on
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
        sysp["_COORD_SYSTEM"] = lambda: float(G_COORD_SYSTEMS[self.cs])
        sysp["_METRIC"] = lambda: float(self.units == "mm")
        sysp["_IMPERIAL"] = lambda: float(self.units == "inch")
        sysp["_ABSOLUTE"] = lambda: float(self.absolute)
        sysp["_INCREMENTAL"] = lambda: float(not self.absolute)
        sysp["_FEED"] = lambda: 0.0 if math.isnan(self.feed) else self.feed / self.scale()
        sysp[5410] = lambda: self.tool_diameter(self.tool) / self.scale()
        # LinuxCNC's return value of the last subroutine: 0 until a return or endsub sets it
        self.params.globals["_VALUE"] = 0.0
        self.params.globals["_VALUE_RETURNED"] = 0.0
        for cs in range(len(G_COORD_SYSTEMS)):  # #5221-#5229 G54 ... #5381-#5389 G59.3
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
        """The tool table's entry of a tool, or None (no table, or not in it)."""
        return None if self.tool_table is None else self.tool_table.get(number)

    def tool_diameter(self, number: int) -> float:
        """Diameter of a tool in the table, mm (0 if unknown)."""
        return float(getattr(self.tool_entry(number), "diameter", 0.0))

    # -- state snapshot for lenient mode ---------------------------------------------------
    def snapshot(self, params: bool = True) -> tuple:
        """What :meth:`restore` needs to undo a block (``params``: copy the parameters too)."""
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
        """Go back to a :meth:`snapshot`: rows and tool changes made since are dropped."""
        n, nt, state, params = snap
        self.__dict__.update(state)
        if params is not None:
            self.params.restore(params)
        del self.rows[n:]
        del self.tool_changes[nt:]


class Block:
    """One block while it runs: its words and codes, and the modal state it will leave.

    The block's steps (:mod:`zmap.sim._gcode_modal`) run in LinuxCNC's order, and each sets
    the fields of the state after the block that are its own, from ``st``'s (the state
    before) and the block's words; a later step reads what an earlier one set. ``st`` itself
    gains only the rows of the block's moves (and a canned cycle's marks of known axes) until
    the block is committed.

    Parameters
    ----------
    st : InterpState
        The state before the block.
    lineno : int
        1-based line of the block in ``st.file``.
    words : dict of str to float
        Value of each word other than G, M and N, in program units.
    columns : dict of str to int
        1-based column of each of those words.
    groups : dict of int to int
        The G code (x10) of each modal group named in the block.
    g_columns : dict of int to int
        Column of each of those G codes.
    cancel_cycle : bool
        The block has G80 (which may share it with another motion code).
    m_groups : dict of int to int
        The M code of each M modal group named in the block.
    m_codes : list of (int, int)
        Every M code of the block and its column.

    Attributes
    ----------
    used : set of str
        Letters of the words some code of the block has taken.
    units, scale
        ``"mm"`` or ``"inch"``, and mm per unit of the block's values (the units step).
    feed, speed
        mm/min and rev/min (the F and S step).
    selected_tool, tool, tool_changed
        T, the loaded tool, and whether M6 loaded it (the T and M6 steps).
    call
        ``(P, L)`` of an M98, else None (the M98 step).
    plane, tlo, comp, cs
        17/18/19, tool length offset (mm), the running CutterComp or None, work offset index.
    absolute, ijk_absolute, retract_r
        Distance modes (G90, G90.1) and the canned cycles' return mode (G99).
    offsets, any_axis
        The work offsets (G10 L2), and whether X, Y or Z words are left for a move.
    motion, cycle_r, cycle_z, cycle_q, new_pos, n_before, set_axes, set_at
        The motion step's: motion mode (x10), the cycles' modal R, Z, Q (mm), the position
        after the block, the rows before it, the axes its move sets and the first row that
        starts with them set.
    ended
        M2 or M30: the program ends with the block.
    """

    __slots__ = ("st", "lineno", "words", "columns", "groups", "g_columns", "cancel_cycle",
                 "m_groups", "m_codes", "used", "units", "scale", "feed", "speed",
                 "selected_tool", "tool", "tool_changed", "call", "plane", "tlo", "comp", "cs",
                 "absolute", "ijk_absolute", "retract_r", "offsets", "any_axis", "motion",
                 "cycle_r", "cycle_z", "cycle_q", "new_pos", "n_before", "set_axes", "set_at",
                 "ended")

    def __init__(self, st: InterpState, lineno: int, words: dict[str, float],
                 columns: dict[str, int], groups: dict[int, int], g_columns: dict[int, int],
                 cancel_cycle: bool, m_groups: dict[int, int], m_codes: list[tuple[int, int]]):
        self.st = st
        self.lineno = lineno
        self.words = words
        self.columns = columns
        self.groups = groups
        self.g_columns = g_columns
        self.cancel_cycle = cancel_cycle
        self.m_groups = m_groups
        self.m_codes = m_codes
        self.used: set[str] = set()

    def word_error(self, letter: str, problem: str) -> GCodeError:
        """A GCodeError at a word of the block."""
        return gcode_error(self.st.file, self.lineno, self.columns[letter],
                           f"{letter}{fmt_number(self.words[letter])}", problem)

    def code_error(self, code: int, problem: str) -> GCodeError:
        """A GCodeError at a G code (x10) of the block, or at column 1 if it is modal only."""
        return gcode_error(self.st.file, self.lineno, self.g_columns.get(code), g_name(code),
                           problem)

    def error_at(self, letters: str, code: int, problem: str) -> GCodeError:
        """A GCodeError at the first of ``letters`` the block has, else at G code ``code``."""
        w = next((w for w in letters if w in self.words), None)
        return self.word_error(w, problem) if w else self.code_error(code, problem)
