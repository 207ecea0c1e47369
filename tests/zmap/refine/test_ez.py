"""EZ-map (paper 004 §3.2): construction, split Coons evaluation, accuracy in 3D, storage.

The analytic parts have exact 3D distances: a step wall z = H on one side of a line (any
angle), a circular boss and a V-ridge are extrusions or surfaces of revolution, so the
distance from a model point (x, y, h) to them is the distance in the cross-section plane
(d, z) to a polyline.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.errors import RefineError
from zmap.interpolate import bezier
from tests.reference import refine as ref
from zmap.refine.ez import BREAK_RATIO, QUANTUM_SHARE, EZMap, build_ez, edge_count

DATA = Path(__file__).resolve().parents[3] / "data"
TOL = 0.01


# ---- exact surfaces and distances --------------------------------------------------------

def step_distance(d, z, H):
    """Distance in the (d, z) plane to floor {z=0, d<0}, wall {d=0, 0<=z<=H}, top {z=H, d>0}."""
    to_floor = np.where(d < 0, np.abs(z), np.hypot(d, z))
    to_top = np.where(d > 0, np.abs(z - H), np.hypot(d, z - H))
    to_wall = np.hypot(d, z - np.clip(z, 0.0, H))
    return np.minimum(np.minimum(to_floor, to_top), to_wall)


def ridge_distance(d, z, H, s):
    """Distance in the (d, z) plane to the V z = H - s|d| (two half-lines from the apex)."""
    out = np.full(np.shape(d), np.inf)
    for sign in (-1.0, 1.0):
        u = np.array([sign, -s]) / math.hypot(1.0, s)
        px, pz = d, z - H
        t = np.maximum(px * u[0] + pz * u[1], 0.0)
        out = np.minimum(out, np.hypot(px - t * u[0], pz - t * u[1]))
    return out


class Step:
    """z = H where n.(x, y) > c, else 0: a vertical wall along a straight line."""

    def __init__(self, angle, c, H=10.0):
        self.n = np.array([math.cos(angle), math.sin(angle)])
        self.c, self.H = c, H

    def d(self, x, y):
        return self.n[0] * x + self.n[1] * y - self.c

    def __call__(self, x, y):
        return np.where(self.d(x, y) > 0, self.H, 0.0)

    def distance(self, x, y, z):
        return step_distance(self.d(x, y), z, self.H)


class Boss:
    """A cylinder of radius R and height H standing on z = 0."""

    def __init__(self, cx, cy, R, H=6.0):
        self.cx, self.cy, self.R, self.H = cx, cy, R, H

    def d(self, x, y):
        return self.R - np.hypot(x - self.cx, y - self.cy)

    def __call__(self, x, y):
        return np.where(self.d(x, y) >= 0, self.H, 0.0)

    def distance(self, x, y, z):
        return step_distance(self.d(x, y), z, self.H)


def points_near(rng, d_func, bounds, n, band=0.6):
    x0, y0, x1, y1 = bounds
    x = rng.uniform(x0, x1, 20 * n)
    y = rng.uniform(y0, y1, 20 * n)
    keep = np.abs(d_func(x, y)) < band
    return x[keep][:n], y[keep][:n]


def model_height(ez, base, x, y):
    """The EZ model: e-cells from the e-map, the base's Bezier elsewhere."""
    h = ez.evaluate(base, x, y)
    miss = np.isnan(h)
    h[miss] = bezier(base, x[miss], y[miss])
    return h


# ---- layout ----------------------------------------------------------------------------

