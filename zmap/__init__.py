"""zmap: precision z-map modelling of die and mould surfaces.

``import zmap`` is light: submodules load on first use, so neither the CAD kernel nor the
JIT compiler starts until a function needs it.
"""

from __future__ import annotations


from ._lazy import attach
from .errors import ZMapError
from .grid import ZMap

__version__ = "0.1.0"
__all__ = ["ZMap", "ZMapError", "interpolate", "surfaces", "accuracy", "errors", "sim", "__version__"]

_LAZY_SUBMODULES = {"interpolate", "surfaces", "accuracy", "errors", "sim", "cli", "grid"}


__getattr__, __dir__ = attach(__name__, submodules=_LAZY_SUBMODULES)
