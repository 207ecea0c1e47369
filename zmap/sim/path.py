"""Moves to elementary tool positions: arcs to chords, then 3D DDA at the ray pitch.

Paper 001 §2: a toolpath is discretised into elementary positions of the tool by a 3D DDA
(Bresenham's algorithm generalised to 3D); the successive positions are the stages of the
simulation. Here every straight segment (a G0/G1 move, or one chord of an arc) from ``a`` to
``b`` is cut into ``n = ceil(max(|b - a|) / pitch)`` equal steps: the dominant axis advances
by at most ``pitch`` per position (one ray spacing), the other axes follow proportionally,
and the last position is ``b`` exactly. Arcs (any plane, helical, multi-turn) are first split
into chords whose sagitta is at most ``chord_tol``.

Stage ``k`` (1..n) is the state after the cutter has been at ``xyz[k-1]``; stage 0 is the
stock.

Examples
--------
>>> from zmap.sim.gcode import parse
>>> pos = positions(parse("G0 X1\\n"), pitch=0.25)
>>> pos.xyz[:, 0].tolist()
[0.25, 0.5, 0.75, 1.0]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .gcode import ARC_CW, MOVE_DTYPE, Program, _PLANE_AXES, arc_sweep

__all__ = ["positions", "Positions", "arc_chords", "dda"]


@dataclass
class Positions:
    """Elementary tool-tip positions; position ``k-1`` makes stage ``k``.

    Attributes
    ----------
    xyz : ndarray of shape (n, 3), float64
        Tool-tip positions in mm.
    tool : ndarray of shape (n,), int32
        Active tool number (0 = none) at each position.
    move : ndarray of shape (n,), int32
        Index into ``program.moves`` of the move each position belongs to.
    line : ndarray of shape (n,), int32
        1-based source line of that move (0 when unknown).
    """

    xyz: np.ndarray
    tool: np.ndarray
    move: np.ndarray
    line: np.ndarray

    def __post_init__(self) -> None:
        self.xyz = np.ascontiguousarray(self.xyz, dtype=np.float64)
        n = self.xyz.shape[0]
        if self.xyz.ndim != 2 or self.xyz.shape[1] != 3:
            raise ValueError(f"xyz must have shape (n, 3), got {self.xyz.shape}")
        for name in ("tool", "move", "line"):
            a = np.ascontiguousarray(getattr(self, name), dtype=np.int32)
            if a.shape != (n,):
                raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
            setattr(self, name, a)

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    @property
    def n(self) -> int:
        """Number of positions (= number of the last stage)."""
        return len(self)

    @classmethod
    def from_xyz(cls, xyz: Any, *, tool: Any = 1) -> "Positions":
        """Positions straight from an array of tip points (for tests and scripts).

        Parameters
        ----------
        xyz : array_like of shape (n, 3)
            Tool-tip positions in mm.
        tool : int or array_like of shape (n,)
            Tool number(s) (default 1).

        Returns
        -------
        Positions
            With ``move = arange(n)`` and ``line = 0``.

        Examples
        --------
        >>> Positions.from_xyz([[0, 0, 1], [1, 0, 1]]).tool.tolist()
        [1, 1]
        """
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        n = xyz.shape[0]
        return cls(xyz=xyz, tool=np.broadcast_to(np.asarray(tool, dtype=np.int32), (n,)),
                   move=np.arange(n, dtype=np.int32), line=np.zeros(n, dtype=np.int32))

    def move_last_stage(self, n_moves: int) -> np.ndarray:
        """Stage reached at the end of each move (0 if none of its positions came yet).

        Parameters
        ----------
        n_moves : int
            Number of moves of the program.

        Returns
        -------
        ndarray of shape (n_moves,), int64
            ``s[i]`` is the stage after the last position of moves ``0..i``.
        """
        counts = np.bincount(self.move, minlength=n_moves)[:n_moves]
        return np.cumsum(counts)


def _check_positive(name: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {v!r}") from None
    if not (math.isfinite(f) and f > 0):
        raise ValueError(f"{name} must be a positive finite number, got {v!r}")
    return f


def dda(a: Any, b: Any, *, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """3D DDA of straight segments: positions after ``a`` up to ``b`` inclusive.

    Parameters
    ----------
    a, b : array_like of shape (m, 3)
        Segment starts and ends (mm).
    pitch : float, keyword-only
        Largest step of the dominant axis (mm), the ray spacing.

    Returns
    -------
    xyz : ndarray of shape (n, 3), float64
        Positions, segment after segment; each segment ends exactly at its ``b``; a
        zero-length segment contributes none.
    seg : ndarray of shape (n,), int64
        Segment index of each position.

    Examples
    --------
    >>> xyz, seg = dda([[0, 0, 0]], [[1, 0.5, 0]], pitch=0.5)
    >>> xyz.tolist(), seg.tolist()
    ([[0.5, 0.25, 0.0], [1.0, 0.5, 0.0]], [0, 0])
    """
    pitch = _check_positive("pitch", pitch)
    a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape, got {a.shape} and {b.shape}")
    d = b - a
    linf = np.abs(d).max(axis=1) if d.shape[0] else np.zeros(0)
    steps = np.ceil(linf / pitch - 1e-9).astype(np.int64)
    steps[linf == 0] = 0
    steps = np.maximum(steps, (linf > 0).astype(np.int64))
    total = int(steps.sum())
    seg = np.repeat(np.arange(a.shape[0], dtype=np.int64), steps)
    first = np.cumsum(steps) - steps
    k = np.arange(total, dtype=np.int64) - first[seg] + 1
    t = k / steps[seg]
    xyz = a[seg] + d[seg] * t[:, None]
    last = k == steps[seg]
    xyz[last] = b[seg[last]]
    return xyz, seg


def arc_chords(start: Any, end: Any, center: Any, plane: Any, sweep: Any, *,
               chord_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Chord vertices of arcs (any plane, helical, multi-turn) within a chord tolerance.

    Parameters
    ----------
    start, end, center : array_like of shape (m, 3)
        Arc start, end and centre in mm (centre's normal coordinate is ignored).
    plane : array_like of shape (m,)
        17, 18 or 19.
    sweep : array_like of shape (m,)
        Signed swept angle in radians (positive counter-clockwise about the plane normal).
    chord_tol : float, keyword-only
        Largest sagitta (distance from a chord to the circle) in mm.

    Returns
    -------
    vertices : ndarray of shape (k, 3), float64
        Chord end points, arc after arc, the start excluded and the end included exactly.
        Between them the radius and the normal coordinate vary linearly with the angle (so
        a circle's vertices lie on it; a helix's on the helix).
    arc : ndarray of shape (k,), int64
        Arc index of each vertex.

    Examples
    --------
    >>> v, _ = arc_chords([[1, 0, 0]], [[-1, 0, 0]], [[0, 0, 0]], [17], [np.pi], chord_tol=0.3)
    >>> np.round(v, 6).tolist()
    [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
    """
    tol = _check_positive("chord_tol", chord_tol)
    s = np.asarray(start, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(end, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(center, dtype=np.float64).reshape(-1, 3)
    pl = np.asarray(plane).reshape(-1)
    sw = np.asarray(sweep, dtype=np.float64).reshape(-1)
    m = s.shape[0]
    ax = np.empty((m, 3), dtype=np.int64)
    for p, axes in _PLANE_AXES.items():
        ax[pl == p] = axes
    bad = ~np.isin(pl, list(_PLANE_AXES))
    if bad.any():
        raise ValueError(f"plane must be 17, 18 or 19, got {pl[bad][0]!r}")
    rows = np.arange(m)
    ia, ib, inn = ax[:, 0], ax[:, 1], ax[:, 2]
    da0, db0 = s[rows, ia] - c[rows, ia], s[rows, ib] - c[rows, ib]
    da1, db1 = e[rows, ia] - c[rows, ia], e[rows, ib] - c[rows, ib]
    r0 = np.hypot(da0, db0)
    r1 = np.hypot(da1, db1)
    rmax = np.maximum(r0, r1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cosv = np.clip(1.0 - tol / rmax, -1.0, 1.0)
        dmax = np.minimum(2.0 * np.arccos(cosv), np.pi / 2)
    dmax = np.where(rmax > 0, dmax, np.pi / 2)
    nseg = np.maximum(np.ceil(np.abs(sw) / dmax - 1e-9), 1).astype(np.int64)
    arc = np.repeat(rows, nseg)
    first = np.cumsum(nseg) - nseg
    k = np.arange(int(nseg.sum()), dtype=np.int64) - first[arc] + 1
    frac = k / nseg[arc]
    ang = np.arctan2(db0, da0)[arc] + sw[arc] * frac
    rad = r0[arc] + (r1 - r0)[arc] * frac
    v = np.empty((arc.shape[0], 3), dtype=np.float64)
    rr = np.arange(arc.shape[0])
    v[rr, ia[arc]] = c[arc, ia[arc]] + rad * np.cos(ang)
    v[rr, ib[arc]] = c[arc, ib[arc]] + rad * np.sin(ang)
    v[rr, inn[arc]] = s[arc, inn[arc]] + (e[arc, inn[arc]] - s[arc, inn[arc]]) * frac
    last = k == nseg[arc]
    v[last] = e[arc[last]]
    return v, arc


def positions(program_or_moves: Program | np.ndarray, *, pitch: float = 0.26,
              chord_tol: float | None = None) -> Positions:
    """Elementary tool-tip positions of a program by 3D DDA at the ray pitch.

    Parameters
    ----------
    program_or_moves : Program or ndarray of MOVE_DTYPE
        Parsed program (see :func:`zmap.sim.gcode.parse`) or its ``moves``. A moves array
        without a ``sweep`` field has its arc angles computed as LinuxCNC does.
    pitch : float, keyword-only
        Largest step of the dominant axis between consecutive positions, mm (default 0.26,
        the paper's ray spacing). Rapids (G0) are discretised too: a rapid into material is a
        collision to show.
    chord_tol : float, optional, keyword-only
        Largest chord error of arcs in mm (default ``pitch / 10``).

    Returns
    -------
    Positions
        In move order; each move ends exactly on its end point; zero-length moves add none.

    Examples
    --------
    >>> from zmap.sim.gcode import parse
    >>> p = positions(parse("G0 X0 Y0 Z1\\nG1 X0.5 F100\\n"), pitch=0.26)
    >>> len(p), p.move.tolist()[-2:], p.xyz[-1].tolist()
    (6, [1, 1], [0.5, 0.0, 1.0])
    """
    pitch = _check_positive("pitch", pitch)
    tol = pitch / 10.0 if chord_tol is None else _check_positive("chord_tol", chord_tol)
    moves = program_or_moves.moves if isinstance(program_or_moves, Program) else program_or_moves
    if not isinstance(moves, np.ndarray) or moves.dtype.names is None:
        raise TypeError("program_or_moves must be a Program or a structured moves array, "
                        f"got {type(program_or_moves).__name__}")
    missing = {"kind", "start", "end", "center", "plane", "tool", "line"} - set(moves.dtype.names)
    if missing:
        raise ValueError(f"moves lack fields {sorted(missing)}; expected {MOVE_DTYPE.names}")
    n_moves = moves.shape[0]
    kind = moves["kind"]
    start = np.ascontiguousarray(moves["start"], dtype=np.float64)
    end = np.ascontiguousarray(moves["end"], dtype=np.float64)
    is_arc = kind >= ARC_CW
    arcs = np.flatnonzero(is_arc)

    # Segment end points: one per line move, one per chord of an arc, in move order.
    seg_end = np.empty((0, 3))
    seg_move = np.empty(0, dtype=np.int64)
    if arcs.size:
        if "sweep" in moves.dtype.names:
            sweep = moves["sweep"][arcs]
        else:
            sweep = _sweeps(moves[arcs])
        verts, arc_of = arc_chords(start[arcs], end[arcs], moves["center"][arcs],
                                   moves["plane"][arcs], sweep, chord_tol=tol)
        lines = np.flatnonzero(~is_arc)
        seg_end = np.concatenate([end[lines], verts])
        seg_move = np.concatenate([lines, arcs[arc_of]])
        order = np.argsort(seg_move, kind="stable")
        seg_end, seg_move = seg_end[order], seg_move[order]
    else:
        seg_end, seg_move = end, np.arange(n_moves, dtype=np.int64)
    # Each segment starts at the previous vertex of the same move, or at the move's start.
    seg_start = np.empty_like(seg_end)
    if seg_end.shape[0]:
        seg_start[1:] = seg_end[:-1]
        new_move = np.ones(seg_end.shape[0], dtype=bool)
        new_move[1:] = seg_move[1:] != seg_move[:-1]
        seg_start[new_move] = start[seg_move[new_move]]
    xyz, seg = dda(seg_start, seg_end, pitch=pitch)
    mv = seg_move[seg]
    return Positions(xyz=xyz, tool=moves["tool"][mv], move=mv, line=moves["line"][mv])


def _sweeps(arcs: np.ndarray) -> np.ndarray:
    out = np.empty(arcs.shape[0])
    turns = arcs["turns"] if "turns" in arcs.dtype.names else np.zeros(arcs.shape[0], int)
    for i, m in enumerate(arcs):
        a, b, _ = _PLANE_AXES[int(m["plane"])]
        s, e, c = m["start"], m["end"], m["center"]
        out[i] = arc_sweep(s[a], s[b], e[a], e[b], c[a], c[b], int(m["kind"]) == 3,
                           int(turns[i]))
    return out
