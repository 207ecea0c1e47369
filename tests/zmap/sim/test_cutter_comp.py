"""Tests of the cutter radius compensation engine (zmap.sim.cutter_comp).

Hand-checked geometry, error cases, paths whose expected numbers come from LinuxCNC's own
interpreter tests (tests/interp/crazy-paths and cam-nisley: rs274ngc's canonical output,
printed to 4 decimals), and a property test on random convex polygons.
"""

from __future__ import annotations

import copy
import math
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.errors import ZMapError
from zmap.sim.cutter_comp import CompError, CutterComp

from tests.conftest import GCODE_DATA as DATA

F = 100.0


class Driver:
    """Feeds an engine the way the reader will: omitted axes and IJ from the programmed point."""

    def __init__(self, side: str, radius: float, start: tuple[float, float, float]):
        self.rows: list[tuple] = []
        self.cc = CutterComp(side, radius, start, self.rows.append)

    def _end(self, x, y, z, inc=False):
        px, py, pz = self.cc.programmed
        if inc:
            return (px + (x or 0.0), py + (y or 0.0), pz + (z or 0.0))
        return (px if x is None else x, py if y is None else y, pz if z is None else z)

    def g0(self, x=None, y=None, z=None, line=0):
        self.cc.straight(0, self._end(x, y, z), F, 1, line)

    def g1(self, x=None, y=None, z=None, line=0, inc=False):
        self.cc.straight(1, self._end(x, y, z, inc), F, 1, line)

    def arc(self, ccw, x=None, y=None, i=0.0, j=0.0, z=None, p=1, line=0, inc=False):
        px, py, _ = self.cc.programmed
        end = self._end(x, y, z, inc)
        self.cc.arc(ccw, end, (px + i, py + j), p - 1, F, 1, line)

    def g2(self, *a, **k):
        self.arc(False, *a, **k)

    def g3(self, *a, **k):
        self.arc(True, *a, **k)

    def g40(self):
        self.cc.flush()
        return self.rows


def xy(row):
    return (row[1], row[2])


def approx_xy(x, y, tol=1e-9):
    return pytest.approx((x, y), abs=tol)


def canon(rows, digits=4):
    """Rows as LinuxCNC's canon calls print them (sai: %.4f, -0.0000 read as 0.0000)."""

    def f(v):
        s = f"{v:.{digits}f}"
        return s[1:] if s == "-" + "0." + "0" * digits else s

    out = []
    for r in rows:
        if r[0] == 0:
            out.append(f"STRAIGHT_TRAVERSE({f(r[1])}, {f(r[2])}, {f(r[3])})")
        elif r[0] == 1:
            out.append(f"STRAIGHT_FEED({f(r[1])}, {f(r[2])}, {f(r[3])})")
        else:
            rot = (r[8] + 1) * (1 if r[0] == 3 else -1)
            out.append(f"ARC_FEED({f(r[1])}, {f(r[2])}, {f(r[4])}, {f(r[5])}, {rot}, "
                       f"{f(r[3])})")
    return out


def check_rows(rows, start, tol=1e-9):
    """Every row is consistent: arcs start and end on their circle, sweep matches kind.

    ``tol`` allows for programmed arcs whose end is off the circle by a rounding error:
    compensation keeps their centre, as LinuxCNC does.
    """
    sx, sy, sz = start
    for r in rows:
        kind, x, y, z, cx, cy, cz, plane, turns, feed, tool, line, sweep = r
        assert plane == 17
        if kind >= 2:
            assert cz == sz
            r1 = math.hypot(sx - cx, sy - cy)
            r2 = math.hypot(x - cx, y - cy)
            assert r1 == pytest.approx(r2, abs=tol)
            assert (sweep > 0) == (kind == 3)
            a0 = math.atan2(sy - cy, sx - cx)
            assert math.cos(a0 + sweep) * r1 + cx == pytest.approx(x, abs=tol)
            assert math.sin(a0 + sweep) * r1 + cy == pytest.approx(y, abs=tol)
        else:
            assert math.isnan(cx) and math.isnan(sweep)
            assert math.isnan(feed) == (kind == 0)
        sx, sy, sz = x, y, z


# ------------------------------------------------------------------ squares -----------------
def test_square_pocket_g41_inside_corners_are_intersections():
    # CCW around the 10 mm square [0,10]^2 with the tool on the left: inside the pocket.
    d = Driver("left", 1.0, (5.0, 5.0, 0.0))
    d.g1(10, 5, line=1)  # entry; its end is moved to the first inside corner
    d.g1(10, 10, line=2)
    d.g1(0, 10, line=3)
    d.g1(0, 0, line=4)
    d.g1(10, 0, line=5)
    d.g1(10, 5, line=6)
    assert d.cc.pending == 1
    rows = d.g40()
    assert [r[0] for r in rows] == [1] * 6
    pts = [xy(r) for r in rows]
    want = [(9, 6), (9, 9), (1, 9), (1, 1), (9, 1), (9, 5)]
    for p, w in zip(pts, want):
        assert p == approx_xy(*w)
    assert [r[11] for r in rows] == [1, 2, 3, 4, 5, 6]
    assert d.cc.position == pytest.approx((9.0, 5.0, 0.0))
    assert d.cc.programmed == (10.0, 5.0, 0.0)
    check_rows(rows, (5.0, 5.0, 0.0))


