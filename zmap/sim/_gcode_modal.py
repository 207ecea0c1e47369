"""The G-code block interpreter: one block's words, run group by group in LinuxCNC's order.

:func:`run_block` reads a block's words into G and M codes of modal groups and other words
(:func:`_read_block`), then runs one small handler per modal group (and per word that acts on
its own: F, S, T) in the order of rs274ngc's ``execute_block``, each reading the state before
the block and writing the state after it into the :class:`~zmap.sim._gcode_state.Block`.
The block's words must all be taken by some code; only then is the new state committed.
Motion (group 1) is :mod:`zmap.sim._gcode_motion`'s.

Examples
--------
>>> from zmap.sim._gcode_state import InterpState
>>> st = InterpState("x.nc", None)
>>> run_block(st, [("G", 20.0, 1), ("G", 91.0, 5), ("X", 1.0, 9)], 1)
Traceback (most recent call last):
...
zmap.errors.GCodeError: x.nc:1:9: X1: axis word with no active motion mode (G80 in effect)
>>> run_block(st, [("G", 20.0, 1), ("G", 91.0, 5), ("G", 0.0, 9), ("X", 1.0, 12)], 1)
>>> st.units, st.absolute, st.pos
('inch', False, [25.4, 0.0, 0.0])
"""

from __future__ import annotations

import math
from typing import Callable

from ._gcode_codes import (AXES_EXTRA, CANNED_CYCLES, G_ABSOLUTE, G_ARC_ABSOLUTE, G_BLENDING,
                           G_CANCEL_CYCLE, G_COMP_LEFT, G_COMP_LEFT_DIAMETER, G_COMP_OFF,
                           G_COMP_RIGHT, G_COORD_SYSTEMS, G_DWELL, G_GROUP, G_INCH, G_RETURN_R,
                           G_SET_OFFSETS, G_TOOL_LENGTH_CANCEL, G_TOOL_LENGTH_OFFSET,
                           G_UNSUPPORTED, M_CALL, M_END, M_END_REWIND, M_FLOOD, M_GROUP,
                           M_GROUP_STOP, M_GROUP_SUBPROGRAM, M_GROUP_TOOL_CHANGE, M_MIST,
                           M_RETURN, M_TOOL_CHANGE, M_UNSUPPORTED, MAX_COORD_MM, MAX_TOOL,
                           MM_PER_INCH, MODAL_GROUP_ARC_DISTANCE, MODAL_GROUP_COORD_SYSTEM,
                           MODAL_GROUP_CUTTER_COMP, MODAL_GROUP_DISTANCE, MODAL_GROUP_MOTION,
                           MODAL_GROUP_NON_MODAL, MODAL_GROUP_PATH_CONTROL, MODAL_GROUP_PLANE,
                           MODAL_GROUP_RETURN_MODE, MODAL_GROUP_TOOL_LENGTH, MODAL_GROUP_UNITS,
                           WORD_LETTERS, XYZ, comp_problem, fmt_number, g_name, gcode_error)
from ._gcode_motion import g18_rows, motion
from ._gcode_program import PLANE_YZ, PLANE_ZX, ToolChange
from ._gcode_state import Block, InterpState
from .cutter_comp import CompError, CutterComp

__all__ = ["run_block"]

#: largest program number M98 P may call (Fanuc's O-numbers have up to 8 digits)
_MAX_PROGRAM_NUMBER = 99_999_999


def run_block(st: InterpState, toks: list[tuple[str, float, int]], lineno: int) -> None:
    """Interpret one block (the words of one line) in LinuxCNC's order of execution.

    Parameters
    ----------
    st : InterpState
        The state before the block; the state after it when the block runs without error.
    toks : list of (str, float, int)
        ``(letter, value, column)`` per word: values in program units, already read from
        numbers, parameters or expressions.
    lineno : int
        1-based line of the block in ``st.file``.

    Raises
    ------
    GCodeError
        An unsupported or invalid block. ``st`` may then hold rows of the block's move (the
        runner's snapshot undoes them under ``lenient``).
    """
    b = _read_block(st, toks, lineno)
    for step in _STEPS:
        step(b)
    unused = [w for w in b.words if w not in b.used]
    if unused:
        w = min(unused, key=lambda x: b.columns[x])
        raise b.word_error(w, f"{w} word is not used by any code in the block")
    _commit(b)