def test_layout_matches_table_2_spacing_and_contract_ids():
    f = Step(0.3, 2.0)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.4)
    ez = build_ez(base, f, tol=0.02, thin=False)
    assert ez.interval == 0.02 and ez.tol == 0.02
    n = np.diff(ez.offsets)
    assert np.all(n == 19)  # paper: 0.4 mm grid, 0.02 mm e-map, 19 points per edge
    # thinned (the default), every edge here is a wall edge read as its 19 samples through a window
    win = build_ez(base, f, tol=0.02)
    assert win.n_windows == win.n_edges == ez.n_edges and np.all(win.full_counts() == 19)
    assert np.all(np.diff(win.offsets) < 19)
    assert ez.codes.dtype == np.uint16 and ez.edge_ids.dtype == np.int64 and ez.heights.dtype == np.float64
    assert np.all(np.diff(ez.edge_ids) > 0)
    assert ez.edge_ratio == pytest.approx(ez.n_edges / edge_count(base.nx, base.ny))
    # stored: header, one bit per grid edge, a point count, an offset (steps of the finest
    # quantum above the lowest, in the bits the largest needs), a float16 quantum, a 4-bit code
    # width and a mode bit per e-edge; each edge's codes in the bits its largest code needs (15
    # here: the 3 mm wall at the finest quantum tol/128 = 1.6e-4 mm), none differenced (a
    # wall's jump)
    bits = sum(n * (int(ez.codes[o:o + n].max()) + 1).bit_length()
               for o, n in zip(ez.offsets[:-1].tolist(), np.diff(ez.offsets).tolist()))
    assert bits <= 15 * ez.n_points
    a = ez.to_arrays()
    steps = sum(a[k].nbytes for k in ("step", "step_common", "step_is_common") if k in a)
    assert steps <= 2 * ez.n_edges
    k = np.rint((ez.lo.astype(np.float64) - float(ez.lo.min())) / (QUANTUM_SHARE * ez.tol)).astype(np.int64)
    lo_bytes = 24 + math.ceil(ez.n_edges * max(1, int(k.max()).bit_length()) / 8)
    assert "lo" not in a and a["lo_lattice"].nbytes + a["lo_k"].nbytes == lo_bytes < 4 * ez.n_edges
    n = np.diff(ez.offsets)  # point counts: in the bits the largest needs, behind their width
    w = int(n.max()).bit_length()
    cnt = 1 + math.ceil(ez.n_edges * w / 8) if w < 8 and ez.n_edges >= 16 else ez.n_edges
    assert ez.nbytes == (104 + math.ceil(edge_count(base.nx, base.ny) / 8) + cnt + lo_bytes + steps
                         + math.ceil(ez.n_edges / 2) + math.ceil(ez.n_edges / 8) + math.ceil(bits / 8))
    px, py = ez.points()
    qx, qy = ref.edge_points(ez)
    assert np.array_equal(px, qx) and np.array_equal(py, qy)
    q = max(f.H / 65534, QUANTUM_SHARE * ez.tol)  # the quantum (no finer than tol/128) rounded up to float16
    assert q / 2 <= ez.resolution <= q / 2 * (1 + 2 ** -10)
    assert np.abs(ez.heights - f(px, py)).max() <= ez.resolution + 1e-6
    # every selected edge is steep or crosses the wall; every edge crossing the wall is selected
    nx, ny = base.shape
    crossing = []
    for eid in range(edge_count(nx, ny)):
        if eid < (nx - 1) * ny:
            i, j = divmod(eid, ny)
            a, b = (base.x[i], base.y[j]), (base.x[i + 1], base.y[j])
        else:
            i, j = divmod(eid - (nx - 1) * ny, ny - 1)
            a, b = (base.x[i], base.y[j]), (base.x[i], base.y[j + 1])
        if (f.d(*a) > 0) != (f.d(*b) > 0):
            crossing.append(eid)
    assert ez.edge_ids.tolist() == crossing


def test_uneven_grid_spacing_holds_interval():
    f = Step(1.0, 2.0)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5, 0.3)
    ez = build_ez(base, f, tol=0.013)
    nxe = (base.nx - 1) * base.ny
    n = ez.full_counts()  # the wall edges are windowed: read as their full samples
    assert np.all(n[ez.edge_ids < nxe] == math.ceil(0.5 / 0.013) - 1)
    assert np.all(n[ez.edge_ids >= nxe] == math.ceil(0.3 / 0.013) - 1)
    assert 0.5 / (n[ez.edge_ids < nxe][0] + 1) <= 0.013


