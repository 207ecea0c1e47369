"""zmap: precision z-map modelling of die and mould surfaces.

``import zmap`` is light: submodules load on first use, so neither the CAD kernel nor the
JIT compiler starts until a function needs it.
"""

from __future__ import annotations

import importlib
from typing import Any

from .errors import ZMapError
from .grid import ZMap

__version__ = "0.1.0"
__all__ = ["ZMap", "ZMapError", "interpolate", "surfaces", "accuracy", "errors", "sim", "__version__"]

_LAZY_SUBMODULES = {"interpolate", "surfaces", "accuracy", "errors", "sim", "cli", "grid"}


def __getattr__(name: str) -> Any:
    if name in _LAZY_SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'zmap' has no attribute {name!r}")
