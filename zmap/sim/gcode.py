"""A reader for 3-axis milling programs (RS274/NGC as LinuxCNC, CAM systems and people write it).

:func:`parse` turns a program into a :class:`Program`: one row per elementary motion (rapid,
feed, clockwise or counter-clockwise arc) in a numpy structured array (:data:`MOVE_DTYPE`), in
millimetres whatever the program's units, as tool-tip positions in machine coordinates. The
semantics are those of LinuxCNC's interpreter (rs274ngc), block by block in its order of
execution.

Supported:

* motion: ``G0``, ``G1``; ``G2``/``G3`` arcs with ``I J K`` or ``R`` in ``G17``/``G18``/``G19``
  (helical, ``P`` turns); rigid tapping ``G33.1`` (in G17); the drilling cycles ``G81``,
  ``G82``, ``G83`` with ``G98``/``G99``, ``L`` repeats and ``G91`` semantics, cancelled by
  ``G80``, expanded into the rapids and feeds LinuxCNC commands;
* modes and offsets: ``G20``/``G21``, ``G90``/``G91``, ``G90.1``/``G91.1``, ``G94``, the work
  offsets ``G54``-``G59.3`` set by ``G10 L2``, ``G53`` (with G0/G1 under G90); ``G4`` (a dwell),
  ``G61``, ``G61.1``, ``G64`` and ``M0``, ``M1``, ``M3``-``M5``, ``M7``-``M9`` are accepted and
  move nothing; ``M2``/``M30`` end the program;
* tools: ``T``, ``M6``, ``G43 H`` (the tip's programmed Z shifted by the tool's length offset),
  ``G49``, checked against a tool table when one is given;
* cutter radius compensation ``G40``, ``G41``/``G42 D`` (a tool number), ``G41.1``/``G42.1 D``
  (a diameter) in G17 and G18, as LinuxCNC's interpreter performs it
  (:mod:`zmap.sim.cutter_comp`);
* LinuxCNC's language (:mod:`zmap.sim.ngc`): ``#`` parameters (numbered, named, global and
  the read-only machine state), ``[...]`` expressions and functions, and O-word control flow
  (``sub``/``endsub``/``call``/``return``, ``while``, ``do``, ``repeat``,
  ``if``/``elseif``/``else``, ``break``, ``continue``), subroutines from ``<name>.ngc`` files;
  Fanuc-style ``M98 P L`` subprograms ``O<n>`` ... ``M99``;
* comments ``( )`` and ``;``, ``N`` numbers, block delete ``/``, ``%`` tape marks, lower case.

Refused, with :class:`zmap.errors.GCodeError` naming ``file:line:column`` and the word:
``G5``/``G5.1``/``G5.2``, ``G7``/``G8``, ``G28``/``G30``, ``G33``, ``G38.x``,
``G43.1``/``G43.2``, ``G73``, ``G74``, ``G76``, ``G84``-``G89``, ``G92``, ``G93``, ``G95``,
``G10`` other than ``L2`` (and ``G10 L2 R``), any other G or M code, axes other than X Y Z and
letters the dialect does not have; cutter compensation in G19, and a tool change, canned cycle,
``G33.1``, ``G53``, plane or coordinate-system change while it is on; invalid blocks (a word
twice, two codes of one modal group, a word no code of the block uses, an arc or cycle that
cannot be made, a feed move with no feed rate, a compensated corner the tool cannot cut, ...);
and what crosses the limits (coordinates beyond :data:`MAX_COORD_MM`, numbers beyond 1e100,
tool numbers beyond :data:`MAX_TOOL`, arcs of more than :data:`MAX_TURNS` turns, more than
``max_blocks`` blocks run again or ``max_moves`` moves). With ``lenient=True`` an invalid block
is skipped, its state undone, and counted in :attr:`Program.warnings`; only the limits stop a
lenient parse. ``docs/gcode.md`` has the full list.

Notes
-----
This module is the reader's public face; the work is done by private modules, each with one
job: :mod:`~zmap.sim._gcode_codes` (codes, modal groups, limits, messages),
:mod:`~zmap.sim._gcode_program` (the moves and :class:`Program`),
:mod:`~zmap.sim._gcode_state` (the interpreter's state), :mod:`~zmap.sim._gcode_modal` (a
block, one handler per modal group), :mod:`~zmap.sim._gcode_motion` (group 1: the moves),
:mod:`~zmap.sim._gcode_runner` (files, O-word flow, calls, lenient mode).

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

import os
from typing import Any, Mapping, Sequence

from ..errors import GCodeError
from ._arcs import arc_sweep
from ._gcode_codes import MAX_BLOCKS, MAX_MOVES, MM_PER_INCH, comp_problem
from ._gcode_motion import fast_block as _fast_block
from ._gcode_program import (ARC_CCW, ARC_CW, KNOWN_ALL, LINEAR, MOVE_DTYPE, RAPID, Program,
                             ToolChange, moves_from_rows, plane_axes)
from ._gcode_runner import Runner, Source, read_source, split_lines, subroutine_dirs
from ._gcode_state import InterpState
from .cutter_comp import CompError

# Importable from here as they were before the reader was split, though not in __all__: the
# limits, the bits of ``known``, and _PLANE_AXES (path.py and pieces.py take it). Tests replace
# _fast_block here to run every block through the full interpreter: parse looks it up here.
from ._gcode_codes import MAX_COORD_MM, MAX_TOOL, MAX_TURNS  # noqa: E402,F401
from ._gcode_program import KNOWN_X, KNOWN_Y, KNOWN_Z  # noqa: E402,F401
from ._gcode_program import PLANE_AXES as _PLANE_AXES  # noqa: E402,F401

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
    text, fname = read_source(source, filename)
    table: dict[int, Any] | None
    if tool_table is None:
        table = None
    elif isinstance(tool_table, (str, os.PathLike)):
        from .tools import load_tool_table

        table = load_tool_table(tool_table)
    else:
        table = dict(tool_table)

    lines = split_lines(text)
    st = InterpState(fname, table)
    warnings: list[str] = []
    src = Source.from_lines(lines, fname, block_delete, lenient, warnings)
    # _fast_block is looked up here at each call, so that replacing it in this module counts
    runner = Runner(st, src, lenient, warnings, max_blocks, max_moves, block_delete,
                    fast_block=_fast_block)
    runner.sub_dirs = subroutine_dirs(subroutine_path, fname)
    runner.run()
    if st.comp is not None:
        _end_compensation(st, runner.end_at, lenient, warnings)
    return Program(
        moves=moves_from_rows(st.rows, st.known_from),
        units_input=st.units_seen or "mm",
        warnings=warnings,
        tool_changes=st.tool_changes,
        n_lines=len(lines),
        filename=fname,
        tool_table=table,
    )


def _end_compensation(st: InterpState, end_at: tuple[str, int, int, str], lenient: bool,
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
                         f"{comp_problem(e, line)}; cutter compensation was still on when the "
                         f"program ended (G40 ends it)")
        if not lenient:
            raise err from None
        warnings.append(str(err))
        st.comp.discard()
    st.comp = None
