"""Meshes of z-maps and workpieces: triangulation, export, local decimation (paper 003).

``from zmap.mesh import triangulate, TriMesh, write_stl`` works; submodules load on first
use, so ``import zmap.mesh`` imports neither pyvista nor numba.

The functions ``triangulate`` and ``decimate`` share their names with the modules that
hold them; the package keeps the function under that name even after the module has
been imported (``from zmap.mesh.triangulate import ...`` reaches the module).
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any

_WHERE = {
    # triangulation and export (zmap/mesh/triangulate.py, zmap/mesh/export.py)
    "TriMesh": "triangulate", "triangulate": "triangulate",
    "write_stl": "export", "write_ply": "export", "write_vtp": "export", "write_gltf": "export",
    # --- local decimation (zmap/mesh/decimate.py, zmap/mesh/local.py): the other helper's names go here ---
    "LocalMesh": "local", "decimate": "decimate", "refine_region": "decimate", "max_error": "decimate",
    "decimate_pro": "decimate", "crack_rays": "decimate",
    # --- end of local decimation ---
}

__all__ = list(_WHERE)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'zmap.mesh' has no attribute {name!r}")


class _Package(types.ModuleType):
    """The package module: importing submodule ``triangulate`` must not hide function ``triangulate``."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _WHERE.get(name) == name:
            return  # the import system binding the submodule: keep the public function's name free
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