@pytest.mark.parametrize("side", ["left", "right"])
def test_square_outside_corners_are_arcs_about_the_corner(side):
    # G42 counter-clockwise or G41 clockwise: the tool runs outside the square.
    corners = [(10, 0), (10, 10), (0, 10), (0, 0), (5, 0)]
    if side == "left":
        corners = [(0, 0), (0, 10), (10, 10), (10, 0), (5, 0)]
    d = Driver(side, 1.0, (5.0, -5.0, 0.0))
    d.g1(5, 0)
    for x, y in corners:
        d.g1(x, y)
    rows = d.g40()
    check_rows(rows, (5.0, -5.0, 0.0))
    arcs = [r for r in rows if r[0] >= 2]
    assert len(arcs) == 4
    kind = 3 if side == "right" else 2
    centres = sorted((r[4], r[5]) for r in arcs)
    assert centres == [(0, 0), (0, 10), (10, 0), (10, 10)]
    for r in arcs:
        assert r[0] == kind
        assert math.hypot(r[1] - r[4], r[2] - r[5]) == pytest.approx(1.0)
        assert abs(r[12]) == pytest.approx(math.pi / 2)
    # lines run 1 mm outside the edges
    for r in rows[1:]:
        if r[0] == 1:
            x, y = xy(r)
            assert min(abs(x + 1), abs(x - 11), abs(y + 1), abs(y - 11)) == pytest.approx(0.0,
                                                                                        abs=1e-12)
    # the entry meets the first edge at an inside corner: (6, -1) for G42, (4, -1) for G41
    assert xy(rows[0]) == approx_xy(6.0 if side == "right" else 4.0, -1.0)


def test_rapid_outside_corner_is_a_traverse_not_an_arc():
    d = Driver("right", 1.0, (5.0, -5.0, 0.0))
    d.g1(5, 0)
    d.g0(10, 0)
    d.g0(10, 10)  # outside corner at (10, 0): G0 cannot arc
    rows = d.g40()
    assert [r[0] for r in rows] == [1, 0, 0, 0]
    assert xy(rows[2]) == approx_xy(11.0, 0.0)  # start of the offset of the new edge
    assert math.isnan(rows[2][9])


# ------------------------------------------------------------------ entries -----------------
def test_line_entry_offsets_the_end_point_perpendicular():
    # cam-nisley: G0 Y-13.675, G42 D1 (r = 0.79375), G1 Y-10.475
    d = Driver("right", 0.79375, (-1.6, -13.675, 10.0))
    d.g1(-1.6, -10.475)
    d.g2(0.0, -8.875, i=1.6, j=0.0)  # tangent arc: no corner
    rows = d.g40()
    assert canon(rows) == ["STRAIGHT_FEED(-0.8063, -10.4750, 10.0000)",
                                 "ARC_FEED(0.0000, -9.6687, 0.0000, -10.4750, -1, 10.0000)"]
    assert rows[0][1] == pytest.approx(-0.80625)
    assert rows[1][2] == pytest.approx(-9.66875)
    assert rows[1][12] == pytest.approx(-math.pi / 2)


def test_arc_entry_moves_the_centre_so_the_arc_starts_at_the_tool():
    # G41 then G3 X10 I5 from (0,0): a half circle cut from inside (radius 5, tool r=1).
    # The compensated end is (9, 0); the arc from the tool at (0,0) to it is centred on the
    # line toward the programmed centre: (4.5, 0), radius 4.5.
    d = Driver("left", 1.0, (0.0, 0.0, 0.0))
    d.g3(10, 0, i=5, j=0)
    rows = d.g40()
    (r,) = rows
    assert r[0] == 3
    assert xy(r) == approx_xy(9.0, 0.0)
    assert (r[4], r[5]) == pytest.approx((4.5, 0.0))
    assert r[12] == pytest.approx(math.pi)
    check_rows(rows, (0.0, 0.0, 0.0))


def test_arc_entry_outside():
    # G42 on the same CCW half circle: tool outside, end (11, 0); centre (5.5, 0).
    d = Driver("right", 1.0, (0.0, 0.0, 0.0))
    d.g3(10, 0, i=5, j=0)
    (r,) = d.g40()
    assert xy(r) == approx_xy(11.0, 0.0)
    assert (r[4], r[5]) == pytest.approx((5.5, 0.0))


def test_entry_move_not_longer_than_radius_raises():
    d = Driver("left", 1.0, (0.0, 0.0, 0.0))
    with pytest.raises(CompError, match="entry move must be longer than the tool radius"):
        d.g1(1.0, 0.0)
    # a Z-only first move is an entry of length 0
    with pytest.raises(CompError, match="entry move"):
        d.g1(z=-1.0)
    with pytest.raises(CompError, match="entry arc"):
        d.g3(0.5, 0.5, i=0.25, j=0.25)
    assert d.rows == [] and d.cc.pending == 0
    d.g1(2.0, 0.0)  # the state is untouched: a proper entry still works
    assert d.cc.position == pytest.approx((2.0, 1.0, 0.0))