# ---- accuracy on exact surfaces ------------------------------------------------------------

@pytest.mark.parametrize("angle", [0.0, 0.3, math.pi / 4, 1.2, math.pi / 2, 2.5])
def test_step_wall_3d_distance_within_tol(angle):
    f = Step(angle, 0.4 * math.cos(angle) * 6 + 0.5 * math.sin(angle) * 6 + 0.0123)
    bounds = (0, 0, 6, 6)
    base = ZMap.from_function(f, bounds, 0.5)
    ez = build_ez(base, f, tol=TOL)
    rng = np.random.default_rng(7)
    x, y = points_near(rng, f.d, bounds, 20000)
    h = model_height(ez, base, x, y)
    assert not np.isnan(h).any()
    assert f.distance(x, y, h).max() <= TOL
    assert f.distance(x, y, bezier(base, x, y)).max() > 0.1


@settings(max_examples=30, deadline=None)
@given(angle=st.floats(0.0, 2 * math.pi), offset=st.floats(-0.5, 0.5), height=st.floats(0.05, 20.0))
@pytest.mark.slow
def test_random_walls_crossings_within_interval_and_distance_within_tol(angle, offset, height):
    f = Step(angle, math.cos(angle) * 2 + math.sin(angle) * 2 + offset, H=height)
    bounds = (0, 0, 4, 4)
    base = ZMap.from_function(f, bounds, 0.5)
    ez = build_ez(base, f, tol=TOL)
    kind, t = ez.breaks(base)
    nx, ny = base.shape
    nxe = (nx - 1) * ny
    for eid, k, tb in zip(ez.edge_ids, kind, t):
        if eid < nxe:
            i, j = divmod(int(eid), ny)
            a, b = np.array([base.x[i], base.y[j]]), np.array([base.x[i + 1], base.y[j]])
        else:
            i, j = divmod(int(eid) - nxe, ny - 1)
            a, b = np.array([base.x[i], base.y[j]]), np.array([base.x[i], base.y[j + 1]])
        da, db = f.d(*a), f.d(*b)
        if (da > 0) != (db > 0):
            assert k == 1  # a jump
            # the crossing found is within half an e-map interval of the wall
            assert abs(f.d(*(a + tb * (b - a)))) <= 0.5 * ez.interval + 1e-9
    rng = np.random.default_rng(11)
    x, y = points_near(rng, f.d, bounds, 3000)
    h = model_height(ez, base, x, y)
    assert f.distance(x, y, h).max() <= TOL


def test_circular_boss_3d_distance_and_memory():
    f = Boss(15.1, 14.9, 6.3)
    bounds = (0, 0, 30, 30)
    base = ZMap.from_function(f, bounds, 0.5)
    ez = build_ez(base, f, tol=TOL)
    rng = np.random.default_rng(5)
    x, y = points_near(rng, f.d, bounds, 40000)
    h = model_height(ez, base, x, y)
    assert f.distance(x, y, h).max() <= TOL
    assert f.distance(x, y, bezier(base, x, y)).max() > 0.1
    # Table 2 figures: EZ model <= 3x the base, <= 1/50 of a plain map at the e-map interval
    assert (base.nbytes + ez.nbytes) / base.nbytes <= 3.0
    plain = ((base.nx - 1) * 50 + 1) * ((base.ny - 1) * 50 + 1) * 8
    assert (base.nbytes + ez.nbytes) / plain <= 1 / 50


