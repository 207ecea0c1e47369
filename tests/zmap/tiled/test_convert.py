"""Tiled conversion (cad_io.tiled): equal to the in-memory conversion of a real part, resumable."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.conftest import DATA, STEP_DATA
from zmap.cli import main
from zmap.errors import ZMapError, ZMapFileError
from zmap.tiled import TiledZMap

PART = STEP_DATA / "featuretype.STEP"  # trimesh's featuretype: 96 faces, planes, cylinders, fillets
GRID = 0.3  # not a binary fraction: node coordinates are rounded, as in a real job


@pytest.fixture(scope="module")
def part_and_map():
    import cad_io

    part = cad_io.read_step(PART)
    return part, cad_io.sample(part, GRID)


def _same(a, b):
    return np.array_equal(a, b, equal_nan=True)


@pytest.mark.slow
def test_grid_plan_and_every_tile_equal_the_in_memory_map(part_and_map):
    from cad_io.tiled import _face_set, plan_grid, sample_tile

    import cad_io

    _, zm = part_and_map
    part = cad_io.read_step(PART)  # meshed afresh, in sample()'s order: start mesh, then the fine one
    g = plan_grid(part, GRID)
    assert (g.x0, g.y0, g.nx, g.ny, g.deflection) == (zm.x0, zm.y0, zm.nx, zm.ny, zm.meta["deflection"])
    fs = _face_set(part, g)
    assert g.fine is not None and g.fine < g.deflection  # the default: facet answers solved again on a fine mesh
    t = 100
    for i0 in range(0, zm.nx, t):
        for j0 in range(0, zm.ny, t):
            i1, j1 = min(i0 + t, zm.nx), min(j0 + t, zm.ny)
            z, face, how = sample_tile(part, fs, g, i0, i1, j0, j1)
            assert _same(z, zm.z[i0:i1, j0:j1]), (i0, j0)
            assert np.array_equal(face, zm.layers["face"][i0:i1, j0:j1])
            assert np.array_equal(how, zm.layers["method"][i0:i1, j0:j1])
    assert np.isfinite(zm.z).mean() > 0.5


@pytest.mark.slow
def test_worker_reads_the_file_only_for_a_fine_pass(part_and_map):
    """Workers get the client's face set; the file is read in a worker only when a tile
    keeps facet answers on exact faces, and then it is not meshed: the fine pass cuts the
    faces it needs to their block and meshes those pieces."""
    import cad_io
    import cad_io.tiled as T

    _, zm = part_and_map
    part = cad_io.read_step(PART)
    g = T.plan_grid(part, GRID)
    fs = T._face_set(part, g)
    T._WORKER_PART.clear()
    lazy = T._LazyPart(str(PART), g)
    z, face, how = T.sample_tile(lazy, fs, g, 0, 60, 0, 60)  # no facet answer here: no read
    assert _same(z, zm.z[:60, :60]) and np.array_equal(face, zm.layers["face"][:60, :60])
    assert not T._WORKER_PART
    again = lazy.get()  # what the fine pass would use
    assert len(T._WORKER_PART) == 1 and lazy.get() is again
    assert len(again.faces) == len(part.faces) and all(a.mesh is None for a in again.faces)
    assert [a.bbox for a in again.faces] == [b.bbox for b in part.faces]
    T._WORKER_PART.clear()


@pytest.mark.slow
def test_tiled_conversion_on_a_local_cluster_equals_in_memory_and_resumes(part_and_map, dask_client, tmp_path):
    from cad_io.tiled import convert_tiled

    part, zm = part_and_map
    out = tmp_path / "featuretype.zarr"
    # interrupted after 5 of the 15 tiles, as by Ctrl-C: the store is refused as unfinished
    with pytest.raises(KeyboardInterrupt):
        convert_tiled(PART, GRID, out, tile=100, client=dask_client, _stop_after=5)
    with pytest.raises(ZMapFileError, match="unfinished tiled store"):
        TiledZMap.open(out)
    done = len(TiledZMap.open(out, incomplete=True).done_tiles())
    assert 5 <= done < 15
    # run again: only the missing tiles are sampled
    store, rep = convert_tiled(PART, GRID, out, tile=100, client=dask_client)
    # (a task already running when the run stopped may still finish its tile: skipped >= done)
    assert rep["tiles"] == 15 and rep["tiles_skipped"] >= done and rep["tiles_skipped"] + rep["tiles_done_now"] == 15
    assert rep["tiles_done_now"] > 0
    assert rep["workers"] == 2 and rep["peak_rss_mb_per_worker"] > 0
    back = TiledZMap.open(out)
    whole = back.to_zmap()
    assert (whole.x0, whole.y0, whole.shape) == (zm.x0, zm.y0, zm.shape)
    assert _same(whole.z, zm.z)
    assert np.array_equal(whole.layers["face"], zm.layers["face"])
    assert np.array_equal(whole.layers["method"], zm.layers["method"])
    # and the queries on the store are the in-memory queries
    rng = np.random.default_rng(3)
    x = rng.uniform(zm.x0, zm.x1, 2000)
    y = rng.uniform(zm.y0, zm.y1, 2000)
    from zmap.interpolate import bezier

    assert _same(back.bezier(x, y), bezier(zm, x, y))
    # a finished store converts to nothing more
    _, rep2 = convert_tiled(PART, GRID, out, tile=100, client=dask_client)
    assert rep2["tiles_done_now"] == 0 and rep2["tiles_skipped"] == 15


def test_scheduler_that_does_not_answer_fails_fast_naming_it(tmp_path, capsys, monkeypatch):
    import zmap.tiled.cluster as ct

    assert ct.CONNECT_TIMEOUT <= 4.0  # with the start of the command (seconds on a loaded machine), within 10 s
    monkeypatch.setattr(ct, "CONNECT_TIMEOUT", 1.0)
    t = time.perf_counter()
    with pytest.raises(ZMapError, match=r"no Dask scheduler answers at tcp://127.0.0.1:9 within 1 s"):
        with ct.dask_client("tcp://127.0.0.1:9"):
            pass
    out = tmp_path / "x.zarr"
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1", "--tiles", "64", "--scheduler",
                 "tcp://127.0.0.1:9", "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("zmap: error: no Dask scheduler answers at tcp://127.0.0.1:9")
    assert time.perf_counter() - t < 10 and not out.exists()


def test_cli_bad_tiles_and_foreign_output(tmp_path, capsys):
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1", "--tiles", "1", "-o",
                 str(tmp_path / "a.zarr")]) == 1
    err = capsys.readouterr().err.strip()
    assert "tile=1 nodes is below the 2-node stencil halo" in err and "\n" not in err
    import zarr

    zarr.open_group(str(tmp_path / "theirs.zarr"), mode="w").attrs["x"] = 1
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1", "--tiles", "64", "-o",
                 str(tmp_path / "theirs.zarr"), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "a zarr group but not a tiled z-map store" in err


@pytest.mark.slow
def test_cli_tiled_convert_end_to_end(tmp_path, capsys):
    import cad_io

    out = tmp_path / "boss.zarr"
    assert main(["convert", str(DATA / "boss.step"), "--grid", "0.7", "--tiles", "40", "-o", str(out),
                 "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "tiled zarr store, complete" in text and "2 workers" in text
    zm = cad_io.sample(cad_io.read_step(DATA / "boss.step"), 0.7)
    assert _same(TiledZMap.open(out).to_zmap().z, zm.z)
    assert main(["info", str(out)]) == 0
    assert "tiled zarr z-map, complete" in capsys.readouterr().out


@pytest.mark.slow
def test_shared_input_survives_the_death_of_its_worker(dask_client):
    """What every tile task reads (the face set, the program) is held by a task, not
    scattered: when the worker holding it dies, the scheduler makes it again elsewhere."""
    import os
    import signal

    from zmap.tiled.cluster import share

    data = np.arange(1000.0)
    held = share(dask_client, data)
    held.result()
    holder = next(iter(dask_client.who_has([held])[held.key]))
    pid = dask_client.run(os.getpid, workers=[holder])[holder]
    os.kill(pid, signal.SIGKILL)
    got = dask_client.submit(lambda a: float(a.sum()), held, pure=False).result(timeout=60)
    assert got == float(data.sum())


def test_cli_tiled_output_must_be_a_zarr_store(tmp_path, capsys):
    """`-o p.zmap.npz` with --tiles is refused before any work (ZMap.load would refuse the
    folder later); a name without a suffix gets `.zarr` (the docstring example of
    cad_io.commands._zarr_name)."""
    assert main(["convert", str(DATA / "boss.step"), "--grid", "1", "--tiles", "64", "-o",
                 str(tmp_path / "p.zmap.npz")]) != 0
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "zarr store" in err and "p.zarr" in err and not list(tmp_path.iterdir())