def test_error_is_a_zmap_error():
    assert issubclass(CompError, ZMapError)


# ------------------------------------------------------------------ arcs --------------------
def test_inside_arc_smaller_than_tool_raises():
    d = Driver("left", 1.0, (0.0, -5.0, 0.0))
    d.g1(0, 0)
    d.g1(5, 0)
    with pytest.raises(CompError, match="not less than the radius"):
        d.g3(5, 1.6, i=0, j=0.8)  # CCW with tool on the left: inside a 0.8 mm arc
    d.g2(5, -2, i=0, j=-1)  # CW radius 1 with the tool on the left: outside, fine
    rows = d.g40()
    check_rows(rows, (0.0, -5.0, 0.0))
    assert math.hypot(rows[-1][1] - 5, rows[-1][2] + 1) == pytest.approx(2.0)


def test_entry_arc_inside_radius_raises():
    d = Driver("right", 2.0, (0.0, 0.0, 0.0))
    with pytest.raises(CompError, match="not less than the radius"):
        d.g2(3, 0, i=1.5, j=0)  # CW with tool on the right: inside, 1.5 <= 2


def test_inside_arc_runs_at_arc_radius_minus_tool_radius():
    d = Driver("left", 1.0, (5.0, -5.0, 0.0))
    d.g1(5, 0)
    d.g3(-5, 0, i=-5, j=0, p=2)  # one and a half turns, P2
    rows = d.g40()
    r = rows[-1]
    assert r[0] == 3 and r[8] == 1
    assert xy(r) == approx_xy(-4.0, 0.0)
    assert r[12] == pytest.approx(3 * math.pi)
    check_rows(rows, (5.0, -5.0, 0.0))


def test_line_into_arc_tangent_and_at_inside_corner():
    # Tangent: the arc leaves (10, 0) heading +X like the line; tool inside it (radius 4).
    d = Driver("left", 1.0, (-5.0, 0.0, 0.0))
    d.g1(0, 0)
    d.g1(10, 0)
    d.g3(10, 10, i=0, j=5)
    rows = d.g40()
    check_rows(rows, (-5.0, 0.0, 0.0))
    assert [r[0] for r in rows] == [1, 1, 3]
    assert xy(rows[1]) == approx_xy(10.0, 1.0)
    assert xy(rows[2]) == approx_xy(10.0, 9.0)
    assert rows[2][12] == pytest.approx(math.pi)

    # Inside corner: the circle about (5, 0) leaves (10, 0) heading +Y, a left turn with the
    # tool on the left. The line's end moves to where y = 1 meets the offset circle (r 4).
    d = Driver("left", 1.0, (-5.0, 0.0, 0.0))
    d.g1(0, 0)
    d.g1(10, 0)
    d.g3(5, 5, i=-5, j=0)
    rows = d.g40()
    check_rows(rows, (-5.0, 0.0, 0.0))
    assert [r[0] for r in rows] == [1, 1, 3]
    assert xy(rows[1]) == approx_xy(5.0 + math.sqrt(15.0), 1.0)
    assert xy(rows[2]) == approx_xy(5.0, 4.0)


# ------------------------------------------------------------------ gouging ----------------
def test_concave_corner_that_would_gouge_raises():
    # LinuxCNC tests/interp/bad/ccomp-gouging: a 0.1 mm step narrower than the tool.
    d = Driver("left", 0.125, (0.0, 0.0, 0.0))
    d.g1(1, 0)
    d.g1(2, 0)
    d.g1(2, 0.1)
    rows_before = list(d.rows)
    snap = copy.deepcopy(d.cc)
    with pytest.raises(CompError, match="straight feed.*gouging"):
        d.g1(1, 0.1)
    assert d.rows == rows_before  # nothing emitted, nothing changed
    assert d.cc.__dict__.keys() == snap.__dict__.keys()
    assert d.cc.position == snap.position and d.cc.programmed == snap.programmed


def _on_circle(cx, cy, start, degrees):
    """End point of an arc about (cx, cy) from ``start`` turned by ``degrees`` (CCW > 0)."""
    a = math.atan2(start[1] - cy, start[0] - cx) + math.radians(degrees)
    rad = math.hypot(start[0] - cx, start[1] - cy)
    return cx + rad * math.cos(a), cy + rad * math.sin(a)


def test_arc_in_concave_corner_that_would_gouge_raises():
    # G41 r=1 along +X, then a 30 degree CW arc about (1, 3) that turns back over the line.
    # The line's offset (y = 1) meets the arc's offset circle (radius sqrt(10) + 1) at -151.3
    # degrees, past the compensated arc's end at -138.4: the tool cannot reach the arc.
    d = Driver("left", 1.0, (-5.0, 0.0, 0.0))
    d.g1(0, 0)
    d.g2(*_on_circle(1, 3, (0, 0), -30), i=1, j=3)
    with pytest.raises(CompError, match="arc ending in an inside corner.*gouging"):
        d.g40()


def test_line_into_arc_corner_too_tight_raises():
    # G42 along +X, then a CW arc about (-1, 1) back over the line: no point on the arc's
    # offset circle (inside it, radius sqrt(2) - 1) lies one radius from the line.
    d = Driver("right", 1.0, (-5.0, 0.0, 0.0))
    d.g1(0, 0)
    with pytest.raises(CompError, match="inside corner the tool cannot reach"):
        d.g2(*_on_circle(-1, 1, (0, 0), -135), i=-1, j=1)


