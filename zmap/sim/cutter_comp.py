"""Cutter radius compensation (G41/G42) as LinuxCNC's interpreter performs it.

:class:`CutterComp` turns the programmed contour (the part outline, in the XY plane) into the
path of the tool centre, one tool radius to the left (G41) or right (G42) of it, and hands
finished rows to a callback in the reader's row format. It reproduces rs274ngc's algorithm
(``convert_straight_comp1/2``, ``convert_arc_comp1/2`` and the canon queue of
``interp_queue.cc``), so its output matches LinuxCNC's canonical calls:

* **Entry move** (the first move after G41/G42): the tool goes from where it stands to the
  programmed end point offset by the radius perpendicular to the entry direction (a line), or
  along an arc through that offset point whose centre is moved so the arc starts at the tool
  (an arc). The entry move must be longer than the tool radius.
* **Outside (convex) corner**: an arc of the tool radius about the programmed corner point is
  inserted (a straight traverse for G0, which has no arc).
* **Inside (concave) corner**: the end of the held-back previous move (and of any Z-only moves
  after it) is moved to the intersection of the two offset paths; the error
  ``... cannot be reached by the tool without gouging`` is raised when that point lies behind
  the start of the previous move.
* **One move of lookahead**: each move is held back until the next one fixes its end point;
  :meth:`CutterComp.flush` releases it (at G40, M0/M1/M2, program end).
* **Z-only moves** (no XY change) keep the tool's XY and are held back with the previous move,
  so a later inside corner moves them too.

The engine works in the XY plane; the reader runs G18 compensation through it in the (Z, X)
frame, as LinuxCNC's results for G18 are the G17 ones with the axes renamed. Problems raise
:class:`CompError`; the reader turns it into :class:`zmap.errors.GCodeError` at the current
block.

Examples
--------
>>> from zmap.sim.cutter_comp import CutterComp
>>> rows = []
>>> cc = CutterComp("left", 1.0, (0.0, -5.0, 0.0), rows.append)
>>> cc.straight(1, (0.0, 0.0, 0.0), 100.0, 1, 2)     # entry move
>>> cc.straight(1, (10.0, 0.0, 0.0), 100.0, 1, 3)    # outside corner
>>> cc.flush()
>>> [(r[0], round(r[1], 4), round(r[2], 4)) for r in rows]
[(1, -1.0, 0.0), (2, 0.0, 1.0), (1, 10.0, 1.0)]
"""

from __future__ import annotations

import math
from typing import Callable

from ..errors import ZMapError
from ._arcs import arc_sweep

__all__ = ["CompError", "CutterComp"]

# rs274ngc's constants (interp_internal.hh).
_CONCAVE = 0.05  # TOLERANCE_CONCAVE_CORNER, radians
_EQUAL = 1e-6  # TOLERANCE_EQUAL
_HALF_PI = 0.5 * math.pi
_TWO_PI = 2.0 * math.pi

_PLANE = 17
_NAN = math.nan


class CompError(ZMapError):
    """A compensation problem (the reader turns it into GCodeError at the current block's line).

    Parameters
    ----------
    problem : str
        What is wrong.
    line : int, optional
        Source line of the held-back move the problem is about, when it is not the move being
        added (an inside corner found when the next move or G40 fixes its end); 0 otherwise.

    Examples
    --------
    >>> from zmap.sim.cutter_comp import CutterComp, CompError
    >>> cc = CutterComp("left", 2.0, (0.0, 0.0, 0.0), print)
    >>> try:
    ...     cc.straight(1, (1.0, 0.0, 0.0), 100.0, 1, 5)
    ... except CompError as e:
    ...     print("entry" in str(e), e.line)
    True 0
    """

    def __init__(self, problem: str, line: int = 0):
        super().__init__(problem)
        self.problem = problem
        self.line = int(line)

    def __reduce__(self):
        return type(self), (self.problem, self.line)


