"""Exact heights on every real part in data/step: sampled grid nodes agree with OCC's
ray cast (``cad_io.raycast``, OCC's own reader and intersector) within 1e-6 mm wherever both see
a face more than one grid interval from a wall, with no empty/non-empty disagreement there; the
same in a side view (``zmap convert --axis``). Coarse grids and sampled nodes keep it quick."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OCP")

STEP = Path(__file__).resolve().parents[2] / "data" / "step"
FAST = ["bm2_ec_t4-A.stp", "trj7_c2-td-203.stp", "featuretype.STEP", "bug27693_cornetta-step.stp",
        "nist_ftc_08_asme1_ap242-2.stp"]
SLOW = ["trj8_b1-ec-214.stp", "bug27453_165-174_piattello.stp", "Ventilator.stp", "nist_ctc_02_asme1_ap242-1.stp"]
#: grid nodes per longer side of the view, and nodes checked per part and view
DIVISIONS = 50
CHECKED = 250
#: trj8 is a thin, sparse sheet: at side/50 only 13 checked nodes in +z saw it away from walls
FINER = {"trj8_b1-ec-214.stp": 150}


@cache
def _part(name: str):
    from cad_io.step import read_step

    return read_step(STEP / name)


@cache
def _caster(name: str, axis: str):
    from cad_io.raycast import RayCaster, read_shape

    return RayCaster(read_shape(STEP / name), axis=axis)


def _near_wall(zm, reach: int = 1) -> np.ndarray:
    """Nodes within ``reach`` grid intervals of a wall or the outline: a neighbour is empty
    while the node is not (or the other way round), or the height jumps by more than two
    intervals to it."""
    z = zm.z
    e = np.isnan(z)
    jump = 2.0 * max(zm.dx, zm.dy)
    wall = np.zeros(z.shape, dtype=bool)
    zp = np.pad(z, 1, constant_values=np.nan)
    ep = np.pad(e, 1, constant_values=True)
    nx, ny = z.shape
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            zn = zp[1 + di:1 + di + nx, 1 + dj:1 + dj + ny]
            en = ep[1 + di:1 + di + nx, 1 + dj:1 + dj + ny]
            with np.errstate(invalid="ignore"):
                wall |= (en != e) | (np.abs(zn - z) > jump)
    out = wall.copy()
    for _ in range(reach):
        grown = np.pad(out, 1)
        out = out | grown[:-2, 1:-1] | grown[2:, 1:-1] | grown[1:-1, :-2] | grown[1:-1, 2:]
    return out


def _compare(name: str, axis: str, seed: int = 0) -> dict:
    import warnings

    from cad_io.sampler import sample
    from cad_io.view import view_matrix

    part = _part(name)
    R = view_matrix(axis)
    ext = np.abs(R @ (np.array(part.bbox[3:]) - np.array(part.bbox[:3])))
    grid = float(max(ext[0], ext[1]) / FINER.get(name, DIVISIONS))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # AP242 tessellated faces: 'sampled from facets'
        zm = sample(part, grid, axis=axis)
    rng = np.random.default_rng(seed)
    i = rng.integers(0, zm.nx, CHECKED)
    j = rng.integers(0, zm.ny, CHECKED)
    zr, _ = _caster(name, axis)(zm.x[i], zm.y[j])
    zs = zm.z[i, j]
    away = ~_near_wall(zm)[i, j]
    exact = zm.layers["method"][i, j] == 1
    both = np.isfinite(zs) & np.isfinite(zr)
    dz = np.abs(zs - zr)
    return {"grid": grid, "away": int(away.sum()), "both": int((both & away).sum()),
            "max_dz": float(dz[both & away & exact].max()) if (both & away & exact).any() else 0.0,
            "facet_away": int((both & away & ~exact).sum()),
            "max_dz_facet": float(dz[both & away & ~exact].max()) if (both & away & ~exact).any() else 0.0,
            "empty_disagree": int(((np.isfinite(zs) != np.isfinite(zr)) & away).sum()),
            "faceted": all(f.surface is None for f in part.faces)}


def _check(stats: dict, name: str, axis: str) -> None:
    print(name, axis, stats)
    assert stats["both"] >= 20, stats  # the check saw the part
    assert stats["empty_disagree"] == 0, (name, axis, stats)
    if stats["faceted"]:
        # AP242 tessellated part (no B-rep surfaces): the triangles themselves are the part
        assert stats["max_dz_facet"] <= 1e-6, (name, axis, stats)
    else:
        assert stats["max_dz"] <= 1e-6, (name, axis, stats)


@pytest.mark.parametrize("name", FAST)
@pytest.mark.slow
def test_real_part_heights_agree_with_occ(name):
    _check(_compare(name, "+z"), name, "+z")


@pytest.mark.parametrize("name", [n for n in FAST if n != "trj7_c2-td-203.stp"])  # trj7: a sheet, edge-on from -y
def test_real_part_side_view_heights_agree_with_occ(name):
    _check(_compare(name, "-y", seed=1), name, "-y")


#: side view of each large part: one it shows depth in (trj8, a sheet, is edge-on from +x)
SIDE = {"trj8_b1-ec-214.stp": "-y"}


@pytest.mark.slow
@pytest.mark.parametrize("name", SLOW)
def test_large_real_part_heights_agree_with_occ(name):
    _check(_compare(name, "+z"), name, "+z")
    axis = SIDE.get(name, "+x")
    _check(_compare(name, axis, seed=2), name, axis)
