"""Modal group 1 of the G-code interpreter: the moves a block makes.

:func:`motion` is the motion step of a block (LinuxCNC's step 20 of ``execute_block``):
straight moves (G0, G1), arcs (G2, G3 with I J K or R, helical, P turns), rigid tapping
(G33.1) and the drilling cycles G81, G82 and G83, expanded as LinuxCNC's ``convert_cycle``
does; under cutter compensation the moves go through :class:`zmap.sim.cutter_comp.CutterComp`.
:func:`fast_block` runs the most common block (coordinates, perhaps F, under G0/G1) without
building a :class:`~zmap.sim._gcode_state.Block`; it declines anything else.

Examples
--------
>>> from zmap.sim._gcode_codes import TOKEN
>>> from zmap.sim._gcode_state import InterpState
>>> st = InterpState("x.nc", None)
>>> fast_block(st, TOKEN.findall("G1 X1 F100"), 1), st.rows[-1][:4]
(True, (1, 1.0, 0.0, 0.0))
>>> fast_block(st, TOKEN.findall("G2 X2 I1"), 2)   # an arc: the full interpreter's
False
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

from ._arcs import arc_sweep
from ._gcode_codes import (ARC_MOTIONS, CANNED_CYCLES, G_ARC_CCW, G_ARC_CW, G_CANCEL_CYCLE,
                           G_DRILL_DWELL, G_DWELL, G_LINEAR, G_MACHINE_COORDS, G_PECK_DRILL,
                           G_RAPID, G_RIGID_TAP, IJK, MAX_COORD_MM, MAX_TURNS, MM_PER_INCH,
                           MODAL_GROUP_MOTION, MODAL_GROUP_NON_MODAL, STRAIGHT_MOTIONS, XYZ,
                           comp_problem, fmt_number, g_name)
from ._gcode_program import (ARC_CCW, ARC_CW, KNOWN_ALL, LINEAR, PLANE_AXES, PLANE_XY, PLANE_ZX,
                             RAPID)
from ._gcode_state import Block, InterpState
from .cutter_comp import CompError
from .ngc import MAX_MAGNITUDE

__all__ = ["motion", "fast_block", "g18_rows"]

# Arc end-point tolerance (LinuxCNC): absolute 0.002 in or 0.05 mm, or relative 0.1 %.
_ARC_ABS_TOL_MM = {"inch": 0.002 * MM_PER_INCH, "mm": 0.05}
_ARC_REL_TOL = 0.001
_G83_RAPID_DELTA_MM = 0.010 * MM_PER_INCH  # LinuxCNC G83_RAPID_DELTA, 0.010 in
_NAN = math.nan


def motion(b: Block) -> None:
    """Group 1 (20.): set the motion mode and make the block's move, if it has one.

    A block moves when it has an axis word (not taken by G10), or names a canned cycle with
    an R or Z word; a G2/G3 with I J K or R but no axis word is an error.
    """
    st, words = b.st, b.words
    b.motion = G_CANCEL_CYCLE if b.cancel_cycle else st.motion
    explicit = b.groups.get(MODAL_GROUP_MOTION, G_CANCEL_CYCLE) != G_CANCEL_CYCLE
    if explicit:
        b.motion = b.groups[MODAL_GROUP_MOTION]
    m = b.motion
    # after G40 the tool sits at the compensated point (the next row starts there: rows chain),
    # while the program goes on from the programmed point, as in LinuxCNC
    pos = list(st.pos)
    pos[2] -= b.tlo - st.tlo  # G43/G49 move the tip's programmed Z, not the machine
    b.new_pos = pos
    b.n_before = len(st.rows)
    b.set_axes, b.set_at = 0, 0
    b.cycle_r, b.cycle_z, b.cycle_q = st.cycle_r, st.cycle_z, st.cycle_q
    nonmodal = b.groups.get(MODAL_GROUP_NON_MODAL)
    g53 = nonmodal == G_MACHINE_COORDS
    if g53:
        if not b.absolute:
            raise b.code_error(G_MACHINE_COORDS, "G53 needs absolute distance mode (G90)")
        if m not in STRAIGHT_MOTIONS:
            raise b.code_error(G_MACHINE_COORDS, "G53 must be used with G0 or G1")
    off = [0.0, 0.0, 0.0] if g53 else b.offsets[b.cs]
    if b.any_axis or (explicit and m in CANNED_CYCLES and ("R" in words or "Z" in words)):
        if m == G_CANCEL_CYCLE:
            w = next(w for w in XYZ if w in words)
            raise b.word_error(w, "axis word with no active motion mode (G80 in effect)")
        if nonmodal == G_DWELL:
            raise b.code_error(G_DWELL, "axis words cannot be used with G4")
        if m in CANNED_CYCLES:
            if b.comp is not None:
                raise b.code_error(m, f"canned cycle {g_name(m)} with cutter compensation on")
            b.new_pos = _canned_cycle(b, pos, off)
            _check_envelope(b, b.new_pos)
        else:
            _move(b, pos, off, g53)
        b.used.update(XYZ)
    elif explicit and m in ARC_MOTIONS and any(w in words for w in "IJKR"):
        raise b.code_error(m, f"{g_name(m)} needs at least one axis word")


def _move(b: Block, pos: list[float], off: Sequence[float], g53: bool) -> None:
    """G0, G1, G2, G3 or G33.1 to the block's end point (``off``: the work offset in force)."""
    st, words, m, f = b.st, b.words, b.motion, b.scale
    end = list(pos)
    for i in range(3):
        w = XYZ[i]
        if w in words:
            end[i] = words[w] * f + off[i] if b.absolute else pos[i] + words[w] * f
    feed = _NAN if m == G_RAPID else b.feed
    if m not in (G_RAPID, G_RIGID_TAP) and not (feed > 0):
        raise b.code_error(m, "feed move with no feed rate (F word) set")
    _check_envelope(b, end)
    if m == G_RIGID_TAP:
        if b.comp is not None:
            raise b.code_error(G_RIGID_TAP, "rigid tapping with cutter compensation on")
        b.new_pos = _rigid_tap(b, pos, end)
        return
    if m in STRAIGHT_MOTIONS:
        row = (RAPID if m == G_RAPID else LINEAR, end[0], end[1], end[2],
               _NAN, _NAN, _NAN, b.plane, 0, feed, b.tool, b.lineno, _NAN)
    else:
        row = _arc(b, pos, end, off, feed)
        _check_envelope(b, row[4:7])
    b.set_axes = ("X" in words) | ("Y" in words) << 1 | ("Z" in words) << 2
    if b.comp is None:
        st.rows.append(row)
        b.set_at = len(st.rows)
    else:
        if g53:
            raise b.code_error(G_MACHINE_COORDS, "G53 with cutter compensation on")
        cend, ccen = tuple(end), (row[4], row[5])
        if b.plane == PLANE_ZX:  # to the (Z, X, Y) frame of the engine
            cend, ccen = (end[2], end[0], end[1]), (row[6], row[4])
        try:
            if m in STRAIGHT_MOTIONS:
                b.comp.straight(row[0], cend, feed, b.tool, b.lineno)
            else:
                b.comp.arc(m == G_ARC_CCW, cend, ccen, row[8], feed, b.tool, b.lineno)
        except CompError as e:
            raise b.code_error(m, comp_problem(e, b.lineno)) from None
        b.set_at = len(st.rows) + b.comp.pending  # the rows held back come first
    b.new_pos = end


