"""Tests of elementary positions: chords and 3D DDA (zmap.sim.path)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.sim.gcode import parse
from zmap.sim.path import Positions, arc_chords, dda, positions

from tests.conftest import GCODE_DATA as DATA


def _dda_reference(a, b, pitch):
    """Slow, obvious DDA: n = ceil(L_inf / pitch) equal steps, last one exactly b."""
    out = []
    for p, q in zip(a, b):
        p, q = np.asarray(p, float), np.asarray(q, float)
        linf = float(np.max(np.abs(q - p)))
        if linf == 0:
            continue
        n = max(1, math.ceil(linf / pitch - 1e-9))
        for k in range(1, n + 1):
            out.append(q if k == n else p + (q - p) * (k / n))
    return np.array(out).reshape(-1, 3)


def test_dda_exact_small_case():
    xyz, seg = dda([[0, 0, 0], [1, 1, 1], [1, 1, 1]], [[1, 1, 1], [1, 1, 1], [1, 0, 0.5]],
                   pitch=0.5)
    np.testing.assert_array_equal(
        xyz, [[0.5, 0.5, 0.5], [1, 1, 1], [1, 0.5, 0.75], [1, 0, 0.5]])
    np.testing.assert_array_equal(seg, [0, 0, 2, 2])  # the zero-length segment gives none


@settings(max_examples=60, deadline=None)
@given(
    pts=st.lists(st.tuples(*[st.floats(-20, 20).map(lambda v: round(v, 6))] * 3),
                 min_size=2, max_size=8),
    pitch=st.floats(0.05, 2.0),
)
def test_dda_invariants_and_reference(pts, pitch):
    p = np.array(pts)
    a, b = p[:-1], p[1:]
    xyz, seg = dda(a, b, pitch=pitch)
    np.testing.assert_allclose(xyz, _dda_reference(a, b, pitch), rtol=0, atol=1e-12)
    # consecutive positions (from the segment start) at most one pitch along the dominant axis
    prev = np.vstack([a[:1], xyz[:-1]])
    newseg = np.ones(len(seg), bool)
    newseg[1:] = seg[1:] != seg[:-1]
    prev[newseg] = a[seg[newseg]]
    assert (np.abs(xyz - prev).max(axis=1) <= pitch * (1 + 1e-9)).all()
    # every nonzero segment ends exactly at its end point
    nz = np.flatnonzero(np.abs(b - a).max(axis=1) > 0)
    ends = xyz[np.r_[seg[1:] != seg[:-1], True]] if len(seg) else np.empty((0, 3))
    np.testing.assert_array_equal(ends, b[nz])
    # positions lie on their segment
    d = b[seg] - a[seg]
    t = np.einsum("ij,ij->i", xyz - a[seg], d) / np.einsum("ij,ij->i", d, d)
    np.testing.assert_allclose(a[seg] + d * t[:, None], xyz, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    c=st.tuples(st.floats(-30, 30), st.floats(-30, 30), st.floats(-30, 30)),
    r=st.floats(0.2, 30), a0=st.floats(-math.pi, math.pi),
    sweep=st.floats(-4 * math.pi, 4 * math.pi).filter(lambda s: abs(s) > 1e-3),
    dz=st.floats(-5, 5), plane=st.sampled_from([17, 18, 19]), tol=st.floats(1e-3, 0.5),
)
def test_arc_chords_on_circle_within_tolerance(c, r, a0, sweep, dz, plane, tol):
    ia, ib, n = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}[plane]
    c = np.array(c)
    s = c.copy()
    s[ia] += r * math.cos(a0)
    s[ib] += r * math.sin(a0)
    e = c.copy()
    e[ia] += r * math.cos(a0 + sweep)
    e[ib] += r * math.sin(a0 + sweep)
    e[n] += dz
    v, arc = arc_chords([s], [e], [c], [plane], [sweep], chord_tol=tol)
    assert (arc == 0).all()
    np.testing.assert_array_equal(v[-1], e)
    allv = np.vstack([s, v])
    rad = np.hypot(allv[:, ia] - c[ia], allv[:, ib] - c[ib])
    np.testing.assert_allclose(rad, r, rtol=1e-9, atol=1e-9)  # every vertex on the circle
    # chord error: the sagitta of each chord is within tol
    step = abs(sweep) / len(v)
    assert r * (1 - math.cos(step / 2)) <= tol * (1 + 1e-9)
    mids = (allv[1:] + allv[:-1]) / 2
    sag = r - np.hypot(mids[:, ia] - c[ia], mids[:, ib] - c[ib])
    assert (sag <= tol * (1 + 1e-9) + 1e-12).all()
    # helix: the normal coordinate advances linearly with the angle
    np.testing.assert_allclose(allv[:, n], s[n] + dz * np.linspace(0, 1, len(allv)), atol=1e-9)
    # the direction of travel follows the sign of the sweep about the plane normal
    u0 = allv[0] - c
    u1 = allv[1] - c
    cross = u0[ia] * u1[ib] - u0[ib] * u1[ia]
    assert np.sign(cross) == np.sign(sweep) or abs(cross) < 1e-12


def test_positions_of_a_program():
    prog = parse("G21 G90 G0 X0 Y0 Z1\nG1 X1 F100\nG1 X1\nG3 X-1 Y0 I-1 J0\nG0 Z5\n")
    pos = positions(prog, pitch=0.1)
    assert isinstance(pos, Positions)
    np.testing.assert_array_equal(pos.xyz[-1], [-1, 0, 5])
    assert (np.diff(pos.move) >= 0).all()
    assert 2 not in pos.move  # the zero-length move adds no position
    # every move's last position is exactly its end point
    for i in np.unique(pos.move):
        np.testing.assert_array_equal(pos.xyz[pos.move == i][-1], prog.moves["end"][i])
    np.testing.assert_array_equal(pos.line, prog.moves["line"][pos.move])
    steps = np.abs(np.diff(np.vstack([[0, 0, 0], pos.xyz]), axis=0)).max(axis=1)
    assert (steps <= 0.1 + 1e-12).all()
    arc_pts = pos.xyz[pos.move == 3]
    np.testing.assert_allclose(np.hypot(arc_pts[:, 0], arc_pts[:, 1]), 1, atol=0.01)
    assert pos.move_last_stage(prog.n_moves)[-1] == len(pos)


def test_positions_without_sweep_field_and_tools():
    prog = parse("T3 M6\nG21 G0 X2 Y0\nG2 X0 Y2 I-2 J0 F10\n")
    moves = prog.moves
    names = [n for n in moves.dtype.names if n != "sweep"]
    bare = np.empty(moves.shape, dtype=[(n, moves.dtype[n]) for n in names])
    for n in names:
        bare[n] = moves[n]
    p1, p2 = positions(prog, pitch=0.2), positions(bare, pitch=0.2)
    np.testing.assert_array_equal(p1.xyz, p2.xyz)
    assert (p1.tool == 3).all()


def test_from_xyz_and_validation():
    p = Positions.from_xyz(np.zeros((4, 3)), tool=2)
    assert p.tool.tolist() == [2] * 4 and p.move.tolist() == [0, 1, 2, 3] and len(p) == 4
    assert p.xyz.dtype == np.float64 and p.tool.dtype == np.int32
    with pytest.raises(ValueError, match="shape"):
        Positions.from_xyz(np.zeros((4, 3)), tool=[1, 2])
    prog = parse("G0 X1\n")
    for bad in (0, -1, float("nan"), "x"):
        with pytest.raises(ValueError, match="pitch"):
            positions(prog, pitch=bad)
    with pytest.raises(ValueError, match="chord_tol"):
        positions(prog, chord_tol=0)
    with pytest.raises(TypeError, match="Program"):
        positions([1, 2, 3])


def test_real_program_counts_match_reference():
    prog = parse(DATA / "flower_mold.nc")
    pos = positions(prog, pitch=0.26)
    m = prog.moves
    linf = np.abs(m["end"] - m["start"]).max(axis=1)
    want = sum(max(1, math.ceil(v / 0.26 - 1e-9)) for v in linf if v > 0)
    assert len(pos) == want
    np.testing.assert_array_equal(pos.xyz[-1], m["end"][-1])
    gates = parse(DATA / "Gates_combined_R12.nc")
    sp = positions(gates, pitch=0.26)
    assert len(sp) > gates.n_moves
    assert np.isfinite(sp.xyz).all()
