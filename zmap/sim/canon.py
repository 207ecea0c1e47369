"""LinuxCNC canonical moves: read an ``rs274 -g`` listing, and list a Program's moves the same way.

LinuxCNC's standalone interpreter prints every motion as a canonical call, e.g.
``STRAIGHT_FEED(1.0000, 0.0000, -0.5000, ...)`` or ``ARC_FEED(first_end, second_end,
first_centre, second_centre, rotation, axis_end, ...)``, in program units. These two functions
put its listing and a :class:`zmap.sim.gcode.Program` side by side, so that the reader can be
checked move for move against LinuxCNC's own output (``bench/linuxcnc_expected.py``, tests).

Examples
--------
>>> from zmap.sim.gcode import parse
>>> program_moves(parse("G21 G0 X1\\nG2 X2 I0.5 F10\\n"))
[('STRAIGHT_TRAVERSE', [1.0, 0.0, 0.0]), ('ARC -1', [2.0, 0.0, 0.0, 1.5, 0.0])]
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from .gcode import MM_PER_INCH, Program

__all__ = ["expected_moves", "program_moves"]

_CANON = re.compile(r"\b(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED)\((.*)\)\s*$")
_AXES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}


def expected_moves(path: str | os.PathLike) -> list[tuple[str, list[float]]]:
    """Every move of an ``rs274 -g`` listing: kind and numbers, in program units.

    Lines are ``("STRAIGHT_TRAVERSE" | "STRAIGHT_FEED", [x, y, z])``; arcs are
    ``("ARC n", [first end, second end, axis end, first centre, second centre])`` with ``n``
    LinuxCNC's rotation (+1 a counter-clockwise arc, -1 clockwise, +-k with k-1 extra turns).
    """
    out = []
    for raw in Path(path).read_text().splitlines():
        m = _CANON.search(raw)
        if m:
            a = [float(v) for v in m.group(2).split(",")]
            if m.group(1) == "ARC_FEED":  # first end, second end, centre, rotation, axis end
                out.append((f"ARC {int(a[4])}", [a[0], a[1], a[5], a[2], a[3]]))
            else:
                out.append((m.group(1), a[:3]))
    return out


def program_moves(prog: Program) -> list[tuple[str, list[float]]]:
    """The moves of a parsed program as :func:`expected_moves` gives them, in its input units."""
    scale = MM_PER_INCH if prog.units_input == "inch" else 1.0
    out = []
    for m in prog.moves:
        e, c = m["end"] / scale, m["center"] / scale
        if m["kind"] >= 2:
            a, b, n = _AXES[int(m["plane"])]
            rot = (1 if m["kind"] == 3 else -1) * (int(m["turns"]) + 1)
            out.append((f"ARC {rot}", [float(v) for v in (e[a], e[b], e[n], c[a], c[b])]))
        else:
            out.append(("STRAIGHT_TRAVERSE" if m["kind"] == 0 else "STRAIGHT_FEED",
                        [float(v) for v in e]))
    return out