def test_arc_into_line_corner_too_tight_raises():
    d = Driver("left", 1.0, (-5.0, 0.0, 0.0))
    d.g1(0, 0)
    d.g3(*_on_circle(2, -3, (0, 0), 30), i=2, j=-3)
    with pytest.raises(CompError, match="arc into this line is too tight"):
        d.g1(2, 3)


def test_arc_into_arc_corner_too_tight_raises():
    d = Driver("left", 1.0, (-5.0, 0.0, 0.0))
    d.g1(0, 0)
    d.g3(2, -2, i=2, j=0)
    with pytest.raises(CompError, match="between these two arcs is too tight"):
        d.g3(*_on_circle(0, -3, (2, -2), 90), i=-2, j=-1)


def test_concave_arcs_with_the_same_centre_raise():
    d = Driver("right", 1.0, (-5.0, 0.0, 0.0))
    d.g1(0, 0)
    d.g2(*_on_circle(-3, -2, (0, 0), -90), i=-3, j=-2)
    px, py, _ = d.cc.programmed
    with pytest.raises(CompError, match="same centre"):
        d.g3(*_on_circle(-3, -2, (px, py), 60), i=-3 - px, j=-2 - py)


# ------------------------------------------------------------------ Z-only moves ----------
def test_z_only_moves_are_held_with_the_previous_move_and_follow_the_corner():
    d = Driver("left", 1.0, (0.0, -5.0, 5.0))
    d.g1(0, 0)
    d.g1(10, 0)
    d.g1(z=-1.0, line=7)
    d.g0(z=2.0, line=8)
    assert d.cc.pending == 3
    assert d.cc.position == pytest.approx((10.0, 1.0, 2.0))
    d.g1(10, 10)  # inside corner: all three held moves end at (9, 1)
    rows = d.rows
    assert [(r[0], r[11]) for r in rows[-3:]] == [(1, 0), (1, 7), (0, 8)]
    for r, z in zip(rows[-3:], (5.0, -1.0, 2.0)):
        assert (r[1], r[2], r[3]) == pytest.approx((9.0, 1.0, z))
    rows = d.g40()
    assert (rows[-1][1], rows[-1][2], rows[-1][3]) == pytest.approx((9.0, 10.0, 2.0))


def test_z_only_move_before_outside_corner_keeps_xy():
    d = Driver("left", 1.0, (-5.0, 0.0, 5.0))
    d.g1(0, 0)
    d.g1(10, 0)
    d.g1(z=0.0)
    d.g1(10, -10)  # outside corner: arc at the new Z
    rows = d.g40()
    assert [r[0] for r in rows] == [1, 1, 1, 2, 1]
    assert (rows[2][1], rows[2][2], rows[2][3]) == pytest.approx((10.0, 1.0, 0.0))
    arc = rows[3]
    assert (arc[4], arc[5], arc[6]) == (10.0, 0.0, 0.0)
    assert (arc[1], arc[2], arc[3]) == pytest.approx((11.0, 0.0, 0.0))
    check_rows(rows, (-5.0, 0.0, 5.0))


# ------------------------------------------------------------------ engine contract -------
def test_rows_have_the_reader_format():
    d = Driver("right", 1.0, (5.0, -5.0, 0.0))
    d.g1(5, 0, line=3)
    d.g0(10, 0, line=4)
    d.g1(10, 10, line=5)
    rows = d.g40()
    for r in rows:
        assert len(r) == 13
        assert r[10] == 1
    assert [r[11] for r in rows] == [3, 4, 5, 5]  # the corner arc carries the next block
    assert rows[2][0] == 3 and rows[2][9] == F


def test_flush_keeps_the_position_and_is_idempotent():
    d = Driver("left", 1.0, (0.0, 0.0, 0.0))
    d.cc.flush()  # nothing yet
    assert d.rows == []
    d.g1(10, 0)
    d.cc.flush()
    d.cc.flush()
    assert len(d.rows) == 1
    assert d.cc.position == pytest.approx((10.0, 1.0, 0.0))
    # a move after an intermediate flush (e.g. M0) still starts from the tool position
    d.g1(20, 0)
    rows = d.g40()
    assert xy(rows[-1]) == approx_xy(20.0, 1.0)


def test_zero_radius_passes_moves_through():
    d = Driver("left", 0.0, (0.0, 0.0, 0.0))
    d.g1(0.5, 0)
    d.g3(1.5, 0, i=0.5, j=0)
    assert d.cc.pending == 0
    assert [xy(r) for r in d.rows] == [(0.5, 0.0), (1.5, 0.0)]
    assert d.rows[1][12] == pytest.approx(math.pi)


def test_negative_radius_swaps_the_side():
    cc = CutterComp("left", -0.5, (0.0, 0.0, 0.0), print)
    assert (cc.side, cc.radius) == ("right", 0.5)