def _read_block(st: InterpState, toks: list[tuple[str, float, int]], lineno: int) -> Block:
    """Sort a block's words into G and M codes by modal group and other words, checked."""
    file = st.file
    gcodes: list[tuple[int, int]] = []
    mcodes: list[tuple[int, int]] = []
    words: dict[str, float] = {}
    columns: dict[str, int] = {}
    for letter, v, k in toks:
        if letter == "G":
            code = round(v * 10) if abs(v) < 1e4 else -1
            if abs(v * 10 - code) > 1e-6 or code not in G_GROUP:
                problem = G_UNSUPPORTED.get(code, f"G{fmt_number(v)} is not a supported G code")
                raise gcode_error(file, lineno, k, f"G{fmt_number(v)}", problem)
            gcodes.append((code, k))
        elif letter == "M":
            code = int(v) if abs(v) < 1e4 else -1
            if code != v or code not in M_GROUP:
                problem = M_UNSUPPORTED.get(code, f"M{fmt_number(v)} is not a supported M code")
                raise gcode_error(file, lineno, k, f"M{fmt_number(v)}", problem)
            mcodes.append((code, k))
        elif letter == "N":
            continue
        elif letter in WORD_LETTERS:
            if letter in words:
                raise gcode_error(file, lineno, k, f"{letter}{fmt_number(v)}",
                                  f"{letter} word appears twice in the block")
            words[letter] = v
            columns[letter] = k
        elif letter in AXES_EXTRA:
            raise gcode_error(file, lineno, k, f"{letter}{fmt_number(v)}",
                              f"axis {letter} is not supported (3-axis XYZ only)")
        else:
            raise gcode_error(file, lineno, k, f"{letter}{fmt_number(v)}",
                              f"word {letter} is not supported")

    # At most one code per modal group; G80 may join a motion code (it runs first: see
    # docs/gcode.md, cameo.nc has such blocks), M7 and M8 (mist and flood) may combine.
    groups: dict[int, int] = {}
    g_columns: dict[int, int] = {}
    cancel_cycle = False
    for code, k in gcodes:
        grp = G_GROUP[code]
        if code == G_CANCEL_CYCLE:
            cancel_cycle = True
            if MODAL_GROUP_MOTION in groups:
                continue
        if grp in groups and not (grp == MODAL_GROUP_MOTION and groups[grp] == G_CANCEL_CYCLE):
            raise gcode_error(file, lineno, k, g_name(code),
                              f"{g_name(groups[grp])} and {g_name(code)} are in the same "
                              f"modal group")
        groups[grp] = code
        g_columns[code] = k
    m_groups: dict[int, int] = {}
    for code, k in mcodes:
        grp = M_GROUP[code]
        if grp in m_groups and {m_groups[grp], code} != {M_MIST, M_FLOOD}:
            raise gcode_error(file, lineno, k, f"M{code}",
                              f"M{m_groups[grp]} and M{code} are in the same modal group")
        m_groups[grp] = code
    return Block(st, lineno, words, columns, groups, g_columns, cancel_cycle, m_groups, mcodes)


# -- the steps of a block, in LinuxCNC's order (rs274ngc's step numbers in parentheses) -----

def _units(b: Block) -> None:
    """Group 6, G20/G21 (12.): first of all, as the block's own values are in its units."""
    b.units = b.st.units
    if MODAL_GROUP_UNITS in b.groups:
        b.units = "inch" if b.groups[MODAL_GROUP_UNITS] == G_INCH else "mm"
    b.scale = MM_PER_INCH if b.units == "inch" else 1.0


def _feed_and_speed(b: Block) -> None:
    """F (3.) in program units per minute, stored in mm/min; S (4.) in rev/min.

    Group 5 has G94 (units per minute) only: the feed needs nothing of it.
    """
    words = b.words
    b.feed, b.speed = b.st.feed, b.st.speed
    if "F" in words:
        if words["F"] < 0:
            raise b.word_error("F", "feed rate must not be negative")
        b.feed = words["F"] * b.scale
        b.used.add("F")
    if "S" in words:
        if words["S"] < 0:
            raise b.word_error("S", "spindle speed must not be negative")
        b.speed = words["S"]
        b.used.add("S")


