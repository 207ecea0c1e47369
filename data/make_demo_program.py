"""Write data/demo_pocket.nc, the bundled program that `make demo` simulates.

A 40 x 30 x 10 mm block (top at z = 0, corner at the origin). Tool 2 (6 mm flat end mill in
data/tools.toml) clears a rounded rectangular pocket 3 mm deep in two 1.5 mm layers of
zigzag, finishing the wall with G2/G3 corner arcs; tool 1 (3 mm ball) cuts a helical
circular groove around a boss and four holes drilled through the block (G81 with G99/G98).

Usage: ``python data/make_demo_program.py [OUT.nc]`` (default: data/demo_pocket.nc).
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["demo_program", "write_demo_program"]


def demo_program() -> str:
    """G-code text of the demo (deterministic)."""
    g = ["%", "(zmap demo: pocket, helical groove and drilled holes in a 40x30x10 block)",
         "G21 G90 G17 G54", "T2 M6 (6 mm flat)", "S9000 M3", "G0 Z5"]
    x0, x1, y0, y1 = 8.0, 32.0, 7.0, 23.0  # tool-centre pocket limits
    for depth in (-1.5, -3.0):
        g.append(f"G0 X{x0:.3f} Y{y0:.3f}")
        g.append(f"G1 Z{depth:.3f} F300")
        y, up = y0, True
        while y <= y1 + 1e-9:
            g.append(f"G1 X{(x1 if up else x0):.3f} Y{y:.3f} F900")
            y += 4.0
            if y <= y1 + 1e-9:
                g.append(f"G1 Y{y:.3f}")
            up = not up
        # wall finish with rounded corners (radius 2 mm about the pocket limits)
        g += [f"G1 X{x0 + 2:.3f} Y{y0:.3f}", f"G1 X{x1 - 2:.3f}",
              f"G3 X{x1:.3f} Y{y0 + 2:.3f} I0 J2", f"G1 Y{y1 - 2:.3f}",
              f"G3 X{x1 - 2:.3f} Y{y1:.3f} I-2 J0", f"G1 X{x0 + 2:.3f}",
              f"G3 X{x0:.3f} Y{y1 - 2:.3f} R2", f"G1 Y{y0 + 2:.3f}",
              f"G3 X{x0 + 2:.3f} Y{y0:.3f} I2 J0"]
        g.append("G0 Z5")
    g += ["M5", "T1 M6 (3 mm ball)", "S12000 M3", "G0 X26 Y15", "G1 Z-3.0 F200",
          "G2 X26 Y15 I-6 J0 Z-4.0 F600", "G2 X26 Y15 I-6 J0 Z-4.5", "G0 Z5",
          "G99 G81 X4 Y4 Z-11 R1 F200", "X36 Y4", "X36 Y26", "G98 X4 Y26", "G80",
          "G0 Z10", "M5", "M30", "%"]
    return "\n".join(g) + "\n"


def write_demo_program(path: str | Path | None = None) -> Path:
    """Write the demo program; default next to this script as demo_pocket.nc."""
    path = Path(path) if path else Path(__file__).resolve().parent / "demo_pocket.nc"
    path.write_text(demo_program())
    return path


if __name__ == "__main__":
    print(write_demo_program(sys.argv[1] if len(sys.argv) > 1 else None))
