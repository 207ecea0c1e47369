"""Tool access of a design that gives heights (a z-map, a precision model, a callable): its
samples against analytic surfaces, and its verdict on shapes whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.access import (AccessModelError, Tool, analyse_design, design_samples, node_directions,
                         voxelize_design)
from zmap.access.directions import to_bool

pytestmark = pytest.mark.xdist_group("access")


@settings(max_examples=60, deadline=None)
@given(a=st.floats(-4, 4), b=st.floats(-4, 4), step=st.floats(0.1, 0.7))
def test_samples_of_a_plane_have_its_normal_its_area_and_no_gap_along_its_slope(a, b, step):
    def plane(x, y):
        return a * x + b * y

    s = design_samples(plane, step, bounds=(0.0, 0.0, 3.0, 2.0))
    w = np.sqrt(1 + a * a + b * b)
    assert np.allclose(s.normals, np.array([-a, -b, 1.0]) / w, atol=1e-9)
    assert np.isclose(s.weight.sum(), 6.0 * w, rtol=1e-9)
    assert np.allclose(s.points[:, 2], plane(s.points[:, 0], s.points[:, 1]))
    assert np.allclose(s.curvature, 0.0, atol=1e-6)
    assert (s.face == 0).all()
    # neighbours along x are no more than about a step apart along the surface
    xs = np.unique(np.round(s.points[:, 0], 9))
    if len(xs) > 1:
        assert (xs[1] - xs[0]) * np.sqrt(1 + a * a) <= step * (1 + 1e-9)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_bowls_curvature_is_concave_and_a_domes_convex(sign):
    R = 8.0

    def surface(x, y):
        return sign * (x * x + y * y) / (2 * R)

    s = design_samples(surface, 0.1, bounds=(-0.5, -0.5, 0.5, 0.5))
    # principal curvatures of the paraboloid at its apex are 1/R (toward +z for the bowl)
    assert np.allclose(s.curvature, sign / R, rtol=0.02)


def test_a_wall_between_two_nodes_is_sampled_up_its_height():
    step = ZMap.from_function(lambda x, y: np.where(x < 5, 0.0, 10.0), (0, 0, 10, 4), 0.5)
    s = design_samples(step, 0.25)
    wall = np.abs(s.normals[:, 2]) < 0.5
    z = np.sort(s.points[wall, 2])
    assert z.min() < 2 and z.max() > 8
    assert np.diff(z).max() < 1.0  # no vertical gap of a voxel in the wall's samples


def test_bad_input_is_refused_with_what_is_wrong():
    flat = ZMap.from_function(lambda x, y: 0 * x, (0, 0, 4, 4), 0.5)
    with pytest.raises(ValueError, match="positive number"):
        design_samples(flat, 0.0)
    with pytest.raises(ValueError, match="positive number"):
        design_samples(flat, float("nan"))
    with pytest.raises(ValueError, match="bounds="):
        design_samples(lambda x, y: 0 * x, 0.25)
    with pytest.raises(ValueError, match="no surface"):
        design_samples(lambda x, y: np.full_like(x, np.nan), 0.25, bounds=(0, 0, 1, 1))
    with pytest.raises(AccessModelError, match="no closed shell"):
        voxelize_design(flat, 1.0, solid="closed")
    with pytest.raises(AccessModelError, match="smaller than the voxel"):
        analyse_design(flat, d=1.0, step=1.5, tool=Tool(2.0))


def test_a_slot_narrower_than_the_ball_is_out_of_reach_and_a_smaller_ball_reaches_its_floor_from_above():
    slot = ZMap.from_function(lambda x, y: np.where(abs(x - 10) < 1, -5.0, 0.0), (0, 0, 20, 20), 0.25)
    floor = (np.full(5, 10.0), np.linspace(6, 14, 5))
    plateau = (np.full(5, 4.0), np.linspace(6, 14, 5))
    big = analyse_design(slot, d=0.5, q=2, tool=Tool(6.0))
    small = analyse_design(slot, d=0.5, q=2, tool=Tool(0.8))
    up = big.vm.directions.index("+z")
    for r in (big, small):
        vox, cnt = node_directions(r.vm, r.amap, *plateau)
        assert (vox >= 0).all() and (cnt == r.vm.directions.k // 2).all()  # the upper hemisphere
    vox, cnt = node_directions(big.vm, big.amap, *floor)
    assert (vox >= 0).all() and (cnt == 0).all()
    vox, cnt = node_directions(small.vm, small.amap, *floor)
    assert to_bool(small.amap, small.vm.directions.k)[vox, up].all()


def test_a_gentle_bowl_is_reached_from_above_away_from_its_rim():
    bowl = ZMap.from_function(lambda x, y: 0.02 * ((x - 10) ** 2 + (y - 10) ** 2), (0, 0, 20, 20), 0.5)
    r = analyse_design(bowl, d=1.0, q=2, tool=Tool(4.0))
    X, Y = np.meshgrid(np.arange(3.0, 17.5, 0.5), np.arange(3.0, 17.5, 0.5), indexing="ij")
    vox, _ = node_directions(r.vm, r.amap, X, Y)
    up = r.vm.directions.index("+z")
    assert (vox >= 0).all()
    assert to_bool(r.amap, r.vm.directions.k)[vox, up].all()
    assert r.vm.solid == "below" and "zmap" in r.vm.solid_note
