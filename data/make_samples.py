"""Make the bundled STEP samples in this folder with cadquery: ``python data/make_samples.py``.

Every sample has known geometry, so the tests can check heights against the exact answer:

- ``sphere_cap.step``  the solid of a sphere (R = 50, centre (0, 0, -30)) above z = 0: a
  spherical cap face ``z = -30 + sqrt(2500 - x^2 - y^2)`` over the disc r <= 40, on a flat
  base disc.
- ``cylinder.step``    a half cylinder lying along x (R = 20, x in 0..60): the top face is
  ``z = sqrt(400 - y^2)``; it turns vertical at y = +-20.
- ``torus.step``       the upper half of a torus about +z (R = 30, r = 10):
  ``z = sqrt(100 - (sqrt(x^2 + y^2) - 30)^2)``.
- ``freeform_die.step`` one free-form B-spline die face over 100 x 100 mm, cubic in u and v,
  interpolating a seeded 9 x 9 grid of control heights (a loose face, no solid).
- ``pocket.step``      a 100 x 80 x 30 block with a 60 x 40 x 15 pocket whose vertical
  corners have 8 mm fillets and whose floor edges have 3 mm fillets (vertical walls).
- ``boss.step``        an 80 x 60 x 10 plate with a 30 x 20 x 12 rectangular boss and a
  round boss (R 8, 6 high), every edge sharp.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

__all__ = ["make_all", "SAMPLES"]

SAMPLES = ("sphere_cap", "cylinder", "torus", "freeform_die", "pocket", "boss")


def sphere_cap():
    import cadquery as cq

    sphere = cq.Workplane("XY").sphere(50.0).translate((0, 0, -30.0))
    box = cq.Workplane("XY").box(200, 200, 100, centered=(True, True, False))
    return sphere.intersect(box).val()


def cylinder():
    import cadquery as cq

    cyl = cq.Workplane("YZ").circle(20.0).extrude(60.0)
    box = cq.Workplane("XY").box(100, 100, 50, centered=(False, True, False)).translate((-10, 0, 0))
    return cyl.intersect(box).val()


def torus():
    import cadquery as cq

    tor = cq.Workplane("XY").add(cq.Solid.makeTorus(30.0, 10.0))
    box = cq.Workplane("XY").box(200, 200, 50, centered=(True, True, False))
    return tor.intersect(box).val()


def freeform_die():
    import cadquery as cq
    from OCP.Geom import Geom_BSplineSurface
    from OCP.TColgp import TColgp_Array2OfPnt
    from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal
    from OCP.gp import gp_Pnt
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    n, deg, size = 9, 3, 100.0
    rng = np.random.default_rng(4)
    xs = np.linspace(0.0, size, n)
    heights = 10.0 + 6.0 * rng.standard_normal((n, n))
    # A die-like bowl: lower in the middle, a ridge along one diagonal.
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    heights += -12.0 * np.exp(-((X - 45) ** 2 + (Y - 55) ** 2) / 900.0) + 0.08 * (X + Y)
    poles = TColgp_Array2OfPnt(1, n, 1, n)
    for a in range(n):
        for b in range(n):
            poles.SetValue(a + 1, b + 1, gp_Pnt(float(xs[a]), float(xs[b]), float(heights[a, b])))
    nk = n - deg + 1
    knots = TColStd_Array1OfReal(1, nk)
    mults = TColStd_Array1OfInteger(1, nk)
    for k in range(nk):
        knots.SetValue(k + 1, k / (nk - 1))
        mults.SetValue(k + 1, deg + 1 if k in (0, nk - 1) else 1)
    surf = Geom_BSplineSurface(poles, knots, knots, mults, mults, deg, deg)
    face = BRepBuilderAPI_MakeFace(surf, 1e-7).Face()
    return cq.Face(face)


def pocket():
    import cadquery as cq

    block = cq.Workplane("XY").box(100, 80, 30, centered=(True, True, False))
    cut = (cq.Workplane("XY").box(60, 40, 15, centered=(True, True, False)).translate((0, 0, 15))
           .edges("|Z").fillet(8.0).faces("<Z").edges().fillet(3.0))
    return block.cut(cut).val()


def boss():
    import cadquery as cq

    plate = cq.Workplane("XY").box(80, 60, 10, centered=(True, True, False))
    rect = cq.Workplane("XY").box(30, 20, 12, centered=(True, True, False)).translate((-15, 5, 10))
    rnd = cq.Workplane("XY").circle(8.0).extrude(6.0).translate((22, -12, 10))
    return plate.union(rect).union(rnd).val()


def make_all(folder: str | Path = HERE) -> list[Path]:
    """Write every sample as ``<name>.step`` into ``folder``; return the paths."""
    import cadquery as cq

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for name in SAMPLES:
        shape = globals()[name]()
        path = folder / f"{name}.step"
        cq.exporters.export(cq.Workplane("XY").add(shape), str(path), exportType="STEP")
        out.append(path)
    return out


if __name__ == "__main__":
    for p in make_all(sys.argv[1] if len(sys.argv) > 1 else HERE):
        print(p, p.stat().st_size)