def _select_tool(b: Block) -> None:
    """T (5.): the tool M6 will load, which must be in the tool table if there is one."""
    b.selected_tool = _tool_number(b, "T", b.st.selected_tool, "tool number")
    if "T" not in b.words:
        return
    b.used.add("T")
    table = b.st.tool_table
    if table is not None and b.selected_tool != 0 and b.selected_tool not in table:
        have = ", ".join(str(x) for x in sorted(table)) or "none"
        raise b.word_error("T", f"tool {b.selected_tool} is not in the tool table "
                                f"(tools: {have})")


def _tool_number(b: Block, letter: str, default: int, name: str) -> int:
    """The tool number word ``letter`` gives (``default`` without it), checked 0..MAX_TOOL."""
    if letter not in b.words:
        return default
    v = b.words[letter]
    if v < 0 or v != int(v) or v > MAX_TOOL:
        raise b.word_error(letter, f"{name} must be an integer 0..{MAX_TOOL}")
    return int(v)


def _change_tool(b: Block) -> None:
    """M group 6, M6 (6.): load the selected tool."""
    b.tool, b.tool_changed = b.st.tool, False
    if b.m_groups.get(M_GROUP_TOOL_CHANGE) != M_TOOL_CHANGE:
        return
    if b.st.comp is not None:
        raise gcode_error(b.st.file, b.lineno, None, "M6", "tool change with cutter "
                                                           "compensation on (G40 first)")
    b.tool = b.selected_tool
    b.tool_changed = True


def _call_subprogram(b: Block) -> None:
    """M group 10 (ours), M98 P L: call program O<P> L times.

    The runner makes the call once the block has run; M99, the return, is the runner's too.
    """
    b.call = None
    if b.m_groups.get(M_GROUP_SUBPROGRAM) != M_CALL:
        return
    words = b.words
    if "P" not in words:
        raise gcode_error(b.st.file, b.lineno, None, "M98", "M98 needs a P word (the program "
                                                            "number)")
    pv = words["P"]
    if pv < 0 or pv != int(pv) or pv > _MAX_PROGRAM_NUMBER:
        raise b.word_error("P", f"M98 P must be a program number 0..{_MAX_PROGRAM_NUMBER}")
    count = 1
    if "L" in words:
        lv = words["L"]
        if lv < 0 or lv != int(lv) or lv > b.st.max_moves:
            raise b.word_error("L", f"M98 L (repeats) must be an integer 0..{b.st.max_moves}")
        count = int(lv)
    b.call = (int(pv), count)
    b.used.update(("P", "L"))


def _dwell(b: Block) -> None:
    """Group 0, G4 P (10.): a dwell, which moves nothing."""
    if b.groups.get(MODAL_GROUP_NON_MODAL) != G_DWELL:
        return
    if "P" not in b.words:
        raise b.code_error(G_DWELL, "G4 dwell needs a P word (seconds)")
    if b.words["P"] < 0:
        raise b.word_error("P", "dwell time must not be negative")
    b.used.add("P")


def _plane(b: Block) -> None:
    """Group 2, G17/G18/G19 (11.): the plane, kept as the moves' plane column has it."""
    b.plane = b.groups[MODAL_GROUP_PLANE] // 10 if MODAL_GROUP_PLANE in b.groups else b.st.plane


def _tool_length(b: Block) -> None:
    """Group 8, G43 H / G49 (14., before 13. here: compensation starts from the new tip).

    G43's H defaults to the loaded tool; its length offset comes from the tool table.
    """
    b.tlo = b.st.tlo
    code = b.groups.get(MODAL_GROUP_TOOL_LENGTH)
    if code == G_TOOL_LENGTH_OFFSET:
        h = _tool_number(b, "H", b.tool, "H")
        if "H" in b.words:
            b.used.add("H")
        entry = b.st.tool_entry(h)
        if entry is None and b.st.tool_table is not None and h != 0:
            raise b.error_at("H", G_TOOL_LENGTH_OFFSET,
                             f"tool {h} (G43 H) is not in the tool table")
        b.tlo = float(getattr(entry, "length_offset", 0.0))
    elif code == G_TOOL_LENGTH_CANCEL:
        b.tlo = 0.0


