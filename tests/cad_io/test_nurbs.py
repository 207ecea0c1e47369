"""cad_io.nurbs against geomdl and against OpenCASCADE (BRepAdaptor_Surface D0/D1/D2)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from numba import njit

from cad_io._nurbs_kernels import eval_point
from cad_io.nurbs import MAX_DEGREE, evaluate, evaluate_packed, pack
from cad_io.part import NurbsSurface
from zmap.errors import NurbsError

geomdl = pytest.importorskip("geomdl")

FAST_PARTS = ["featuretype.STEP", "trj7_c2-td-203.stp", "bm2_ec_t4-A.stp",
              "bug27693_cornetta-step.stp"]
ALL_PARTS = FAST_PARTS + ["Ventilator.stp", "bug27453_165-174_piattello.stp",
                          "nist_ctc_02_asme1_ap242-1.stp", "nist_ftc_08_asme1_ap242-2.stp",
                          "trj8_b1-ec-214.stp"]


def _random_surface(rng, p, q, nu, nv, rational, mult=1):
    """A random NurbsSurface and the same geomdl surface."""
    from geomdl import NURBS

    def kv(deg, n):
        inner = np.sort(rng.uniform(0.0, 1.0, n - deg - 1))
        if mult > 1 and len(inner) >= mult:
            inner[1:mult] = inner[0]  # a knot of multiplicity `mult`
        inner = np.sort(inner)
        return np.r_[np.zeros(deg + 1), inner, np.ones(deg + 1)]  # geomdl keeps [0, 1]

    P = rng.normal(scale=20.0, size=(nu, nv, 3))
    W = rng.uniform(0.3, 3.0, (nu, nv)) if rational else np.ones((nu, nv))
    ku, kvv = kv(p, nu), kv(q, nv)
    g = NURBS.Surface()
    g.degree_u, g.degree_v = p, q
    g.ctrlpts_size_u, g.ctrlpts_size_v = nu, nv
    g.ctrlpts = P.reshape(-1, 3).tolist()
    g.weights = W.ravel().tolist()
    g.knotvector_u, g.knotvector_v = ku.tolist(), kvv.tolist()
    return NurbsSurface(p, q, ku, kvv, P, W), g


@pytest.mark.parametrize("p,q,nu,nv,rational,mult", [
    (1, 1, 2, 2, False, 1), (3, 3, 7, 6, False, 1), (3, 2, 6, 5, True, 2),
    (2, 5, 4, 9, True, 1), (5, 4, 8, 8, True, 3), (1, 3, 5, 4, True, 1),
])
def test_agrees_with_geomdl(p, q, nu, nv, rational, mult):
    rng = np.random.default_rng(100 * p + q)
    s, g = _random_surface(rng, p, q, nu, nv, rational, mult)
    u0, u1, v0, v1 = s.domain
    uv = np.c_[rng.uniform(u0, u1, 40), rng.uniform(v0, v1, 40)]
    uv = np.r_[uv, [[u0, v0], [u1, v1], [u0, v1], [u1, v0]]]
    ours = evaluate(s, uv[:, 0], uv[:, 1], derivs=2)
    scale = np.abs(s.poles).max()
    for (u, v), e in zip(uv, ours):
        d = np.array(g.derivatives(u, v, order=2))
        ref = np.array([d[0, 0], d[1, 0], d[0, 1], d[2, 0], d[1, 1], d[0, 2]])
        # derivatives scale with 1/knot span^k: compare relative to the reference size
        tol = 1e-12 * scale * np.maximum(1.0, np.abs(ref).max(axis=1, keepdims=True))
        err = np.abs(e - ref)
        assert (err <= np.maximum(tol, 1e-9)).all(), f"at ({u}, {v}): {err.max()}"


def test_shapes_broadcast_and_rows():
    rng = np.random.default_rng(1)
    s, _ = _random_surface(rng, 3, 3, 5, 5, True)
    assert evaluate(s, 0.0, 0.0).shape == (1, 3)
    assert evaluate(s, np.zeros((4, 1)), np.zeros(5), derivs=1).shape == (4, 5, 3, 3)
    assert evaluate(s, [0.1, 0.2], 0.3, derivs=2).shape == (2, 6, 3)


def test_outside_domain_is_clamped_and_nan_gives_nan():
    rng = np.random.default_rng(2)
    s, _ = _random_surface(rng, 2, 3, 5, 6, True)
    u0, u1, v0, v1 = s.domain
    a = evaluate(s, [u0 - 5, u1 + 5], [v1 + 1, v0 - 1])
    b = evaluate(s, [u0, u1], [v1, v0])
    np.testing.assert_array_equal(a, b)
    assert np.isnan(evaluate(s, np.nan, 0.0)).all()


def test_corners_interpolate_clamped_poles():
    rng = np.random.default_rng(3)
    s, _ = _random_surface(rng, 3, 2, 6, 4, True)
    u0, u1, v0, v1 = s.domain
    got = evaluate(s, [u0, u0, u1, u1], [v0, v1, v0, v1])[:, 0]
    want = s.poles[[0, 0, -1, -1], [0, -1, 0, -1]]
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_pack_layout_and_missing_faces():
    rng = np.random.default_rng(4)
    s1, _ = _random_surface(rng, 3, 2, 6, 5, True)
    s2, _ = _random_surface(rng, 1, 4, 3, 7, False)
    pk = pack([s1, None, s2])
    assert pk.deg.tolist() == [[3, 2], [-1, -1], [1, 4]]
    assert pk.ncp.tolist() == [[6, 5], [0, 0], [3, 7]]
    k = 2
    a, b = 1, 4
    row = pk.cpw[pk.poff[k] + a * pk.ncp[k, 1] + b]
    np.testing.assert_allclose(row[:3] / row[3], s2.poles[a, b])
    np.testing.assert_array_equal(pk.knots[pk.koff[k, 0]:pk.koff[k, 0] + 3 + 1 + 1],
                                  s2.knots_u)
    out = evaluate_packed(pk, [0, 1, 2], 0.3, 0.4, derivs=1)
    assert np.isnan(out[1]).all() and np.isfinite(out[[0, 2]]).all()
    np.testing.assert_array_equal(out[2], evaluate(s2, 0.3, 0.4, derivs=1))


@pytest.mark.slow
def test_eval_point_inside_njit_matches_evaluate():
    rng = np.random.default_rng(5)
    s, _ = _random_surface(rng, 3, 3, 6, 6, True)
    pk = pack([None, s])

    @njit
    def run(deg, ncp, koff, poff, knots, cpw, u, v):
        out = np.empty((u.size, 6, 3))
        for i in range(u.size):
            eval_point(deg, ncp, koff, poff, knots, cpw, 1, u[i], v[i], 2, out[i])
        return out

    u = rng.uniform(-1, 2, 20)
    v = rng.uniform(-1, 2, 20)
    np.testing.assert_array_equal(run(*pk.arrays(), u, v), evaluate(s, u, v, derivs=2))


def test_bad_input_messages():
    rng = np.random.default_rng(6)
    s, _ = _random_surface(rng, 2, 2, 4, 4, False)
    with pytest.raises(ValueError, match="derivs=3 is not one of"):
        evaluate(s, 0.0, 0.0, derivs=3)
    big = NurbsSurface(MAX_DEGREE + 1, 1, np.r_[np.zeros(17), np.ones(17)],
                       np.array([0.0, 0, 1, 1]), np.zeros((17, 2, 3)), np.ones((17, 2)))
    with pytest.raises(NurbsError, match="above the limit 15"):
        pack([big])
    bad = NurbsSurface(2, 2, s.knots_u[:-1], s.knots_v, s.poles, s.weights)
    with pytest.raises(NurbsError, match="do not match"):
        pack([bad])
    with pytest.raises(IndexError, match="out of range"):
        evaluate_packed(pack([s]), 3, 0.0, 0.0)


# --------------------------------------------------------------------------------------
# against OpenCASCADE on the faces of real parts


@cache
def _part(path):
    from cad_io.step import read_step

    return read_step(path)


def _occ_deviation(part, n_per_face: int, seed: int) -> float:
    """Largest |ours - OCC| over S, Su, Sv, Suu, Suv, Svv, relative to max(1, |OCC|)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.gp import gp_Pnt, gp_Vec

    rng = np.random.default_rng(seed)
    worst = 0.0
    checked = 0
    for f in part.faces:
        if f.surface is None:
            continue
        u0, u1, v0, v1 = f.surface.domain
        if f.loops:  # stay near the face (the surface may extend far beyond it)
            lo = np.maximum(np.min(f.loops[0], axis=0), [u0, v0])
            hi = np.minimum(np.max(f.loops[0], axis=0), [u1, v1])
            if np.all(hi > lo):
                (u0, v0), (u1, v1) = lo, hi
        uv = np.c_[rng.uniform(u0, u1, n_per_face), rng.uniform(v0, v1, n_per_face)]
        ours = evaluate(f.surface, uv[:, 0], uv[:, 1], derivs=2)
        ad = BRepAdaptor_Surface(f.topo, False)
        for (u, v), e in zip(uv, ours):
            P = gp_Pnt()
            d1u, d1v, d2u, d2v, d2uv = gp_Vec(), gp_Vec(), gp_Vec(), gp_Vec(), gp_Vec()
            ad.D2(u, v, P, d1u, d1v, d2u, d2v, d2uv)
            ref = np.array([P.Coord(), d1u.Coord(), d1v.Coord(), d2u.Coord(), d2uv.Coord(),
                            d2v.Coord()])
            # points are compared absolutely (mm); derivatives relative to their size
            scale = np.maximum(1.0, np.linalg.norm(ref, axis=1))
            scale[0] = 1.0
            dev = float(np.max(np.linalg.norm(e - ref, axis=1) / scale))
            worst = max(worst, dev)
            checked += 1
    assert checked > 0
    return worst


