"""Tiled simulation (zmap.sim.tiled) on a real 2-worker LocalCluster: equal to the single-process run."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from tests.conftest import GCODE_DATA
from zmap.cli import main
from zmap.sim.session import Run, simulate
from zmap.sim.tools import load_camotics_project

PROGRAM = GCODE_DATA / "flower_mold.nc"  # CAMotics example: 16562 lines, inch, a ball-nose mould finish
PITCH = 0.6


@pytest.fixture(scope="module")
def job():
    from zmap.sim.gcode import parse

    tools, bounds, _units = load_camotics_project(GCODE_DATA / "flower_mold.camotics")
    tool = tools[min(tools)]
    return parse(PROGRAM), bounds, tools, tool


@pytest.fixture(scope="module")
def single(job):
    prog, bounds, tools, tool = job
    return {h: simulate(prog, bounds, tools=tools, tool=tool, pitch=PITCH, history=h)
            for h in ("none", "ztrace", "ttrace", "treap")}


def _stages(run, n=9):
    return sorted(set(np.linspace(0, run.n_stages, n).astype(int).tolist()) | {1, run.n_stages - 1})


def _assert_same_run(a: Run, b: Run, history: str):
    assert a.n_stages == b.n_stages and a.final.same_as(b.final) and a.stock.same_as(b.stock)
    for key in ("dexels_created", "dexels_deleted", "dexels_final", "rays"):
        assert a.summary[key] == b.summary[key], key
    for k in _stages(a):
        assert np.array_equal(a.display(k), b.display(k), equal_nan=True), (history, k)
        if history in ("ztrace", "treap"):
            assert a.reconstruct(k).same_as(b.reconstruct(k)), (history, k)


@pytest.mark.parametrize("history", ["none", "ztrace", "ttrace", "treap"])
@pytest.mark.slow
def test_tiled_run_equals_single_process_run(job, single, dask_client, history):
    prog, bounds, tools, tool = job
    run = simulate(prog, bounds, tools=tools, tool=tool, pitch=PITCH, history=history, tiles=40,
                   scheduler=dask_client.scheduler.address)
    t = run.summary["tiles"]
    assert t["tiles"] == 9 and t["workers"] == 2 and 0 < t["tiles_with_positions"] <= 9
    # positions reaching several tiles are cut in each: more than the program's, but each tile only its own
    assert run.n_stages <= t["positions_cut"] < 4 * run.n_stages
    _assert_same_run(single[history], run, history)


@pytest.mark.parametrize("through_files", [True, False])
@pytest.mark.slow
def test_tiles_come_back_through_files_on_this_machine_and_through_dask_elsewhere(job, single, dask_client,
                                                                                 monkeypatch, through_files):
    """Workers that see the client's files hand the program, stock and tiles over as .npy files
    (the folder is gone after the run, the mapped results stay readable); workers that do not
    (monkeypatched: as on another host) get and return them through Dask. Both are exact."""
    import zmap.tiled.handoff as H

    made = []
    real_open = H.Handoff.open.__func__

    def spy(cls, client):
        h = real_open(cls, client) if through_files else None
        made.append(h)
        return h

    monkeypatch.setattr(H.Handoff, "open", classmethod(spy))
    prog, bounds, tools, tool = job
    run = simulate(prog, bounds, tools=tools, tool=tool, pitch=PITCH, history="treap", tiles=40,
                   scheduler=dask_client.scheduler.address)
    assert len(made) == 1 and (made[0] is not None) == through_files
    if through_files:
        assert not os.path.exists(made[0].path)
    _assert_same_run(single["treap"], run, "treap")


def test_handoff_is_refused_when_a_worker_does_not_see_the_folder(tmp_path):
    import zmap.tiled.handoff as H

    class Client:
        def __init__(self, answer):
            self.answer = answer

        def run(self, fn, path, token):
            return {"w1": fn(path, token), "w2": self.answer(path, token)}

    h = H.Handoff.open(Client(H._sees))
    assert h is not None and os.path.isdir(h.path)
    big, small = np.arange(100_000, dtype=np.float64), np.arange(3, dtype=np.int32)
    ref = H.save_arrays(h.path, "t", {"big": big, "small": small, "empty": np.zeros(0)})
    assert set(ref["files"]) == {"big"} and set(ref["inline"]) == {"small", "empty"}
    back = H.load_arrays(ref)
    assert np.array_equal(back["big"], big) and back["big"].flags.writeable and type(back["big"]) is np.ndarray
    assert not H.load_arrays(ref, writeable=False)["big"].flags.writeable
    h.close()
    assert not os.path.exists(h.path) and np.array_equal(back["big"], big)  # mapped data outlive the folder
    assert H.Handoff.open(Client(lambda path, token: False)) is None  # e.g. a worker on another host


def test_tiled_history_saves_and_loads(job, single, dask_client, tmp_path):
    prog, bounds, tools, tool = job
    run = simulate(prog, bounds, tools=tools, tool=tool, pitch=PITCH, history="treap", tiles=64,
                   scheduler=dask_client.scheduler.address)
    back = Run.load(run.save(tmp_path / "tiled.zsim"))
    _assert_same_run(single["treap"], back, "treap")
    assert back.summary["tiles"]["tile"] == 64


@pytest.mark.slow
def test_a_worker_killed_mid_run_is_recovered_and_the_result_is_exact(job, single, dask_client):
    from zmap.sim.session import _as_positions, _resolve_tools, stock_from_spec
    from zmap.sim.tiled import TiledHistory, simulate_tiles

    prog, bounds, tools, tool = job
    path = _as_positions(prog, PITCH)
    _numbers, cutters, slot = _resolve_tools(path, tool, tools)
    stock = stock_from_spec(bounds, pitch=PITCH)
    killed = {}

    def kill_one(cl, done):
        if killed:
            return
        pids = cl.run(os.getpid)  # {worker address: pid}
        addr, pid = sorted(pids.items())[0]
        killed.update(addr=addr, pid=pid, done=done)
        os.kill(pid, signal.SIGKILL)

    final, structure, rep = simulate_tiles(stock, path.pieces, slot, cutters, "treap", tiles=12, client=dask_client,
                                           _on_result=kill_one)
    assert killed and killed["done"] < rep["tiles"]  # killed while tiles were still to come
    assert isinstance(structure, TiledHistory) and rep["tiles"] == 100
    ref = single["treap"]
    assert final.same_as(ref.final)
    for k in _stages(ref):
        assert np.array_equal(structure.display(k), ref.structure.display(k), equal_nan=True), k
    off, near, far = structure.reconstruct(ref.n_stages // 2)
    r_off, r_near, r_far = ref.structure.reconstruct(ref.n_stages // 2)
    assert np.array_equal(off, r_off) and np.array_equal(near, r_near) and np.array_equal(far, r_far)


def test_bad_tiles_is_a_one_line_error(job, tmp_path, capsys):
    prog, bounds, tools, tool = job
    with pytest.raises(ValueError, match="tiles=1 rays: a tile needs at least 2 x 2 rays"):
        simulate(prog, bounds, tools=tools, tool=tool, pitch=PITCH, tiles=1)
    assert main(["simulate", str(PROGRAM), "--camotics", str(GCODE_DATA / "flower_mold.camotics"), "--tiles", "0",
                 "-o", str(tmp_path / "r.zsim"), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip()
    assert "tiles=0 rays" in err and "\n" not in err and not (tmp_path / "r.zsim").exists()


@pytest.mark.slow
def test_cli_simulate_tiles(tmp_path, capsys):
    out = tmp_path / "flower.zsim"
    assert main(["simulate", str(PROGRAM), "--camotics", str(GCODE_DATA / "flower_mold.camotics"), "--pitch", "1",
                 "--tiles", "50", "-o", str(out), "--no-progress"]) == 0
    cap = capsys.readouterr()
    assert "tiles            4 of 50 x 50 rays on 2 workers" in cap.out
    assert "dask     2 workers at tcp://" in cap.err and "dashboard http://" in cap.err  # as convert --tiles
    run = Run.load(out)
    tools, bounds, _ = load_camotics_project(GCODE_DATA / "flower_mold.camotics")
    ref = simulate(PROGRAM, bounds, tools=tools, tool=tools[min(tools)], pitch=1.0)
    k = run.stage("1/2")
    assert np.array_equal(run.display(k), ref.display(k), equal_nan=True) and run.final.same_as(ref.final)


def test_our_local_workers_run_without_the_profiler_and_the_malloc_trim_setting(dask_client):
    """Our LocalCluster's workers: no statistical profiler, glibc's own mmap threshold (the
    fixed 128 KB one made every tile array a fresh mmap), workers restarted after a death
    included; this process's environment is left as it was (Dask's nanny writes the spawn
    variables into it)."""
    got = dask_client.run(lambda: (os.environ.get("MALLOC_TRIM_THRESHOLD_"),
                                   __import__("dask").config.get("distributed.worker.profile.enabled")))
    assert len(got) == 2 and set(got.values()) == {(None, False)}, got
    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ


@pytest.mark.slow
def test_tiles_of_a_handful_of_rays_warn(job, dask_client, monkeypatch):
    """Thousands of 2 x 2-ray tasks run slower than no tiles: a warning names the count and a size."""
    import zmap.sim.tiled as st

    prog, bounds, tools, tool = job
    monkeypatch.setattr(st, "MANY_TILES", 8)  # the same rule on a stock small enough for a unit test
    with pytest.warns(UserWarning, match=r"tiles=20 makes \d+ tiles of 20 x 20 rays.*128 rays or more"):
        simulate(prog, bounds, tools=tools, tool=tool, pitch=1.0, history="none", tiles=20,
                 scheduler=dask_client.scheduler.address)
