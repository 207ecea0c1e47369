"""zmap.mesh.triangulate: grids to triangle meshes, open and closed (paper 003)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zmap import ZMap
from zmap.mesh import TriMesh, triangulate


def _random_map(seed: int, nx: int = 9, ny: int = 7, holes: float = 0.2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    z = rng.uniform(-3.0, 5.0, (nx, ny))
    z[rng.random((nx, ny)) < holes] = np.nan
    return z


def _prism_reference(z: np.ndarray, dx: float, dy: float, bottom: float) -> tuple[float, float, int]:
    """Brute force: per valid cell, the two triangles' prism volumes and top areas."""
    vol = area = 0.0
    cells = 0
    nx, ny = z.shape
    for i in range(nx - 1):
        for j in range(ny - 1):
            a = np.array([0.0, 0.0, z[i, j]])
            b = np.array([dx, 0.0, z[i + 1, j]])
            c = np.array([dx, dy, z[i + 1, j + 1]])
            d = np.array([0.0, dy, z[i, j + 1]])
            if np.isnan([a[2], b[2], c[2], d[2]]).any():
                continue
            cells += 1
            for p, q, r in ((a, b, c), (a, c, d)):
                vol += 0.5 * dx * dy * ((p[2] + q[2] + r[2]) / 3.0 - bottom)
                area += 0.5 * float(np.linalg.norm(np.cross(q - p, r - p)))
    return vol, area, cells


# ---- open meshes ---------------------------------------------------------------------------


def test_faces_per_cell_diagonal_and_orientation():
    z = np.arange(12, dtype=float).reshape(3, 4) * 0.1
    m = triangulate(z, grid=(1.0, 2.0, 0.5, 0.25))
    assert (m.n_vertices, m.n_faces) == (12, 12)
    assert m.faces.dtype == np.int32 and m.vertices.dtype == np.float64
    # cell (0, 0): nodes a=(0,0)=0, b=(1,0)=4, c=(1,1)=5, d=(0,1)=1; diagonal a-c
    assert m.faces[:2].tolist() == [[0, 4, 5], [0, 5, 1]]
    v = m.vertices
    n = np.cross(v[m.faces[:, 1]] - v[m.faces[:, 0]], v[m.faces[:, 2]] - v[m.faces[:, 0]])
    assert (n[:, 2] > 0).all()  # counter-clockwise seen from +z
    X, Y = np.meshgrid(1.0 + 0.5 * np.arange(3), 2.0 + 0.25 * np.arange(4), indexing="ij")
    assert np.array_equal(v, np.column_stack([X.ravel(), Y.ravel(), z.ravel()]))


@pytest.mark.parametrize("seed", range(4))
def test_random_open_mesh_against_brute_force(seed):
    z = _random_map(seed)
    m = triangulate(z, grid=(-2.0, 3.0, 0.7, 1.3))
    vol, area, cells = _prism_reference(z, 0.7, 1.3, 0.0)
    assert m.n_faces == 2 * cells
    assert m.area() == pytest.approx(area, rel=1e-12)
    # no duplicate vertex, and every vertex used by a face
    assert len(np.unique(m.vertices, axis=0)) == m.n_vertices
    assert np.array_equal(np.unique(m.faces), np.arange(m.n_vertices))
    assert np.isfinite(m.vertices).all()
    assert not m.is_watertight() or m.n_faces == 0


def test_zmap_local_frame_is_applied():
    zm = ZMap(1.0, -2.0, 0.5, 0.75, _random_map(7, 5, 6, holes=0.0), angle=0.3, origin=(10.0, 20.0))
    m = triangulate(zm)
    X, Y = zm.grid_points()
    assert np.allclose(m.vertices[:, 0], X.ravel(), atol=1e-12)
    assert np.allclose(m.vertices[:, 1], Y.ravel(), atol=1e-12)
    # a rotation keeps areas and volumes
    plain = triangulate(zm.z, grid=(zm.x0, zm.y0, zm.dx, zm.dy), closed=True, bottom=-10.0)
    rotated = triangulate(zm, closed=True, bottom=-10.0)
    assert rotated.volume() == pytest.approx(plain.volume(), rel=1e-12)
    assert rotated.area() == pytest.approx(plain.area(), rel=1e-12)


