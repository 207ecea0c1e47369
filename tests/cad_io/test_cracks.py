"""cad_io.cracks.bridge_cracks: gaps narrower than 2 tol spanned, real slots, holes and walls kept."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cad_io.cracks import bridge_cracks
from zmap.grid import ZMap

TOL = 0.01


def _slot(centre: float, width: float, depth: float = 20.0):
    """A plane z = 1 + 0.1 x with a straight slot along y, ``width`` wide, ``depth`` deep:
    ``(heights, sampler)``, the sampler also giving faces (0 the plane, 1 the slot's floor)."""
    def h(x, y):
        x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        return np.where(np.abs(x - centre) < width / 2, 1.0 - depth, 1.0 + 0.1 * x)

    def sampler(x, y):
        z = h(x, y)
        return z, np.where(z < 0, 1, 0)
    return h, sampler


@settings(max_examples=60, deadline=None)
@given(width=st.floats(0.001, 0.019), centre=st.floats(1.05, 1.45), y=st.floats(0.1, 1.9),
       at=st.floats(-0.49, 0.49))
def test_crack_narrower_than_two_tol_is_spanned(width, centre, y, at):
    """Every point of a crack up to 2 tol wide inside a cell takes the plane's height."""
    h, sampler = _slot(centre, width)
    base = ZMap.from_function(h, (0, 0, 2, 2), 0.5)
    x = np.array([centre + at * width])
    z, n = bridge_cracks(sampler, base, x, np.array([y]), h(x, y), TOL)
    assert n == 1
    assert abs(z[0] - (1.0 + 0.1 * x[0])) < 1e-9


@settings(max_examples=60, deadline=None)
@given(width=st.floats(0.041, 0.4), centre=st.floats(1.25, 1.3), at=st.floats(-0.49, 0.49))
def test_slot_wider_than_four_tol_is_kept(width, centre, at):
    """A real slot (wider than twice the probe distance) keeps its floor everywhere."""
    h, sampler = _slot(centre, width)
    base = ZMap.from_function(h, (0, 0, 2, 2), 0.5)
    x = np.array([centre + at * width])
    z0 = h(x, 0.7)
    z, n = bridge_cracks(sampler, base, x, np.array([0.7]), z0, TOL)
    assert n == 0 and z[0] == z0[0]
    # faces whose edges carry 0.3 mm reach across a crack up to 0.6 mm wide: probes out to
    # 0.16 mm (the doubling 0.02, 0.04, 0.08, 0.16 with 2 w <= 0.3 + 0.3) span it where both
    # land beyond its rims
    z, n = bridge_cracks(sampler, base, x, np.array([0.7]), z0, TOL, face_tol=np.array([0.3, 0.3]))
    reach = width / 2 + abs(at) * width
    if abs(reach - 0.16) > 1e-6:
        assert n == int(reach < 0.16), (reach, n)


def test_wall_foot_is_not_probed():
    """A point at the foot of a step has the step's low nodes among its cell's: not probed."""
    calls = []

    def step(x, y):
        calls.append(np.size(x))
        x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        z = np.where(x < 1.23, 0.0, 5.0)
        return z, np.zeros(z.shape, dtype=int)

    base = ZMap.from_function(lambda x, y: step(x, y)[0], (0, 0, 2, 2), 0.5)
    calls.clear()
    x, y = np.array([1.2, 1.229, 0.3]), np.array([0.4, 0.4, 1.0])
    z, n = bridge_cracks(step, base, x, y, step(x, y)[0], TOL, face_tol=np.array([1.0]))
    assert n == 0 and z.tolist() == [0.0, 0.0, 0.0] and calls == [3]


def test_no_surface_and_bad_points_left_as_they_are():
    h, sampler = _slot(1.2, 0.01)
    base = ZMap.from_function(h, (0, 0, 2, 2), 0.5)
    x, y = np.array([np.nan, 5.0, 1.2]), np.array([0.3, 0.3, 0.3])
    z0 = np.array([np.nan, np.nan, -19.0])
    z, n = bridge_cracks(sampler, base, x, y, z0, TOL)
    assert n == 1 and np.isnan(z[:2]).all() and abs(z[2] - 1.12) < 1e-9


@pytest.mark.slow
def test_trj8_seam_crack_spanned():
    """trj8's faces 351 and 42 (edges 0.30 mm) leave a crack about 0.015 mm wide on their seam,
    through which the sampler and OCC see face 49, 46 mm below: the EZ heights span it."""
    pytest.importorskip("OCP")
    from cad_io.sampler import sample, sample_points
    from cad_io.step import read_step

    part = read_step(Path(__file__).resolve().parents[2] / "data" / "step" / "trj8_b1-ec-214.stp")
    base = sample(part, 0.5, bounds=(173.5, -27.0, 177.5, -23.0), progress=False)

    def sampler(x, y):
        z, face, _ = sample_points(part, x, y, deflection=0.005)
        return z, face

    face_tol = np.array([f.tolerance for f in part.faces])
    x, y = np.array([175.2583, 175.4583, 175.0]), np.array([-25.2768, -25.1768, -25.0])
    z0 = sampler(x, y)[0]
    assert (z0[:2] < -18).all() and z0[2] > 27
    # 0.028 mm wide at the first point: wider than the first probes span
    z, n = bridge_cracks(sampler, base, x, y, z0, TOL)
    assert n == 1
    z, n = bridge_cracks(sampler, base, x, y, z0, TOL, face_tol)
    assert n == 2
    assert (np.abs(z[:2] - np.array([27.70, 27.55])) < 0.03).all(), z
    assert z[2] == z0[2]


def test_crack_in_a_cell_by_the_outline_spanned():
    """A cell with a corner off the part (the map's outline) still has its crack spanned:
    trj8's faces 123 and 62 by the map's first row (y = -65.5 has no surface there)."""
    h, sampler = _slot(1.2, 0.012)

    def holed(x, y):
        z, f = sampler(x, y)
        return np.where(np.asarray(y) < 0.25, np.nan, z), f

    base = ZMap.from_function(lambda x, y: holed(x, y)[0], (0, 0, 2, 2), 0.5)
    assert np.isnan(base.z[:, 0]).all()
    x, y = np.array([1.2]), np.array([0.4])
    z, n = bridge_cracks(holed, base, x, y, holed(x, y)[0], TOL)
    assert n == 1 and abs(z[0] - 1.12) < 1e-9


def test_node_in_a_crack_spanned_in_a_copy():
    """A crack through a base node: the copy's node takes the plane across it, the master
    map is left as it is; a node at the bottom of a real slot keeps its height."""
    from cad_io.cracks import span_node_cracks

    h, sampler = _slot(1.0, 0.012)
    base = ZMap.from_function(h, (0, 0, 2, 2), 0.5)
    assert (base.z[2] < -18).all()
    spanned, n = span_node_cracks(sampler, base, TOL)
    assert n == base.ny and np.allclose(spanned.z[2], 1.1) and (base.z[2] < -18).all()
    h2, sampler2 = _slot(1.0, 0.3)
    base2 = ZMap.from_function(h2, (0, 0, 2, 2), 0.5)
    same, n2 = span_node_cracks(sampler2, base2, TOL)
    assert n2 == 0 and same is base2


def test_probe_falling_into_the_crack_elsewhere_does_not_span():
    """One probe on a rim, the other in the crack (a crack bending back): no span from that
    pair, whose heights differ more than either stands above the point."""
    def sampler(x, y):
        x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        z = np.where((np.abs(x - 1.2) < 0.006) | ((x > 1.215) & (x < 1.23)), -20.0, 1.0)
        z = np.where(np.abs(x - 1.22) < 0.0001, -18.0, z)
        return z, np.zeros(z.shape, dtype=int)

    base = ZMap.from_function(lambda x, y: sampler(x, y)[0], (0, 0, 2, 2), 0.5)
    x, y = np.array([1.2]), np.array([0.3])
    # along x: 1.18 is a rim (1.0), 1.22 is at -18: that pair does not span; the others do
    z, n = bridge_cracks(sampler, base, x, y, sampler(x, y)[0], TOL)
    assert n == 1 and z[0] == 1.0
