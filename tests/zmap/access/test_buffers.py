"""The dilated max-depth buffers of the tool test and the skin culling of the casting, against
plain computations: max filters by brute force, disc staircases by sampled discs, and the whole
shank/holder test against the pair-by-pair reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.access._access_kernels import disc_max
from tests.reference.access import tool_clearance_reference
from zmap.access.directions import count, to_bool
from zmap.access.voxelmap import (Tool, VoxelMap, _disc_rows, _hide_masks, global_visibility,
                                  tool_clearance)

from .test_voxelmap import box_samples, sphere_samples

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")


def _cells(widths):
    return {(p, q) for p in range(-len(widths) + 1, len(widths)) for q in range(-widths[abs(p)], widths[abs(p)] + 1)}


@settings(max_examples=40, deadline=None)
@given(na=st.integers(1, 9), nb=st.integers(1, 9), seed=st.integers(0, 2**31 - 1),
       widths=st.lists(st.integers(-1, 5), min_size=1, max_size=6))
def test_disc_max_equals_brute_force(na, nb, seed, widths):
    buf = np.random.default_rng(seed).normal(size=(na, nb))
    out, out0 = np.empty_like(buf), np.empty_like(buf)
    disc_max(buf, np.array(widths, dtype=np.int64), np.zeros(1, dtype=np.int64), out, out0)
    want = np.full(buf.shape, -1.0e300)
    for p in range(na):
        for q in range(nb):
            for dp, dq in _cells(widths):
                if 0 <= p + dp < na and 0 <= q + dq < nb:
                    want[p, q] = max(want[p, q], buf[p + dp, q + dq])
    assert np.array_equal(out, want)
    assert np.array_equal(out0, buf)


@pytest.mark.parametrize("rad", [0.4, 1.0, 2.5, 5.0, 6.0, 7.3])
def test_disc_rows_hold_every_cell_a_disc_meets_and_only_cells_every_disc_meets(rad):
    """outer: a superset of the cells a disc of radius rad (cells) centred anywhere in cell
    (0, 0) meets; inner: a subset of those that every such disc meets."""
    outer, inner = _cells(_disc_rows(rad, outer=True)), _cells(_disc_rows(rad, outer=False))
    rng = np.random.default_rng(3)
    n = int(np.ceil(rad)) + 2
    every = None
    for x, y in np.concatenate([rng.random((300, 2)), [[0, 0], [1, 1], [0, 1], [0.5, 0.5]]]):
        met = set()
        for p in range(-n, n + 1):
            for q in range(-n, n + 1):
                du = max(p - x, 0.0, x - (p + 1))
                dv = max(q - y, 0.0, y - (q + 1))
                if du * du + dv * dv < rad * rad:
                    met.add((p, q))
        assert met <= outer
        every = met if every is None else every & met
    assert inner <= every
    if rad >= 2:
        assert len(inner) > 0.4 * len(outer)  # tight enough to decide most pairs


def test_hide_masks_need_the_neighbours_a_line_can_enter():
    m = _hide_masks(np.array([[0.0, 0, 1], [0.6, 0.0, -0.8], [1 / np.sqrt(3)] * 3]))
    bit = lambda dx, dy, dz: 1 << ((dx + 1) * 9 + (dy + 1) * 3 + (dz + 1))  # noqa: E731
    # +z: the nine voxels above and the eight beside (the line may run along a face or an edge)
    assert m[0] == sum(bit(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (0, 1)) - bit(0, 0, 0)
    # (+x, 0, -z): x in {0, 1}, y in {-1, 0, 1}, z in {0, -1}, less the voxel itself
    assert m[1] == sum(bit(dx, dy, dz) for dx in (0, 1) for dy in (-1, 0, 1) for dz in (0, -1)) - bit(0, 0, 0)
    assert bin(int(m[2])).count("1") == 7


@pytest.fixture(scope="module")
def step_block():
    a = box_samples(np.zeros(3), np.array([4.0, 3.0, 2.0]), 0.25)
    b = box_samples(np.array([0.0, 0.0, 2.0]), np.array([2.0, 3.0, 3.2]), 0.25, fid0=6)
    keep = ~((a[3] == 5) & (a[0][:, 0] < 2.0))
    return VoxelMap.from_samples(*[np.concatenate([x[keep], y]) for x, y in zip(a, b)], d=0.4, q=2,
                                 step=0.25, check=False)


@pytest.mark.parametrize("tool", [Tool(1.0), Tool(0.8, stickout=1.2, holder_diameter=2.4, holder_length=5.0),
                                  Tool(1.6, stickout=1.0, holder_diameter=3.0, holder_length=5.0)],
                         ids=["ball", "holder", "wide"])
@pytest.mark.slow
def test_tool_clearance_kernel_matches_the_plain_reference(step_block, tool):
    vm = step_block
    fast = tool_clearance(vm, vm.vl, tool, cell=0.3, cell_holder=0.5)
    _between_the_references(vm, fast, tool, cell=0.3, cell_holder=0.5)
    # the step blocks tilted directions near its foot, and not everything
    assert 0 < count(fast).sum() < count(vm.vl).sum()
    # with the skin cubes drawn too (the rule before): within its reference, a subset
    fast_s = tool_clearance(vm, vm.vl, tool, cell=0.3, cell_holder=0.5, skin=True)
    _between_the_references(vm, fast_s, tool, cell=0.3, cell_holder=0.5, skin=True)
    assert not (fast_s & ~fast).any()


def _between_the_references(vm, fast, tool, **kw):
    """The kernel's bits hold every pair the plain reference clears with its heights 1e-9 mm
    stricter and none it blocks with them 1e-9 mm laxer (the exits agree but for rounding)."""
    strict, lax = tool_clearance_reference(vm, vm.vl, tool, slack=(-1e-9, 1e-9), **kw)
    assert not (strict & ~fast).any() and not (fast & ~lax).any()
    # the band holds only ties of the axis-aligned part's heights: few pairs
    assert count(lax).sum() - count(strict).sum() <= 0.02 * count(lax).sum()


@pytest.mark.parametrize("cells", [(0.2, 0.4), (0.1, 0.8)], ids=["x2", "x8"])
@pytest.mark.slow
def test_holder_buffer_from_block_maxima_matches_the_reference(step_block, cells):
    """A holder cell a power of two times the shank's: its buffer is the shank's block maxima,
    with the bits of the reference's box-by-box drawing (and of the drawn path)."""
    vm = step_block
    tool = Tool(0.8, stickout=1.2, holder_diameter=2.4, holder_length=5.0)
    fast = tool_clearance(vm, vm.vl, tool, cell=cells[0], cell_holder=cells[1])
    _between_the_references(vm, fast, tool, cell=cells[0], cell_holder=cells[1])
    # the cells drawn box by box (a ratio just off the power of two takes that path), each
    # grown by its coarse cell: as much or more
    off = tool_clearance(vm, vm.vl, tool, cell=cells[0], cell_holder=cells[1] * (1 + 1e-12))
    _between_the_references(vm, off, tool, cell=cells[0], cell_holder=cells[1] * (1 + 1e-12))
    assert not (off & ~fast).any()
    assert 0 < count(fast).sum() < count(vm.vl).sum()
    # the holder takes directions here (so its buffer is tested)
    bare = tool_clearance(vm, vm.vl, Tool(0.8), cell=cells[0], cell_holder=cells[1])
    assert count(fast).sum() < count(bare).sum()


