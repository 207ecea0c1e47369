"""Tests of the cutters and tool tables (zmap.sim.tools)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap.errors import ToolError
from zmap.sim._tool_kernels import _envelope, _envelope_many
from zmap.sim.tools import Cutter, load_camotics_project, load_tool_table, parse_tool_spec

REPO = Path(__file__).resolve().parents[3]
from tests.conftest import GCODE_DATA as DATA


def test_envelopes_exact():
    flat, ball, bull = Cutter("flat", 6), Cutter("ball", 6), Cutter("bull", 10, corner_radius=2)
    np.testing.assert_array_equal(flat.lower_envelope([0, 1.5, 3]), [0, 0, 0])
    assert math.isnan(flat.lower_envelope(3.0000001))
    np.testing.assert_allclose(ball.lower_envelope([0, 3, 3 * math.sin(math.pi / 6)]),
                               [0, 3, 3 - 3 * math.cos(math.pi / 6)])
    # bull: flat to r = 3, then a quarter circle of radius 2 centred at (3, 2)
    np.testing.assert_allclose(bull.lower_envelope([0, 3, 4, 5]), [0, 0, 2 - math.sqrt(3), 2])
    assert math.isnan(bull.lower_envelope(-1.0))
    assert np.isnan(bull.lower_envelope(np.nan))
    assert flat.radius == 3 and (flat.code, ball.code, bull.code) == (0, 1, 2)
    assert ball.corner_radius == 3


def test_njit_kernel_matches_numpy_reference():
    r = np.linspace(-0.5, 6.0, 1301)
    for c in (Cutter("flat", 8), Cutter("ball", 8), Cutter("bull", 8, corner_radius=1.25),
              Cutter("bull", 8, corner_radius=4)):
        out = np.empty_like(r)
        _envelope_many(c.code, c.radius, c.corner_radius, r, out)
        np.testing.assert_array_equal(out, c.lower_envelope(r))
        assert math.isnan(_envelope(c.code, c.radius, c.corner_radius, c.radius + 1e-9))


def test_ray_interval():
    c = Cutter("ball", 4, length=20)
    assert c.ray_interval(0.0, 0.0, 5.0) == (5.0, 25.0)
    zlo, zhi = c.ray_interval([0, 2, 3], 0.0, [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(zlo[:2], [1.0, 3.0])
    np.testing.assert_array_equal(zhi[:2], [21.0, 21.0])
    assert np.isnan(zlo[2]) and np.isnan(zhi[2])


@settings(max_examples=80, deadline=None)
@given(d=st.floats(0.1, 50), frac=st.floats(0.01, 1.0), r1=st.floats(0, 1), r2=st.floats(0, 1))
def test_envelope_properties(d, frac, r1, r2):
    c = Cutter("bull", d, corner_radius=frac * d / 2)
    a, b = sorted((r1 * c.radius, r2 * c.radius))
    ha, hb = c.lower_envelope([a, b])
    assert 0.0 <= ha <= hb <= c.corner_radius + 1e-12  # monotone, bounded
    if frac == 1.0:
        np.testing.assert_allclose([ha, hb], Cutter("ball", d).lower_envelope([a, b]))


@pytest.mark.parametrize(
    "kwargs,key",
    [
        (dict(kind="drill", diameter=3), "kind='drill' is not one of"),
        (dict(kind="flat", diameter=0), "diameter must be positive"),
        (dict(kind="flat", diameter=float("nan")), "finite"),
        (dict(kind="flat", diameter=3, corner_radius=0.5), "flat cutter"),
        (dict(kind="ball", diameter=3, corner_radius=1), "ball cutter"),
        (dict(kind="bull", diameter=3, corner_radius=2), "bull-nose"),
        (dict(kind="bull", diameter=3), "bull-nose"),
        (dict(kind="ball", diameter=3, length=1), "length"),
        (dict(kind="ball", diameter="3"), "must be a number"),
    ],
)
def test_cutter_validation(kwargs, key):
    with pytest.raises(ToolError, match=key):
        Cutter(**kwargs)


def test_cutter_is_frozen():
    c = Cutter("flat", 2)
    with pytest.raises(AttributeError):
        c.diameter = 3  # type: ignore[misc]


def test_parse_tool_spec():
    assert parse_tool_spec("ball:3") == Cutter("ball", 3)
    assert parse_tool_spec("flat:6") == Cutter("flat", 6)
    assert parse_tool_spec("bull:10:1") == Cutter("bull", 10, corner_radius=1)
    assert parse_tool_spec("ball:3:40") == Cutter("ball", 3, length=40)
    assert parse_tool_spec("BULL:10:1:30").length == 30
    for spec, key in [("drill:3", "not one of"), ("ball", "must read"), ("bull:10", "must read"),
                      ("ball:x", "numbers"), ("flat:-1", "positive"), (3, "string")]:
        with pytest.raises(ToolError, match=key):
            parse_tool_spec(spec)


def test_load_tool_table_sample_and_errors(tmp_path):
    table = load_tool_table(REPO / "data" / "tools.toml")
    assert table[1] == Cutter("ball", 3, length=40)
    assert table[3] == Cutter("bull", 10, corner_radius=1, length=45)
    assert table[4].diameter == pytest.approx(6.35)  # 1/4 in
    bad = tmp_path / "bad.toml"
    cases = [
        ('[tool.1]\nkind = "ball"\n', "tool.1: needs 'kind' and 'diameter'"),
        ('[tool.x]\nkind = "ball"\ndiameter = 3\n', "tool.x: tool number"),
        ('[tool.2]\nkind = "cone"\ndiameter = 3\n', "tool.2: kind='cone'"),
        ('[tool.2]\nkind = "ball"\ndiameter = 3\ncolour = 1\n', "unknown keys"),
        ('[tool.2]\nkind = "ball"\ndiameter = 3\nunits = "cm"\n', "units='cm'"),
        ("[tool.2\n", "not a valid TOML"),
        ("x = 1\n", "no \\[tool.N\\]"),
    ]
    for text, key in cases:
        bad.write_text(text)
        with pytest.raises(ToolError, match=key) as info:
            load_tool_table(bad)
        assert str(bad) in str(info.value)
    with pytest.raises(ToolError, match="cannot read"):
        load_tool_table(tmp_path / "missing.toml")


@pytest.mark.parametrize("name", ["flower_mold", "cameo", "botomata_bottom"])
def test_camotics_projects(name):
    path = DATA / f"{name}.camotics"
    tools, bounds, units = load_camotics_project(path)
    raw = json.loads(path.read_text())
    assert units == "mm"
    assert bounds == tuple(raw["workpiece"]["bounds"]["min"] + raw["workpiece"]["bounds"]["max"])
    assert set(tools) == {int(k) for k in raw["tools"]}
    for k, t in raw["tools"].items():
        s = 25.4 if t["units"] == "imperial" else 1.0
        c = tools[int(k)]
        assert c.kind == {"cylindrical": "flat", "ballnose": "ball"}[t["shape"]]
        assert c.diameter == pytest.approx(t["diameter"] * s)
        assert c.length == pytest.approx(t["length"] * s)


def test_camotics_with_comments_imperial_and_errors(tmp_path):
    p = tmp_path / "p.camotics"
    p.write_text('/* header */ {"units": "imperial", // inches\n'
                 '"tools": {"2": {"units": "imperial", "shape": "ballnose", "diameter": 0.125,'
                 ' "length": 1, "description": "see http://x//y"},},'
                 '"workpiece": {"bounds": {"min": [0, 0, -1], "max": [2, 3, 0]}}}')
    tools, bounds, units = load_camotics_project(p)
    assert units == "inch"
    assert bounds == pytest.approx((0, 0, -25.4, 50.8, 76.2, 0))
    assert tools[2].diameter == pytest.approx(3.175)
    p.write_text('{"tools": {"1": {"shape": "conical", "diameter": 1}}, '
                 '"workpiece": {"bounds": {"min": [0, 0, 0], "max": [1, 1, 1]}}}')
    with pytest.raises(ToolError, match="tools.1: shape 'conical'"):
        load_camotics_project(p)
    p.write_text('{"tools": {}}')
    with pytest.raises(ToolError, match="workpiece.bounds"):
        load_camotics_project(p)
    p.write_text("{not json")
    with pytest.raises(ToolError, match="JSON"):
        load_camotics_project(p)