@pytest.mark.parametrize("name", FAST_PARTS)
@pytest.mark.slow
def test_agrees_with_occ_on_real_parts(sample_data, name):
    part = _part(str(sample_data / "step" / name))
    assert _occ_deviation(part, 4, seed=7) < 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in ALL_PARTS if n not in FAST_PARTS
                                  and not n.startswith("nist_ftc")])
def test_agrees_with_occ_on_all_parts(sample_data, name):
    part = _part(str(sample_data / "step" / name))
    assert _occ_deviation(part, 4, seed=8) < 1e-9


def test_agrees_with_occ_on_analytic_faces(tmp_path):
    cq = pytest.importorskip("cadquery")
    solid = (cq.Workplane().box(30, 20, 10).edges("|Z").fillet(3)
             .faces(">Z").workplane().hole(6)
             .union(cq.Workplane().sphere(4).translate((8, 0, 5)))
             .union(cq.Workplane().cylinder(6, 2).translate((-8, 0, 8)))
             .union(cq.Solid.makeTorus(6, 1.5).translate(cq.Vector(0, 0, -5)))
             .union(cq.Solid.makeCone(3, 1, 4).translate(cq.Vector(-8, 5, 5))))
    path = tmp_path / "analytic.step"
    cq.exporters.export(solid, str(path))
    part = _part(str(path))
    kinds = {f.kind for f in part.faces}
    assert {"plane", "cylinder", "sphere", "torus", "cone"} <= kinds
    assert _occ_deviation(part, 6, seed=9) < 1e-9