@pytest.mark.parametrize("only_se", [True, False])
def test_v_ridge_sharp_edge(only_se):
    H, s, ang, c = 10.0, 1.5, 0.4, 2.07
    n = np.array([math.cos(ang), math.sin(ang)])

    def f(x, y):
        return H - s * np.abs(n[0] * x + n[1] * y - c)

    bounds = (0, 0, 4, 4)
    base = ZMap.from_function(f, bounds, 0.5)
    # the ridge as an SE curve (the z-map alone cannot see it where an edge straddles it
    # symmetrically: equal end heights, no slope)
    line = np.array([[c / n[0] + 2 * math.tan(ang), -2.0], [c / n[0] - 6 * math.tan(ang), 6.0]])
    if only_se:  # no edge steep: e-points only where the SE curve crosses
        ez = build_ez(base, f, tol=TOL, eps_r=math.inf, se_curves=[line])
        assert ez.edge_ratio < 0.2
    else:  # slope 1.5 > eps_r: every edge is a candidate; the planes' edges are pruned (the
        # base's Bezier holds a plane), the edges the ridge crosses and their neighbours stay
        full = build_ez(base, f, tol=TOL, se_curves=[line], prune=False, verify=False)
        assert full.edge_ratio == 1.0
        ez = build_ez(base, f, tol=TOL, se_curves=[line])
        assert ez.pruned > 0 and ez.n_edges + ez.pruned == full.n_edges
        crossed = np.isin(full.edge_ids, build_ez(base, f, tol=TOL, eps_r=math.inf, se_curves=[line],
                                                  prune=False, verify=False).edge_ids)
        assert np.isin(full.edge_ids[crossed], ez.edge_ids).all()
    kind, _ = ez.breaks(base)
    assert np.count_nonzero(kind == 2) >= 8
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, 4, 30000), rng.uniform(0, 4, 30000)
    h = model_height(ez, base, x, y)
    d = n[0] * x + n[1] * y - c
    assert ridge_distance(d, h, H, s).max() <= TOL
    # within 1e-4 mm of the planes, plus the codes' half quantum (QUANTUM_SHARE)
    assert np.abs(h - f(x, y)).max() <= 1e-4 + 0.5 * QUANTUM_SHARE * TOL
    assert ridge_distance(d, bezier(base, x, y), H, s).max() > 0.1


def test_plane_reproduced():
    def f(x, y):
        return 0.3 * x - 1.7 * y + 2.0

    base = ZMap.from_function(f, (0, 0, 3, 3), 0.5)
    # the paper's procedure as it stands: a pruned map would drop every edge of a plane
    ez = build_ez(base, f, tol=TOL, prune=False, verify=False)
    assert ez.edge_ratio == 1.0  # slope above eps_r everywhere
    assert build_ez(base, f, tol=TOL).n_edges == 0  # the base's Bezier holds a plane
    kind, _ = ez.breaks(base)
    assert not kind.any()
    rng = np.random.default_rng(1)
    x, y = rng.uniform(0, 3, 5000), rng.uniform(0, 3, 5000)
    # exact up to the 16-bit coding: the Coons patch adds two curves' errors
    assert np.abs(ez.evaluate(base, x, y) - f(x, y)).max() <= 2 * ez.resolution + 1e-6


def test_tilted_planes_either_side_of_a_wall_reproduced_off_the_wall():
    wall = Step(0.7, 2.1, H=3.0)

    def f(x, y):
        return 0.2 * x + 0.1 * y + wall(x, y)

    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=TOL)
    rng = np.random.default_rng(2)
    x, y = rng.uniform(0, 4, 20000), rng.uniform(0, 4, 20000)
    off = np.abs(wall.d(x, y)) > 2 * ez.interval
    h = ez.evaluate(base, x, y)
    inside = ~np.isnan(h) & off
    assert inside.sum() > 2000
    assert np.abs(h[inside] - f(x, y)[inside]).max() <= 2 * ez.resolution + 1e-6


