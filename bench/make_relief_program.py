"""Write the deterministic relief-carving program of the simulation benchmark.

A 120 x 80 x 15 mm stock (top at z = 0, corner at the origin) carved into a smooth relief
up to 6 mm deep, with two tools (LinuxCNC dialect, mm, ``T1 M6`` and ``T2 M6``):

* T1, a 2.5 mm flat end mill, roughs three layers (-2, -4, -5.6 mm, 0.3 mm allowance): each
  layer starts with helical bores into the deepest spots (G2/G3 with a Z change, some with
  ``P2`` full turns, a flat clean-up circle at the bottom), then a zigzag raster along x of
  0.8 mm 3D ramps following the relief, 1.5 mm step-over.
* T2, a 6 mm bull nose with a 1 mm corner, finishes with a zigzag raster along x of 0.5 mm
  3D ramps whose tip follows the relief, 0.4 mm step-over, then scallops the four borders
  with G18 (along x) and G19 (along y) arcs dipping 0.7 mm.

About 71,000 moves. The tools are :data:`TOOLS` (specs for :func:`zmap.sim.tools.parse_tool_spec`);
:func:`write_tool_table` writes them as a TOML tool table for ``simulate(..., tools=...)``.

Usage: ``python bench/make_relief_program.py [OUT.nc]`` (default ``relief.nc``; the tool
table goes beside it as ``OUT.toml``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

__all__ = ["STOCK", "TOOLS", "relief_surface", "relief_program", "write_relief_program",
           "write_tool_table"]

STOCK = (0.0, 0.0, -15.0, 120.0, 80.0, 0.0)  # x0, y0, z0, x1, y1, z1 in mm
TOOLS = {1: "flat:2.5", 2: "bull:6:1"}  # tool number -> spec (mm)
SEED = 20240611
_TOML = {1: 'kind = "flat"\ndiameter = 2.5\n',
         2: 'kind = "bull"\ndiameter = 6.0\ncorner_radius = 1.0\n'}


def relief_surface(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height of the relief, mm, in [-6, 0]: 0 on a 4 mm border, smooth everywhere."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    u = np.clip(np.minimum(np.minimum(x - 4.0, 116.0 - x), np.minimum(y - 4.0, 76.0 - y)) / 8.0, 0.0, 1.0)
    field = u * u * (3.0 - 2.0 * u)
    waves = 1.1 * np.sin(x / 7.5 + 0.6 * np.cos(y / 11.0)) * np.cos(y / 6.5)
    hills = (1.8 * np.exp(-(((x - 34.0) / 11.0) ** 2 + ((y - 44.0) / 8.0) ** 2))
             + 1.2 * np.exp(-(((x - 92.0) / 7.0) ** 2 + ((y - 58.0) / 9.0) ** 2)))
    dents = (2.3 * np.exp(-(((x - 82.0) / 8.0) ** 2 + ((y - 28.0) / 9.5) ** 2))
             + 1.9 * np.exp(-(((x - 22.0) / 6.0) ** 2 + ((y - 18.0) / 6.0) ** 2)))
    depth = field * (3.0 + waves - hills + dents)
    return -np.clip(depth, 0.0, 6.0)


def _helix_spots(rng: np.random.Generator, layer: float, n: int, clear: float) -> list[tuple[float, float, float]]:
    """``n`` spots ``(x, y, z)`` where a bore of reach ``clear`` gets closest to ``layer``
    without going below the relief + 0.3 mm; candidates drawn at random, deepest first."""
    cand = np.column_stack([rng.uniform(12, 108, 400), rng.uniform(12, 68, 400)])
    ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    rr = np.array([0.0, 0.5 * clear, clear])
    dx = (rr[:, None] * np.cos(ang)[None]).ravel()
    dy = (rr[:, None] * np.sin(ang)[None]).ravel()
    floor = relief_surface(cand[:, :1] + dx[None], cand[:, 1:] + dy[None]).max(axis=1) + 0.3
    z = np.maximum(floor, layer)
    out: list[tuple[float, float, float]] = []
    for k in np.argsort(z, kind="stable"):
        x, y = cand[k]
        if all(np.hypot(x - a, y - b) > 3 * clear for a, b, _ in out):
            out.append((float(x), float(y), float(z[k])))
        if len(out) == n:
            break
    return out


def relief_program(seed: int = SEED) -> str:
    """G-code text of the relief program (deterministic for a given ``seed``)."""
    rng = np.random.default_rng(seed)
    out = ["%", "(zmap bench: relief carving, T1 flat 2.5 mm, T2 bull 6 mm r1, stock 120x80x15)",
           "G21 G90 G17 G94 G40 G49 G80", "T1 M6", "S18000 M3", "G0 Z5.000"]
    f3 = "{:.4f}".format
    # ---- T1: roughing layers, each opened by helical bores -------------------------------
    xs = np.linspace(2.0, 118.0, 146)
    ys = np.arange(2.0, 78.0 + 1e-9, 1.5)
    for n_layer, layer in enumerate((-2.0, -4.0, -5.6)):
        for n_spot, (cx, cy, cz) in enumerate(_helix_spots(rng, layer, 4, clear=1.25 + 1.6)):
            r = float(rng.uniform(0.9, 1.6))
            out.append(f"G0 X{f3(cx + r)} Y{f3(cy)}")
            out.append("G0 Z1.000")
            out.append("G1 Z0.200 F300")
            if (n_layer + n_spot) % 2 == 0:  # two full turns down, then a flat circle
                out.append(f"G3 X{f3(cx + r)} Y{f3(cy)} Z{f3(cz)} I{f3(-r)} J0 P2 F500")
                out.append(f"G3 X{f3(cx + r)} Y{f3(cy)} I{f3(-r)} J0")
            else:  # half-turn ramps down, alternating sides, clockwise
                z = 0.2
                side = 1.0
                while z > cz + 1e-9:
                    z = max(cz, z - 0.6)
                    out.append(f"G2 X{f3(cx - side * r)} Y{f3(cy)} Z{f3(z)} I{f3(-side * r)} J0 F500")
                    side = -side
                out.append(f"G2 X{f3(cx - side * r)} Y{f3(cy)} I{f3(-side * r)} J0")
            out.append("G0 Z5.000")
        z0 = max(layer, float(relief_surface(xs[0], ys[0])) + 0.3)
        out.append(f"G0 X{f3(xs[0])} Y{f3(ys[0])}")
        out.append(f"G1 Z{f3(z0)} F300")
        out.append("F1800")
        for n, y in enumerate(ys):
            xx = xs if n % 2 == 0 else xs[::-1]
            zz = np.maximum(layer, relief_surface(xx, np.full_like(xx, y)) + 0.3)
            out.extend(f"G1 X{f3(x)} Y{f3(y)} Z{f3(z)}" for x, z in zip(xx, zz))
        out.append("G0 Z5.000")
    # ---- T2: finishing raster, tip on the relief ------------------------------------------
    out += ["M5", "T2 M6", "S16000 M3", "G0 Z5.000"]
    xs = np.linspace(0.0, 120.0, 241)
    ys = np.arange(0.0, 80.0 + 1e-9, 0.4)
    out.append(f"G0 X{f3(xs[0])} Y{f3(ys[0])}")
    out.append(f"G1 Z{f3(float(relief_surface(xs[0], ys[0])))} F400")
    out.append("F2400")
    for n, y in enumerate(ys):
        xx = xs if n % 2 == 0 else xs[::-1]
        zz = relief_surface(xx, np.full_like(xx, y))
        out.extend(f"G1 X{f3(x)} Y{f3(y)} Z{f3(z)}" for x, z in zip(xx, zz))
    out.append("G0 Z5.000")
    # ---- T2: scalloped borders: G18 arcs along x, G19 arcs along y (each dips 0.7 mm) ----
    k = float(np.sqrt(2.0**2 - 1.5**2))  # centre 1.32 mm above the chord: radius 2, chord 3
    zb = -0.3
    for yb in (2.0, 78.0):  # along +x in the XZ plane: clockwise (G2) dips
        out += [f"G0 X4.000 Y{f3(yb)}", "G0 Z1.000", f"G1 Z{f3(zb)} F300", "G18"]
        for x in np.arange(4.0, 113.0 + 1e-9, 3.0):
            out.append(f"G2 X{f3(x + 3.0)} Z{f3(zb)} I1.5000 K{f3(k)} F1200")
        out += ["G17", "G0 Z5.000"]
    for xb in (2.0, 118.0):  # along +y in the YZ plane: counter-clockwise (G3) dips
        out += [f"G0 X{f3(xb)} Y4.000", "G0 Z1.000", f"G1 Z{f3(zb)} F300", "G19"]
        for y in np.arange(4.0, 73.0 + 1e-9, 3.0):
            out.append(f"G3 Y{f3(y + 3.0)} Z{f3(zb)} J1.5000 K{f3(k)} F1200")
        out += ["G17", "G0 Z5.000"]
    out += ["M5", "G0 X0 Y0", "M30", "%"]
    return "\n".join(out) + "\n"


def write_tool_table(path: str | Path) -> Path:
    """Write :data:`TOOLS` as a TOML tool table (``[tool.N]``); returns the path."""
    path = Path(path)
    path.write_text("".join(f"[tool.{n}]\n{_TOML[n]}\n" for n in sorted(TOOLS)))
    return path


def write_relief_program(path: str | Path, *, seed: int = SEED, tool_table: str | Path | None = None) -> Path:
    """Write :func:`relief_program` to ``path`` (and the tool table to ``tool_table`` if
    given); returns the program's path."""
    path = Path(path)
    path.write_text(relief_program(seed))
    if tool_table is not None:
        write_tool_table(tool_table)
    return path


if __name__ == "__main__":
    nc = Path(sys.argv[1] if len(sys.argv) > 1 else "relief.nc")
    print(write_relief_program(nc, tool_table=nc.with_suffix(".toml")))
