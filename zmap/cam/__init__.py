"""CAM from the design model: drop-cutter CL surfaces and raster finishing programs.

``from zmap.cam import drop_cutter`` works; submodules load on first use.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["drop_cutter", "raster_program", "RasterProgram", "scallop_height"]

_WHERE = {"drop_cutter": "drop", "raster_program": "raster", "RasterProgram": "raster",
          "scallop_height": "raster"}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module 'zmap.cam' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