def _cutter_comp(b: Block) -> None:
    """Group 7, G40/G41/G42/G41.1/G42.1 (13.): start or end cutter radius compensation.

    While it is on, the block may not change the plane or the coordinate system.
    """
    st = b.st
    b.comp = st.comp
    code = b.groups.get(MODAL_GROUP_CUTTER_COMP)
    if code is not None and code != G_COMP_OFF:
        b.comp = _start_comp(b, code)
    elif code == G_COMP_OFF and b.comp is not None:
        try:
            b.comp.flush()
        except CompError as e:
            raise b.code_error(G_COMP_OFF, comp_problem(e, b.lineno)) from None
        b.comp = None
    if st.comp is not None and b.comp is not None:
        if MODAL_GROUP_COORD_SYSTEM in b.groups:
            raise b.code_error(b.groups[MODAL_GROUP_COORD_SYSTEM],
                               "coordinate system change with cutter compensation on")
        if b.plane != st.plane:
            raise b.code_error(b.groups[MODAL_GROUP_PLANE],
                               "plane change with cutter compensation on")


def _start_comp(b: Block, code: int) -> CutterComp:
    """The compensation G41/G42 (D: a tool number) or G41.1/G42.1 (D: the diameter) starts."""
    st = b.st
    if b.comp is not None:
        raise b.code_error(code, "cutter compensation is already on (G40 first)")
    if b.plane == PLANE_YZ:  # LinuxCNC: "radius compensation only in XY or XZ plane"
        raise b.code_error(code, "cutter compensation in the G19 plane is not supported "
                                 "(G17 and G18 only, as LinuxCNC)")
    if code in (G_COMP_LEFT, G_COMP_RIGHT):
        d = _tool_number(b, "D", b.tool, "D (tool number)")
        if st.tool_table is not None and d != 0 and st.tool_entry(d) is None:
            raise b.error_at("D", code, f"tool {d} is not in the tool table")
        radius = st.tool_diameter(d) / 2.0
    else:
        if "D" not in b.words:
            raise b.code_error(code, f"{g_name(code)} needs a D word (the diameter)")
        radius = b.words["D"] * b.scale / 2.0  # negative: the other side, as LinuxCNC
    b.used.add("D")
    pos0 = list(st.pos)
    pos0[2] -= b.tlo - st.tlo
    side = "left" if code in (G_COMP_LEFT, G_COMP_LEFT_DIAMETER) else "right"
    if radius < 0:  # LinuxCNC: a negative radius (D or table) cuts on the other side
        radius = -radius
        side = "right" if side == "left" else "left"
    if b.plane == PLANE_ZX:  # the XY engine in the (Z, X, Y) frame: G18 is right-handed as G17
        return CutterComp(side, radius, (pos0[2], pos0[0], pos0[1]), g18_rows(st.rows.append))
    return CutterComp(side, radius, tuple(pos0), st.rows.append)


def _coordinate_system(b: Block) -> None:
    """Group 12, G54 ... G59.3 (15.): the work offset in force."""
    b.cs = b.st.cs
    if MODAL_GROUP_COORD_SYSTEM in b.groups:
        b.cs = G_COORD_SYSTEMS.index(b.groups[MODAL_GROUP_COORD_SYSTEM])


def _path_control(b: Block) -> None:
    """Group 13, G61/G61.1/G64 (16.): nothing to do for a path of tool-tip positions.

    G64's P and Q (blending tolerances) are taken and ignored (a G4's P stays the dwell's).
    """
    if b.groups.get(MODAL_GROUP_PATH_CONTROL) == G_BLENDING:
        for w in "PQ":
            if w in b.words and b.groups.get(MODAL_GROUP_NON_MODAL) != G_DWELL:
                b.used.add(w)


def _distance_modes(b: Block) -> None:
    """Groups 3 and 4 (17.): G90/G91 for the axes, G90.1/G91.1 for arc centres (I J K)."""
    groups = b.groups
    b.absolute = (groups[MODAL_GROUP_DISTANCE] == G_ABSOLUTE
                  if MODAL_GROUP_DISTANCE in groups else b.st.absolute)
    b.ijk_absolute = (groups[MODAL_GROUP_ARC_DISTANCE] == G_ARC_ABSOLUTE
                      if MODAL_GROUP_ARC_DISTANCE in groups else b.st.ijk_absolute)


