"""simulate / Run: validation, stages, branch, animate, save/load."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from zmap.errors import SimFileError, StageError, ToolError
from zmap.grid import ZMap
from zmap.sim.dexel import DexelWorkpiece
from zmap.sim.session import Run, parse_stage, simulate, stock_from_spec
from zmap.sim.tools import Cutter

BOX = (0.0, 0.0, -4.0, 6.0, 4.0, 0.0)


def _path(n=80, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)
    return np.column_stack([0.5 + 5 * t, 2 + 1.5 * np.sin(9 * t), -0.3 - 4.5 * t * rng.random(n)])


@pytest.fixture(scope="module")
def runs():
    xyz = _path()
    return {h: simulate(xyz, BOX, tool="ball:2", pitch=0.25, history=h) for h in ("none", "ztrace", "ttrace", "treap")}


def test_history_choice_is_validated():
    with pytest.raises(ValueError, match="history='trap' is not one of 'none', 'ztrace', 'ttrace', 'treap'"):
        simulate(_path(3), BOX, tool="ball:2", history="trap")


@pytest.mark.parametrize("kwargs, match", [
    ({"pitch": 0.0}, "pitch"),
    ({"pitch": float("nan")}, "pitch"),
])
def test_bad_pitch(kwargs, match):
    with pytest.raises(ValueError, match=match):
        simulate(_path(3), BOX, tool="ball:2", **kwargs)


def test_bad_positions_and_stock():
    with pytest.raises(ValueError, match=r"shape \(n, 3\), got shape \(4,\)"):
        simulate(np.zeros(4), BOX, tool="ball:2")
    with pytest.raises(ValueError, match="NaN"):
        simulate(np.array([[0, 0, np.nan]]), BOX, tool="ball:2")
    with pytest.raises(ValueError, match="box:LxWxH"):
        simulate(_path(3), "box:1x2", tool="ball:2")
    with pytest.raises(ValueError, match="stock must be"):
        simulate(_path(3), 42, tool="ball:2")


def test_options_are_keyword_only():
    with pytest.raises(TypeError):
        simulate(_path(3), BOX, "ball:2")  # type: ignore[misc]


def test_missing_tool_names_number_and_line():
    text = "G21 G90\nT7 M6\nG0 X1 Y1 Z1\nG1 Z-1 F100\nM2\n"
    with pytest.raises(ToolError, match=r"T7 \(first used at line \d+\).*no default tool"):
        simulate(text, BOX, tools={1: Cutter("ball", 2)})
    run = simulate(text, BOX, tools={7: Cutter("flat", 2)})
    assert run.cutters[0].kind == "flat" and run.tool_numbers == [7]


def test_stage_range_and_parsing(runs):
    run = runs["treap"]
    n = run.n_stages
    with pytest.raises(StageError, match=f"stage {n + 1} is out of range 0..{n}"):
        run.reconstruct(n + 1)
    with pytest.raises(StageError, match="out of range"):
        run.display(-1)
    with pytest.raises(StageError, match="fraction"):
        run.stage("abc")
    assert run.stage("1/2") == n // 2 and run.stage("end") == n and run.stage("0.25") == n // 4
    assert parse_stage("3/4", 8) == 6


def test_histories_agree_with_each_other(runs):
    n = runs["none"].n_stages
    for k in (0, 1, n // 3, n - 1, n):
        ref = runs["none"].reconstruct(k)
        for h in ("ztrace", "ttrace", "treap"):
            assert runs[h].reconstruct(k).same_as(ref), (h, k)
            assert np.array_equal(runs[h].display(k), ref.top(), equal_nan=True), (h, k)


def test_summary(runs):
    s = runs["treap"].summary
    for key in ("moves", "positions", "rays", "dexels_created", "dexels_deleted", "history_bytes", "seconds"):
        assert key in s
    assert s["positions"] == 80 and s["rays"] == 25 * 17
    assert s["history_bytes"] == runs["treap"].structure.nbytes > 0
    assert runs["none"].summary["history_bytes"] == 0


def test_animate_forward_and_backward(runs):
    run = runs["treap"]
    fwd = list(run.animate(2, 11, 3))
    assert [k for k, _ in fwd] == [2, 5, 8, 11]
    back = list(run.animate(11, 2, 3))
    assert [k for k, _ in back] == [11, 8, 5, 2]
    for k, img in fwd + back:
        assert np.array_equal(img, run.display(k), equal_nan=True)
    with pytest.raises(ValueError, match="step"):
        list(run.animate(0, 3, 0))


def test_branch_continues_from_reconstructed_stage(runs):
    run = runs["treap"]
    other = np.array([[3.0, 2.0, -2.0], [4.0, 2.0, -2.5], [5.0, 3.0, -3.9]])
    k = run.n_stages // 2
    br = run.branch(k, other)
    assert br.stock.same_as(run.reconstruct(k))
    expect = run.stock.copy().cut(run.xyz[:k], run.cutters, run.slot[:k]).cut(other, run.cutters[0])
    assert br.final.same_as(expect)
    assert br.summary["branched_from_stage"] == k and br.history == "treap"
    assert br.reconstruct(0).same_as(run.reconstruct(k))


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(st.sampled_from(["none", "ztrace", "ttrace", "treap"]), st.integers(0, 2**31))
def test_save_load_round_trip(tmp_path, history, seed):
    run = simulate(_path(30, seed), BOX, tool=Cutter("bull", 2, 0.4, 6), pitch=0.3, history=history)
    p = run.save(tmp_path / f"r{seed}.zsim")
    back = Run.load(p)
    assert back.history == history and back.n_stages == run.n_stages
    assert back.summary == run.summary and back.cutters == run.cutters
    assert back.stock.same_as(run.stock) and back.final.same_as(run.final)
    for k in (0, run.n_stages // 2, run.n_stages):
        assert back.reconstruct(k).same_as(run.reconstruct(k))
        assert np.array_equal(back.display(k), run.display(k), equal_nan=True)


def test_load_rejects_missing_corrupt_and_foreign_files(tmp_path, runs):
    with pytest.raises(SimFileError, match="no such file"):
        Run.load(tmp_path / "nope.zsim")
    bad = tmp_path / "bad.zsim"
    bad.write_bytes(b"not a zip at all")
    with pytest.raises(SimFileError, match="corrupt"):
        Run.load(bad)
    good = runs["treap"].save(tmp_path / "good.zsim")
    data = good.read_bytes()
    cut = tmp_path / "cut.zsim"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(SimFileError):
        Run.load(cut)
    zm = ZMap(0, 0, 1, 1, np.zeros((3, 3))).save(tmp_path / "m.zmap.npz")
    with pytest.raises(SimFileError, match="format is 'zmap.ZMap', expected 'zmap.sim.Run'"):
        Run.load(zm)
    plain = tmp_path / "plain.npz"
    np.savez(plain, a=np.zeros(3))
    with pytest.raises(SimFileError, match="header"):
        Run.load(plain)


def test_save_failure_leaves_no_file(tmp_path, runs):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(OSError):
        runs["treap"].save(blocker / "run.zsim")
    assert sorted(os.listdir(tmp_path)) == ["file"]


def test_stock_specs():
    wp = stock_from_spec("box:10x4x2", pitch=0.5, xy_extent=(0, 0, 20, 10))
    assert (wp.x0, wp.y0) == (5.0, 3.0) and wp.intervals(0, 0).tolist() == [[-2.0, 0.0]]
    wp = stock_from_spec("box:0,0,-1,2,2,1", pitch=0.5)
    assert wp.shape == (5, 5) and wp.intervals(4, 4).tolist() == [[-1.0, 1.0]]
    with pytest.raises(ValueError, match="box:LxWxH"):
        stock_from_spec("box:1,2,3", pitch=0.5)


def test_zmap_stock(tmp_path):
    zm = ZMap.from_function(lambda x, y: -0.1 * x, (0, 0, 4, 3), 0.25)
    run = simulate(np.array([[2.0, 1.5, -1.0]]), zm, tool="ball:1", pitch=0.25, history="treap")
    assert run.stock.shape == zm.shape
    assert np.allclose(run.display(0), zm.z.astype(np.float32))
    assert np.isclose(np.nanmin(run.display(1)), -1.0)
    path = zm.save(tmp_path / "s.zmap.npz")
    run2 = simulate(np.array([[2.0, 1.5, -1.0]]), str(path), tool="ball:1", pitch=0.25)
    assert run2.final.same_as(run.final)


def test_dexel_workpiece_stock_is_copied():
    wp = DexelWorkpiece.from_box(BOX, pitch=0.5)
    simulate(_path(10), wp, tool="ball:2", pitch=0.5)
    assert wp.n_dexels == wp.n_rays and wp.created == 0
