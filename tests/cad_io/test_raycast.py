"""The OCC ray-cast reference against exact answers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cad_io.raycast import RayCaster, raycast

DATA = Path(__file__).resolve().parents[2] / "data"


def _shape(name):
    import cadquery as cq

    return cq.importers.importStep(str(DATA / name)).val()


def test_box_and_miss():
    import cadquery as cq

    box = cq.Workplane().box(10, 10, 4).val()
    z, f = raycast(box, [0.0, 3.0, 20.0], [0.0, -4.0, 0.0])
    assert z[0] == pytest.approx(2.0, abs=1e-12) and z[1] == pytest.approx(2.0, abs=1e-12)
    assert np.isnan(z[2]) and f[2] == -1 and f[0] >= 0


def test_sphere_cap_exact():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-45, 45, 500), rng.uniform(-45, 45, 500)
    z, _ = raycast(_shape("sphere_cap.step"), x, y)
    r2 = x * x + y * y
    exact = np.where(r2 <= 1600, -30 + np.sqrt(np.maximum(2500 - r2, 0)), np.nan)
    inside = r2 < 1600 - 1e-6
    outside = r2 > 1600 + 1e-6
    assert np.max(np.abs(z[inside] - exact[inside])) < 1e-9
    assert np.isnan(z[outside]).all()


@pytest.mark.parametrize("axis,expect", [("+z", 20.0), ("-z", 0.0), ("+y", 20.0), ("-y", 20.0), ("+x", 60.0), ("-x", 0.0)])
def test_axes_on_the_half_cylinder(axis, expect):
    # half cylinder along x (R 20, x 0..60, z >= 0); its extreme along each axis is known
    caster = RayCaster(_shape("cylinder.step"), axis=axis)
    pts = {"+z": (30.0, 0.0), "-z": (30.0, 0.0), "+y": (30.0, 0.0), "-y": (30.0, 0.0),
           "+x": (0.0, 5.0), "-x": (0.0, -5.0)}[axis]
    z, _ = caster(np.array([pts[0]]), np.array([pts[1]]))
    assert z[0] == pytest.approx(expect, abs=1e-9)


@pytest.mark.slow
def test_the_rays_do_not_depend_on_the_shape_being_meshed():
    """The rays start above the shape's geometric box, not its mesh's: a caster of the same
    faces gives the same heights to the last bit in a process that meshed the part and in one
    that did not (a tiled conversion's workers and its checker)."""
    from cad_io.mesh import triangulate
    from cad_io.step import read_step

    part = read_step(DATA / "step" / "bug27693_cornetta-step.stp")
    x0, y0, _, x1, y1, _ = part.bbox
    rng = np.random.default_rng(2)
    x, y = rng.uniform(x0, x1, 400), rng.uniform(y0, y1, 400)
    bare = RayCaster(part.shape)
    z0, f0 = bare(x, y)
    triangulate(part, 2.0)  # a coarse mesh: its box pokes out of the geometry's
    meshed = RayCaster(part.shape)
    z1, f1 = meshed(x, y)
    assert meshed._top == bare._top
    assert np.isfinite(z0).sum() > 200
    assert np.array_equal(z0, z1, equal_nan=True) and np.array_equal(f0, f1)
