"""The path pieces the stages cut: each stage cuts the exact sweep of the path since the last.

A program's moves are cut into stages (:func:`zmap.sim.path.positions`); stage ``k`` is the
tool at position ``k - 1``, and it cuts the exact swept volume of the tool along the path
piece from the previous position to this one (:mod:`zmap.sim._sweep_kernels`), so the
stock after stage ``k`` is the exact sweep of the program up to there. A piece is a range
``[t0, t1]`` of the parameter of one move, whose geometry is one row of a small per-move
table: a line from its start to its end, or an arc or helix (plane, centre, start angle,
signed sweep, start and end radius, start and end normal coordinate).

Tool positions given as a bare array (no program) are stamps: each position cuts the tool
standing there, and nothing between positions.

Examples
--------
>>> from zmap.sim.gcode import parse
>>> from zmap.sim.path import positions
>>> p = Pieces.of(positions(parse("G0 X0 Y0 Z1\\nG1 X1 F100\\n"), pitch=0.5))
>>> p.kind.tolist()  # the first move starts from an unknown point: it does not cut
[0, 2]
>>> p.move.tolist(), p.params(0, len(p))[1].tolist()  # each stage's piece: t0 of its move
([0, 0, 1, 1], [0.0, 0.5, 0.0, 0.5])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _sweep_kernels as _sk
from .gcode import ARC_CW, KNOWN_ALL, _PLANE_AXES

__all__ = ["Pieces"]


@dataclass
class Pieces:
    """Per-move geometry and the move of each stage.

    Attributes
    ----------
    kind : ndarray of shape (m,), int8
        0 no cut (the tool's start was unknown), 1 stamp, 2 line, 17/18/19 arc.
    geo : ndarray of shape (m, 8), float64
        Line: start xyz, end xyz. Arc: in-plane centre (a, b), start angle, signed sweep
        (rad), start and end radius, start and end normal coordinate (mm).
    move : ndarray of shape (n,), int32
        Row of ``kind``/``geo`` of each stage; the stages of one row are contiguous and
        split its parameter into equal steps.
    """

    kind: np.ndarray
    geo: np.ndarray
    move: np.ndarray

    def __len__(self) -> int:
        return int(self.move.shape[0])

    @classmethod
    def stamps(cls, xyz: Any) -> "Pieces":
        """Every position a stamp of the tool (no sweep between positions)."""
        xyz = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 3)
        n = xyz.shape[0]
        geo = np.zeros((n, 8), dtype=np.float64)
        geo[:, :3] = xyz
        return cls(np.full(n, _sk.STAMP, dtype=np.int8), geo, np.arange(n, dtype=np.int32))

    @classmethod
    def of(cls, pos: Any) -> "Pieces":
        """The pieces of :class:`zmap.sim.path.Positions` (stamps when it has no moves)."""
        moves = getattr(pos, "moves", None)
        if moves is None:
            return cls.stamps(pos.xyz)
        return cls.from_moves(moves, pos.move)

    @classmethod
    def from_moves(cls, moves: np.ndarray, move: Any) -> "Pieces":
        """Geometry of a program's moves; ``move`` the move index of each stage."""
        m = moves.shape[0]
        kind = np.full(m, _sk.LINE, dtype=np.int8)
        geo = np.zeros((m, 8), dtype=np.float64)
        start = np.asarray(moves["start"], dtype=np.float64)
        end = np.asarray(moves["end"], dtype=np.float64)
        geo[:, :3] = start
        geo[:, 3:6] = end
        arcs = np.flatnonzero(moves["kind"] >= ARC_CW)
        if arcs.size:
            plane = np.asarray(moves["plane"][arcs], dtype=np.int64)
            ax = np.array([_PLANE_AXES[int(p)] for p in (17, 18, 19)])[plane - 17]
            rows = np.arange(arcs.size)
            s, e = start[arcs], end[arcs]
            c = np.asarray(moves["center"][arcs], dtype=np.float64)
            da0, db0 = s[rows, ax[:, 0]] - c[rows, ax[:, 0]], s[rows, ax[:, 1]] - c[rows, ax[:, 1]]
            da1, db1 = e[rows, ax[:, 0]] - c[rows, ax[:, 0]], e[rows, ax[:, 1]] - c[rows, ax[:, 1]]
            kind[arcs] = plane
            geo[arcs] = np.column_stack([
                c[rows, ax[:, 0]], c[rows, ax[:, 1]], np.arctan2(db0, da0),
                np.asarray(moves["sweep"][arcs], dtype=np.float64), np.hypot(da0, db0), np.hypot(da1, db1),
                s[rows, ax[:, 2]], e[rows, ax[:, 2]]])
        if "known" in (moves.dtype.names or ()):
            kind[(moves["known"] & KNOWN_ALL) != KNOWN_ALL] = _sk.NO_CUT
        return cls(kind, geo, np.ascontiguousarray(move, dtype=np.int32))

    def params(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(move, t0, t1)`` of stages ``lo..hi-1``: each stage's piece of its move."""
        mv = self.move[lo:hi]
        first, count = self._first_count()
        j = np.arange(lo, hi, dtype=np.int64) - first[mv]
        n = count[mv].astype(np.float64)
        t1 = (j + 1) / n
        t0 = j / n
        return np.ascontiguousarray(mv), t0, t1

    def _first_count(self) -> tuple[np.ndarray, np.ndarray]:
        cache = getattr(self, "_fc", None)
        if cache is None:
            count = np.bincount(self.move, minlength=self.kind.shape[0]).astype(np.int64)
            first = np.cumsum(count) - count
            cache = (first, count)
            object.__setattr__(self, "_fc", cache)
        return cache

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays to save with a run."""
        return {"kind": self.kind, "geo": self.geo, "move": self.move}

    @classmethod
    def from_arrays(cls, a: dict, n: int) -> "Pieces":
        """Read back :meth:`to_arrays`; ``n`` the run's stage count."""
        kind = np.ascontiguousarray(a["kind"], dtype=np.int8)
        geo = np.ascontiguousarray(a["geo"], dtype=np.float64)
        move = np.ascontiguousarray(a["move"], dtype=np.int32)
        if geo.shape != (kind.shape[0], 8) or move.shape != (n,):
            raise ValueError(f"path pieces have shapes {kind.shape}, {geo.shape}, {move.shape} "
                             f"for {n} stages")
        if n and (move.min() < 0 or move.max() >= kind.shape[0] or np.any(np.diff(move) < 0)):
            raise ValueError("path pieces: stage moves out of range or out of order")
        return cls(kind, geo, move)

    @property
    def nbytes(self) -> int:
        return int(self.kind.nbytes + self.geo.nbytes + self.move.nbytes)