class _Move:
    """A held-back motion: a line (kind 0/1, programmed direction dx, dy) or an arc (kind 2/3)."""

    __slots__ = ("kind", "x", "y", "z", "dx", "dy", "cx", "cy", "turn", "sweep0", "feed",
                 "tool", "line")

    def __init__(self, kind, x, y, z, dx=0.0, dy=0.0, cx=_NAN, cy=_NAN, turn=0, sweep0=0.0,
                 feed=_NAN, tool=0, line=0):
        self.kind, self.x, self.y, self.z = kind, x, y, z
        self.dx, self.dy = dx, dy
        self.cx, self.cy, self.turn, self.sweep0 = cx, cy, turn, sweep0
        self.feed, self.tool, self.line = feed, tool, line

    @property
    def is_arc(self) -> bool:
        return self.kind >= 2

    def copy(self) -> "_Move":
        new = object.__new__(_Move)
        for name in _Move.__slots__:
            setattr(new, name, getattr(self, name))
        return new


def _find_turn(x1: float, y1: float, cx: float, cy: float, turn: int, x2: float,
               y2: float) -> float:
    """Signed sweep of an arc with LinuxCNC's ``turn`` (+n CCW, -n CW, 0 none)."""
    if turn == 0:
        return 0.0
    return arc_sweep(x1, y1, x2, y2, cx, cy, turn > 0, abs(turn) - 1)


