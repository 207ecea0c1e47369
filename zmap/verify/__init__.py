"""Stock against design: deviation, gouge / excess regions, first offending line, collisions.

``from zmap.verify import compare`` works; submodules load on first use, so ``import
zmap.verify`` compiles nothing.
"""

from __future__ import annotations

from .._lazy import attach


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


__getattr__, __dir__ = attach(__name__, _WHERE)
