"""Height-field workpiece: the top surface only, on a ZMap grid.

Each grid point keeps one height; a cutter at tip ``(tx, ty, tz)`` lowers it to
``min(z, tz + envelope(d))`` where ``d`` is the point's distance to the cutter axis, and a
cutter moving along a path piece to the lowest such height over the piece (the exact sweep,
:mod:`zmap.sim._sweep_kernels`). It
cannot show undercuts or holes through the stock (use :mod:`zmap.sim.dexel` for that), but it
is the cheapest workpiece and works directly on any :class:`zmap.ZMap`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..grid import ZMap
from . import _dexel_kernels as _k
from .dexel import cutter_table

__all__ = ["HeightField", "cut_heightfield"]


def cut_heightfield(zm: ZMap, xyz: np.ndarray, cutter: Any, tool_slot: np.ndarray | None = None) -> ZMap:
    """A copy of ``zm`` cut by the cutter at every tool-tip position.

    Parameters
    ----------
    zm : ZMap
        Surface to cut (plain map, no local frame); NaN points stay NaN.
    xyz : ndarray of shape (n, 3), float64
        Tool-tip positions in mm.
    cutter : Cutter or list of Cutter
        One cutter, or a list indexed by ``tool_slot``.
    tool_slot : ndarray of shape (n,), int, optional

    Returns
    -------
    ZMap
        The cut surface, ``z <= zm.z`` everywhere.

    Examples
    --------
    >>> import numpy as np
    >>> from zmap.sim.tools import Cutter
    >>> zm = ZMap(0, 0, 0.5, 0.5, np.zeros((5, 5)))
    >>> out = cut_heightfield(zm, np.array([[1.0, 1.0, -1.0]]), Cutter("flat", 1))
    >>> float(out.z[2, 2]), float(out.z[0, 0])
    (-1.0, 0.0)
    """
    hf = HeightField(zm)
    hf.cut(xyz, cutter, tool_slot)
    return hf.to_zmap()


class HeightField:
    """A mutable height field on the grid of a ZMap.

    Parameters
    ----------
    zm : ZMap
        Initial surface (copied); no local frame.
    """

    def __init__(self, zm: ZMap):
        if zm.has_frame:
            raise ValueError("a ZMap with a local frame (angle/origin) cannot be a height-field workpiece")
        self.template = zm
        self.z = np.ascontiguousarray(zm.z, dtype=np.float64).copy()

    @property
    def nbytes(self) -> int:
        return int(self.z.nbytes)

    def cut(self, xyz: Any, cutter: Any, tool_slot: np.ndarray | None = None) -> "HeightField":
        """Lower the surface under the cutter, in place; returns self.

        ``xyz`` is an (n, 3) array of tool tips (each stamps the tool there) or a
        :class:`zmap.sim.pieces.Pieces` (each stage lowers the surface to the exact sweep of
        its path piece).
        """
        from .pieces import Pieces

        cutters = list(cutter) if isinstance(cutter, (list, tuple)) else [cutter]
        if isinstance(xyz, Pieces):
            pieces = xyz
        else:
            xyz = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 3)
            if not np.isfinite(xyz).all():
                raise ValueError("tool positions hold NaN or infinite coordinates")
            pieces = Pieces.stamps(xyz)
        slot = (np.zeros(len(pieces), dtype=np.int32) if tool_slot is None
                else np.ascontiguousarray(tool_slot, dtype=np.int32))
        code, radius, corner, length = cutter_table(cutters)
        zm = self.template
        mv, t0, t1 = pieces.params(0, len(pieces))
        _k.heightfield_cut(pieces.kind, pieces.geo, mv, t0, t1, slot, code, radius, corner, length,
                           zm.x0, zm.y0, zm.dx, zm.dy, self.z)
        return self

    def to_zmap(self) -> ZMap:
        zm = self.template
        return ZMap(zm.x0, zm.y0, zm.dx, zm.dy, self.z.copy(), meta=dict(zm.meta, method="heightfield-cut"))