class CutterComp:
    """Cutter radius compensation in the XY plane, one held-back move, as LinuxCNC.

    Parameters
    ----------
    side : {"left", "right"}
        G41 (tool left of the contour, looking along the motion) or G42.
    radius : float
        Tool radius in mm. A negative radius swaps the side and takes the absolute value
        (LinuxCNC's rule for negative tool-table diameters); zero makes compensation a no-op
        (moves pass through unchanged, as LinuxCNC does).
    position : tuple of 3 float
        Tool position (mm) when compensation turns on; it is also the programmed point.
    emit : callable
        Receives each finished row ``(kind, x, y, z, cx, cy, cz, plane, turns, feed, tool,
        line, sweep)`` in order (see :mod:`zmap.sim.gcode`). Public attribute; the engine's
        deep copy shares it.

    Notes
    -----
    LinuxCNC refuses G41/G42 while compensation is on (no change of side or radius on the
    fly), tool changes, coordinate-system changes and plane changes while it is on; those
    checks belong to the reader. While compensation is on the reader must resolve omitted
    axes and incremental words against :attr:`programmed` and compute arc centres from it
    (IJK are relative to the programmed start). After G40 (:meth:`flush`) LinuxCNC takes
    :attr:`programmed` as the current point, while the tool physically stands at
    :attr:`position`, where the next (exit) row starts; that move must be a line.

    Examples
    --------
    A 10 mm square traced counter-clockwise with the tool outside (G42), radius 1, entered
    from below its bottom edge: the inside corner after the entry moves the entry's end,
    each outside corner gets a quarter circle (kind 3) about the programmed corner.

    >>> rows = []
    >>> cc = CutterComp("right", 1.0, (5.0, -5.0, 0.0), rows.append)
    >>> for x, y in [(5, 0), (10, 0), (10, 10), (0, 10), (0, 0), (5, 0)]:
    ...     cc.straight(1, (float(x), float(y), 0.0), 100.0, 1, 7)
    >>> cc.flush()
    >>> [(r[0], round(r[1], 3) + 0.0, round(r[2], 3) + 0.0) for r in rows[:5]]
    [(1, 6.0, -1.0), (1, 10.0, -1.0), (3, 11.0, 0.0), (1, 11.0, 10.0), (3, 10.0, 11.0)]
    >>> rows[2][4:6], round(rows[2][12], 4)
    ((10.0, 0.0), 1.5708)
    """

    def __init__(self, side: str, radius: float, position: tuple[float, float, float],
                 emit: Callable[[tuple], None]) -> None:
        if side not in ("left", "right"):
            raise ValueError(f"side={side!r} is not one of 'left', 'right'")
        radius = float(radius)
        if not math.isfinite(radius):
            raise ValueError(f"radius must be a finite number of mm, got {radius}")
        if radius < 0.0:
            radius = -radius
            side = "right" if side == "left" else "left"
        pos = tuple(float(v) for v in position)
        if len(pos) != 3:
            raise ValueError(f"position must be (x, y, z), got {len(pos)} values")
        self.side = side
        self.radius = radius
        self.emit = emit
        self._left = side == "left"
        self._cur = list(pos)  # compensated tool position (LinuxCNC current_*)
        self._prog = list(pos)  # programmed point (LinuxCNC program_*)
        self._last = list(pos)  # end of the last emitted row
        self._first = True  # no move yet since comp turned on
        self._queue: list[_Move] = []
        self._endpoint = [pos[0], pos[1]]  # start of the first held-back move
        self._endpoint_valid = False

    # -- public state ---------------------------------------------------------------------

    @property
    def position(self) -> tuple[float, float, float]:
        """Current compensated tool position (mm): end of the last row, emitted or held back."""
        return (self._cur[0], self._cur[1], self._cur[2])

    @property
    def programmed(self) -> tuple[float, float, float]:
        """Current programmed (uncompensated) point (mm)."""
        return (self._prog[0], self._prog[1], self._prog[2])

    @property
    def pending(self) -> int:
        """Number of rows held back, waiting for the next move or :meth:`flush`."""
        return len(self._queue)

    def __deepcopy__(self, memo: dict) -> "CutterComp":
        # by hand: the reader's lenient mode copies the engine before every block, and
        # copy.deepcopy of the held-back moves took ~130 us
        new = object.__new__(CutterComp)
        memo[id(self)] = new
        new.__dict__.update(self.__dict__)  # scalars, and emit shared
        for k in ("_cur", "_prog", "_last", "_endpoint"):
            setattr(new, k, list(getattr(self, k)))
        new._queue = [m.copy() for m in self._queue]
        return new

    # -- moves ----------------------------------------------------------------------------

    def straight(self, kind: int, end: tuple[float, float, float], feed: float, tool: int,
                 line: int) -> None:
        """A programmed G0 (``kind=0``) or G1 (``kind=1``) to ``end``.

        Parameters
        ----------
        kind : {0, 1}
            Rapid or feed.
        end : tuple of 3 float
            Programmed end point (mm, machine coordinates after offsets).
        feed : float
            Feed rate (mm/min); ignored for rapids (rows get NaN).
        tool, line : int
            Tool number and source line recorded in the rows.

        Raises
        ------
        CompError
            Entry move not longer than the tool radius; an inside corner the tool cannot
            reach without gouging.

        Examples
        --------
        >>> rows = []
        >>> cc = CutterComp("left", 1.0, (0.0, 0.0, 5.0), rows.append)
        >>> cc.straight(1, (10.0, 0.0, 5.0), 100.0, 1, 1)
        >>> cc.position
        (10.0, 1.0, 5.0)
        >>> len(rows), cc.pending
        (0, 1)
        """
        if kind not in (0, 1):
            raise ValueError(f"kind={getattr(kind, 'item', lambda: kind)()!r} is not one of "
                             "0 (rapid), 1 (feed)")
        px, py, pz = (float(v) for v in end)
        feed = _NAN if kind == 0 else float(feed)
        if self.radius == 0.0:
            self._emit_row(_Move(kind, px, py, pz, feed=feed, tool=tool, line=line))
            self._cur = [px, py, pz]
            self._prog = [px, py, pz]
            return
        if self._first:
            self._straight_entry(kind, px, py, pz, feed, tool, line)
        else:
            self._straight_next(kind, px, py, pz, feed, tool, line)

    def arc(self, ccw: bool, end: tuple[float, float, float], center: tuple[float, float],
            turns: int, feed: float, tool: int, line: int) -> None:
        """A programmed G2 (``ccw=False``) or G3 (``ccw=True``) in the XY plane.

        Parameters
        ----------
        ccw : bool
            Direction.
        end : tuple of 3 float
            Programmed end point (mm); Z may change (helix).
        center : tuple of 2 float
            XY centre of the programmed arc (mm). With IJK it is :attr:`programmed` plus the
            offsets, as in LinuxCNC.
        turns : int
            Extra full turns (P word minus one).
        feed : float
            Feed rate (mm/min).
        tool, line : int
            Tool number and source line recorded in the rows.

        Raises
        ------
        CompError
            Tool radius not less than the radius of an arc the tool runs inside; an entry
            arc ending within a tool radius of the start; a corner the tool cannot reach
            without gouging.

        Examples
        --------
        A half circle of radius 5 cut from inside (G41 on a CCW arc) runs at radius 4:

        >>> rows = []
        >>> cc = CutterComp("left", 1.0, (5.0, -5.0, 0.0), rows.append)
        >>> cc.straight(1, (5.0, 0.0, 0.0), 100.0, 1, 1)
        >>> cc.arc(True, (-5.0, 0.0, 0.0), (0.0, 0.0), 0, 100.0, 1, 2)
        >>> cc.flush()
        >>> r = rows[-1]
        >>> r[0], round(r[1], 4), round(r[2], 4), round(r[12], 4)
        (3, -4.0, 0.0, 3.1416)
        """
        px, py, pz = (float(v) for v in end)
        ccx, ccy = (float(v) for v in center)
        turns = int(turns)
        if turns < 0:
            raise ValueError(f"turns must be >= 0 (P word minus one), got {turns}")
        turn = (turns + 1) if ccw else -(turns + 1)
        feed = float(feed)
        if self.radius == 0.0:
            self._emit_row(_Move(3 if ccw else 2, px, py, pz, cx=ccx, cy=ccy, turn=turn,
                                 feed=feed, tool=tool, line=line))
            self._cur = [px, py, pz]
            self._prog = [px, py, pz]
            return
        if self._first:
            self._arc_entry(turn, px, py, pz, ccx, ccy, feed, tool, line)
        else:
            self._arc_next(turn, px, py, pz, ccx, ccy, feed, tool, line)

    def flush(self) -> None:
        """Emit the held-back rows (G40, M0/M1/M2, program end).

        The end points stay where they are; the gouging checks of LinuxCNC's flush still
        apply.

        Examples
        --------
        >>> rows = []
        >>> cc = CutterComp("left", 1.0, (0.0, 0.0, 0.0), rows.append)
        >>> cc.straight(1, (10.0, 0.0, 0.0), 100.0, 1, 1)
        >>> cc.flush()
        >>> len(rows), cc.pending
        (1, 0)
        """
        self._move_endpoint_and_flush(self._cur[0], self._cur[1])
        self._dequeue()

    def discard(self) -> list[int]:
        """Drop the held-back moves unemitted (the reader's lenient mode, when :meth:`flush`
        fails at the end of a program); return their source lines.

        Examples
        --------
        >>> rows = []
        >>> cc = CutterComp("left", 1.0, (0.0, 0.0, 0.0), rows.append)
        >>> cc.straight(1, (10.0, 0.0, 0.0), 100.0, 1, 4)
        >>> cc.discard(), rows, cc.pending
        ([4], [], 0)
        """
        lines = [q.line for q in self._queue]
        self._queue.clear()
        self._endpoint_valid = False
        return lines

    # -- LinuxCNC's convert_straight_comp1 / comp2 ----------------------------------------

    def _inside(self, turn: int) -> bool:
        """Tool on the concave side of an arc turning ``turn`` (TOOL_INSIDE_ARC)."""
        return (self._left and turn > 0) or (not self._left and turn < 0)

    def _straight_entry(self, kind, px, py, pz, feed, tool, line) -> None:
        cx, cy, _ = self._cur
        r = self.radius
        distance = math.hypot(px - cx, py - cy)
        if distance <= r:
            raise CompError(
                f"cutter compensation entry move must be longer than the tool radius "
                f"{r:.6g} mm, got {distance:.6g} mm")
        alpha = math.atan2(py - cy, px - cx) + (_HALF_PI if self._left else -_HALF_PI)
        ex = px + r * math.cos(alpha)
        ey = py + r * math.sin(alpha)
        self._set_endpoint(cx, cy)
        # LinuxCNC records the offset direction (not the motion) for the entry line.
        self._queue.append(_Move(kind, ex, ey, pz, math.cos(alpha), math.sin(alpha),
                                 feed=feed, tool=tool, line=line))
        self._first = False
        self._cur = [ex, ey, pz]
        self._prog = [px, py, pz]

    def _straight_next(self, kind, px, py, pz, feed, tool, line) -> None:
        cx, cy, cz = self._cur
        opx, opy, _ = self._prog
        r = self.radius
        if px == opx and py == opy:  # no XY motion: keep the tool's XY, hold it back too
            self._queue.append(_Move(kind, cx, cy, pz, 0.0, 0.0, feed=feed, tool=tool,
                                     line=line))
            self._cur = [cx, cy, pz]
            self._prog = [px, py, pz]
            return
        theta = math.atan2(cy - opy, cx - opx)
        alpha = math.atan2(py - opy, px - opx)
        if self._left:
            if theta < alpha:
                theta += _TWO_PI
            beta = theta - alpha - _HALF_PI
            gamma = _HALF_PI
        else:
            if alpha < theta:
                alpha += _TWO_PI
            beta = alpha - theta - _HALF_PI
            gamma = -_HALF_PI
        ex = px + r * math.cos(alpha + gamma)
        ey = py + r * math.sin(alpha + gamma)
        mx = opx + r * math.cos(alpha + gamma)
        my = opy + r * math.sin(alpha + gamma)
        front = self._queue[0] if self._queue else None
        if beta < -_CONCAVE or beta > math.pi + _CONCAVE:
            concave = True
        elif (beta > math.pi - _CONCAVE and front is not None and front.is_arc
              and self._inside(-front.turn)):
            # an "h" shape: over the round top, then down beside the stem; stay outside
            concave = True
        else:
            concave = False

        if not concave and beta > _CONCAVE:  # outside corner: go round it
            self._move_endpoint_and_flush(cx, cy)
            if kind == 1:
                self._queue.append(_Move(2 if self._left else 3, mx, my, cz, cx=opx, cy=opy,
                                         turn=-1 if self._left else 1, feed=feed, tool=tool,
                                         line=line))
            else:  # no rapid arc: a traverse to the start of the offset line
                self._queue.append(_Move(0, mx, my, cz, feed=_NAN, tool=tool, line=line))
            self._dequeue()
            self._set_endpoint(mx, my)
        elif concave:
            if front is None or not front.is_arc:  # line -> line
                halfcorner = (beta + math.pi) / 2.0
                if halfcorner == 0.0:
                    raise CompError("a zero-degree inside corner cannot be compensated")
                retreat = r / math.tan(halfcorner)
                mx = cx + retreat * math.cos(theta + gamma)
                my = cy + retreat * math.sin(theta + gamma)
            else:  # arc -> line; the held-back arc is already compensated
                oldrad = math.hypot(front.cy - front.y, front.cx - front.x)
                base_dir = math.atan2(py - opy, px - opx)
                th = base_dir + _HALF_PI if front.turn > 0 else base_dir - _HALF_PI
                phi = math.atan2(front.cy - opy, front.cx - opx)
                inside = self._inside(front.turn)
                oldrad_uncomp = oldrad + r if inside else oldrad - r
                d = oldrad_uncomp * math.cos(th - phi)
                d2 = d - r if inside else d + r
                ratio = d2 / oldrad
                if ratio > 1.0 or ratio < -1.0:
                    raise CompError("the corner from the arc into this line is too tight for "
                                    "the compensated tool without gouging")
                if inside == (front.turn > 0):
                    ang = -math.acos(ratio) + th + math.pi
                else:
                    ang = math.acos(ratio) + th + math.pi
                mx = front.cx + oldrad * math.cos(ang)
                my = front.cy + oldrad * math.sin(ang)
            self._move_endpoint_and_flush(mx, my)
        else:  # collinear, or tangent arc -> line
            self._dequeue()
            self._set_endpoint(cx, cy)
        self._queue.append(_Move(kind, ex, ey, pz, px - opx, py - opy, feed=feed, tool=tool,
                                 line=line))
        self._cur = [ex, ey, pz]
        self._prog = [px, py, pz]

    # -- LinuxCNC's convert_arc_comp1 / comp2 ---------------------------------------------

    def _arc_entry(self, turn, px, py, pz, ccx, ccy, feed, tool, line) -> None:
        cx, cy, _ = self._cur
        r = self.radius
        chord = math.hypot(px - cx, py - cy)
        if chord <= r:
            raise CompError(
                f"cutter compensation entry arc must end farther than the tool radius "
                f"{r:.6g} mm from its start, got {chord:.6g} mm")
        arc_radius = math.hypot(ccx - cx, ccy - cy)
        inside = self._inside(turn)
        if inside and arc_radius <= r:
            raise CompError(
                f"tool radius {r:.6g} mm is not less than the radius {arc_radius:.6g} mm of "
                f"an arc cut from inside")
        if inside:
            gamma = math.atan2(ccy - py, ccx - px)
        else:
            gamma = math.atan2(py - ccy, px - ccx)
        ex = px + r * math.cos(gamma)
        ey = py + r * math.sin(gamma)
        # The compensated arc runs from the tool to (ex, ey): its centre lies on the line
        # from (ex, ey) toward the programmed centre, equidistant from both ends.
        half = math.hypot(cy - ey, cx - ex) / 2.0
        ab = math.atan2(ccy - ey, ccx - ex)
        a_ang = math.atan2(cy - ey, cx - ex) - ab
        if abs(math.cos(a_ang)) < _EQUAL:
            raise CompError(
                f"tool radius {r:.6g} mm is not less than the radius of the entry arc")
        c_len = half / math.cos(a_ang)
        ncx = ex + c_len * math.cos(ab)
        ncy = ey + c_len * math.sin(ab)
        self._queue.append(_Move(3 if turn > 0 else 2, ex, ey, pz, cx=ncx, cy=ncy, turn=turn,
                                 sweep0=_find_turn(cx, cy, ncx, ncy, turn, ex, ey),
                                 feed=feed, tool=tool, line=line))
        self._first = False
        self._cur = [ex, ey, pz]
        self._prog = [px, py, pz]

    def _arc_next(self, turn, px, py, pz, ccx, ccy, feed, tool, line) -> None:
        opx, opy, _ = self._prog
        cx, cy, cz = self._cur
        r = self.radius
        left = self._left
        ccw = turn > 0
        arc_radius = math.hypot(ccx - px, ccy - py)
        theta = math.atan2(cy - opy, cx - opx)
        theta = theta - _HALF_PI if left else theta + _HALF_PI
        delta = math.atan2(ccy - opy, ccx - opx)
        alpha = delta - _HALF_PI if ccw else delta + _HALF_PI
        beta = theta - alpha if left else alpha - theta
        if beta > 1.5 * math.pi:
            beta -= _TWO_PI
        elif beta < -_HALF_PI:
            beta += _TWO_PI
        inside = self._inside(turn)
        if inside:
            gamma = math.atan2(ccy - py, ccx - px)
            if arc_radius <= r:
                raise CompError(
                    f"tool radius {r:.6g} mm is not less than the radius {arc_radius:.6g} mm "
                    f"of an arc cut from inside")
        else:
            gamma = math.atan2(py - ccy, px - ccx)
            delta += math.pi
        ex = px + r * math.cos(gamma)
        ey = py + r * math.sin(gamma)
        main = _Move(3 if ccw else 2, ex, ey, pz, cx=ccx, cy=ccy, turn=turn,
                     sweep0=_find_turn(opx, opy, ccx, ccy, turn, px, py), feed=feed,
                     tool=tool, line=line)
        front = self._queue[0] if self._queue else None

        if (beta < -_CONCAVE or beta > math.pi + _CONCAVE
                or (abs(beta - math.pi) < _CONCAVE and not inside)):
            # inside corner
            if front is None or not front.is_arc:  # line -> arc
                off = arc_radius * math.sin(beta - _HALF_PI)
                if inside:
                    dist = arc_radius - r
                    ratio = (off + r) / dist
                else:
                    dist = arc_radius + r
                    ratio = (off - r) / dist
                if ratio > 1.0 or ratio < -1.0:
                    raise CompError("the arc starts in an inside corner the tool cannot reach "
                                    "without gouging")
                if inside:
                    ang = theta + math.asin(ratio) if turn > 0 else theta - math.asin(ratio)
                else:
                    ang = (theta + math.pi - math.asin(ratio) if turn > 0
                           else theta + math.pi + math.asin(ratio))
                mx = ccx + dist * math.cos(ang)
                my = ccy + dist * math.sin(ang)
            else:  # arc -> arc
                oldrad = math.hypot(front.cy - front.y, front.cx - front.x)
                newrad = arc_radius - r if inside else arc_radius + r
                arc_cc = math.hypot(front.cy - ccy, front.cx - ccx)
                if oldrad == 0.0 or arc_cc == 0.0:
                    raise CompError("consecutive arcs with the same centre meet at an inside "
                                    "corner; compensation cannot join them")
                a = (oldrad ** 2 + arc_cc ** 2 - newrad ** 2) / (2.0 * oldrad * arc_cc)
                if a > 1.0 or a < -1.0:
                    raise CompError("the corner between these two arcs is too tight for the "
                                    "compensated tool without gouging")
                pullback = math.acos(a)
                cc_dir = math.atan2(ccy - front.cy, ccx - front.cx)
                if self._inside(front.turn) == (turn > 0):
                    ang = cc_dir + pullback
                else:
                    ang = cc_dir - pullback
                mx = front.cx + oldrad * math.cos(ang)
                my = front.cy + oldrad * math.sin(ang)
            self._move_endpoint_and_flush(mx, my)
            self._queue.append(main)
        elif beta > _CONCAVE:  # outside corner: an arc about the programmed corner first
            mx = opx + r * math.cos(delta)
            my = opy + r * math.sin(delta)
            self._dequeue()
            self._queue.append(_Move(2 if left else 3, mx, my, cz, cx=opx, cy=opy,
                                     turn=-1 if left else 1, feed=feed, tool=tool, line=line))
            self._dequeue()
            self._set_endpoint(mx, my)
            self._queue.append(main)
        else:  # tangent
            self._dequeue()
            self._set_endpoint(cx, cy)
            self._queue.append(main)
        self._cur = [ex, ey, pz]
        self._prog = [px, py, pz]

    # -- LinuxCNC's canon queue (interp_queue.cc) ------------------------------------------

    def _set_endpoint(self, x: float, y: float) -> None:
        self._endpoint = [x, y]
        self._endpoint_valid = True

    def _move_endpoint_and_flush(self, x: float, y: float) -> None:
        """Move the end of every held-back move to (x, y), check for gouging, emit them."""
        if not self._queue:
            return
        ex, ey = self._endpoint
        # check every move first so an error leaves the state untouched
        for q in self._queue:
            if q.is_arc:
                r1 = math.hypot(q.x - q.cx, q.y - q.cy)
                r2 = math.hypot(x - q.cx, y - q.cy)
                if abs(r1 - r2) > 0.01:
                    raise CompError(
                        f"internal error: compensation made an arc with mismatched radii "
                        f"{r1:.6g} and {r2:.6g} mm", q.line)
                if q.sweep0 and self._endpoint_valid:
                    sweep = _find_turn(ex, ey, q.cx, q.cy, q.turn, x, y)
                    if abs(sweep) > abs(q.sweep0) + 0.001:
                        raise CompError("an arc ending in an inside corner cannot be cut "
                                        "without gouging (the tool does not fit the corner)",
                                        q.line)
            elif self._endpoint_valid and q.dx * (x - ex) + q.dy * (y - ey) < 0.0:
                what = "straight traverse" if q.kind == 0 else "straight feed"
                raise CompError(f"a {what} ending in an inside corner cannot be cut without "
                                f"gouging (the move would run backwards)", q.line)
        for q in self._queue:
            q.x, q.y = x, y
        self._dequeue()
        self._set_endpoint(x, y)

    def _dequeue(self) -> None:
        self._endpoint_valid = False
        for q in self._queue:
            self._emit_row(q)
        self._queue.clear()

    def _emit_row(self, q: _Move) -> None:
        sx, sy, sz = self._last
        if q.is_arc:
            sweep = _find_turn(sx, sy, q.cx, q.cy, q.turn, q.x, q.y)
            row = (2 if q.turn < 0 else 3, q.x, q.y, q.z, q.cx, q.cy, sz, _PLANE,
                   abs(q.turn) - 1, q.feed, q.tool, q.line, sweep)
        else:
            row = (q.kind, q.x, q.y, q.z, _NAN, _NAN, _NAN, _PLANE, 0, q.feed, q.tool, q.line,
                   _NAN)
        self._last = [q.x, q.y, q.z]
        self.emit(row)