def test_point_data_and_pyvista():
    z = _random_map(3, 5, 4)
    dev = np.arange(20, dtype=float).reshape(5, 4)
    m = triangulate(z, grid=(0, 0, 1, 1), point_data={"deviation": dev})
    nodes = np.round(m.vertices[:, 0]).astype(int) * 4 + np.round(m.vertices[:, 1]).astype(int)
    assert np.array_equal(m.point_data["deviation"], dev.ravel()[nodes])
    pd = m.to_pyvista()
    assert (pd.n_points, pd.n_cells) == (m.n_vertices, m.n_faces)
    assert np.array_equal(pd.point_data["height"], m.vertices[:, 2])
    assert np.array_equal(pd.point_data["deviation"], m.point_data["deviation"])
    assert np.array_equal(pd.regular_faces, m.faces)
    closed = triangulate(z, grid=(0, 0, 1, 1), closed=True, point_data={"deviation": dev})
    n = m.n_vertices
    assert np.array_equal(closed.point_data["deviation"][:n], m.point_data["deviation"])
    assert np.isnan(closed.point_data["deviation"][n:]).all()


def test_mesh_is_read_only_and_reports_sizes():
    m = triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1))
    with pytest.raises(ValueError):
        m.vertices[0, 0] = 1.0
    with pytest.raises(AttributeError):
        m.faces = m.faces  # type: ignore[misc]
    assert m.nbytes == 9 * 24 + 8 * 12
    assert "n_faces=8" in repr(m)


# ---- closed meshes -------------------------------------------------------------------------


@pytest.mark.parametrize("shape,dx,dy,h", [((2, 2), 1.0, 1.0, 3.0), ((6, 4), 0.3, 0.7, 2.5),
                                           ((11, 13), 0.26, 0.26, 12.0)])
def test_constant_height_volume_is_area_times_height(shape, dx, dy, h):
    m = triangulate(np.full(shape, h), grid=(-5.0, 7.0, dx, dy), closed=True, bottom=0.0)
    assert m.is_watertight()
    area = (shape[0] - 1) * dx * (shape[1] - 1) * dy
    assert m.volume() == pytest.approx(area * h, rel=1e-13, abs=0)
    top = triangulate(np.full(shape, h), grid=(-5.0, 7.0, dx, dy))
    side = 2 * ((shape[0] - 1) * dx + (shape[1] - 1) * dy) * h
    assert m.area() == pytest.approx(2 * top.area() + side, rel=1e-13)


@pytest.mark.parametrize("seed", range(6))
def test_random_closed_mesh_is_watertight_with_prism_volume(seed):
    z = _random_map(seed, 10, 8, holes=0.25)
    m = triangulate(z, grid=(1.0, -1.0, 0.6, 0.4), closed=True, bottom=-4.0)
    vol, _, cells = _prism_reference(z, 0.6, 0.4, -4.0)
    assert m.is_watertight()
    assert m.volume() == pytest.approx(vol, rel=1e-12, abs=1e-12)
    assert m.bounds()[2] == -4.0
    # one wall quad per boundary edge of the open top (edges whose reverse no face uses)
    top = triangulate(z, grid=(1.0, -1.0, 0.6, 0.4))
    directed = set(map(tuple, top.edges().tolist()))
    boundary = sum((v, u) not in directed for u, v in directed)
    assert m.n_faces == 2 * top.n_faces + 2 * boundary
    # the bottom cap faces down
    v, f = m.vertices, m.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    at_bottom = (v[f][:, :, 2] == -4.0).all(axis=1)
    assert at_bottom.sum() == 2 * cells and (n[at_bottom, 2] < 0).all()


