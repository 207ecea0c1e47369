"""NC cutting simulation on z-map workpieces with full history (papers 000 and 001).

``from zmap.sim import simulate, parse, Cutter`` works; submodules load on first use so
``import zmap.sim`` compiles nothing.
"""

from __future__ import annotations

from .._lazy import attach


__all__ = ["simulate", "Run", "parse", "Program", "Cutter", "parse_tool_spec", "load_tool_table",
           "positions", "Positions", "DexelWorkpiece", "HeightField"]

_WHERE = {
    "simulate": "session", "Run": "session",
    "parse": "gcode", "Program": "gcode",
    "Cutter": "tools", "parse_tool_spec": "tools", "load_tool_table": "tools",
    "positions": "path", "Positions": "path",
    "DexelWorkpiece": "dexel", "HeightField": "heightfield",
}


__getattr__, __dir__ = attach(__name__, _WHERE)
