"""Write a :class:`~zmap.mesh.triangulate.TriMesh` to STL, PLY, VTP or glTF.

STL (binary or ASCII) and PLY (binary little endian, with the point scalars) are written
with numpy alone; VTP and glTF go through pyvista, imported when called. Every writer
writes a temporary file beside the target and renames it, so no half-written file is ever
left; a failure raises :class:`zmap.errors.ZMapFileError` naming the file.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .._npzfile import atomic_write
from ..errors import ZMapFileError
from .triangulate import TriMesh

__all__ = ["write_stl", "write_ply", "write_vtp", "write_gltf"]

_PLY_TYPES = {
    np.dtype(np.int8): "char", np.dtype(np.uint8): "uchar", np.dtype(np.int16): "short",
    np.dtype(np.uint16): "ushort", np.dtype(np.int32): "int", np.dtype(np.uint32): "uint",
    np.dtype(np.float32): "float", np.dtype(np.float64): "double",
}


def _check_mesh(mesh: Any, func: str) -> TriMesh:
    if not isinstance(mesh, TriMesh):
        raise TypeError(f"{func} takes a zmap.mesh.TriMesh, got {type(mesh).__module__}.{type(mesh).__qualname__}")
    return mesh


def _write(path: str | os.PathLike, what: str, write: Callable[[str], None], suffix: str = "") -> Path:
    """atomic_write, with OS errors turned into a ZMapFileError naming ``path``."""
    try:
        return atomic_write(path, write, suffix=suffix)
    except OSError as err:
        raise ZMapFileError(str(path), f"cannot write {what}: {err.strerror or err}") from err


def _pyvista(func: str, path: Any) -> Any:
    try:
        import pyvista as pv
    except ImportError as err:
        raise ImportError(f"{func} needs pyvista to write {path} (pip install pyvista)") from err
    return pv


def _face_normals(mesh: TriMesh) -> np.ndarray:
    """Unit normals of the faces, shape (m, 3), float64; zero for a degenerate triangle."""
    v, f = mesh.vertices, mesh.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1)
    ok = length > 0
    n[ok] /= length[ok, None]
    n[~ok] = 0.0
    return n


def write_stl(mesh: TriMesh, path: str | os.PathLike, *, binary: bool = True, name: str = "zmap") -> Path:
    """Write an STL file, binary (float32, the usual) or ASCII (17 significant digits).

    Parameters
    ----------
    mesh : TriMesh
        The mesh; STL repeats each face's three vertices and adds its unit normal.
    path : str or PathLike
        Target file, written through a temporary name.
    binary : bool, keyword-only
        Binary STL (80-byte header, uint32 count, 50 bytes a face) or ASCII.
    name : str, keyword-only
        Solid name (ASCII) or header text (binary), ASCII only.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ZMapFileError
        The file cannot be written (the message names it).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from zmap.mesh import triangulate
    >>> m = triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1))
    >>> p = write_stl(m, os.path.join(tempfile.mkdtemp(), "flat.stl"))
    >>> os.path.getsize(p) == 84 + 50 * m.n_faces
    True
    """
    mesh = _check_mesh(mesh, "write_stl")
    if not name.isascii() or "\n" in name:
        raise ValueError(f"name must be one line of ASCII text, got {name!r}")
    if mesh.n_faces > np.iinfo(np.uint32).max:
        raise ValueError(f"binary STL holds at most {np.iinfo(np.uint32).max} faces, got {mesh.n_faces}")
    normals = _face_normals(mesh)
    tri = mesh.vertices[mesh.faces]  # (m, 3, 3)

    if binary:
        rec = np.zeros(mesh.n_faces, dtype=np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")]))
        rec["n"] = normals
        rec["v"] = tri
        header = name.encode("ascii")[:80].ljust(80, b" ")
        if header.lower().startswith(b"solid"):  # some readers take such a header for ASCII
            header = (b"zmap " + header)[:80]

        def write(tmp: str) -> None:
            with open(tmp, "wb") as fh:
                fh.write(header)
                fh.write(np.uint32(mesh.n_faces).tobytes())
                fh.write(rec.tobytes())
    else:
        data = np.concatenate([normals[:, None, :], tri], axis=1).reshape(len(tri), 12)
        facet = ("facet normal %.17g %.17g %.17g\n  outer loop\n"
                 + "    vertex %.17g %.17g %.17g\n" * 3 + "  endloop\nendfacet\n")

        def write(tmp: str) -> None:
            with open(tmp, "w", encoding="ascii", newline="\n") as fh:
                fh.write(f"solid {name}\n")
                for start in range(0, len(data), 65536):
                    chunk = data[start:start + 65536]
                    fh.write((facet * len(chunk)) % tuple(chunk.ravel().tolist()))
                fh.write(f"endsolid {name}\n")

    return _write(path, "STL", write)


def write_ply(mesh: TriMesh, path: str | os.PathLike) -> Path:
    """Write a binary little-endian PLY file with the point data as vertex properties.

    Vertices are ``double x, y, z`` (exact), faces ``list uchar int vertex_indices``; each
    point scalar becomes a vertex property of its name (float32/float64/int8-32/uint8-32
    as they are, bool as uchar, 64-bit integers as double).

    Parameters
    ----------
    mesh : TriMesh
    path : str or PathLike
        Target file, written through a temporary name.

    Returns
    -------
    Path

    Raises
    ------
    ZMapFileError
        The file cannot be written (the message names it).
    ValueError
        A point-data name that PLY cannot hold (empty or with white space).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from zmap.mesh import triangulate
    >>> m = triangulate(np.zeros((2, 2)), grid=(0, 0, 1, 1), point_data={"deviation": np.ones((2, 2))})
    >>> p = write_ply(m, os.path.join(tempfile.mkdtemp(), "flat.ply"))
    >>> open(p, "rb").read().split(b"end_header")[0].decode().splitlines()[4:8]
    ['property double x', 'property double y', 'property double z', 'property double deviation']
    """
    mesh = _check_mesh(mesh, "write_ply")
    fields: list[tuple[str, Any]] = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    props = ["property double x", "property double y", "property double z"]
    values = {}
    for pname, arr in mesh.point_data.items():
        if not pname or any(ch.isspace() for ch in pname) or not pname.isascii() or pname in ("x", "y", "z"):
            raise ValueError(f"point data name {pname!r} cannot be a PLY property (ASCII, no spaces, not x/y/z)")
        if arr.dtype == np.bool_:
            arr = arr.astype(np.uint8)
        elif arr.dtype not in _PLY_TYPES:
            arr = arr.astype(np.float64)
        dt = arr.dtype.newbyteorder("<")
        fields.append((pname, dt))
        props.append(f"property {_PLY_TYPES[arr.dtype]} {pname}")
        values[pname] = arr
    vrec = np.empty(mesh.n_vertices, dtype=np.dtype(fields))
    vrec["x"], vrec["y"], vrec["z"] = mesh.vertices.T
    for pname, arr in values.items():
        vrec[pname] = arr
    frec = np.empty(mesh.n_faces, dtype=np.dtype([("n", "u1"), ("v", "<i4", (3,))]))
    frec["n"] = 3
    frec["v"] = mesh.faces
    header = "\n".join(["ply", "format binary_little_endian 1.0", "comment written by zmap",
                        f"element vertex {mesh.n_vertices}", *props,
                        f"element face {mesh.n_faces}", "property list uchar int vertex_indices",
                        "end_header"]) + "\n"

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(header.encode("ascii"))
            fh.write(vrec.tobytes())
            fh.write(frec.tobytes())

    return _write(path, "PLY", write)


def write_vtp(mesh: TriMesh, path: str | os.PathLike) -> Path:
    """Write a VTK XML PolyData file (``.vtp``) through pyvista, with ``height`` and the point data.

    Parameters
    ----------
    mesh : TriMesh
    path : str or PathLike
        Target file, written through a temporary name (any extension; the format is VTP).

    Returns
    -------
    Path

    Raises
    ------
    ZMapFileError
        The file cannot be written (the message names it).
    ImportError
        pyvista is not installed.

    Examples
    --------
    >>> import numpy as np, tempfile, os, pyvista
    >>> from zmap.mesh import triangulate
    >>> m = triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1))
    >>> pyvista.read(write_vtp(m, os.path.join(tempfile.mkdtemp(), "flat.vtp"))).n_cells
    8
    """
    mesh = _check_mesh(mesh, "write_vtp")
    _pyvista("write_vtp", path)
    poly = mesh.to_pyvista()

    def write(tmp: str) -> None:
        poly.save(tmp, binary=True)

    return _write(path, "VTP", write, suffix=".vtp")


def write_gltf(mesh: TriMesh, path: str | os.PathLike, *, scalars: str | None = None) -> Path:
    """Write a glTF 2.0 file (``.gltf``, buffers inline) through ``pyvista.Plotter.export_gltf``.

    The plotter renders off screen (no display needed). Positions are float32 in zmap's
    coordinates, under a node matrix that turns +z into glTF's up axis +y (pyvista's
    ``rotate_scene``). The colours (a colour-map texture, glTF's way of carrying a scalar)
    follow ``scalars``: by default the mesh's ``deviation`` where it has one (diverging
    colours, symmetric about 0), else ``height``.

    Parameters
    ----------
    mesh : TriMesh
    path : str or PathLike
        Target file, written through a temporary name.
    scalars : str, optional
        ``'height'`` or the name of one of the mesh's point scalars.

    Returns
    -------
    Path

    Raises
    ------
    ZMapFileError
        The file cannot be written (the message names it).
    ImportError
        pyvista is not installed.

    Examples
    --------
    >>> import numpy as np, tempfile, os, json
    >>> from zmap.mesh import triangulate
    >>> m = triangulate(np.zeros((3, 3)), grid=(0, 0, 1, 1))
    >>> p = write_gltf(m, os.path.join(tempfile.mkdtemp(), "flat.gltf"))
    >>> json.load(open(p))["asset"]["version"]
    '2.0'
    """
    mesh = _check_mesh(mesh, "write_gltf")
    if scalars is None:
        scalars = "deviation" if "deviation" in mesh.point_data else "height"
    if scalars != "height" and scalars not in mesh.point_data:
        raise ValueError(f"scalars={scalars!r} is not 'height' or one of the mesh's point scalars "
                         f"({', '.join(mesh.point_data) or 'none'})")
    pv = _pyvista("write_gltf", path)
    poly = mesh.to_pyvista()
    style: dict[str, Any] = {"cmap": "viridis"}
    if scalars != "height":
        v = np.asarray(mesh.point_data[scalars], dtype=np.float64)
        m = float(np.nanmax(np.abs(v))) if np.isfinite(v).any() else 0.0
        style = {"cmap": "RdBu_r", "clim": (-m, m) if m > 0 else (-1.0, 1.0), "nan_color": "grey"}

    def write(tmp: str) -> None:
        plotter = pv.Plotter(off_screen=True)
        try:
            if mesh.n_faces:
                plotter.add_mesh(poly, scalars=scalars, show_scalar_bar=False, **style)
            plotter.export_gltf(tmp, inline_data=True)
        finally:
            plotter.close()
        if not os.path.exists(tmp) or os.path.getsize(tmp) == 0:
            raise OSError(f"pyvista wrote no glTF data to {tmp}")

    return _write(path, "glTF", write, suffix=".gltf")