def g18_rows(append: Callable[[tuple], None]) -> Callable[[tuple], None]:
    """Rows of the compensation engine run in the (Z, X, Y) frame, back in X Y Z, plane 18."""
    def emit(r: tuple) -> None:
        append((r[0], r[2], r[3], r[1], r[5], r[6], r[4], PLANE_ZX) + tuple(r[8:]))
    return emit


def _check_envelope(b: Block, point: Sequence[float]) -> None:
    """Refuse a position or centre outside the work envelope (|coordinate| <= MAX_COORD_MM)."""
    for i, v in enumerate(point):
        if abs(v) > MAX_COORD_MM:  # NaN (a line's centre) compares False
            problem = (f"{XYZ[i]} = {v:.6g} mm is outside the work envelope "
                       f"(|coordinate| <= {MAX_COORD_MM:g} mm)")
            raise b.error_at(XYZ[i] + XYZ, b.motion, problem)


def _rigid_tap(b: Block, pos: list[float], end: list[float]) -> list[float]:
    """G33.1: feed to the hole bottom synchronised with the spindle, then back to the start.

    The feed is the pitch ``K`` times the spindle speed (the F word when S is not set).
    """
    words = b.words
    if b.plane != PLANE_XY:
        raise b.code_error(G_RIGID_TAP, "rigid tapping is supported in the G17 plane only")
    if "K" not in words:
        raise b.code_error(G_RIGID_TAP, "G33.1 needs a K word (the thread pitch)")
    if not words["K"] > 0:
        raise b.word_error("K", "K (the thread pitch) must be positive")
    b.used.add("K")
    tap_feed = words["K"] * b.scale * b.speed if b.speed > 0 else b.feed
    if not tap_feed > 0:
        raise b.code_error(G_RIGID_TAP, "G33.1 with no spindle speed (S) and no feed rate (F) set")
    for p in (end, pos):
        b.st.rows.append((LINEAR, p[0], p[1], p[2], _NAN, _NAN, _NAN, b.plane, 0, tap_feed,
                          b.tool, b.lineno, _NAN))
    return list(pos)