def test_bad_arguments():
    with pytest.raises(ValueError, match="'middle' is not one of 'left', 'right'"):
        CutterComp("middle", 1.0, (0.0, 0.0, 0.0), print)
    with pytest.raises(ValueError, match="finite"):
        CutterComp("left", math.nan, (0.0, 0.0, 0.0), print)
    cc = CutterComp("left", 1.0, (0.0, 0.0, 0.0), print)
    with pytest.raises(ValueError, match="kind=2"):
        cc.straight(2, (5.0, 0.0, 0.0), F, 1, 1)


def test_deepcopy_snapshots_state_and_shares_emit():
    d = Driver("left", 1.0, (0.0, -5.0, 0.0))
    d.g1(0, 0)
    d.g1(10, 0)
    snap = copy.deepcopy(d.cc)
    assert snap.emit == d.cc.emit
    n = len(d.rows)
    d.g1(10, 10)
    d.g1(0, 10)
    first = d.rows[n:]
    del d.rows[n:]
    d.cc = snap  # restore and replay: the same rows again
    d.g1(10, 10)
    d.g1(0, 10)
    assert d.rows[n:] == first


# ------------------------------------------------------------------ LinuxCNC paths --------
# Paths of LinuxCNC's tests/interp/crazy-paths (G41.1 D0.5 and D-0.5: radius 0.25, left and
# right), with the canonical moves its interpreter prints.
CRAZY = {
    "line-arc-lines-arc": (
        (-100.0, -100.0),
        [("G1", -100.0, -102.0), ("G2", -99.562609, -102.978473, 1.095697, -0.097206),
         ("G1", -97.562609, -99.978473), ("G1", -91.562609, -97.978473),
         ("G3", -90.369054, -100.648542, -1.365837, -2.212349)],
        ["STRAIGHT_FEED(-100.2500, -102.0000)",
         "ARC_FEED(-99.7510, -102.0221, -100.0000, -102.0000, 1)",
         "ARC_FEED(-99.2047, -102.8923, -98.9043, -102.0972, -1)",
         "STRAIGHT_FEED(-97.4022, -100.1885)", "STRAIGHT_FEED(-91.4836, -98.2156)",
         "ARC_FEED(-91.4313, -97.7657, -91.5626, -97.9785, 1)",
         "ARC_FEED(-90.1230, -100.6926, -92.9284, -100.1908, 1)"],
        ["STRAIGHT_FEED(-99.7500, -101.0449)",
         "ARC_FEED(-99.7122, -103.1788, -98.9043, -102.0972, -1)",
         "ARC_FEED(-99.7706, -102.8398, -99.5626, -102.9785, -1)",
         "STRAIGHT_FEED(-97.7706, -99.8398)",
         "ARC_FEED(-97.6417, -99.7413, -97.5626, -99.9785, -1)",
         "STRAIGHT_FEED(-92.2450, -97.9424)",
         "ARC_FEED(-90.6151, -100.6045, -92.9284, -100.1908, 1)"],
    ),
    "arcs-and-line": (
        (-100.0, -50.0),
        [("G1", -100.0, -52.0), ("G3", -95.923035, -61.120458, 2.240368, -4.469983),
         ("G1", -97.923035, -57.120458), ("G2", -94.440783, -55.745223, 1.316612, 1.762536),
         ("G3", -95.540324, -52.554728, 1.795380, 2.403458)],
        ["STRAIGHT_FEED(-100.2500, -51.8482)",
         "ARC_FEED(-95.8312, -61.3530, -97.7596, -56.4700, 1)",
         "ARC_FEED(-95.6994, -61.0087, -95.9230, -61.1205, 1)",
         "STRAIGHT_FEED(-97.6994, -57.0087)",
         "ARC_FEED(-97.7734, -56.9202, -97.9230, -57.1205, 1)",
         "ARC_FEED(-94.6869, -55.7012, -96.6064, -55.3579, -1)",
         "ARC_FEED(-94.5904, -55.9455, -94.4408, -55.7452, 1)",
         "ARC_FEED(-95.7816, -52.4891, -92.6454, -53.3418, 1)"],
        ["STRAIGHT_FEED(-99.7500, -52.0000)",
         "ARC_FEED(-99.8880, -52.2235, -100.0000, -52.0000, -1)",
         "ARC_FEED(-96.2722, -60.9811, -97.7596, -56.4700, 1)",
         "STRAIGHT_FEED(-98.1209, -57.2838)",
         "ARC_FEED(-94.1715, -55.6294, -96.6064, -55.3579, -1)",
         "ARC_FEED(-95.2991, -52.6203, -92.6454, -53.3418, 1)"],
    ),
    "zigzag-lines": (
        (-100.0, 0.0),
        [("G1", -100.0, -2.0), ("G1", -85.0, 3.0), ("G1", -87.0, -2.0), ("G1", -82.0, -8.0),
         ("G1", -85.0, -5.5)],
        ["STRAIGHT_FEED(-100.2500, -2.0000)",
         "ARC_FEED(-99.9209, -2.2372, -100.0000, -2.0000, 1)",
         "STRAIGHT_FEED(-85.4323, 2.5924)", "STRAIGHT_FEED(-87.2321, -1.9072)",
         "ARC_FEED(-87.1921, -2.1600, -87.0000, -2.0000, 1)",
         "STRAIGHT_FEED(-83.9526, -6.0474)", "STRAIGHT_FEED(-84.8400, -5.3079)"],
        ["STRAIGHT_FEED(-99.7500, -1.6531)", "STRAIGHT_FEED(-85.0791, 3.2372)",
         "ARC_FEED(-84.7679, 2.9072, -85.0000, 3.0000, -1)",
         "STRAIGHT_FEED(-86.7125, -1.9545)", "STRAIGHT_FEED(-81.8079, -7.8400)",
         "ARC_FEED(-82.1600, -8.1921, -82.0000, -8.0000, -1)",
         "STRAIGHT_FEED(-85.1600, -5.6921)"],
    ),
    "arc-arc-line-line": (
        (-100.0, 100.0),
        [("G1", -100.0, 98.0), ("G3", -98.990068, 95.740711, -1.155708, -1.871988),
         ("G2", -97.598155, 97.441626, 0.658306, 0.881268), ("G1", -93.598155, 107.441626),
         ("G1", -96.598155, 105.441626)],
        ["STRAIGHT_FEED(-100.2500, 98.4045)",
         "ARC_FEED(-98.7440, 95.6967, -101.1557, 96.1280, 1)",
         "ARC_FEED(-98.8405, 95.9410, -98.9901, 95.7407, 1)",
         "ARC_FEED(-97.7649, 97.2553, -98.3318, 96.6220, -1)",
         "ARC_FEED(-97.3660, 97.3488, -97.5982, 97.4416, 1)",
         "STRAIGHT_FEED(-93.3660, 107.3488)",
         "ARC_FEED(-93.7368, 107.6496, -93.5982, 107.4416, 1)",
         "STRAIGHT_FEED(-96.7368, 105.6496)"],
        ["STRAIGHT_FEED(-99.7500, 98.0000)",
         "ARC_FEED(-100.1313, 97.7873, -100.0000, 98.0000, -1)",
         "ARC_FEED(-99.2659, 95.6473, -101.1557, 96.1280, 1)",
         "ARC_FEED(-97.7149, 97.8228, -98.3318, 96.6220, -1)",
         "STRAIGHT_FEED(-94.1292, 106.7871)", "STRAIGHT_FEED(-96.4595, 105.2336)"],
    ),
}


