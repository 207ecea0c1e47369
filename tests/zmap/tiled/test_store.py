"""TiledZMap: zarr store, completion markers, lazy dask view, queries equal to in-memory."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.cli import main
from zmap.errors import ZMapFileError
from zmap.interpolate import bezier as mem_bezier
from zmap.interpolate import bilinear as mem_bilinear
from zmap.tiled import HALO, TiledZMap, bezier, bilinear


def _rough_map(nx=37, ny=29, seed=0, holes=True, angle=0.0, origin=(0.0, 0.0)):
    """A bumpy map with NaN holes, so that every stencil fallback path is taken."""
    rng = np.random.default_rng(seed)
    x0, y0, dx, dy = -3.1, 7.7, 0.37, 0.23
    xs = x0 + dx * np.arange(nx)
    ys = y0 + dy * np.arange(ny)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    z = np.sin(0.7 * X) * np.cos(0.4 * Y) + 0.05 * rng.standard_normal((nx, ny))
    if holes:
        z[rng.random((nx, ny)) < 0.04] = np.nan
    return ZMap(x0, y0, dx, dy, z, angle=angle, origin=origin, meta={"source": "test"},
                layers={"face": rng.integers(-1, 9, (nx, ny)).astype(np.int32)})


@pytest.fixture
def rough(tmp_path):
    zm = _rough_map()
    return zm, TiledZMap.from_zmap(zm, tmp_path / "rough.zarr", tile=8)


def _queries(zm, n, seed):
    rng = np.random.default_rng(seed)
    lx = rng.uniform(zm.x0 - 0.3, zm.x1 + 0.3, n)
    ly = rng.uniform(zm.y0 - 0.3, zm.y1 + 0.3, n)
    # grid nodes and tile borders exactly, where the cell choice is decided by rounding
    lx[: n // 4] = zm.x0 + zm.dx * rng.integers(0, zm.nx, n // 4)
    ly[: n // 8] = zm.y0 + zm.dy * rng.integers(0, zm.ny, n // 8)
    return zm.local_to_world(lx, ly)


@pytest.mark.parametrize("tangent", ["circle", "central", "quartic"])
@pytest.mark.parametrize("boundary", ["dummy", "one-sided"])
def test_bezier_equals_in_memory_to_the_last_bit(rough, tangent, boundary):
    zm, tz = rough
    x, y = _queries(zm, 4000, 1)
    a = mem_bezier(zm, x, y, tangent=tangent, boundary=boundary)
    b = bezier(tz, x, y, tangent=tangent, boundary=boundary)
    assert np.array_equal(a, b, equal_nan=True)
    assert np.isfinite(a).sum() > 2500


@pytest.mark.slow
def test_bilinear_equals_in_memory_and_in_a_rotated_frame(tmp_path):
    zm = _rough_map(angle=0.3, origin=(5.0, -2.0))
    tz = TiledZMap.from_zmap(zm, tmp_path / "rot.zarr", tile=5)
    x, y = _queries(zm, 3000, 2)
    assert np.array_equal(mem_bilinear(zm, x, y), bilinear(tz, x, y), equal_nan=True)
    assert np.array_equal(mem_bezier(zm, x, y, tangent="quartic"), bezier(tz, x, y, tangent="quartic"),
                          equal_nan=True)


@settings(max_examples=10, deadline=None)
@given(nx=st.integers(2, 19), ny=st.integers(2, 19), tile=st.integers(HALO, 9), seed=st.integers(0, 2**16))
@pytest.mark.slow
def test_property_any_tile_size_matches_in_memory(tmp_path_factory, nx, ny, tile, seed):
    zm = _rough_map(nx, ny, seed)
    tz = TiledZMap.from_zmap(zm, tmp_path_factory.mktemp("p") / "m.zarr", tile=tile)
    x, y = _queries(zm, 300, seed)
    assert np.array_equal(mem_bezier(zm, x, y, tangent="quartic"), bezier(tz, x, y, tangent="quartic"),
                          equal_nan=True)
    assert np.array_equal(mem_bezier(zm, x, y), tz.bezier(x, y), equal_nan=True)
    assert np.array_equal(tz.to_zmap().z, zm.z, equal_nan=True)


def test_queries_read_only_their_tile_and_its_halo(rough):
    zm, tz = rough
    # points inside tile (1, 2): cells i in 8..15, j in 16..23
    lx = zm.x0 + zm.dx * np.array([8.2, 12.5, 15.9])
    ly = zm.y0 + zm.dy * np.array([16.1, 20.0, 23.7])
    tz.reads.clear()
    bezier(tz, lx, ly)
    assert tz.reads == [(8 - HALO, 16 + HALO + 1, 16 - HALO, 24 + HALO + 1)]
    # points in two tiles: two windows, one each
    tz.reads.clear()
    bezier(tz, zm.x0 + zm.dx * np.array([0.5, 30.5]), zm.y0 + zm.dy * np.array([0.5, 0.5]))
    assert tz.reads == [(0, 8 + HALO + 1, 0, 8 + HALO + 1), (24 - HALO, 32 + HALO + 1, 0, 8 + HALO + 1)]


def test_strict_names_the_point(rough):
    zm, tz = rough
    from zmap.errors import OutOfDomainError

    with pytest.raises(OutOfDomainError, match="outside the map"):
        bezier(tz, [zm.x0 + 1.0, zm.x1 + 5.0], [zm.y0 + 1.0, zm.y0 + 1.0], strict=True)
    assert math.isnan(bezier(tz, zm.x1 + 5.0, zm.y0))


def test_to_zmap_window_and_dask_view(rough):
    zm, tz = rough
    w = tz.to_zmap((zm.x0 + 3 * zm.dx, zm.y0 + 5 * zm.dy, zm.x0 + 20 * zm.dx, zm.y0 + 11.5 * zm.dy))
    assert w.shape == (18, 7) and w.x0 == zm.x0 + 3 * zm.dx and w.y0 == zm.y0 + 5 * zm.dy
    assert np.array_equal(w.z, zm.z[3:21, 5:12], equal_nan=True)
    assert np.array_equal(w.layers["face"], zm.layers["face"][3:21, 5:12])
    d = tz.to_dask()
    assert d.chunksize == (8, 8) and d.shape == zm.shape
    assert np.array_equal(d.compute(), zm.z, equal_nan=True)
    assert np.array_equal(tz.to_dask("face").compute(), zm.layers["face"])
    with pytest.raises(ValueError, match="2 x 2"):
        tz.to_zmap((zm.x0, zm.y0, zm.x0, zm.y1))
    with pytest.raises(ValueError, match="'nope' is not one of"):
        tz.to_dask("nope")


def test_tile_below_halo_is_a_one_line_error(tmp_path):
    zm = _rough_map(6, 6)
    with pytest.raises(ValueError, match=r"tile=1 nodes is below the 2-node stencil halo"):
        TiledZMap.from_zmap(zm, tmp_path / "a.zarr", tile=1)
    assert not (tmp_path / "a.zarr").exists()


def test_unfinished_store_is_never_taken_for_a_finished_one(tmp_path):
    zm = _rough_map(20, 12)
    p = tmp_path / "half.zarr"
    tz = TiledZMap.create(p, x0=zm.x0, y0=zm.y0, dx=zm.dx, dy=zm.dy, nx=zm.nx, ny=zm.ny, tile=8)
    si, sj = tz.tile_slices(0, 1)
    tz.write_tile(0, 1, zm.z[si, sj])
    with pytest.raises(ZMapFileError, match=r"unfinished tiled store: 1 of 6 tiles"):
        TiledZMap.open(p)
    with pytest.raises(ZMapFileError, match="5 of 6 tiles are not written"):
        tz.finish()
    again = TiledZMap.create(p, x0=zm.x0, y0=zm.y0, dx=zm.dx, dy=zm.dy, nx=zm.nx, ny=zm.ny, tile=8, resume=True)
    assert again.done_tiles() == [(0, 1)]
    with pytest.raises(ZMapFileError, match="holds another tiled map"):
        TiledZMap.create(p, x0=zm.x0, y0=zm.y0, dx=zm.dx, dy=zm.dy, nx=zm.nx, ny=zm.ny, tile=4, resume=True)
    with pytest.raises(ZMapFileError, match="already exists"):
        TiledZMap.create(p, x0=zm.x0, y0=zm.y0, dx=zm.dx, dy=zm.dy, nx=zm.nx, ny=zm.ny, tile=8)
    for t in again.tiles():
        if not again.tile_done(*t):
            si, sj = again.tile_slices(*t)
            again.write_tile(*t, zm.z[si, sj])
    again.finish()
    assert np.array_equal(TiledZMap.open(p).to_zmap().z, zm.z, equal_nan=True)


def test_foreign_stores_are_refused_in_one_line(tmp_path):
    import zarr

    g = zarr.open_group(str(tmp_path / "other.zarr"), mode="w")
    g.attrs["title"] = "someone else's"
    with pytest.raises(ZMapFileError, match="a zarr group but not a tiled z-map store"):
        TiledZMap.open(tmp_path / "other.zarr")
    (tmp_path / "plain").mkdir()
    with pytest.raises(ZMapFileError, match="not a tiled z-map store"):
        TiledZMap.open(tmp_path / "plain")
    (tmp_path / "f.zarr").write_text("x")
    with pytest.raises(ZMapFileError, match="a file, not a zarr folder"):
        TiledZMap.open(tmp_path / "f.zarr")


def test_pickles_as_path_and_header(rough):
    import pickle

    zm, tz = rough
    tz.bezier(zm.x0 + 1, zm.y0 + 1)
    back = pickle.loads(pickle.dumps(tz))
    assert back.header() == tz.header() and back.path == tz.path and len(pickle.dumps(tz)) < 2000


def test_zmap_info_describes_a_store(rough, tmp_path, capsys):
    zm, tz = rough
    assert main(["info", str(tz.path)]) == 0
    out = capsys.readouterr().out
    assert "tiled zarr z-map, complete" in out and f"{zm.nx} x {zm.ny}" in out
    f = np.isfinite(zm.z)
    assert f"{zm.z[f].min():.6g} .. {zm.z[f].max():.6g} mm, {int(f.sum()):,} with surface" in out
    meta = json.loads(out.split("meta     ")[1])
    assert meta["source"] == "test"
    p = tmp_path / "half.zarr"
    TiledZMap.create(p, x0=0, y0=0, dx=1, dy=1, nx=10, ny=10, tile=4)
    assert main(["info", str(p)]) == 0
    assert "UNFINISHED: 0 of 9 tiles" in capsys.readouterr().out
    import zarr

    zarr.open_group(str(tmp_path / "o.zarr"), mode="w")
    assert main(["info", str(tmp_path / "o.zarr")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("zmap: error: ") and "not a tiled z-map store" in err and "\n" not in err
