"""LocalMesh: region-by-region re-meshing that follows a simulation run."""

from __future__ import annotations

import numpy as np
import pytest

from zmap.errors import StageError
from zmap.grid import ZMap
from zmap.mesh.decimate import max_error
from zmap.mesh.local import LocalMesh
from zmap.sim.session import simulate

from .test_decimate import crack_rays, walls


def small_run(history: str):
    # a ball cutter ploughing two passes through a 12 x 10 mm stock, rays at 0.25 mm
    t = np.linspace(0.0, 1.0, 60)
    a = np.stack([1 + 10 * t, 3 + 0 * t, -0.5 - 0.5 * np.sin(6 * t)], axis=1)
    b = np.stack([11 - 3 * t, 3 + 5 * t, -0.8 + 0 * t], axis=1)
    return simulate(np.concatenate([a, b]), (0, 0, -3, 12, 10, 0), tool="ball:1.5", pitch=0.25,
                    history=history)


@pytest.fixture(scope="module")
def run():
    return small_run("treap")


def same_as_fresh(lm: LocalMesh, run) -> None:
    fresh = LocalMesh(run.display(lm.stage), allowance=lm.allowance, region=lm.region)
    assert np.array_equal(fresh.mesh.faces, lm.mesh.faces)
    assert np.array_equal(fresh.mesh.vertices[:, 2], lm.mesh.vertices[:, 2])


def test_goto_forwards_and_backwards_matches_a_fresh_mesh(run):
    lm = LocalMesh(run, allowance=0.01, region=8, period=1)
    assert lm.stage == 0 and lm.max_error() <= 0.01
    n = run.n_stages
    for k in (10, 60, n, 30, 0, n // 2):
        c = lm.goto(k)
        assert set(c) >= {"stage", "regions_touched", "triangles", "ms"}
        assert c["stage"] == k and c["triangles"] == lm.mesh.n_faces
        same_as_fresh(lm, run)
        assert lm.max_error() <= 0.01
        s = run.stock
        assert max_error(lm.mesh, ZMap(s.x0, s.y0, s.pitch, s.pitch, lm.z)) == lm.max_error()
    x1 = run.stock.x0 + run.stock.pitch * (run.stock.nx - 1)
    y1 = run.stock.y0 + run.stock.pitch * (run.stock.ny - 1)
    assert crack_rays(lm.mesh, (run.stock.x0, run.stock.y0), (x1, y1)) == 0
    assert len(lm.updates) == 7


@pytest.mark.slow
def test_only_touched_regions_are_remeshed(run):
    lm = LocalMesh(run, allowance=0.01, region=8)
    nreg = lm._reg.nrx * lm._reg.nry
    c = lm.goto(3)
    assert 0 < c["regions_touched"] < nreg / 4
    assert lm.goto(3)["regions_touched"] == 0


@pytest.mark.parametrize("history", ["none", "ztrace", "ttrace"])
@pytest.mark.slow
def test_every_history_kind_gives_the_same_meshes(history):
    r = small_run(history)
    lm = LocalMesh(r, allowance=0.02, region=10, period=1)
    for k in (25, 90, 5):
        lm.goto(k)
        same_as_fresh(lm, r)


def _domain(run):
    s = run.stock
    return (s.x0, s.y0), (s.x0 + s.pitch * (s.nx - 1), s.y0 + s.pitch * (s.ny - 1))


def test_periodic_decimation_stays_crack_free_and_exact(run):
    lm = LocalMesh(run, allowance=0.01, region=8, period=3)
    lo, hi = _domain(run)
    tri, fresh = [], []
    for k in (20, 40, 60, 80, 100, 119):
        lm.goto(k)
        tri.append(lm.n_triangles)
        fresh.append(LocalMesh(run.display(k), allowance=0.01, region=8).n_triangles)
        assert lm.max_error() <= 0.01
        assert crack_rays(lm.mesh, lo, hi, n=1500) == 0
    # between decimations the touched regions are refined incrementally (vertices only added)
    assert tri[1] > fresh[1]
    # the third and sixth updates decimate every region touched since the last decimation
    assert tri[2] == fresh[2] and tri[5] == fresh[5]


def test_incremental_updates_hold_the_bound_in_any_order(run):
    """period=-1: only incremental updates after the first mesh; every stage visited in a
    random order keeps every node within the allowance, crack-free, and never has fewer
    triangles than the fresh mesh of that stage needs to be valid for its own heights."""
    lo, hi = _domain(run)
    rng = np.random.default_rng(7)
    lm = LocalMesh(run, allowance=0.005, region=6, period=-1)
    for k in rng.integers(0, run.n_stages + 1, 12):
        c = lm.goto(int(k))
        assert c["triangles"] == lm.mesh.n_faces
        assert lm.max_error() <= 0.005
        assert crack_rays(lm.mesh, lo, hi, n=1000, seed=int(k)) == 0
        s = run.stock
        assert max_error(lm.mesh, ZMap(s.x0, s.y0, s.pitch, s.pitch, run.display(int(k)))) <= 0.005


def test_incremental_update_touches_only_the_changed_regions(run):
    lm = LocalMesh(run, allowance=0.01, region=8, period=-1)
    nreg = lm._reg.nrx * lm._reg.nry
    before = lm._reg.nt.copy()
    c = lm.goto(3)
    changed = np.flatnonzero(lm._reg.nt != before)
    assert 0 < c["regions_touched"] < nreg / 4 and len(changed) <= c["regions_touched"]


def test_period_minus_one_decimates_only_once(run):
    once = LocalMesh(run, allowance=0.01, region=8, period=-1)
    every = LocalMesh(run, allowance=0.01, region=8, period=1)
    lo, hi = _domain(run)
    for k in (20, 60, 119, 30):
        once.goto(k)
        every.goto(k)
        assert once.max_error() <= 0.01
        assert crack_rays(once.mesh, lo, hi, n=1500) == 0
    # back at stage 30 the incremental mesh keeps the vertices of the later stages
    assert once.n_triangles > every.n_triangles


def test_stage_out_of_range_is_the_runs_stage_error(run):
    lm = LocalMesh(run, region=8)
    with pytest.raises(StageError, match="out of range"):
        lm.goto(run.n_stages + 1)
    with pytest.raises(TypeError, match="Run"):
        LocalMesh(walls(9)).goto(1)


@pytest.mark.parametrize("kw, word", [({"allowance": -1.0}, "allowance.*-1.0"),
                                      ({"allowance": float("nan")}, "allowance.*nan"),
                                      ({"region": 1}, "region.*1"),
                                      ({"period": 0}, "period.*0"),
                                      ({"period": -2}, "period.*-2")])
def test_bad_options_name_the_value(kw, word):
    with pytest.raises(ValueError, match=word):
        LocalMesh(walls(9), **kw)


def test_map_source_and_empty_map():
    lm = LocalMesh(walls(65), allowance=0.01, region=16)
    assert lm.max_error() <= 0.01 and lm.stage is None
    empty = LocalMesh(np.zeros((0, 0)))
    assert empty.mesh.n_faces == 0 and empty.max_error() == 0.0
