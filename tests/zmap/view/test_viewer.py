"""The web viewer: captions and scene updates, and the real page in a headless Chromium."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.conftest import DATA
from zmap.errors import StageError
from zmap.sim import simulate
from zmap.view.app import Viewer, free_port, stage_caption


@pytest.fixture(scope="module")
def pocket_run():
    return simulate(DATA / "demo_pocket.nc", (0, 0, -10, 40, 30, 0), tools=DATA / "tools.toml",
                    pitch=0.5, history="treap")


def test_caption_names_stage_line_and_code(pocket_run):
    lines = (DATA / "demo_pocket.nc").read_text().splitlines()
    n = pocket_run.n_stages
    assert stage_caption(pocket_run, 0, lines) == f"stage 0 / {n}"
    k = n // 2
    line = int(pocket_run.line[k - 1])
    assert stage_caption(pocket_run, k, lines) == f"stage {k} / {n}, line {line}: {lines[line - 1].strip()}"
    assert stage_caption(pocket_run, k, None) == f"stage {k} / {n}, line {line}"


def test_scene_follows_the_stage(pocket_run):
    viewer = Viewer(pocket_run, allowance=0.01)
    assert viewer.local.max_error() <= 0.01  # the drawn stock is within the allowance
    assert viewer.poly.n_points < 0.5 * np.isfinite(pocket_run.display("end")).sum()
    caption = viewer.show_stage(0)
    assert caption.startswith("stage 0 /") and "regions re-meshed" in caption
    assert np.all(viewer.poly.points[:, 2] == 0.0)  # the uncut box top
    assert np.all(viewer.poly["height (mm)"] == 0.0)
    viewer.show_stage(pocket_run.n_stages)
    assert viewer.poly.points[:, 2].min() < -5  # the pocket is back
    with pytest.raises(StageError):
        viewer.show_stage(pocket_run.n_stages + 1)


def test_deviation_from_a_design(pocket_run):
    from zmap import ZMap

    s = pocket_run.stock
    design = ZMap(s.x0 - 1, s.y0 - 1, 0.5, 0.5, np.full((s.nx + 4, s.ny + 4), -2.0))
    viewer = Viewer(pocket_run, design=design, tol=0.05)
    viewer.show_stage(0)
    np.testing.assert_allclose(viewer.poly["deviation (mm)"], 2.0)  # the box top is 2 mm above
    # the colours follow the tolerance: bands of tol to +-3 tol, other colours beyond, a legend
    actor = viewer.plotter.actors[next(k for k in viewer.plotter.actors if k.startswith("PolyData"))]
    lut = actor.mapper.lookup_table
    assert tuple(actor.mapper.scalar_range) == pytest.approx((-0.15, 0.15))
    assert lut.n_values == 6 and lut.below_range_color is not None and lut.above_range_color is not None
    assert tuple(lut.below_range_color.float_rgb) != tuple(lut.above_range_color.float_rgb)
    assert viewer.plotter.legend is not None


def test_deviation_bands():
    from zmap.view.app import BAND_COLOURS, deviation_bands

    b = deviation_bands(0.02)
    assert b["clim"] == (-0.06, 0.06) and b["n_colors"] == 6
    assert b["below_color"] not in BAND_COLOURS and b["above_color"] not in BAND_COLOURS
    with pytest.raises(ValueError, match="tol must be a positive"):
        deviation_bands(0.0)


def test_stock_is_drawn_closed(pocket_run):
    """Walls from every open edge of the top down to the stock's bottom, and a bottom: a drilled
    hole is a hole in a solid, no spike hangs below a sheet."""
    viewer = Viewer(pocket_run)
    for k in (pocket_run.n_stages // 2, pocket_run.n_stages):
        viewer.show_stage(k)
        top, sides = viewer.poly, viewer.sides
        tri = np.asarray(top.faces).reshape(-1, 4)[:, 1:]
        e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        _, counts = np.unique(e, axis=0, return_counts=True)
        assert sides.n_cells > (counts == 1).sum()  # one wall per open edge, and the bottom's triangles
        assert sides.bounds[4] == pytest.approx(-10.0) and viewer.bottom == pytest.approx(-10.0)
        # top + sides, cleaned, is closed
        import pyvista as pv

        solid = pv.merge([top, sides.triangulate()]).clean()
        assert solid.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False,
                                           non_manifold_edges=False).n_cells == 0


def test_caption_quotes_the_program_kept_in_the_run(pocket_run, tmp_path):
    from zmap.sim.session import Run

    lines = (DATA / "demo_pocket.nc").read_text().splitlines()
    run = Run.load(pocket_run.save(tmp_path / "pocket.zsim"))
    viewer = Viewer(run)  # no program given: the .zsim keeps it
    k = run.n_stages // 2
    line = int(run.line[k - 1])
    assert viewer.show_stage(k).startswith(f"stage {k} / {run.n_stages}, line {line}: {lines[line - 1].strip()}")


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def _wait_port(port: int, proc: subprocess.Popen, seconds: float = 60.0) -> None:
    t = time.monotonic()
    while time.monotonic() - t < seconds:
        if proc.poll() is not None:
            raise AssertionError(f"zmap view exited early: {proc.stderr.read().decode()[-2000:]}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise AssertionError(f"zmap view did not listen on port {port} within {seconds} s")


@pytest.mark.slow
def test_page_in_headless_chromium(tmp_path, pocket_run):
    browser = _chromium()
    if browser is None:
        pytest.skip("NO BROWSER: Debian's chromium is not installed (.ci/run installs it); the web "
                    "viewer was not tested in a browser")
    from playwright.sync_api import sync_playwright

    run_path = pocket_run.save(tmp_path / "pocket.zsim")
    port = free_port()
    # no --program: the caption quotes the G-code kept in the .zsim
    proc = subprocess.Popen([sys.executable, "-m", "zmap.cli", "view", str(run_path), "--port", str(port),
                             "--no-browser"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        _wait_port(port, proc)
        n = pocket_run.n_stages
        with sync_playwright() as p:
            b = p.chromium.launch(executable_path=browser, headless=True, args=[
                "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--no-first-run"])
            page = b.new_page(viewport={"width": 1000, "height": 760})
            bad = []  # every failed request and console error of the page (the old POST /paraview/ 405)
            page.on("response", lambda r: r.status >= 400 and bad.append(f"{r.status} {r.request.method} {r.url}"))
            page.on("console", lambda m: m.type == "error" and bad.append(m.text))
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function(f"document.querySelector('#caption') && "
                                   f"document.querySelector('#caption').innerText.includes('stage {n} / {n}')",
                                   timeout=60_000)
            view = page.locator("#view")
            y0 = _share_when(view, lambda y: y > 0.01)  # the first picture has arrived
            # the caption: the line's G-code text, on its own line above the picture, full width
            lines = (DATA / "demo_pocket.nc").read_text().splitlines()
            last = lines[int(pocket_run.line[n - 1]) - 1].strip()
            cap = page.locator("#caption")
            assert last in cap.inner_text(), cap.inner_text()
            cb, vb = cap.bounding_box(), view.bounding_box()
            assert cb["y"] + cb["height"] <= vb["y"] + 1 and cb["width"] >= 0.9 * vb["width"], (cb, vb)
            page.locator("#stage-slider [role=slider], [role=slider]").first.focus()
            page.keyboard.press("Home")  # the slider to stage 0
            page.wait_for_function("document.querySelector('#caption').innerText.startsWith('stage 0 /')",
                                   timeout=30_000)
            # the uncut top is the colour bar's top colour (yellow): at stage 0 it covers the
            # whole box, at the end the pocket and holes are cut out of it (pictures come as
            # JPEG: compare areas, not pixels)
            y1 = _share_when(view, lambda y: y > 1.3 * y0)
            page.locator("#end").click()
            page.wait_for_function(f"document.querySelector('#caption').innerText.includes('stage {n} / {n}')",
                                   timeout=30_000)
            y2 = _share_when(view, lambda y: abs(y - y0) < 0.1 * y0)
            page.screenshot(path=str(tmp_path / "page.png"))
            b.close()
        assert y1 > 1.3 * y0, (y0, y1)
        assert abs(y2 - y0) < 0.1 * y0, (y0, y2)
        assert not bad, bad
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()


def _share_when(locator, done, seconds: float = 30.0) -> float:
    """Top-colour share of the view once ``done(share)`` holds for two screenshots in a row
    (the server renders after each change and sends the picture), or the last one."""
    t = time.monotonic()
    last = None
    while time.monotonic() - t < seconds:
        y = _top_colour_share(_pixels(locator.screenshot()))
        if done(y) and last is not None and done(last):
            return y
        last = y
        time.sleep(0.2)
    return last


def _top_colour_share(rgb: np.ndarray) -> float:
    """Share of the picture in viridis' top colour (253, 231, 37), the uncut stock top."""
    return float(np.mean((rgb[..., 0] > 180) & (rgb[..., 1] > 170) & (rgb[..., 2] < 110)))


def _pixels(png: bytes) -> np.ndarray:
    import io

    import matplotlib.image as mpimg

    return mpimg.imread(io.BytesIO(png), format="png")[..., :3].astype(np.float64) * 255


@pytest.mark.slow
def test_serve_in_a_child_process_for_notebooks(tmp_path, pocket_run):
    import urllib.request

    from zmap.errors import ZMapError
    from zmap.view import serve

    handle = serve(pocket_run.save(tmp_path / "pocket.zsim"))
    try:
        with urllib.request.urlopen(handle.url, timeout=10) as r:
            assert r.status == 200
        assert f'src="{handle.url}"' in handle._repr_html_()
        assert "running" in repr(handle)
    finally:
        handle.stop()
    assert "exited" in repr(handle)
    with pytest.raises(ZMapError, match="nope.zsim"):
        serve(tmp_path / "nope.zsim", timeout=20)
