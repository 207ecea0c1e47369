"""zmap.design: one protocol for every kind of design, STEP parts registered from cad_io."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import DATA
from zmap import ZMap
from zmap.design import Design, as_design, read_design
from zmap.errors import ZMapFileError

ROOT = DATA.parent


def test_builtin_kinds():
    zm = ZMap.from_function(lambda x, y: x - y, (0, 0, 3, 2), 0.5)
    d = as_design(zm)
    assert (d.kind, d.exact, d.pitch, d.bounds) == ("zmap", True, 0.5, (0.0, 0.0, 3.0, 2.0))
    assert d.heights(np.array([2.0]), np.array([1.0]))[0] == pytest.approx(1.0)
    f = as_design(lambda x, y: x * 0 + 7.0)
    assert (f.kind, f.bounds, f.exact) == ("callable", None, False)
    assert f.sample_grid(0.0, 0.0, 1.0, 3, 2).shape == (3, 2)
    assert as_design(d) is d
    with pytest.raises(ValueError, match="must be a ZMap, a TiledZMap, a PrecisionModel, a STEP part"):
        as_design(42)


def test_a_tiled_zmap_is_a_design_with_the_heights_of_its_map_in_memory(tmp_path):
    from zmap.tiled import TiledZMap

    zm = ZMap.from_function(lambda x, y: np.sin(x) * np.cos(y), (0, 0, 6, 5), 0.25)
    path = tmp_path / "die.zarr"
    TiledZMap.from_zmap(zm, path, tile=8)
    d = as_design(read_design(path))
    assert (d.kind, d.exact, d.pitch, d.bounds) == ("tiled zmap", True, 0.25, as_design(zm).bounds)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-0.5, 6.5, 500), rng.uniform(-0.5, 5.5, 500)
    assert np.array_equal(d.heights(x, y), as_design(zm).heights(x, y), equal_nan=True)
    # the comparison takes it as it takes the map it was written from
    from zmap.verify.deviation import design_heights

    assert np.array_equal(design_heights(d.source)(x, y), design_heights(zm)(x, y), equal_nan=True)
    # and the drop-cutter
    from zmap.cam import drop_cutter

    xs, ys = np.linspace(1, 5, 30), np.full(30, 2.5)
    assert np.array_equal(drop_cutter(d.source, "ball:2", xs, ys), drop_cutter(zm, "ball:2", xs, ys))


def test_a_step_part_is_a_design_with_its_own_grid_sampler():
    cad_io = pytest.importorskip("cad_io")
    part = cad_io.read_step(DATA / "boss.step")
    d = as_design(part)
    assert d.kind == "part" and d.exact and d.grid is not None and d.drop_pitch == 0.25
    b = part.bbox
    assert d.bounds == pytest.approx((b[0], b[1], b[3], b[4]))
    # its grid sampler and its scattered heights agree (two paths to the exact B-rep)
    g = d.sample_grid(-20.0, 0.0, 0.5, 9, 7)
    X, Y = np.meshgrid(-20.0 + 0.5 * np.arange(9), 0.5 * np.arange(7), indexing="ij")
    assert np.allclose(g, d.heights(X.ravel(), Y.ravel()).reshape(9, 7), atol=1e-9, equal_nan=True)


@pytest.mark.slow
def test_read_design_finds_step_files_without_importing_cad_io_first():
    # zmap never imports cad_io; cad_io's entry point registers .step files on demand
    code = ("import sys; from zmap.design import read_design; assert 'cad_io' not in sys.modules; "
            f"p = read_design({str(DATA / 'boss.step')!r}); print(type(p).__module__, len(p.faces))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.split()[0] == "cad_io.part" and int(out.stdout.split()[1]) > 0


def test_read_design_errors_name_the_file(tmp_path):
    with pytest.raises(ZMapFileError, match="no such file"):
        read_design(tmp_path / "missing.step")
    p = tmp_path / "part.igs"
    p.write_text("not a design")
    with pytest.raises(ValueError, match=r"part\.igs.*\.step \(a STEP part\)"):
        read_design(p)


def test_design_is_frozen():
    d = as_design(lambda x, y: x)
    with pytest.raises(AttributeError):
        d.kind = "other"  # type: ignore[misc]
    assert isinstance(d, Design)
