"""Meshes of z-maps and workpieces: triangulation, export, local decimation (paper 003).

``from zmap.mesh import triangulate, TriMesh, write_stl`` works; submodules load on first
use, so ``import zmap.mesh`` imports neither pyvista nor numba.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    # triangulation and export (zmap/mesh/triangulate.py, zmap/mesh/export.py)
    "TriMesh": "triangulate", "triangulate": "triangulate",
    "write_stl": "export", "write_ply": "export", "write_vtp": "export", "write_gltf": "export",
    # --- local decimation (zmap/mesh/decimate.py, zmap/mesh/local.py): the other helper's names go here ---
    "LocalMesh": "local", "decimate": "decimate", "refine_region": "local",
    # --- end of local decimation ---
}

__all__ = list(_WHERE)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module 'zmap.mesh' has no attribute {name!r}")