def _short(rows):
    out = []
    for s in canon(rows):
        name, args = s[:-1].split("(")
        a = args.split(", ")
        out.append(f"{name}({', '.join(a[:5] if name == 'ARC_FEED' else a[:2])})")
    return out


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("name", sorted(CRAZY))
def test_linuxcnc_crazy_paths(name, side):
    start, moves, want_right, want_left = CRAZY[name]
    d = Driver("left", 0.25 if side == "left" else -0.25, (start[0], start[1], 0.0))
    for m in moves:
        if m[0] == "G1":
            d.g1(m[1], m[2])
        else:
            d.arc(m[0] == "G3", m[1], m[2], i=m[3], j=m[4])
    rows = d.g40()
    check_rows(rows, (start[0], start[1], 0.0), tol=1e-5)
    assert _short(rows) == (want_right if side == "right" else want_left)


def _cam_nisley(radius: float) -> list[tuple]:
    """data/gcode/cam-nisley_cam.ngc from G42 D1 to G40, its O-word loops unrolled by hand."""
    d = Driver("right", radius, (-1.6, -13.675, 10.0))
    sin = lambda a: math.sin(math.radians(a))  # noqa: E731
    cos = lambda a: math.cos(math.radians(a))  # noqa: E731
    asin = lambda v: math.degrees(math.asin(v))  # noqa: E731
    fillet, raw, shaft, cam, cutter = 1.60, 17.75 / 2, 10.30 / 2, 17.36 / 2, 3.10
    d.g1(-1.6, -(raw + fillet))
    d.g2(0, -raw, i=fillet, j=0)
    d.g0(z=10.0)
    for z0, zdepth, rmin in ((0.0, 4.17, shaft), (-4.17, 2.95, cam)):
        nz = math.ceil(zdepth / 1.0)
        nr = math.ceil((raw - rmin) / 1.0)
        zstep, rstep = zdepth / nz, (raw - rmin) / nr
        z = z0
        for _ in range(nz + 1):
            d.g1(z=z)
            rad = raw
            for _ in range(nr + 1):
                if rad != raw:
                    d.g2(y=0 - 2 * fillet, j=0 - fillet, inc=True)
                    d.g2(y=rstep + 2 * fillet, j=fillet + rstep / 2, inc=True)
                d.g3(y=0 - rad, j=rad)
                rad = rad - rstep
            d.g2(y=0 - (raw + 2 * fillet), j=0 - (((raw - rmin) / 2) + fillet))
            d.g2(y=0 - raw, j=fillet)
            z = z - zstep
    d.g0(z=10.0)
    clear = cutter + 2 * fillet
    outer = raw + clear
    d.g2(y=0 - outer, j=0 - clear / 2)
    op = outer - fillet
    beta = 108.0 - asin(fillet / op)
    ob = op * cos(asin(fillet / op))
    ax, ay = outer * sin(beta), outer * cos(beta)
    bx, by = ob * sin(108.0), ob * cos(108.0)
    px_, py_ = op * sin(beta), op * cos(beta)
    zstep = 2.95 / 3
    rstep = (raw - shaft) / math.ceil((raw - shaft) / 1.0)
    z = -4.17
    for _ in range(4):
        d.g1(z=z)
        rad = raw
        for _ in range(5):
            oq = rad + fillet
            gamma = asin(fillet / oq)
            delta = 108.0 - gamma
            oc = oq * cos(gamma)
            cx, cy = oc * sin(108.0), oc * cos(108.0)
            dx, dy = rad * sin(delta), rad * cos(delta)
            qx, qy = oq * sin(delta), oq * cos(delta)
            d.g2(0 - ax, 0 - ay, i=0.0, j=outer)
            d.g2(0 - bx, 0 - by, i=ax - px_, j=ay - py_)
            d.g1(0 - cx, 0 - cy)
            d.g2(0 - dx, 0 - dy, i=cx - qx, j=cy - qy)
            d.g3(dx, 0 - dy, i=dx, j=dy)
            d.g2(cx, 0 - cy, i=qx - dx, j=dy - qy)
            d.g1(bx, 0 - by)
            d.g2(ax, 0 - ay, i=px_ - bx, j=by - py_)
            d.g2(0.0, 0 - outer, i=0 - ax, j=ay)
            rad = rad - rstep
        z = z - zstep
    d.g0(z=75.0)
    return d.g40()