def _arc(b: Block, pos: list[float], end: list[float], off: Sequence[float],
         feed: float) -> tuple:
    """The row of a G2/G3 from ``pos`` to ``end``, its centre from I J K or R, checked."""
    words, m, f = b.words, b.motion, b.scale
    plane = b.plane
    a, bb, n = PLANE_AXES[plane]
    ccw = m == G_ARC_CCW
    name = g_name(m)
    bad = IJK[n]
    if bad in words:
        raise b.word_error(bad, f"{bad} word cannot be used for an arc in the G{plane} plane")
    turns = 0
    if "P" in words:
        p = words["P"]
        if p != int(p) or p < 1 or p > MAX_TURNS:
            raise b.word_error("P", f"P (number of turns) must be an integer 1..{MAX_TURNS}, "
                                    f"got {fmt_number(p)}")
        turns = int(p) - 1
        b.used.add("P")
    tol = _ARC_ABS_TOL_MM[b.units]
    a0, b0, a1, b1 = pos[a], pos[bb], end[a], end[bb]
    ia, ib = IJK[a], IJK[bb]
    if "R" in words:
        if ia in words or ib in words:
            w = ia if ia in words else ib
            raise b.word_error(w, f"{name} cannot have both R and {w} words")
        radius = words["R"] * f
        b.used.add("R")
        if a1 == a0 and b1 == b0:
            raise b.word_error("R", "R-form arc whose end point is its start point (use I J K)")
        abs_r = abs(radius)
        mid_a, mid_b = (a0 + a1) / 2.0, (b0 + b1) / 2.0
        half = math.hypot(mid_a - a1, mid_b - b1)
        if half - abs_r > tol:
            raise b.word_error("R", f"radius {abs_r / f:.6g} is too small to reach the end point "
                                    f"(half chord {half / f:.6g})")
        if abs_r == 0.0:
            raise b.word_error("R", "zero radius arc")
        if half / abs_r > 1.0 - 1e-12:  # within the tolerance: a half circle
            half = abs_r
        # the centre lies right of the chord for G2 with R > 0 (or G3 with R < 0), else left
        if (not ccw and radius > 0) or (ccw and radius < 0):
            theta = math.atan2(b1 - b0, a1 - a0) - math.pi / 2
        else:
            theta = math.atan2(b1 - b0, a1 - a0) + math.pi / 2
        offset = abs_r * math.cos(math.asin(half / abs_r))
        ca = mid_a + offset * math.cos(theta)
        cb = mid_b + offset * math.sin(theta)
    else:
        if ia not in words and ib not in words:
            raise b.code_error(m, f"{name} in the G{plane} plane needs {ia}/{ib} or R words")
        vi = words.get(ia, 0.0) * f
        vj = words.get(ib, 0.0) * f
        if b.ijk_absolute:
            ca, cb = vi + off[a], vj + off[bb]
        else:
            ca, cb = a0 + vi, b0 + vj
        b.used.update((ia, ib))
        r1 = math.hypot(ca - a0, cb - b0)
        r2 = math.hypot(ca - a1, cb - b1)
        w = ia if ia in words else ib
        if r1 < 1e-9 or r2 < 1e-9:
            raise b.word_error(w, "zero radius arc")
        d = abs(r1 - r2)
        if d > tol and d > _ARC_REL_TOL * r1:
            raise b.word_error(w, f"radius to end of arc differs from radius to start: "
                                  f"r1={r1 / f:.6g} r2={r2 / f:.6g} (difference {d / f:.3g} "
                                  f"exceeds {tol / f:.3g} and {_ARC_REL_TOL:.1%})")
    sweep = arc_sweep(a0, b0, a1, b1, ca, cb, ccw, turns)
    c = [0.0, 0.0, 0.0]
    c[a], c[bb], c[n] = ca, cb, pos[n]
    return (ARC_CW if m == G_ARC_CW else ARC_CCW, end[0], end[1], end[2], c[0], c[1], c[2],
            plane, turns, feed, b.tool, b.lineno, sweep)