# ---- kernel against the slow reference -----------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_reference(seed):
    rng = np.random.default_rng(seed)
    wall = Step(rng.uniform(0, math.pi), rng.uniform(1.5, 2.5), H=3.0)

    def f(x, y):
        return 0.2 * x + wall(x, y) - 0.5 * np.abs(x - 1.3 - 0.2 * y)

    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    # the reference knows the Coons/split cells, not the cell patches of verify=True
    ez = build_ez(base, f, tol=0.02, eps_r=0.6, se_curves=[np.array([[1.3, -1.0], [2.3, 5.0]])], verify=False)
    kind, t = ez.breaks(base)
    m = int(np.diff(ez.offsets).max()) + 1
    expect = [ref.edge_break(ez, base, int(e), ez.tol, 4 * ez.tol / m, BREAK_RATIO) for e in ez.edge_ids]
    assert kind.tolist() == [k for k, _ in expect]
    assert np.allclose(t, [tb for _, tb in expect], rtol=0, atol=1e-12)
    assert set(kind.tolist()) == {0, 1, 2}
    # wall (jump) and sharp-edge (kink) edges windowed: the reference reads their full sequences
    assert (ez.win[kind == 1] >= 0).all() and (ez.win[kind == 2] >= 0).any()
    x, y = rng.uniform(-0.1, 4.1, 2000), rng.uniform(-0.1, 4.1, 2000)
    a = ez.evaluate(base, x, y)
    b = ref.evaluate(ez, base, x, y)
    assert np.array_equal(np.isnan(a), np.isnan(b))
    assert np.nanmax(np.abs(a - b)) <= 1e-12


@pytest.mark.slow
def test_kernel_matches_reference_on_curved_walls():
    f = Boss(2.1, 1.9, 1.3, H=2.0)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=0.02, verify=False)
    assert (ez._tables(base)["arc"][:, 2] > 0).sum() >= 8  # traces bent into arcs
    rng = np.random.default_rng(4)
    x, y = points_near(rng, f.d, (0, 0, 4, 4), 3000, band=0.3)
    a = ez.evaluate(base, x, y)
    b = ref.evaluate(ez, base, x, y)
    # the reference draws the arc as a 400-gon: points within its chord error may differ
    near = np.abs(np.hypot(x - f.cx, y - f.cy) - f.R) < 0.005
    same = np.isclose(a, b, rtol=0, atol=1e-12)
    assert same[~near].all() and same.mean() > 0.99


# ---- API, storage, bad input -----------------------------------------------------------

def test_evaluate_domain_nan_and_shapes():
    f = Boss(2.0, 2.0, 1.1, H=3.0)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=TOL)
    mask = ez.cell_mask()
    assert mask.shape == (base.nx - 1, base.ny - 1) and 0 < mask.sum() < mask.size
    ci, cj = np.nonzero(~mask)
    h = ez.evaluate(base, base.x[ci] + 0.25, base.y[cj] + 0.25)
    assert np.isnan(h).all()  # no answer outside the e-cells: the caller uses the base
    assert np.isnan(ez.evaluate(base, [-1.0, 5.0, np.nan], [1.0, 1.0, 1.0])).all()
    assert isinstance(ez.evaluate(base, 2.0, 2.0), float)
    assert ez.evaluate(base, np.zeros((2, 3)) + 2.0, 2.0).shape == (2, 3)
    other = ZMap.from_function(f, (0, 0, 4, 4), 0.25)
    with pytest.raises(ValueError, match="base grid"):
        ez.evaluate(other, 1.0, 1.0)