def _cam_expected() -> list[str]:
    out = []
    for line in (DATA / "cam-nisley_cam.expected").read_text().splitlines():
        m = re.search(r"(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED)\(([^)]*)\)", line)
        if m:
            a = ["0.0000" if s == "-0.0000" else s for s in m.group(2).split(", ")]
            out.append(f"{m.group(1)}({', '.join(a[:6] if m.group(1) == 'ARC_FEED' else a[:3])})")
    # drop the two traverses before G42 and the return home after G40
    assert out[1] == "STRAIGHT_TRAVERSE(-1.6000, -13.6750, 10.0000)"
    return out[2:-1]


def test_linuxcnc_cam_nisley_exact():
    # LinuxCNC's test harness converts the inch tool table with 1 / 0.03937007874016 mm per
    # inch, a hair under 25.4: with that radius every move prints identically.
    rows = _cam_nisley(0.0625 / 0.03937007874016 / 2)
    check_rows(rows, (-1.6, -13.675, 10.0), tol=1e-6)
    assert canon(rows) == _cam_expected()


def test_linuxcnc_cam_nisley_nominal_radius_within_print_precision():
    # With the nominal 0.79375 mm some ends fall exactly on a half of the last printed digit
    # (e.g. -11.28125) and print the other way: compare numerically.
    rows = _cam_nisley(0.0625 * 25.4 / 2)
    want = _cam_expected()
    assert len(rows) == len(want) == 314
    for row, w in zip(rows, want):
        name = w.split("(")[0]
        wv = [float(v) for v in w[len(name) + 1:-1].split(", ")]
        if name == "ARC_FEED":
            got = [row[1], row[2], row[4], row[5], (row[8] + 1) * (1 if row[0] == 3 else -1),
                   row[3]]
        else:
            got = [row[1], row[2], row[3]]
            assert row[0] == (0 if name == "STRAIGHT_TRAVERSE" else 1)
        assert got == pytest.approx(wv, abs=0.5e-4 + 1e-9)


# ------------------------------------------------------------------ property --------------
def _seg_dist(px, py, ax, ay, bx, by):
    ux, uy = bx - ax, by - ay
    t = ((px - ax) * ux + (py - ay) * uy) / (ux * ux + uy * uy)
    t = min(1.0, max(0.0, t))
    return math.hypot(px - ax - t * ux, py - ay - t * uy)


def _contour_dist(p, poly):
    n = len(poly)
    return min(_seg_dist(p[0], p[1], *poly[k], *poly[(k + 1) % n]) for k in range(n))


@st.composite
def convex_polygons(draw):
    """Vertices CCW on a circle of radius 20..50, angular gaps 20..120 degrees."""
    R = draw(st.floats(20.0, 50.0))
    gaps = []
    total = 0.0
    while True:
        g = draw(st.floats(20.0, 120.0))
        if total + g > 340.0:
            break
        gaps.append(g)
        total += g
    if 360.0 - total > 120.0:
        gaps.append(120.0)
        total += 120.0
    phase = draw(st.floats(0.0, 360.0))
    angles = [phase]
    for g in gaps:
        angles.append(angles[-1] + g)
    if len(angles) < 3 or 360.0 - (angles[-1] - angles[0]) < 20.0:
        angles = [phase, phase + 120.0, phase + 240.0]
    pts = [(R * math.cos(math.radians(a)), R * math.sin(math.radians(a))) for a in angles]
    r = draw(st.floats(0.05, 1.5))
    return pts, r