def _canned_cycle(b: Block, pos: list[float], off: Sequence[float]) -> list[float]:
    """Expand G81/G82/G83 into moves as LinuxCNC's convert_cycle does; the end position.

    The cycle's R, Z (the hole bottom along the plane's normal) and Q are modal: the block's
    words set ``b.cycle_r``, ``b.cycle_z`` and ``b.cycle_q``, the next blocks reuse them.
    """
    st, words, m, f = b.st, b.words, b.motion, b.scale
    a, bb, n = PLANE_AXES[b.plane]
    name = g_name(m)
    wn = XYZ[n]
    if "R" in words:
        b.cycle_r = words["R"] * f
        b.used.add("R")
    if wn in words:
        b.cycle_z = words[wn] * f
    if math.isnan(b.cycle_r):
        raise b.code_error(m, f"{name} needs an R word (retract plane)")
    if math.isnan(b.cycle_z):
        raise b.code_error(m, f"{name} needs a {wn} word (hole bottom)")
    if not (b.feed > 0):
        raise b.code_error(m, f"{name} with no feed rate (F word) set")
    repeats = 1
    if "L" in words:
        lv = words["L"]
        if lv != int(lv) or lv < 0:
            raise b.word_error("L", f"L (repeats) must be a non-negative integer, "
                                    f"got {fmt_number(lv)}")
        repeats = int(lv)
        b.used.add("L")
    if m == G_DRILL_DWELL and "P" in words:  # the dwell at the bottom (G81 has none)
        if words["P"] < 0:
            raise b.word_error("P", "dwell time must not be negative")
        b.used.add("P")
    if m == G_PECK_DRILL:
        if "Q" in words:
            b.cycle_q = words["Q"] * f
            b.used.add("Q")
        if math.isnan(b.cycle_q):
            raise b.code_error(m, "G83 needs a Q word (peck depth)")
        if not b.cycle_q > 0:
            raise b.error_at("Q", m, "Q (peck depth) must be positive")
    # LinuxCNC's initial level: the Z where the first block of this run of cycles began
    old_cc = pos[n] if math.isnan(st.cycle_il) else st.cycle_il
    st.cycle_il = old_cc
    if b.absolute:
        aa = words[XYZ[a]] * f + off[a] if XYZ[a] in words else pos[a]
        bv = words[XYZ[bb]] * f + off[bb] if XYZ[bb] in words else pos[bb]
        aa_inc = bb_inc = 0.0
        r = b.cycle_r + off[n]
        cc = b.cycle_z + off[n]
    else:
        aa, bv = pos[a], pos[bb]
        aa_inc = words[XYZ[a]] * f if XYZ[a] in words else 0.0
        bb_inc = words[XYZ[bb]] * f if XYZ[bb] in words else 0.0
        r = b.cycle_r + old_cc
        cc = r + b.cycle_z
    if r < cc:
        raise b.error_at("R" + wn, m, f"R ({fmt_number(r / f)}) is below the hole bottom {wn} "
                                      f"({fmt_number(cc / f)}) in {name}")
    rows = st.rows
    pecks = 1 if m != G_PECK_DRILL else max(1.0, math.ceil((r - cc) / b.cycle_q))
    estimate = repeats * (3.0 + 3.0 * pecks)
    if len(rows) + estimate > st.max_moves:
        first = "Q" if m == G_PECK_DRILL and pecks > repeats else ""
        raise b.error_at(first + "L", m, f"{name} would make {estimate:.3g} moves (limit "
                                         f"{st.max_moves}; parse(max_moves=...) allows more)")

    def pt(u: float, v: float, w: float) -> tuple[float, float, float]:
        p = [0.0, 0.0, 0.0]
        p[a], p[bb], p[n] = u, v, w
        return p[0], p[1], p[2]

    def go(kind: int, u: float, v: float, w: float) -> None:
        x, y, z = pt(u, v, w)
        rows.append((kind, x, y, z, _NAN, _NAN, _NAN, b.plane, 0,
                     b.feed if kind == LINEAR else _NAN, b.tool, b.lineno, _NAN))

    # axes the cycle sets (MOVE_DTYPE's known): the drilling axis once at R, the plane axes
    # given by words once over the hole
    bit_n = 1 << n
    bits_ab = (XYZ[a] in words) << a | (XYZ[bb] in words) << bb
    if old_cc < r:
        go(RAPID, pos[a], pos[bb], r)
        st.mark(bit_n, len(rows))
        old_cc = r
    clear_cc = r if b.retract_r else old_cc
    cur = list(pos)
    cur[n] = old_cc
    for _ in range(repeats):
        aa += aa_inc
        bv += bb_inc
        go(RAPID, aa, bv, old_cc)
        st.mark(bits_ab | (bit_n if old_cc == r else 0), len(rows))
        if old_cc != r:
            go(RAPID, aa, bv, r)
            st.mark(bit_n, len(rows))
        if m == G_PECK_DRILL:
            depth = r - b.cycle_q
            while depth > cc:
                go(LINEAR, aa, bv, depth)
                go(RAPID, aa, bv, r)
                go(RAPID, aa, bv, depth + _G83_RAPID_DELTA_MM)
                depth -= b.cycle_q
        go(LINEAR, aa, bv, cc)
        go(RAPID, aa, bv, clear_cc)
        old_cc = clear_cc
        cur = list(pt(aa, bv, clear_cc))
    return cur


