"""Meshes of z-maps and workpieces: triangulation, export, local decimation (paper 003).

``from zmap.mesh import triangulate, TriMesh, write_stl`` works; submodules load on first
use, so ``import zmap.mesh`` imports neither pyvista nor numba.

The functions ``triangulate`` and ``decimate`` share their names with the modules that
hold them; the package keeps the function under that name even after the module has
been imported (``from zmap.mesh.triangulate import ...`` reaches the module).
"""

from __future__ import annotations

from .._lazy import attach


_WHERE = {
    # triangulation and export (zmap/mesh/triangulate.py, zmap/mesh/export.py)
    "TriMesh": "triangulate", "triangulate": "triangulate",
    "write_stl": "export", "write_ply": "export", "write_vtp": "export", "write_gltf": "export",
    # local decimation (zmap/mesh/decimate.py, zmap/mesh/local.py)
    "LocalMesh": "local", "decimate": "decimate", "refine_region": "decimate", "max_error": "decimate",
    "decimate_pro": "decimate", "crack_rays": "decimate",
}

__all__ = list(_WHERE)

__getattr__, __dir__ = attach(__name__, _WHERE)  # keeps triangulate and decimate the functions