def test_holes_and_corner_contacts_stay_watertight():
    z = np.ones((7, 7))
    z[3, 3] = np.nan                        # a hole: four cells out, walls around it
    m = triangulate(z, grid=(0, 0, 1, 1), closed=True, bottom=0.0)
    assert m.is_watertight() and m.volume() == pytest.approx(36.0 - 4.0)
    both = np.full((3, 3), 2.0)
    both[0, 2] = both[2, 0] = np.nan        # cells (0, 0) and (1, 1) share only node (1, 1)
    other = np.full((3, 3), 2.0)
    other[0, 0] = other[2, 2] = np.nan      # cells (1, 0) and (0, 1) share only node (1, 1)
    for zz in (both, other):
        s = triangulate(zz, grid=(0, 0, 1, 1), closed=True, bottom=0.0)
        assert s.is_watertight()
        assert s.volume() == pytest.approx(4.0, rel=1e-12)    # two 1x1 cells, 2 mm high
        assert s.n_vertices == 2 * 8                          # 7 nodes, one doubled; top and bottom
        assert len(np.unique(s.vertices, axis=0)) == 14
        assert triangulate(zz, grid=(0, 0, 1, 1)).n_vertices == 7   # the open top shares it


def test_default_bottom_is_one_below_the_lowest_height():
    z = _random_map(11, 5, 5, holes=0.0)
    m = triangulate(z, grid=(0, 0, 1, 1), closed=True)
    assert m.bounds()[2] == pytest.approx(np.min(z) - 1.0)


def test_is_watertight_detects_flips_and_open_edges():
    m = triangulate(np.ones((4, 3)), grid=(0, 0, 1, 1), closed=True)
    assert m.is_watertight()
    flipped = m.faces.copy()
    flipped[0] = flipped[0, ::-1]
    assert not TriMesh(m.vertices, flipped).is_watertight()
    assert not TriMesh(m.vertices, m.faces[1:]).is_watertight()
    assert TriMesh(m.vertices, m.faces).volume() == pytest.approx(6.0 * 1.0)
    assert TriMesh(m.vertices, m.faces[:, ::-1]).volume() == pytest.approx(-6.0)


# ---- workpieces ----------------------------------------------------------------------------


def test_heightfield_and_dexel_sources():
    from zmap.sim.dexel import DexelWorkpiece
    from zmap.sim.heightfield import HeightField

    zm = ZMap(0.0, 0.0, 0.5, 0.5, _random_map(5, 6, 5, holes=0.0))
    hf = HeightField(zm)
    hf.z[2, 2] = -9.0
    m = triangulate(hf)
    assert m.vertices[2 * 5 + 2, 2] == -9.0
    wp = DexelWorkpiece.from_box((1.0, 2.0, -5.0, 3.0, 3.0, 0.0), pitch=0.5)
    s = triangulate(wp, closed=True)        # default bottom: the stock bottom
    assert s.is_watertight()
    assert s.bounds() == (1.0, 2.0, -5.0, 3.0, 3.0, 0.0)
    assert s.volume() == pytest.approx(2.0 * 1.0 * 5.0, rel=1e-13)


