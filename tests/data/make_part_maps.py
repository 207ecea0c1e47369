"""Writes tests/data/part_maps/*.zmap.npz: the master z-map of every real part of data/step,
converted with the project's own sampler at a grid of ``max(0.5, extent / 120)`` mm (at most
about 120 x 120 nodes), for the drop-cutter and loop tests on real designs.

Run from the repository root: ``.venv/bin/python tests/data/make_part_maps.py``.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def main() -> None:
    import cad_io

    out = ROOT / "tests" / "data" / "part_maps"
    out.mkdir(parents=True, exist_ok=True)
    for f in sorted((ROOT / "data" / "step").iterdir()):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            part = cad_io.read_step(f)
            b = part.bbox
            grid = max(0.5, round(max(b[3] - b[0], b[4] - b[1]) / 120, 2))
            zm = cad_io.sample(part, grid)
        path = out / (f.stem + ".zmap.npz")
        zm.save(path)
        print(f"{f.name}: grid {grid:g} mm, {zm.z.shape[0]} x {zm.z.shape[1]} nodes -> {path.relative_to(ROOT)}",
              flush=True)


if __name__ == "__main__":
    main()
