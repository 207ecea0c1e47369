"""Everything that touches a CAD kernel: STEP reading, NURBS evaluation, z-map sampling.

The public functions load lazily: ``import cad_io`` imports neither OCP nor numba kernels;
``cad_io.read_step`` does on first use.

Examples
--------
>>> import cad_io
>>> callable(cad_io.from_geomdl)
True
"""

from __future__ import annotations

import importlib
from typing import Any

from cad_io.part import Edge, Face, FaceMesh, NurbsSurface, Part
from cad_io import design as _design  # noqa: F401  (registers Part and .step files with zmap.design)

__all__ = [
    "Edge",
    "Face",
    "FaceMesh",
    "NurbsSurface",
    "Part",
    "from_geomdl",
    "read_step",
    "sample",
    "triangulate",
]

_LAZY = {
    "read_step": "cad_io.step",
    "from_geomdl": "cad_io.geomdl_io",
    "sample": "cad_io.sampler",
    "triangulate": "cad_io.mesh",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'cad_io' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
