"""3D views rendered off-screen with pyvista: files of the window size, not blank, NaN left out."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pyvista")
from PIL import Image  # noqa: E402

from zmap import ZMap  # noqa: E402
from zmap.plot.scene import stock_3d, zmap_3d  # noqa: E402

SIZE = (400, 300)


def _check_png(path):
    with Image.open(path) as im:
        assert im.size == SIZE
        a = np.asarray(im.convert("RGB"), dtype=np.float64)
    assert a.std() > 10.0  # not blank
    return a


@pytest.mark.slow
def test_zmap_3d_writes_png_with_nan_nodes_left_out(tmp_path):
    zm = ZMap.from_function(lambda x, y: 3 * np.exp(-(x * x + y * y) / 20), (-8, -8, 8, 8), 1.0)
    zm.z[:4, :4] = np.nan
    out = zmap_3d(zm, tmp_path / "bump.png", title="bump", window_size=SIZE)
    assert out == tmp_path / "bump.png"
    _check_png(out)
    assert not list(tmp_path.glob(".*tmp*"))  # written through a temporary name, renamed


def test_zmap_3d_scalars_are_checked(tmp_path):
    zm = ZMap(0.0, 0.0, 1.0, 1.0, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="'slope' is not one of"):
        zmap_3d(zm, tmp_path / "x.png", scalars="slope")
    with pytest.raises(ValueError, match="shape of z"):
        zmap_3d(zm, tmp_path / "x.png", scalars=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="every height is NaN"):
        zmap_3d(ZMap(0.0, 0.0, 1.0, 1.0, np.full((3, 3), np.nan)), tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


@pytest.mark.slow
def test_stock_3d_at_a_stage_and_against_a_design(tmp_path):
    from zmap.sim import simulate

    xyz = np.array([[1.0, 1.0, -1.0], [3.0, 1.0, -1.0], [3.0, 3.0, -1.5]])
    run = simulate(xyz, (0, 0, -3, 4, 4, 0), tool="ball:2", pitch=0.25, history="treap")
    _check_png(stock_3d(run, "1/2", tmp_path / "half.png", name="tiny", window_size=SIZE))
    design = ZMap(0.0, 0.0, 1.0, 1.0, np.full((5, 5), -1.0))
    _check_png(stock_3d(run, "end", tmp_path / "dev.png", design=design, window_size=SIZE))
    p = stock_3d(run, 2, None, window_size=SIZE)  # a Plotter for notebooks
    try:
        assert hasattr(p, "screenshot")
    finally:
        p.close()
