"""zmap.verify.compare: deviation classes, regions, totals and first offending stages."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.conftest import GCODE_DATA
from zmap import ZMap
from zmap.sim import simulate
from zmap.verify import compare, first_offending
from zmap.verify.report import deviation_png, format_json, format_markdown, regions_csv


def _flat(z, bounds=(-5, -5, 15, 15), h=0.5):
    return ZMap.from_function(lambda x, y: 0 * x + z, bounds, h)


def test_flat_cutter_pocket_gouge_area_volume_and_first_stage():
    # a 2 mm flat end mill plunged to -1 at (5, 5): a round gouge of the design z = -0.9
    xyz = np.array([[5.0, 5.0, -0.5], [5.0, 5.0, -1.0]])
    run = simulate(xyz, (0, 0, -3, 10, 10, 0), tool="flat:2", pitch=0.1)
    c = compare(run, _flat(-0.9), tol=0.01)
    g = c.gouges
    assert len(g) == 1
    r = g[0]
    # rays within radius 1 of the axis: area close to pi, depth 0.1, volume area * 0.1
    d2 = (run.stock.x[:, None] - 5) ** 2 + (run.stock.y[None, :] - 5) ** 2
    assert int((d2 < 1 - 1e-6).sum()) <= r.rays <= int((d2 <= 1 + 1e-6).sum())
    assert r.area == pytest.approx(r.rays * 0.01)
    assert abs(r.area - math.pi) < 0.1
    assert r.depth == pytest.approx(0.1, abs=1e-6)
    assert r.volume == pytest.approx(r.area * 0.1, rel=1e-5)
    assert r.first_stage == 2 and c.totals["first_gouge_stage"] == 2
    assert r.bbox == pytest.approx((4.0, 4.0, 6.0, 6.0), abs=1e-9)
    # everything else stands 0.9 above the design: one excess region
    assert len(c.excesses) == 1 and c.totals["max_excess_mm"] == pytest.approx(0.9, abs=1e-6)
    assert c.totals["within_rays"] == 0
    # with the allowance 0.9 mm the untouched top is within, and the pocket deeper
    c2 = compare(run, _flat(-0.9), tol=0.01, offset=0.9)
    assert len(c2.excesses) == 0
    assert c2.totals["max_gouge_mm"] == pytest.approx(1.0, abs=1e-6)
    assert c2.gouges[0].first_stage == 1  # -0.5 is already below -0.9 + 0.9 - 0.01


def test_within_band_edges():
    xyz = np.array([[1.0, 1.0, 5.0]])  # above the stock: cuts nothing
    run = simulate(xyz, (0, 0, -3, 2, 2, 0), tool="flat:1", pitch=0.5)
    # below the band but never cut: the stock was short of the design, not gouged
    for design, cls in ((0.0, "within"), (0.0099, "within"), (-0.0099, "within"), (0.02, "short"), (-0.02, "excess")):
        c = compare(run, _flat(design), tol=0.01)
        assert c.totals[f"{cls}_rays"] == run.stock.n_rays, design
        assert c.totals["gouge_regions"] == 0
    # a 6 mm end mill faces the whole 2 x 2 stock down to -0.5: below the band is a gouge
    run = simulate(np.array([[1.0, 1.0, 5.0], [1.0, 1.0, -0.5]]), (0, 0, -3, 2, 2, 0), tool="flat:6", pitch=0.5)
    for design, cls in ((-0.5, "within"), (-0.4901, "within"), (-0.48, "gouge"), (-0.52, "excess")):
        c = compare(run, _flat(design), tol=0.01)
        assert c.totals[f"{cls}_rays"] == run.stock.n_rays, design


def test_uncovered_area_reported_without_nan():
    run = simulate(np.array([[1.0, 1.0, -0.5]]), (0, 0, -3, 10, 10, 0), tool="flat:1", pitch=0.5)
    half = ZMap.from_function(lambda x, y: 0 * x - 0.2, (-1, -1, 4.5, 11), 0.5)  # covers x <= 4.5 only
    with pytest.warns(UserWarning, match="does not cover"):
        c = compare(run, half, tol=0.01)
    t = c.totals
    assert t["uncovered_rays"] == 11 * 21  # beyond the design's extent: uncovered, not outline
    assert t["uncovered_area_mm2"] == pytest.approx(11 * 21 * 0.25)
    assert t["outline_rays"] == 0 and t["outline_area_mm2"] == 0.0
    for k, v in t.items():
        assert not (isinstance(v, float) and math.isnan(v)), k
    assert (c.classes[np.isnan(c.design)] == 0).all()
    js = json.loads(format_json(c))
    assert js["totals"]["uncovered_rays"] == 231


def test_no_cover_at_all_warns_and_zero_figures():
    run = simulate(np.array([[1.0, 1.0, -0.5]]), (0, 0, -3, 2, 2, 0), tool="flat:1", pitch=0.5)
    far = ZMap.from_function(lambda x, y: 0 * x, (100, 100, 110, 110), 1.0)
    with pytest.warns(UserWarning, match="covers none"):
        c = compare(run, far)
    assert c.totals["covered_rays"] == 0 and c.totals["max_gouge_mm"] == 0.0


def test_inch_design_refused_as_units_mismatch():
    run = simulate(np.array([[20.0, 20.0, -0.5]]), (0, 0, -3, 50, 50, 0), tool="flat:1", pitch=1.0)
    inch = ZMap.from_function(lambda x, y: 0 * x, (0, 0, 2.0, 2.0), 0.05)  # the same part drawn in inches
    with pytest.raises(ValueError, match="inches"):
        compare(run, inch)


@pytest.mark.parametrize("tol", [-0.01, math.nan, math.inf])
def test_bad_tolerance(tol):
    run = simulate(np.array([[1.0, 1.0, -0.5]]), (0, 0, -3, 2, 2, 0), tool="flat:1", pitch=0.5)
    with pytest.raises(ValueError, match="tol"):
        compare(run, _flat(0.0), tol=tol)


def _brute_first(run, ray, level):
    for k in range(run.n_stages + 1):
        t = run.display(k).ravel()[ray]
        if math.isnan(t) or t < level:
            return k
    return -1


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000))
@pytest.mark.slow
def test_first_offending_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 12
    xyz = np.column_stack([rng.uniform(0, 4, n), rng.uniform(0, 4, n), rng.uniform(-2.5, 0.2, n)])
    run = simulate(xyz, (0, 0, -2, 4, 4, 0), tool="ball:1.5", pitch=0.25)
    rays = rng.integers(0, run.stock.n_rays, 20)
    level = rng.uniform(-2.2, 0.1, 20)
    got = first_offending(run, rays, level)
    want = [_brute_first(run, int(r), float(lv)) for r, lv in zip(rays, level)]
    assert got.tolist() == want
    # the bisection over displays (other histories) answers the same
    run2 = simulate(xyz, (0, 0, -2, 4, 4, 0), tool="ball:1.5", pitch=0.25, history="ztrace")
    assert first_offending(run2, rays, level).tolist() == want


@pytest.fixture(scope="module")
def flower():
    from zmap.sim.tools import load_camotics_project

    tools, box, _units = load_camotics_project(GCODE_DATA / "flower_mold.camotics")
    return simulate(GCODE_DATA / "flower_mold.nc", box, tools=tools, tool=tools[1], pitch=0.26)


def test_real_program_first_offending_lines(flower):
    # design: the stock as it stood half way; everything cut after it is a gouge
    run = flower
    half = run.n_stages // 2
    s = run.stock
    top = run.display(half)
    design = ZMap(s.x0, s.y0, s.pitch, s.pitch, np.where(np.isnan(top), s.to_csr()[1].min(), top))
    c = compare(run, design, tol=0.01)
    assert c.gouges, "cuts after half way must show as gouges"
    fs = c.first_stage[c.classes == 1]
    assert (fs > half).all()
    rng = np.random.default_rng(0)
    gi = np.flatnonzero((c.classes == 1).ravel())
    for ray in rng.choice(gi, 10, replace=False):
        k = int(c.first_stage.ravel()[ray])
        lev = design.z.ravel()[ray] - 0.01
        assert run.display(k).ravel()[ray] < lev <= run.display(k - 1).ravel()[ray]
        assert c.first_line.ravel()[ray] == run.line[k - 1] > 0
    md = format_markdown(c, program_lines=(GCODE_DATA / "flower_mold.nc").read_text().splitlines())
    assert "first_gouge_line" in md
    rows = regions_csv(c).splitlines()
    assert rows[0].startswith("kind,rays,area_mm2") and len(rows) == len(c.regions) + 1
    vols = [r.volume for r in c.gouges]
    assert vols == sorted(vols, reverse=True)
    assert c.totals["gouge_volume_mm3"] == pytest.approx(sum(vols), rel=1e-9)


def test_deviation_png(tmp_path):
    xyz = np.array([[5.0, 5.0, -0.5], [5.0, 5.0, -1.0]])
    run = simulate(xyz, (0, 0, -3, 10, 10, 0), tool="flat:2", pitch=0.2)
    c = compare(run, _flat(-0.9), tol=0.05, offset=0.85)
    p = deviation_png(c, tmp_path / "dev.png")
    assert p.exists() and p.stat().st_size > 10_000
    assert not list(tmp_path.glob("*.tmp*"))


def test_deviation_png_leaves_the_backend_alone(tmp_path):
    import matplotlib

    before = matplotlib.get_backend()
    matplotlib.use("pdf")  # as a notebook's inline backend would be: not Agg
    try:
        xyz = np.array([[5.0, 5.0, -1.0]])
        run = simulate(xyz, (0, 0, -3, 10, 10, 0), tool="flat:2", pitch=0.2)
        deviation_png(compare(run, _flat(-0.9), tol=0.05, offset=0.85), tmp_path / "dev.png")
        assert matplotlib.get_backend() == "pdf"
    finally:
        matplotlib.use(before)


def test_deviation_3d_picture(tmp_path):
    from zmap.verify.report import deviation_3d

    xyz = np.array([[5.0, 5.0, -0.5], [5.0, 5.0, -1.0]])
    run = simulate(xyz, (0, 0, -3, 10, 10, 0), tool="ball:2", pitch=0.25)
    c = compare(run, _flat(-0.9), tol=0.05, offset=0.85)
    p = deviation_3d(c, tmp_path / "dev3d.png", window_size=(640, 480))
    assert p.exists() and p.stat().st_size > 10_000


# ---- no false alarms: the stock as sampled, the part's outline ------------------------------
def _hemisphere(r=10.0, h=0.5):
    """A hemisphere of radius ``r`` on the origin, NaN (no surface) outside its outline."""
    def z(x, y):
        q = r * r - x * x - y * y
        return np.where(q >= 0, np.sqrt(np.maximum(q, 0.0)), np.nan)
    return ZMap.from_function(z, (-12, -12, 12, 12), h)


@pytest.mark.parametrize("pitch", [None, 0.26, 0.3])
def test_allowance_stock_at_stage_0_has_no_gouges(pitch):
    # stock = design + 0.5 mm, as a dexel stock sampled from the design's map: at 0.26 and
    # 0.3 mm the stock's rays fall between the map's points (bilinear heights) while the design
    # is read by Bezier, so near the steep rim the stock starts up to 0.5 mm below the target
    from zmap.sim.session import stock_from_spec

    design = _hemisphere()
    stock = stock_from_spec(ZMap(design.x0, design.y0, design.dx, design.dy, design.z + 0.5),
                            pitch=pitch if pitch is not None else design.dx)
    run = simulate(np.array([[0.0, 0.0, 50.0]]), stock, tool="ball:2", pitch=stock.pitch)
    for offset in (0.5, 0.0):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the design does not cover the stock's corners
            c = compare(run, design, stage=0, tol=0.01, offset=offset)
        t = c.totals
        assert t["gouge_regions"] == 0 and t["gouge_rays"] == 0 and c.gouges == []
        assert "first_gouge_line" not in t and "first_gouge_stage" not in t
        assert t["uncovered_rays"] + t["outline_rays"] + t["short_rays"] + t["within_rays"] \
            + t["excess_rays"] == t["rays"]
        assert (c.first_line == -1).all()
    if pitch is not None:  # the rim's rays are told apart, and counted
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            c = compare(run, design, stage=0, tol=0.01, offset=0.5)
        assert c.totals["outline_rays"] > 0
        r = np.hypot(*np.meshgrid(run.stock.x, run.stock.y, indexing="ij"))
        assert r[c.classes == 4].min() > 9.0  # along the outline (radius 10)


def test_one_sided_rays_along_the_outline():
    # stock: a hemisphere 0.5 mm larger (radius 10.5), the design radius 10: on the ring
    # between them the stock has material and the design no height
    design = _hemisphere(10.0)
    stock = _hemisphere(10.5)
    run = simulate(np.array([[0.0, 0.0, 50.0]]), stock, tool="ball:2", pitch=0.5)
    with pytest.warns(UserWarning, match="inside its extent, along the part's outline"):
        c = compare(run, design, stage=0, tol=0.01, offset=0.5)
    one_sided = np.isfinite(c.top) ^ np.isfinite(c.design)
    assert one_sided.any() and (c.classes[one_sided] == 4).all()
    assert c.totals["outline_rays"] >= int(one_sided.sum()) and c.totals["gouge_regions"] == 0
    assert c.totals["outline_area_mm2"] == pytest.approx(c.totals["outline_rays"] * 0.25)


def test_first_gouge_line_is_a_line_of_the_program(tmp_path):
    # the stock starts 0.02 short of the design everywhere: short, not gouged; the plunge on
    # line 3 cuts deeper: a gouge, first found on line 3 (never stage 0 / line 0)
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X5 Y5 Z2\nG1 Z-0.5 F50\nG0 Z2\n")
    run = simulate(prog, (0, 0, -3, 10, 10, 0), tool="flat:2", pitch=0.25)
    design = _flat(0.02, bounds=(-1, -1, 11, 11))
    c0 = compare(run, design, stage=0, tol=0.01)
    assert c0.totals["gouge_regions"] == 0 and c0.totals["short_rays"] == run.stock.n_rays
    c = compare(run, design, tol=0.01)
    assert len(c.gouges) == 1 and c.gouges[0].first_line == 3 and c.gouges[0].first_stage >= 1
    assert c.totals["first_gouge_line"] == 3
    assert set(c.first_line[c.classes == 1].tolist()) == {3}
    assert c.totals["short_rays"] == run.stock.n_rays - c.totals["gouge_rays"]
    assert (c.first_stage[c.classes != 1] == -1).all()


def test_allowance_stock_then_a_real_gouge_at_its_line():
    from zmap.sim.session import stock_from_spec

    design = _hemisphere()
    stock = stock_from_spec(ZMap(design.x0, design.y0, design.dx, design.dy, design.z + 0.5), pitch=0.26)
    prog = "G21 G90\nG0 X0 Y0 Z20\nG1 Z9 F100\nG0 Z20\n"  # a plunge 1 mm into the top (z = 10)
    run = simulate(prog, stock, tool="ball:2", pitch=0.26)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = compare(run, design, tol=0.01, offset=0.5)
    assert len(c.gouges) == 1 and c.totals["first_gouge_line"] == 3
    g = c.gouges[0]
    assert abs(g.deepest[0]) < 0.3 and abs(g.deepest[1]) < 0.3 and g.depth == pytest.approx(1.5, abs=0.05)