def test_casting_without_hidden_skin_cubes_gives_the_same_bits():
    """A thick interior (a ball in a block with a cavity): leaving out the skin cubes hidden
    along each direction changes no bit, and it does leave some out."""
    from zmap.access.voxelmap import INTERIOR

    blk = box_samples(np.zeros(3), np.array([8.0, 7.0, 6.0]), 0.2)
    cav = sphere_samples([4.0, 3.5, 3.0], 2.0, 6000, fid=6)
    cav = (cav[0], -cav[1], -cav[2], cav[3], cav[4])
    vm = VoxelMap.from_samples(*[np.concatenate([x, y]) for x, y in zip(blk, cav)], d=0.5, q=2, step=0.2,
                               check=False)
    assert vm.n_interior > 200
    a = global_visibility(vm)
    b = global_visibility(vm, cull=False)
    assert (a == b).all()
    assert count(a).sum() < count(vm.vl).sum()  # the cavity hides directions
    from zmap.access._access_kernels import skin_masks

    ijk = vm.skin_ijk()
    m = np.zeros(len(ijk), dtype=np.int64)
    skin_masks(vm.state, ijk.astype(np.int64), m)
    hidden = ((m[:, None] & _hide_masks(vm.directions.normals)[None]) == _hide_masks(vm.directions.normals)[None])
    assert hidden.mean() > 0.2
    assert (vm.state[tuple(ijk.T)] == INTERIOR).all()


@pytest.mark.slow
def test_a_ball_on_a_plane_keeps_every_tilt_its_holder_allows():
    """A ball touching a 30 x 30 mm plate's top at its middle: its shank, tilted by t < 90
    degrees, stays above the plane (a (1 - sin t) clear of it), so every upper direction
    clears it; the holder (radius R from L - a above the ball's centre) dips below the plane
    exactly when a + (L - a) cos t < R sin t, within the plate. The map keeps every tilt 1
    degree short of that limit and none 1 degree past it."""
    from scipy.optimize import brentq

    vm = VoxelMap.from_samples(*box_samples(np.array([-15.0, -15.0, 0.0]), np.array([15.0, 15.0, 2.0]), 0.125),
                               d=0.5, q=4, step=0.125, check=False)
    b = int(vm.voxel_of([[0.1, 0.1, 2.0]])[0])
    tilt = np.degrees(np.arccos(np.clip(vm.directions.normals[:, 2], -1, 1)))
    vl = to_bool(vm.vl[b:b + 1], vm.directions.k)[0]
    assert vl.sum() > 100 and (tilt[vl] < 90).all()
    shank = to_bool(tool_clearance(vm, vm.vl, Tool(2.0))[b:b + 1], vm.directions.k)[0]
    assert (shank == vl).all()
    tool = Tool(2.0, stickout=4.0, holder_diameter=8.0, holder_length=5.0)
    a, lift, r = 1.0, 3.0, 4.0
    limit = np.degrees(brentq(lambda t: a + lift * np.cos(t) - r * np.sin(t), 0.1, np.pi / 2))
    full = to_bool(tool_clearance(vm, vm.vl, tool)[b:b + 1], vm.directions.k)[0]
    assert full[vl & (tilt < limit - 1)].all()
    assert not full[tilt > limit + 1].any()
    assert (vl & (tilt > limit + 1)).any()