@settings(max_examples=150, deadline=None)
@given(convex_polygons(), st.booleans())
def test_offset_of_convex_polygon_stays_at_tool_radius(poly_r, outside):
    """CCW with G41 (inside) or G42 (outside): every emitted vertex, line midpoint and arc
    point after the entry lies exactly one tool radius from the programmed contour."""
    poly, r = poly_r
    side = "right" if outside else "left"
    d = Driver(side, r, (0.0, 0.0, -1.0))  # enter from the polygon's centre
    n = len(poly)
    for k in range(n + 1):  # move 0 is the entry, then every edge, then the first again
        d.g1(*poly[k % n], line=k)
    d.g1(*poly[1], line=n + 1)  # so the corner at poly[0] is compensated too
    rows = d.g40()
    check_rows(rows, (0.0, 0.0, -1.0))
    n_arcs = 0
    # Rows of move 1 turn the corner from the entry, which is not part of the contour; the
    # last row ends beside a corner no further move resolves (one radius from its own edge
    # only, which for an inside offset is too close to the next edge).
    for prev_row, row in zip(rows, rows[1:-1] if not outside else rows[1:]):
        if row[11] < 2:
            continue
        prev, p = xy(prev_row), xy(row)
        assert _contour_dist(p, poly) == pytest.approx(r, rel=1e-9, abs=1e-9)
        if row[0] == 1:
            mid = ((prev[0] + p[0]) / 2, (prev[1] + p[1]) / 2)
            assert _contour_dist(mid, poly) == pytest.approx(r, rel=1e-9, abs=1e-9)
        else:
            n_arcs += 1
            assert (row[4], row[5]) in poly  # about a programmed corner
            assert row[0] == 3  # G42 around a CCW contour turns CCW
            a0 = math.atan2(prev[1] - row[5], prev[0] - row[4])
            for f in (0.25, 0.5, 0.75):
                a = a0 + f * row[12]
                q = (row[4] + r * math.cos(a), row[5] + r * math.sin(a))
                assert _contour_dist(q, poly) == pytest.approx(r, rel=1e-9, abs=1e-9)
    # outside: one arc per corner; inside: none (corners are intersections)
    assert n_arcs == (n if outside else 0)


# ------------------------------------------------------------------ through the reader -----
# LinuxCNC's ccomp-gouging case as a program: a 0.25 mm tool (tool table) under G41 cannot
# follow a 0.1 mm step back (line 8 would make the held-back move of line 7 run backwards).
_GOUGE = ("T1 M6\nG0 X0 Y0 Z1\nG1 Z-1 F100\nG41 D1\nG1 X1 Y0\nG1 X2\nG1 Y0.1\nG1 X1\nG1 Y5\n"
          "G40\nG0 Z5\nM2\n")


def _table():
    from zmap.sim.tools import Cutter

    return {1: Cutter("flat", 0.25)}


def test_reader_comp_error_strict_names_file_line_column():
    from zmap.errors import GCodeError
    from zmap.sim.gcode import parse

    with pytest.raises(GCodeError, match="gouging") as info:
        parse(_GOUGE, tool_table=_table(), filename="step.ngc")
    e = info.value
    assert (e.file, e.line, e.column, e.word) == ("step.ngc", 8, 1, "G1")
    assert str(e).startswith("step.ngc:8:1: G1: a straight feed ending in an inside corner")
    assert "the move is on line 7" in str(e)


def test_reader_comp_error_lenient_skips_the_block_and_warns():
    from zmap.sim.gcode import parse

    p = parse(_GOUGE, tool_table=_table(), lenient=True, filename="step.ngc")
    assert len(p.warnings) == 1
    assert re.match(r"^step\.ngc:8:1: G1: a straight feed ending in an inside corner .*gouging",
                    p.warnings[0])
    assert 8 not in p.moves["line"].tolist()  # the block is skipped, the rest is read
    assert p.moves["line"].tolist()[-1] == 11 and p.moves["end"][-1, 2] == 5.0


def _arc_gouge(tail: str) -> str:
    # test_arc_in_concave_corner_that_would_gouge_raises as a program: the gouge is found
    # only when the held-back arc (line 5) is flushed
    ex, ey = _on_circle(1, 3, (0, 0), -30)
    return f"G0 X-5 Y0 Z1\nF100\nG41.1 D2\nG1 X0 Y0\nG2 X{ex:.9f} Y{ey:.9f} I1 J3\n{tail}"


@pytest.mark.parametrize("tail,line,col,word", [
    ("G40\nG0 X-5\n", 6, 1, "G40"),        # flushed by G40
    ("G0 Z5 M2\n", 6, 7, "M2"),            # flushed at the program's end (M2)
    ("", 5, 1, "end of file"),             # the file ends with compensation on
])
def test_reader_comp_error_at_flush_strict_and_lenient(tail, line, col, word):
    from zmap.errors import GCodeError
    from zmap.sim.gcode import parse

    text = _arc_gouge(tail)
    with pytest.raises(GCodeError, match="arc ending in an inside corner") as info:
        parse(text)
    e = info.value
    assert (e.line, e.column, e.word) == (line, col, word)
    p = parse(text, lenient=True)  # never aborts, every problem a located warning
    assert p.warnings and all(re.match(r"^<string>:\d+:\d+: .+: .+", w) for w in p.warnings)
    assert p.warnings[0].startswith(f"<string>:{line}:{col}: {word}: ")
    assert 5 not in p.moves["line"].tolist()  # the arc that cannot be cut is dropped
