"""The shank and holder test on surface samples against a brute force over every sample."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.access._sample_kernels import _rim, sample_tool_kernel
from zmap.access.directions import direction_set, to_bool
from zmap.access.voxelmap import _covered_rows, _direction_pairs, _disc_rows

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("access")


def brute_force(dirs, centre, pts, r_shank, stick, r_holder):
    """(k, m) bool: no sample within r of the axis above the start, for either cylinder."""
    out = np.zeros((len(dirs), len(centre)), dtype=bool)
    for i, n in enumerate(dirs):
        for b, c in enumerate(centre):
            d = pts - c
            h = d @ n
            lat2 = (d * d).sum(axis=1) - h * h
            hit = ((h > 0) & (lat2 < r_shank ** 2)).any()
            if r_holder > 0:
                hit |= ((h > stick) & (lat2 < r_holder ** 2)).any()
            out[i, b] = not hit
    return out


def run_kernel(ds, local, centre, pts, r_shank, stick, r_holder, cell, paired=True):
    """The kernel, with each direction paired with its opposite (one sort for both) or alone."""
    dirs = ds.normals
    pairs = _direction_pairs(ds) if paired else (np.arange(len(dirs)), np.full(len(dirs), -1))
    if paired:
        assert len(pairs[0]) == len(dirs) // 2 and (pairs[1] >= 0).all()
    out = np.zeros((len(dirs), len(centre)), dtype=np.uint8)
    stats = np.zeros((len(dirs), 3), dtype=np.int64)
    sample_tool_kernel(np.ascontiguousarray(dirs), local, np.ascontiguousarray(centre), np.ascontiguousarray(pts),
                       r_shank, stick, r_holder, cell, _disc_rows(r_shank / cell, outer=True),
                       _covered_rows(r_shank / cell), _disc_rows(r_holder / cell, outer=True),
                       _covered_rows(r_holder / cell), out, stats, numba.get_num_threads(), *pairs)
    return out.astype(bool), stats


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), cell=st.sampled_from([0.3, 0.5, 1.1]),
       holder=st.sampled_from([0.0, 2.5]), paired=st.booleans())
def test_sample_kernel_matches_a_brute_force(seed, cell, holder, paired):
    rng = np.random.default_rng(seed)
    ds = direction_set(1)
    # a bumpy sheet of samples, and ball centres above it and among it
    xy = rng.uniform(-6, 6, size=(1500, 2))
    z = 0.8 * np.sin(xy[:, 0]) * np.cos(0.7 * xy[:, 1]) + rng.normal(0, 0.05, len(xy))
    pts = np.c_[xy, z]
    centre = np.c_[rng.uniform(-7, 7, size=(25, 2)), rng.uniform(-1.0, 3.0, 25)]
    local = np.full((len(centre), ds.words), np.uint64(0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
    got, stats = run_kernel(ds, local, centre, pts, 1.0, 2.0, holder, cell, paired)
    want = brute_force(ds.normals, centre, pts, 1.0, 2.0, holder)
    assert (got == want).all()
    assert stats.sum() > 0


def test_sample_kernel_skips_what_local_leaves_out():
    ds = direction_set(1)
    pts = np.array([[0.0, 0.0, -1.0], [5.0, 5.0, 5.0]])
    centre = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 10.0]])
    local = np.zeros((2, ds.words), dtype=np.uint64)
    local[0, 0] = np.uint64(0b101)
    got, _ = run_kernel(ds, local, centre, pts, 0.5, 1.0, 0.0, 0.4)
    assert got[[0, 2], 0].all() and not got[1, 0] and not got[:, 1].any()
    assert to_bool(local, ds.k)[0, [0, 2]].all()


@pytest.mark.parametrize("rad", [0.5, 1.0, 1.5, 2.9, 6.0, 20.0])
def test_covered_rows_are_whole_cells_inside_every_disc(rad):
    """A covered cell lies inside the disc from every centre of cell (0, 0); the cells a disc
    can meet include every cell it covers."""
    w = _covered_rows(rad)
    outer = _disc_rows(rad, outer=True)
    rng = np.random.default_rng(1)
    centres = rng.uniform(0, 1, size=(200, 2))
    corners = np.array([[0, 0], [0, 1], [1, 0], [1, 1]], dtype=float)
    for dp, half in enumerate(w):
        if half < 0:
            continue
        assert dp < len(outer) and outer[dp] >= half
        for dq in range(-half, half + 1):
            for sgn in (1, -1):
                cell = np.array([sgn * dp, dq], dtype=float) + corners
                far = np.sqrt(((cell[None, :, :] - centres[:, None, :]) ** 2).sum(axis=2)).max()
                assert far < rad


@pytest.mark.parametrize("rad", [0.0, 0.5, 1.0, 2.9, 6.0, 20.0])
def test_rim_is_the_cells_a_disc_meets_less_those_it_covers(rad):
    """A scan looks at the rim only: with the covered cells it makes every cell a disc can meet,
    each once."""
    outer, covered = _disc_rows(rad, outer=True), _covered_rows(rad)

    def cells(w):
        return {(s * p, q) for p, h in enumerate(w) for s in (1, -1) for q in range(-h, h + 1)}

    rim = [tuple(r) for r in _rim(outer, covered)]
    assert len(rim) == len(set(rim))
    assert set(rim) == cells(outer) - cells(covered)
    assert cells(covered) <= cells(outer)
