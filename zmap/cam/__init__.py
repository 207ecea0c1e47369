"""CAM from the design model: drop-cutter CL surfaces and raster finishing programs.

``from zmap.cam import drop_cutter`` works; submodules load on first use.
"""

from __future__ import annotations

from .._lazy import attach


__all__ = ["drop_cutter", "raster_program", "RasterProgram", "scallop_height"]

_WHERE = {"drop_cutter": "drop", "raster_program": "raster", "RasterProgram": "raster",
          "scallop_height": "raster"}


__getattr__, __dir__ = attach(__name__, _WHERE)
