"""zmap.mesh.export: STL, PLY, VTP and glTF writers, read back with numpy and pyvista."""

from __future__ import annotations

import base64
import json
import os

import numpy as np
import pytest

from zmap.errors import ZMapFileError
from zmap.mesh import TriMesh, triangulate, write_gltf, write_ply, write_stl, write_vtp


@pytest.fixture(scope="module")
def mesh() -> TriMesh:
    rng = np.random.default_rng(42)
    z = rng.uniform(-1.0, 2.0, (8, 6))
    z[3:5, 2:4] = np.nan
    dev = rng.normal(0.0, 0.01, z.shape)
    return triangulate(z, grid=(10.0, -5.0, 0.5, 0.8), closed=True, bottom=-3.0,
                       point_data={"deviation": dev})


def _read_binary_stl(path) -> tuple[bytes, np.ndarray, np.ndarray]:
    raw = open(path, "rb").read()
    n = int(np.frombuffer(raw, "<u4", 1, 80)[0])
    rec = np.frombuffer(raw, np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")]), n, 84)
    assert len(raw) == 84 + 50 * n
    return raw[:80], rec["n"], rec["v"]


def _read_ascii_stl(path) -> tuple[np.ndarray, np.ndarray]:
    lines = [ln.split() for ln in open(path).read().splitlines()]
    assert lines[0][0] == "solid" and lines[-1][0] == "endsolid"
    normals = np.array([ln[2:] for ln in lines if ln[0] == "facet"], dtype=float)
    verts = np.array([ln[1:] for ln in lines if ln[0] == "vertex"], dtype=float).reshape(-1, 3, 3)
    return normals, verts


def _faces_from_triangles(tri: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Vertex indices of STL triangles, looked up among ``vertices`` (all distinct here)."""
    order = np.lexsort(vertices.T[::-1])
    keys = vertices[order]
    flat = tri.reshape(-1, 3)
    idx = np.empty(len(flat), dtype=np.int64)
    for k, p in enumerate(flat):
        hit = np.flatnonzero((keys == p).all(axis=1))
        assert len(hit) == 1
        idx[k] = order[hit[0]]
    return idx.reshape(-1, 3)


def _distinct(m: TriMesh) -> TriMesh:
    """The mesh without doubled corner vertices, so that coordinates identify a vertex."""
    assert len(np.unique(m.vertices, axis=0)) == m.n_vertices
    return m


def test_binary_stl_round_trip(mesh, tmp_path):
    p = write_stl(_distinct(mesh), tmp_path / "part.stl")
    header, normals, tri = _read_binary_stl(p)
    assert not header.lower().startswith(b"solid")
    assert np.array_equal(tri, mesh.vertices[mesh.faces].astype(np.float32))
    v32 = mesh.vertices.astype(np.float32)
    assert np.array_equal(_faces_from_triangles(tri, v32), mesh.faces)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
    import pyvista as pv
    back = pv.read(p)                 # VTK merges the repeated corners again
    assert (back.n_points, back.n_cells) == (mesh.n_vertices, mesh.n_faces)
    assert np.allclose(np.sort(back.points, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-5)
    assert back.volume == pytest.approx(mesh.volume(), rel=1e-5)


def test_ascii_stl_round_trip_is_exact(mesh, tmp_path):
    p = write_stl(mesh, tmp_path / "part.stl", binary=False, name="stock")
    normals, tri = _read_ascii_stl(p)
    assert np.array_equal(tri, mesh.vertices[mesh.faces])  # 17 digits: exact float64
    assert np.array_equal(_faces_from_triangles(tri, mesh.vertices), mesh.faces)
    v = mesh.vertices[mesh.faces]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    assert np.allclose(normals, n / np.linalg.norm(n, axis=1)[:, None], atol=1e-15)
    assert open(p).readline() == "solid stock\n"


def _read_ply(path) -> tuple[list[str], np.ndarray, np.ndarray]:
    raw = open(path, "rb").read()
    head, body = raw.split(b"end_header\n", 1)
    lines = head.decode("ascii").splitlines()
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    types = {"double": "<f8", "float": "<f4", "int": "<i4", "uchar": "u1"}
    vfields, nv, nf = [], 0, 0
    for ln in lines:
        w = ln.split()
        if w[:2] == ["element", "vertex"]:
            nv = int(w[2])
        elif w[:2] == ["element", "face"]:
            nf = int(w[2])
        elif w[0] == "property" and w[1] != "list":
            vfields.append((w[2], types[w[1]]))
    vdt = np.dtype(vfields)
    vrec = np.frombuffer(body, vdt, nv)
    frec = np.frombuffer(body, np.dtype([("n", "u1"), ("v", "<i4", (3,))]), nf, nv * vdt.itemsize)
    assert len(body) == nv * vdt.itemsize + nf * 13 and (frec["n"] == 3).all()
    return [f for f, _ in vfields], vrec, frec["v"]


def test_ply_round_trip_with_point_scalars(mesh, tmp_path):
    p = write_ply(mesh, tmp_path / "part.ply")
    names, vrec, faces = _read_ply(p)
    assert names == ["x", "y", "z", "deviation"]
    assert np.array_equal(np.column_stack([vrec["x"], vrec["y"], vrec["z"]]), mesh.vertices)
    assert np.array_equal(faces, mesh.faces)
    assert np.array_equal(vrec["deviation"], mesh.point_data["deviation"], equal_nan=True)
    import pyvista as pv
    back = pv.read(p)
    assert np.allclose(back.points, mesh.vertices, atol=1e-5)
    assert np.array_equal(back.regular_faces, mesh.faces)


def test_ply_point_data_types(tmp_path):
    m = TriMesh(np.eye(3), np.array([[0, 1, 2]]),
                {"flag": np.array([True, False, True]), "id": np.arange(3, dtype=np.int64),
                 "w": np.ones(3, np.float32)})
    names, vrec, faces = _read_ply(write_ply(m, tmp_path / "t.ply"))
    head = open(tmp_path / "t.ply", "rb").read().split(b"end_header")[0].decode()
    assert "property uchar flag" in head and "property double id" in head and "property float w" in head
    assert vrec["flag"].tolist() == [1, 0, 1] and vrec["id"].tolist() == [0.0, 1.0, 2.0]
    with pytest.raises(ValueError, match="'bad name'"):
        write_ply(TriMesh(np.eye(3), np.array([[0, 1, 2]]), {"bad name": np.ones(3)}), tmp_path / "u.ply")
    assert not (tmp_path / "u.ply").exists()


def test_vtp_round_trip(mesh, tmp_path):
    import pyvista as pv
    p = write_vtp(mesh, tmp_path / "part.vtp")
    back = pv.read(p)
    assert np.array_equal(back.points, mesh.vertices)
    assert np.array_equal(back.regular_faces, mesh.faces)
    assert np.array_equal(back.point_data["height"], mesh.vertices[:, 2])
    assert np.array_equal(back.point_data["deviation"], mesh.point_data["deviation"], equal_nan=True)


def test_gltf_positions_and_indices(mesh, tmp_path):
    p = write_gltf(mesh, tmp_path / "part.gltf")
    doc = json.load(open(p))
    prim = doc["meshes"][0]["primitives"][0]

    def accessor(k: int) -> np.ndarray:
        acc = doc["accessors"][k]
        view = doc["bufferViews"][acc["bufferView"]]
        uri = doc["buffers"][view["buffer"]]["uri"]
        data = base64.b64decode(uri.split(",", 1)[1])[view.get("byteOffset", 0):][acc.get("byteOffset", 0):]
        dt = {5126: "<f4", 5125: "<u4"}[acc["componentType"]]
        width = {"VEC3": 3, "VEC2": 2, "SCALAR": 1}[acc["type"]]
        return np.frombuffer(data, dt, acc["count"] * width).reshape(acc["count"], width)

    pos = accessor(prim["attributes"]["POSITION"])
    idx = accessor(prim["indices"]).reshape(-1, 3)
    assert np.array_equal(pos, mesh.vertices.astype(np.float32))
    assert np.array_equal(idx, mesh.faces)


def test_every_writer_on_an_empty_mesh(tmp_path):
    empty = triangulate(np.full((3, 3), np.nan), grid=(0, 0, 1, 1), closed=True)
    for write, ext in ((write_stl, "stl"), (write_ply, "ply"), (write_vtp, "vtp"), (write_gltf, "gltf")):
        assert write(empty, tmp_path / f"e.{ext}").stat().st_size > 0
    assert _read_binary_stl(tmp_path / "e.stl")[2].shape == (0, 3, 3)


def test_failures_name_the_file_and_leave_nothing_behind(mesh, tmp_path, monkeypatch):
    target = tmp_path / "a_folder.stl"
    target.mkdir()
    for write in (write_stl, write_ply, write_vtp):
        with pytest.raises(ZMapFileError, match="a_folder.stl: cannot write"):
            write(mesh, target)
    old = tmp_path / "old.vtp"
    old.write_bytes(b"previous")
    import pyvista as pv

    def broken(self, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pv.PolyData, "save", broken)
    with pytest.raises(ZMapFileError, match="old.vtp: cannot write VTP: No space left on device"):
        write_vtp(mesh, old)
    assert old.read_bytes() == b"previous"
    assert sorted(os.listdir(tmp_path)) == ["a_folder.stl", "old.vtp"]
    with pytest.raises(TypeError, match="TriMesh, got numpy.ndarray"):
        write_stl(np.zeros((3, 3)), tmp_path / "x.stl")


@pytest.mark.slow
def test_simulated_stock_exports_as_a_closed_solid(tmp_path):
    from zmap.sim import simulate

    run = simulate("G0 X1 Y1 Z1\nG1 Z-1 F100\nG1 X5 Y3\nM2\n", (0, 0, -2, 6, 4, 0), tool="ball:2", pitch=0.25)
    solid = triangulate(run.reconstruct(run.stage("1/1")), closed=True)
    assert solid.is_watertight()
    _, _, tri = _read_binary_stl(write_stl(solid, tmp_path / "stock.stl"))
    tri = tri.astype(np.float64)
    vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    assert vol == pytest.approx(solid.volume(), rel=1e-6)
    assert vol < 6 * 4 * 2 - 1.0


def _accessor(doc: dict, k: int) -> np.ndarray:
    acc = doc["accessors"][k]
    view = doc["bufferViews"][acc["bufferView"]]
    uri = doc["buffers"][view["buffer"]]["uri"]
    data = base64.b64decode(uri.split(",", 1)[1])[view.get("byteOffset", 0):][acc.get("byteOffset", 0):]
    dt = {5126: "<f4", 5125: "<u4"}[acc["componentType"]]
    width = {"VEC3": 3, "VEC2": 2, "SCALAR": 1}[acc["type"]]
    return np.frombuffer(data, dt, acc["count"] * width).reshape(acc["count"], width)


def test_gltf_colours_follow_the_deviation(tmp_path):
    """glTF carries a scalar as a colour-map texture: each vertex's texture coordinate is its
    deviation mapped linearly onto the symmetric range (-max |d|, max |d|), so a deviation of
    0 sits in the middle of the (diverging) map, at its white."""
    dev = np.linspace(-0.2, 0.05, 20).reshape(4, 5)
    m = triangulate(np.zeros((4, 5)), grid=(0, 0, 1, 1), point_data={"deviation": dev})
    doc = json.load(open(write_gltf(m, tmp_path / "dev.gltf")))
    prim = doc["meshes"][0]["primitives"][0]
    u = _accessor(doc, prim["attributes"]["TEXCOORD_0"])[:, 0]
    d = m.point_data["deviation"]
    slope, mid = np.polyfit(d, u, 1)  # u = mid + slope * d
    assert slope > 0 and np.allclose(u, mid + slope * d, atol=1e-5)
    assert abs(mid - 0.5) < 0.01 and abs(slope * 0.4 - 1) < 0.02
    doc_h = json.load(open(write_gltf(m, tmp_path / "h.gltf", scalars="height")))
    assert doc_h["meshes"][0]["primitives"][0]["attributes"].keys() >= {"POSITION"}
    with pytest.raises(ValueError, match="scalars='depth'"):
        write_gltf(m, tmp_path / "x.gltf", scalars="depth")