#: the letters of the blocks :func:`fast_block` runs
_FAST_LETTERS = frozenset("XYZFN")


def fast_block(st: InterpState, toks: list, lineno: int) -> bool:
    """Fast path for the common block: coordinates (and F) under modal G0/G1.

    Parameters
    ----------
    st : InterpState
        The state, changed only when the block is run here.
    toks : list of (str, str, str)
        ``TOKEN.findall`` of the line: letter, number, or a stray character.
    lineno : int
        1-based line number.

    Returns
    -------
    bool
        True if the block was run; False, having changed nothing, for anything else (the
        full interpreter runs it, and says what is wrong with it if anything is).
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
                motion = G_RAPID
            elif v == 1.0:
                motion = G_LINEAR
            else:
                return False
            vals["G"] = v
        elif letter not in _FAST_LETTERS:
            return False
        elif letter != "N":
            vals[letter] = float(num)
    if motion not in STRAIGHT_MOTIONS:
        return False
    vals.pop("G", None)
    for v in vals.values():
        if not abs(v) <= MAX_MAGNITUDE:  # huge or not finite: the full interpreter says why
            return False
    f = st.scale()
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
    if motion == G_LINEAR and not feed > 0:
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
    if motion == G_RAPID:
        st.rows.append((RAPID, x, y, z, _NAN, _NAN, _NAN, st.plane, 0, _NAN, st.tool, lineno,
                        _NAN))
    else:
        st.rows.append((LINEAR, x, y, z, _NAN, _NAN, _NAN, st.plane, 0, feed, st.tool, lineno,
                        _NAN))
    if st.known != KNOWN_ALL:
        st.mark(("X" in vals) | ("Y" in vals) << 1 | ("Z" in vals) << 2, len(st.rows))
    st.pos = [x, y, z]
    st.feed = feed
    st.motion = motion
    st.cycle_il = math.nan
    return True
