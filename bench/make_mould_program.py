"""Write the deterministic mould program of the simulation benchmark (paper 001 s.5 shape).

A 107 x 72 x 33 mm stock (top at z = 0, corner at the origin), a 3 mm ball cutter and a
mould-like cavity: a rounded pocket with a raised boss and a groove. The program roughs one
zigzag layer along y (4 mm moves), then finishes the surface with a zigzag along x of
0.5 mm moves, 0.93 mm step-over: about 17,000 moves, mostly 0.5 mm long, about 44,000
elementary positions at a 0.26 mm pitch.

Usage: ``python bench/make_mould_program.py [OUT.nc]`` (default ``mould.nc``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

__all__ = ["STOCK", "mould_surface", "mould_program", "write_mould_program"]

STOCK = (0.0, 0.0, -33.0, 107.0, 72.0, 0.0)  # x0, y0, z0, x1, y1, z1 in mm
TOOL = "ball:3"


def mould_surface(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height of the mould cavity's surface (ball-centre offset not applied), mm, in [-26, -1]."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    # rounded rectangular pocket: smooth walls 8 mm wide
    u = np.clip(np.minimum(np.minimum(x - 6, 101 - x), np.minimum(y - 6, 66 - y)) / 8.0, 0.0, 1.0)
    pocket = u * u * (3 - 2 * u)
    boss = 9.0 * np.exp(-(((x - 38) / 11.0) ** 2 + ((y - 36) / 9.0) ** 2))
    groove = -4.0 * np.exp(-(((x + 0.5 * y - 95) / 3.0) ** 2)) * (y > 12) * (y < 60)
    waves = 0.8 * np.sin(x / 6.0) * np.cos(y / 5.0)
    return -1.0 - pocket * (22.0 - boss - waves) + groove * pocket


def mould_program() -> str:
    """G-code text of the benchmark program (deterministic)."""
    r = 1.5  # ball radius: the tip follows the surface (a simple, slightly gouging finish)
    out = ["%", "(zmap bench: mould program, 3 mm ball, stock 107x72x33)", "G21 G90 G17", "T1 M6",
           "S12000 M3", "G0 Z5"]
    fmt = "G1 X{:.3f} Y{:.3f} Z{:.3f}"
    # roughing: one zigzag layer along y at 6 mm step-over, 4 mm moves, 0.6 mm allowance
    layer = -12.0
    xs = np.arange(r, 107.0 - r + 1e-9, 6.0)
    ys = np.linspace(r, 72.0 - r, 18)
    out.append(f"G0 X{xs[0]:.3f} Y{ys[0]:.3f}")
    out.append("G1 Z0 F600")
    out.append("F2400")
    for n, x in enumerate(xs):
        yy = ys if n % 2 == 0 else ys[::-1]
        for y in yy:
            z = max(layer, float(mould_surface(x, y)) + 0.6)
            out.append(fmt.format(x, y, z))
    out.append("G0 Z5")
    # finishing: zigzag along x, 1 mm step-over, 0.5 mm moves following the surface
    xs = np.linspace(0.5, 106.5, 213)
    ys = np.linspace(0.5, 71.5, 78)
    out.append(f"G0 X{xs[0]:.3f} Y{ys[0]:.3f}")
    out.append(f"G1 Z{float(mould_surface(xs[0], ys[0])):.3f} F600")
    out.append("F3000")
    for n, y in enumerate(ys):
        xx = xs if n % 2 == 0 else xs[::-1]
        zz = mould_surface(xx, np.full_like(xx, y))
        for x, z in zip(xx, zz):
            out.append(fmt.format(x, y, z))
    out += ["G0 Z5", "M5", "M30", "%"]
    return "\n".join(out) + "\n"


def write_mould_program(path: str | Path) -> Path:
    """Write :func:`mould_program` to ``path``; returns the path."""
    path = Path(path)
    path.write_text(mould_program())
    return path


if __name__ == "__main__":
    print(write_mould_program(sys.argv[1] if len(sys.argv) > 1 else "mould.nc"))
