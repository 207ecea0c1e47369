import json
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from zmap import ZMap
from zmap.errors import ZMapFileError


def test_index_and_world_helpers():
    zm = ZMap(10.0, -5.0, 0.5, 0.25, np.zeros((5, 9)))
    assert zm.shape == (5, 9)
    assert zm.bounds == (10.0, -5.0, 12.0, -3.0)
    i, j = zm.index_of(11.0, -4.5)
    assert (i, j) == (2.0, 2.0)
    x, y = zm.world_of(2, 2)
    assert (x, y) == (11.0, -4.5)
    assert zm.contains(12.0, -3.0) and not zm.contains(12.01, -3.0)
    assert zm.nbytes == 5 * 9 * 8


def test_local_frame_round_trip():
    zm = ZMap(0.0, 0.0, 1.0, 1.0, np.zeros((3, 3)), angle=0.7, origin=(5.0, -2.0))
    x, y = zm.local_to_world(np.array([1.0, 2.0]), np.array([0.5, -1.0]))
    lx, ly = zm.world_to_local(x, y)
    np.testing.assert_allclose(lx, [1.0, 2.0], atol=1e-14)
    np.testing.assert_allclose(ly, [0.5, -1.0], atol=1e-14)
    # The local x axis points along the angle.
    x, y = zm.local_to_world(1.0, 0.0)
    assert math.isclose(x, 5.0 + math.cos(0.7)) and math.isclose(y, -2.0 + math.sin(0.7))


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(dx=0.0), "dx"),
        (dict(dx=-1.0), "dx"),
        (dict(dy=float("nan")), "dy"),
        (dict(dy=float("inf")), "dy"),
        (dict(x0=float("nan")), "x0"),
        (dict(y0=float("inf")), "y0"),
        (dict(z=np.zeros(5)), "2D"),
        (dict(z=np.zeros((1, 5))), "at least 2"),
        (dict(z=np.array([[0.0, np.inf], [0.0, 0.0]])), "infinite"),
        (dict(origin=(0.0, float("nan"))), "origin"),
        (dict(angle=float("nan")), "angle"),
    ],
)
def test_bad_fields_name_the_field(kwargs, word):
    args = dict(x0=0.0, y0=0.0, dx=1.0, dy=1.0, z=np.zeros((3, 3)))
    args.update(kwargs)
    with pytest.raises(ValueError, match=word):
        ZMap(**args)


def test_layer_shape_must_match():
    with pytest.raises(ValueError, match="layer 'face'"):
        ZMap(0, 0, 1, 1, np.zeros((3, 3)), layers={"face": np.zeros((2, 3), np.int32)})


heights = arrays(np.float64, st.tuples(st.integers(2, 6), st.integers(2, 6)),
                 elements=st.one_of(st.floats(-1e6, 1e6), st.just(np.nan)))


@settings(max_examples=40, deadline=None)
@given(z=heights, x0=st.floats(-1e4, 1e4), dx=st.floats(1e-3, 1e3), dy=st.floats(1e-3, 1e3),
       angle=st.floats(-3.2, 3.2))
def test_save_load_round_trip_is_exact(tmp_path_factory, z, x0, dx, dy, angle):
    layers = {"face": np.arange(z.size, dtype=np.int32).reshape(z.shape), "method": np.ones(z.shape, np.int8)}
    zm = ZMap(x0, -x0, dx, dy, z, angle=angle, origin=(1.5, -2.5),
              meta={"source": "test", "method": "exact", "nested": {"a": [1, 2]}}, layers=layers)
    path = zm.save(tmp_path_factory.mktemp("rt") / "m.zmap.npz")
    back = ZMap.load(path)
    assert (back.x0, back.y0, back.dx, back.dy, back.angle, back.origin) == (zm.x0, zm.y0, zm.dx, zm.dy, zm.angle, zm.origin)
    np.testing.assert_array_equal(back.z, zm.z)
    assert back.meta == zm.meta
    assert set(back.layers) == set(layers)
    for k, v in layers.items():
        np.testing.assert_array_equal(back.layers[k], v)
        assert back.layers[k].dtype == v.dtype


def test_load_missing_corrupt_and_foreign_files(tmp_path):
    with pytest.raises(ZMapFileError, match="no such file"):
        ZMap.load(tmp_path / "absent.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip at all")
    with pytest.raises(ZMapFileError, match="corrupt"):
        ZMap.load(bad)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.zeros(3))
    with pytest.raises(ZMapFileError, match="not a zmap file"):
        ZMap.load(foreign)
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, z=np.zeros((2, 2)), header=np.array(json.dumps({"format": "other", "version": 1})))
    with pytest.raises(ZMapFileError, match="format is 'other'"):
        ZMap.load(wrong)
    future = tmp_path / "future.npz"
    hdr = ZMap(0, 0, 1, 1, np.zeros((2, 2))).header() | {"version": 99}
    np.savez(future, z=np.zeros((2, 2)), header=np.array(json.dumps(hdr)))
    with pytest.raises(ZMapFileError, match="version 99"):
        ZMap.load(future)
    mismatch = tmp_path / "mismatch.npz"
    hdr = ZMap(0, 0, 1, 1, np.zeros((2, 2))).header() | {"nx": 5}
    np.savez(mismatch, z=np.zeros((2, 2)), header=np.array(json.dumps(hdr)))
    with pytest.raises(ZMapFileError, match="shape"):
        ZMap.load(mismatch)
    truncated = tmp_path / "trunc.npz"
    good = ZMap(0, 0, 1, 1, np.ones((50, 50))).save(tmp_path / "good.npz")
    truncated.write_bytes(good.read_bytes()[:200])
    with pytest.raises(ZMapFileError):
        ZMap.load(truncated)


def test_failed_save_leaves_no_file(tmp_path, monkeypatch):
    zm = ZMap(0, 0, 1, 1, np.ones((3, 3)))
    target = tmp_path / "out.zmap.npz"

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(OSError, match="disk full"):
        zm.save(target)
    assert os.listdir(tmp_path) == []


def test_from_function_covers_bounds():
    zm = ZMap.from_function(lambda x, y: x * 0 + y, (0, 0, 1.0, 0.3), 0.1)
    assert zm.shape == (11, 4)
    np.testing.assert_allclose(zm.z[0], [0.0, 0.1, 0.2, 0.3])