def test_round_trip(tmp_path):
    f = Boss(2.0, 2.0, 1.1, H=3.0)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)
    ez = build_ez(base, f, tol=TOL, interval=0.008)
    path = tmp_path / "ez.npz"
    np.savez(path, **ez.to_arrays())
    with np.load(path) as npz:
        back = EZMap.from_arrays({k: npz[k] for k in npz.files})
    for name in ("x0", "y0", "dx", "dy", "nx", "ny", "interval", "tol", "failed"):
        assert getattr(back, name) == getattr(ez, name)
    for name in ("edge_ids", "offsets", "codes", "lo", "step"):
        assert np.array_equal(getattr(back, name), getattr(ez, name))
        assert getattr(back, name).dtype == getattr(ez, name).dtype
    x = np.linspace(0, 4, 777)
    assert np.array_equal(back.evaluate(base, x, x[::-1]), ez.evaluate(base, x, x[::-1]), equal_nan=True)
    assert np.array_equal(back.heights, ez.heights, equal_nan=True)
    arrays = ez.to_arrays()
    del arrays["codes_bits"]
    with pytest.raises(ValueError, match="codes"):
        EZMap.from_arrays(arrays)
    arrays = ez.to_arrays()
    arrays["version"] = np.array([99])
    with pytest.raises(ValueError, match="version 99"):
        EZMap.from_arrays(arrays)
    arrays = ez.to_arrays()
    key = "counts_b" if "counts_b" in arrays else "counts"  # format 6: in the bits the largest needs
    arrays[key] = arrays[key][:-1]
    with pytest.raises(ValueError, match="point counts"):
        EZMap.from_arrays(arrays)
    # format 5 stored them a byte each
    arrays = {k: v for k, v in ez.to_arrays().items() if k not in ("counts_b", "counts_w")}
    back = EZMap.from_arrays(arrays | {"counts": np.diff(ez.offsets).astype(np.uint8)})
    assert np.array_equal(back.heights, ez.heights, equal_nan=True)
    arrays = ez.to_arrays()
    arrays["codes_bits"] = arrays["codes_bits"][:-1]
    with pytest.raises(ValueError, match="bytes of codes"):
        EZMap.from_arrays(arrays)
    arrays = ez.to_arrays()
    arrays["codes"] = ez.codes[:-1]  # format 4: 16-bit codes
    del arrays["codes_bits"]
    with pytest.raises(ValueError, match="offsets"):
        EZMap.from_arrays(arrays)
    # format 2 (edge ids and offsets stored) still loads
    arrays = {k: v for k, v in ez.to_arrays().items() if k not in ("edge_bits", "counts")}
    arrays.update(version=np.array([2]), edge_ids=ez.edge_ids, offsets=ez.offsets)
    old = EZMap.from_arrays(arrays)
    assert np.array_equal(old.offsets, ez.offsets) and np.array_equal(old.edge_ids, ez.edge_ids)


def test_bad_input():
    f = Step(0.3, 2.0)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5, 0.4)
    with pytest.raises(ValueError, match=r"tol=0\.4 must be smaller than the grid interval min\(dx, dy\)=0\.4"):
        build_ez(base, f, tol=0.4)
    with pytest.raises(ValueError, match="tol"):
        build_ez(base, f, tol=-0.01)
    with pytest.raises(ValueError, match="interval=0.45"):
        build_ez(base, f, tol=0.01, interval=0.45)
    with pytest.raises(RefineError, match="exact surface"):
        build_ez(base, None, tol=0.01)
    with pytest.raises(RefineError, match="one height per point"):
        build_ez(base, lambda x, y: np.zeros(3), tol=0.01)
    with pytest.raises(TypeError, match="ZMap"):
        build_ez(base.z, f, tol=0.01)


def test_nan_heights_counted():
    f = Step(0.3, 2.0)
    base = ZMap.from_function(f, (0, 0, 4, 4), 0.5)

    def holes(x, y):
        return np.where(x > 1.9, np.nan, f(x, y))

    ez = build_ez(base, holes, tol=TOL)
    px, _ = ez.points()
    assert ez.failed == np.count_nonzero(px > 1.9) > 0
    assert np.isnan(ez.heights).sum() == ez.failed
    assert EZMap.from_arrays(ez.to_arrays()).failed == ez.failed