def _return_mode(b: Block) -> None:
    """Group 10, G98/G99 (18.): canned cycles retract to the old Z or to R."""
    b.retract_r = (b.groups[MODAL_GROUP_RETURN_MODE] == G_RETURN_R
                   if MODAL_GROUP_RETURN_MODE in b.groups else b.st.retract_r)


def _set_offsets(b: Block) -> None:
    """Group 0, G10 L2 P X Y Z (19.): set a work offset; the block's axis words are its."""
    words = b.words
    b.offsets = b.st.offsets
    b.any_axis = "X" in words or "Y" in words or "Z" in words
    if b.groups.get(MODAL_GROUP_NON_MODAL) != G_SET_OFFSETS:
        return
    if "L" not in words or words["L"] != 2:
        raise b.code_error(G_SET_OFFSETS, "only G10 L2 (set a work offset) is supported"
                           + (f", got L{fmt_number(words['L'])}" if "L" in words
                              else ", L word missing"))
    if "P" not in words:
        raise b.code_error(G_SET_OFFSETS, "G10 L2 needs a P word (0 = current, 1-9 = "
                                          "G54-G59.3)")
    p = words["P"]
    if p != int(p) or not 0 <= p <= 9:
        raise b.word_error("P", f"G10 L2 P must be an integer 0..9, got {fmt_number(p)}")
    if "R" in words:
        raise b.word_error("R", "rotated coordinate systems (G10 L2 R) are not supported")
    idx = b.cs if p == 0 else int(p) - 1
    b.offsets = [list(o) for o in b.offsets]
    for i, w in enumerate(XYZ):
        if w in words:
            if abs(words[w] * b.scale) > MAX_COORD_MM:
                raise b.word_error(w, f"offset beyond the work envelope (|{w}| <= "
                                      f"{MAX_COORD_MM:g} mm)")
            b.offsets[idx][i] = words[w] * b.scale
    b.used.update(("L", "P", "X", "Y", "Z"))
    b.any_axis = False  # taken by G10: the block does not move


def _stop(b: Block) -> None:
    """M group 4, M2/M30 (21.): the program ends after this block (M0, M1: nothing)."""
    b.ended = b.m_groups.get(M_GROUP_STOP) in (M_END, M_END_REWIND)


#: the handlers, in the order they run
_STEPS: tuple[Callable[[Block], None], ...] = (
    _units, _feed_and_speed, _select_tool, _change_tool, _call_subprogram, _dwell, _plane,
    _tool_length, _cutter_comp, _coordinate_system, _path_control, _distance_modes,
    _return_mode, _set_offsets, motion, _stop,
)


def _commit(b: Block) -> None:
    """Write the state the block leaves into ``b.st``."""
    st = b.st
    st.pos = list(b.new_pos)
    st.mark(b.set_axes, b.set_at)
    st.units = b.units
    if MODAL_GROUP_UNITS in b.groups and st.units_seen is None:
        st.units_seen = b.units
    st.feed = b.feed
    st.selected_tool = b.selected_tool
    if b.tool_changed:
        st.tool = b.tool
        st.tool_changes.append(ToolChange(b.n_before, b.tool, b.lineno))
    st.plane = b.plane
    st.cs = b.cs
    st.absolute = b.absolute
    st.ijk_absolute = b.ijk_absolute
    st.retract_r = b.retract_r
    st.offsets = b.offsets
    st.motion = b.motion
    st.cycle_r, st.cycle_z, st.cycle_q = b.cycle_r, b.cycle_z, b.cycle_q
    st.tlo = b.tlo
    st.speed = b.speed
    st.comp = b.comp
    if b.motion not in CANNED_CYCLES:  # a run of cycles ends: the next starts a new one
        st.cycle_il = math.nan
    st.call = b.call
    st.m99 = b.m_groups.get(M_GROUP_SUBPROGRAM) == M_RETURN
    stop = b.m_groups.get(M_GROUP_STOP) if b.ended else M_RETURN if st.m99 else None
    if stop is not None:
        st.stop = (f"M{stop}", next(k for code, k in b.m_codes if code == stop))
    if b.ended:
        st.ended = True