def test_simulated_stock_is_a_watertight_solid_with_the_right_volume():
    from zmap.sim import simulate

    # a pocket, a ramp, and a plunge through the stock bottom (empty rays: a hole with walls)
    program = "G21 G90\nG0 X1 Y1 Z2\nG1 Z-1 F100\nG1 X7\nG1 Y4 Z-2\nG1 X2\nG1 Z-4\nG0 Z5\nM2\n"
    box = (0.0, 0.0, -3.0, 8.0, 5.0, 0.0)
    run = simulate(program, box, tool="flat:1.5", pitch=0.25, history="treap")
    wp = run.reconstruct(run.stage("1/1"))
    m = triangulate(wp, closed=True)
    assert m.is_watertight()
    assert m.n_faces > 0 and m.bounds()[2] == -3.0
    # stock volume minus the removed volume, from the dexel heights (linear over each triangle)
    top = wp.top()
    removed = 0.0
    for i in range(wp.nx - 1):
        for j in range(wp.ny - 1):
            a, b, c, d = top[i, j], top[i + 1, j], top[i + 1, j + 1], top[i, j + 1]
            if np.isnan([a, b, c, d]).any():    # a cell with an empty ray is left out
                removed += 0.25 ** 2 * 3.0
                continue
            removed += 0.5 * 0.25 ** 2 * ((0.0 - (a + b + c) / 3.0) + (0.0 - (a + c + d) / 3.0))
    stock = (wp.nx - 1) * 0.25 * (wp.ny - 1) * 0.25 * 3.0
    assert removed > 1.0 and np.isnan(top).any()
    assert m.volume() == pytest.approx(stock - removed, rel=1e-12)


# ---- bad input -----------------------------------------------------------------------------


def test_all_nan_gives_an_empty_mesh():
    for closed in (False, True):
        m = triangulate(np.full((4, 5), np.nan), grid=(0, 0, 1, 1), closed=closed)
        assert (m.n_vertices, m.n_faces) == (0, 0)
        assert m.vertices.shape == (0, 3) and m.faces.shape == (0, 3)
        assert m.area() == 0.0 and m.volume() == 0.0 and m.is_watertight()
        assert all(math.isnan(b) for b in m.bounds())
    assert triangulate(np.ones((1, 5)), grid=(0, 0, 1, 1)).n_faces == 0


def test_bad_input_names_what_arrived():
    with pytest.raises(ValueError, match=r"2D array .* got shape \(3, 3, 3\)"):
        triangulate(np.zeros((3, 3, 3)), grid=(0, 0, 1, 1))
    with pytest.raises(TypeError, match="builtins.str"):
        triangulate("heights.npz")
    with pytest.raises(TypeError, match="dtype <U1"):
        triangulate(np.array([["a", "b"], ["c", "d"]]), grid=(0, 0, 1, 1))
    with pytest.raises(ValueError, match="needs grid"):
        triangulate(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="grid is taken from the ZMap"):
        triangulate(ZMap(0, 0, 1, 1, np.zeros((2, 2))), grid=(0, 0, 1, 1))
    with pytest.raises(ValueError, match=r"positive, got dx=0.0"):
        triangulate(np.zeros((3, 3)), grid=(0, 0, 0, 1))
    with pytest.raises(ValueError, match="4 finite numbers"):
        triangulate(np.zeros((3, 3)), grid=(0, 0, 1))
    with pytest.raises(ValueError, match="infinite"):
        triangulate(np.array([[0.0, np.inf], [0.0, 0.0]]), grid=(0, 0, 1, 1))
    with pytest.raises(ValueError, match=r"'deviation' must have the grid's shape \(3, 3\), got \(2, 2\)"):
        triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1), point_data={"deviation": np.zeros((2, 2))})
    with pytest.raises(ValueError, match="bottom=1.0 is above the lowest height 0.0"):
        triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1), closed=True, bottom=1.0)
    with pytest.raises(ValueError, match="bottom must be finite"):
        triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1), closed=True, bottom=np.nan)
    with pytest.raises(ValueError, match=r"shape \(n, 3\), got shape \(4, 2\)"):
        TriMesh(np.zeros((4, 2)), np.zeros((0, 3), int))
    with pytest.raises(ValueError, match=r"indices 0\.\.7"):
        TriMesh(np.zeros((4, 3)), np.array([[0, 1, 7]]))
    with pytest.raises(ValueError, match=r"point_data 'h' must have shape \(4,\), got \(3,\)"):
        TriMesh(np.zeros((4, 3)), np.array([[0, 1, 2]]), {"h": np.zeros(3)})
