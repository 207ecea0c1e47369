"""A STEP part as a zmap design (:mod:`zmap.design`): its exact top-most heights.

Importing :mod:`cad_io` registers :class:`cad_io.Part` with :func:`zmap.design.register` and
``.step``/``.stp`` files with :func:`zmap.design.register_reader`, so the drop-cutter, the
comparison and ``zmap toolpath``/``zmap compare`` take a part without zmap importing cad_io.

Examples
--------
>>> from pathlib import Path
>>> import cad_io
>>> from zmap.design import as_design, read_design
>>> part = read_design(Path(cad_io.__file__).parents[1] / "data" / "pocket.step")
>>> d = as_design(part)
>>> d.kind, d.exact, d.drop_pitch
('part', True, 0.25)
"""

from __future__ import annotations

import numpy as np

from zmap.design import Design, register, register_reader

from cad_io.part import Part

__all__ = ["part_design", "DROP_PITCH"]

#: mm: the drop-cutter samples a part this finely (and twice as finely for its margins)
DROP_PITCH = 0.25


def part_design(part: Part) -> Design:
    """The :class:`zmap.design.Design` of a part: exact heights, its grid sampler."""
    from cad_io.sampler import height_function, sample

    def grid(x0: float, y0: float, h: float, nx: int, ny: int) -> np.ndarray:
        zm = sample(part, h, bounds=(x0, y0, x0 + (nx - 1) * h, y0 + (ny - 1) * h))
        out = np.full((nx, ny), np.nan)
        i0 = int(round((zm.x0 - x0) / h))
        j0 = int(round((zm.y0 - y0) / h))
        a = zm.z[max(0, -i0):, max(0, -j0):][:nx - max(i0, 0), :ny - max(j0, 0)]
        out[max(i0, 0):max(i0, 0) + a.shape[0], max(j0, 0):max(j0, 0) + a.shape[1]] = a
        return out

    b = part.bbox
    return Design(height_function(part), (float(b[0]), float(b[1]), float(b[3]), float(b[4])),
                  max(b[3] - b[0], b[4] - b[1]) / 400, "part", True, grid=grid, drop_pitch=DROP_PITCH,
                  drop_check=2, source=part)


def _read_step(path: str) -> Part:
    from cad_io.step import read_step

    return read_step(path)


register(Part, part_design)
register_reader((".step", ".stp"), _read_step, "a STEP part")