def test_single_low_samples_on_a_wall_line_are_lifted():
    f = Step(0.0, 1.2)

    def faulty(x, y):  # answers points on the wall's line with a lower face
        return np.where(np.abs(x - 1.2) < 1e-9, -5.0, f(x, y))

    base = ZMap.from_function(f, (0, 0, 3, 3), 0.5)
    ez = build_ez(base, faulty, tol=TOL)
    px, _ = ez.points()
    on_line = np.abs(px - 1.2) < 1e-9
    assert ez.lifted == on_line.sum() == base.ny
    assert np.allclose(ez.heights[on_line], 10.0, rtol=0, atol=ez.resolution + 1e-6)
    assert ez.failed == 0 and EZMap.from_arrays(ez.to_arrays()).lifted == ez.lifted
    clean = build_ez(base, f, tol=TOL)
    assert clean.lifted == 0


# ---- bundled parts with vertical walls and sharp edges ---------------------------------------

def _occ_distance(shape, pts):
    """Exact 3D distance to the part's faces (its shell) by OCC BRepExtrema."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.gp import gp_Pnt
    from OCP.TopAbs import TopAbs_SHELL
    from OCP.TopExp import TopExp_Explorer

    s = shape.wrapped if hasattr(shape, "wrapped") else shape
    shell = TopExp_Explorer(s, TopAbs_SHELL).Current()
    out = np.empty(len(pts))
    for k, p in enumerate(pts):
        v = BRepBuilderAPI_MakeVertex(gp_Pnt(*map(float, p))).Vertex()
        out[k] = BRepExtrema_DistShapeShape(shell, v).Value()
    return out


def _part_case(name, heights_kind):
    cad_io = pytest.importorskip("cad_io")
    pytest.importorskip("OCP")
    from zmap.features import sharp_edge_curves

    part = cad_io.read_step(DATA / f"{name}.step")
    base = cad_io.sample(part, 0.5)
    if heights_kind == "sample_points":
        from cad_io.sampler import height_function

        heights = height_function(part)
    else:
        from cad_io.raycast import RayCaster

        caster = RayCaster(part.shape)

        def heights(x, y):
            return caster(x, y)[0]

    # the cell check casts tens of thousands of rays: it runs with the converter's sampler
    ez = build_ez(base, heights, tol=TOL, se_curves=sharp_edge_curves(part.edges),
                  verify=heights_kind == "sample_points")
    rng = np.random.default_rng(0)
    ci, cj = np.nonzero(ez.cell_mask())
    k = rng.integers(0, ci.size, 400)
    x = np.concatenate([base.x0 + (ci[k] + rng.random(400)) * base.dx, rng.uniform(base.x0, base.x1, 100)])
    y = np.concatenate([base.y0 + (cj[k] + rng.random(400)) * base.dy, rng.uniform(base.y0, base.y1, 100)])
    h = model_height(ez, base, x, y)
    hb = bezier(base, x, y)
    d = _occ_distance(part.shape, np.column_stack([x, y, h]))
    db = _occ_distance(part.shape, np.column_stack([x, y, hb]))
    return base, ez, d, db


@pytest.mark.slow
@pytest.mark.parametrize("name", ["pocket", "boss"])
def test_bundled_parts_exact_heights(name):
    """E-point heights by OCC ray casting (the exact top-most surface)."""
    base, ez, d, db = _part_case(name, "raycast")
    assert ez.failed == 0
    assert d.max() <= TOL
    assert db.max() > 0.1
    assert (base.nbytes + ez.nbytes) / base.nbytes <= 3.0
    plain = ((base.nx - 1) * 50 + 1) * ((base.ny - 1) * 50 + 1) * 8
    assert (base.nbytes + ez.nbytes) / plain <= 1 / 50


@pytest.mark.parametrize("name", ["pocket", "boss"])
@pytest.mark.slow
def test_bundled_parts_sample_points(name):
    """E-point heights from the converter's own sampler, as `zmap refine` takes them.

    Where the sampler answers a point on a wall's line with a lower face (seen on the
    pocket's corner tori and the round boss), the single low e-point is lifted."""
    _, _, d, db = _part_case(name, "sample_points")
    assert d.max() <= TOL
    assert db.max() > 0.1
