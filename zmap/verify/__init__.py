"""Stock against design: deviation, gouge / excess regions, first offending line, collisions.

``from zmap.verify import compare`` works; submodules load on first use, so ``import
zmap.verify`` compiles nothing.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["compare", "Comparison", "Region", "first_offending", "design_heights", "load_design",
           "collisions", "Collision", "Holder", "load_holders",
           "write_report", "format_markdown", "regions_csv", "deviation_png", "deviation_3d"]

_WHERE = {
    "compare": "deviation", "Comparison": "deviation", "Region": "deviation", "first_offending": "deviation",
    "design_heights": "deviation", "load_design": "deviation",
    "collisions": "clash", "Collision": "clash", "Holder": "clash", "load_holders": "clash",
    "write_report": "report", "format_markdown": "report", "regions_csv": "report",
    "deviation_png": "report", "deviation_3d": "report",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module 'zmap.verify' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
