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

from zmap._lazy import attach

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

_LAZY = {"read_step": "step", "from_geomdl": "geomdl_io", "sample": "sampler", "triangulate": "mesh"}

__getattr__, __dir__ = attach(__name__, _LAZY)
