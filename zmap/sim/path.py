"""Moves to the stages of a simulation: tool positions at most one pitch apart on the path.

Paper 001 §2: a toolpath is discretised into elementary positions of the tool by a 3D DDA
(Bresenham's algorithm generalised to 3D); the successive positions are the stages of the
simulation. Here every straight move from ``a`` to ``b`` is cut into ``n = ceil(max(|b -
a|) / pitch)`` equal steps: the dominant axis advances by at most ``pitch`` per position
(one ray spacing), the other axes follow proportionally, and the last position is ``b``
exactly. Arcs and helices (any plane, multi-turn) are cut into equal steps of their angle,
no longer than ``pitch`` along the path; their positions lie on the arc (no chords).
``stages="move"`` makes one position per move instead.

Stage ``k`` (1..n) is the state after the cutter has moved to ``xyz[k-1]``: it cuts the
exact swept volume of the tool along the path from the previous position
(:mod:`zmap.sim.pieces`), so the pitch sets only how far apart the stages are, never the
depth of the cut. Stage 0 is the stock.

Limits: the number of positions is computed in float64 before
anything is allocated; above ``max_positions`` (default :data:`DEFAULT_MAX_POSITIONS`,
2e8) or above 80 % of the memory available, :class:`zmap.errors.PathTooLargeError` names
the line of the move that crosses the limit. Non-finite coordinates and negative tool
numbers raise :class:`zmap.errors.PathError` naming their line.

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

from ..errors import PathError, PathTooLargeError
from ..fmt import count, size
from ..memory import MEMORY_SHARE, memory_limit
from .gcode import ARC_CW, KNOWN_ALL, MOVE_DTYPE, Program, _PLANE_AXES, arc_sweep

__all__ = ["DEFAULT_MAX_POSITIONS", "STAGE_MODES", "Positions", "arc_chords", "dda", "positions"]

#: Default cap on the tool positions of one program: 2e8 positions (7.2 GB of
#: :class:`Positions`, about 24 GB of working memory while they are made) is a 1 m x 1 m
#: raster at 0.26 mm stepover and pitch, cut 13 times.
DEFAULT_MAX_POSITIONS = 200_000_000

# Peak working memory of positions() per tool position, bytes (tracemalloc: 96 for lines,
# 122 for short arc chords; the result itself is 36).
_POSITION_BYTES = 120
# Below this estimate, memory is not asked for (reading /proc costs more than the DDA).
_MEMORY_CHECK_BYTES = 256 * 1024**2
_MOVE_NAMES = {0: "G0", 1: "G1", 2: "G2", 3: "G3"}


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
    moves : ndarray of MOVE_DTYPE, optional
        The program's moves (the geometry each stage sweeps); None for bare positions,
        which are stamps of the tool.
    """

    xyz: np.ndarray
    tool: np.ndarray
    move: np.ndarray
    line: np.ndarray
    moves: np.ndarray | None = None

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
        raise ValueError(f"{name} must be a positive finite number, got {f!r}")
    return f


def dda(a: Any, b: Any, *, pitch: float,
        max_positions: float = DEFAULT_MAX_POSITIONS) -> tuple[np.ndarray, np.ndarray]:
    """3D DDA of straight segments: positions after ``a`` up to ``b`` inclusive.

    Parameters
    ----------
    a, b : array_like of shape (m, 3)
        Segment starts and ends (mm).
    pitch : float, keyword-only
        Largest step of the dominant axis (mm), the ray spacing.
    max_positions : float, keyword-only
        Most positions allowed (default :data:`DEFAULT_MAX_POSITIONS`); counted in float64
        before anything is allocated.

    Returns
    -------
    xyz : ndarray of shape (n, 3), float64
        Positions, segment after segment; each segment ends exactly at its ``b``; a
        zero-length segment contributes none.
    seg : ndarray of shape (n,), int64
        Segment index of each position.

    Raises
    ------
    zmap.errors.PathError
        A non-finite end point (``PathTooLargeError``: more than ``max_positions``).

    Examples
    --------
    >>> xyz, seg = dda([[0, 0, 0]], [[1, 0.5, 0]], pitch=0.5)
    >>> xyz.tolist(), seg.tolist()
    ([[0.5, 0.25, 0.0], [1.0, 0.5, 0.0]], [0, 0])
    """
    pitch = _check_positive("pitch", pitch)
    cap = _check_cap(max_positions)
    a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape, got {a.shape} and {b.shape}")
    bad = ~(np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1))
    if bad.any():
        i = int(np.argmax(bad))
        raise PathError("<dda>", 0, f"segment {i} has a non-finite end point: "
                        f"a={a[i].tolist()}, b={b[i].tolist()}")
    d, steps = _dda_steps(a, b, pitch)
    total = float(steps.sum())
    if not total <= cap:
        i = int(np.argmax(np.cumsum(steps) > cap))
        raise PathTooLargeError(
            "<dda>", 0, f"segments need {total:.3g} positions at pitch {pitch:g} mm, more than "
            f"max_positions={cap:.3g} (segment {i} alone needs {steps[i]:.3g})", total, cap)
    return _dda_fill(a, b, d, steps.astype(np.int64))


def _dda_steps(a: np.ndarray, b: np.ndarray, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Differences and DDA step counts (float64, uncapped: no integer overflow) of segments."""
    with np.errstate(over="ignore"):  # finite ends far apart: inf steps, refused by the cap
        d = b - a
        ad = np.abs(d)
        linf = np.maximum(np.maximum(ad[:, 0], ad[:, 1]), ad[:, 2])  # faster than max(axis=1)
        steps = np.ceil(linf / pitch - 1e-9)
    steps[linf == 0] = 0.0
    return d, np.maximum(steps, linf > 0)


def _dda_fill(a: np.ndarray, b: np.ndarray, d: np.ndarray,
              steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The DDA positions for int64 ``steps`` already checked against the cap."""
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
               chord_tol: float,
               max_vertices: float = DEFAULT_MAX_POSITIONS) -> tuple[np.ndarray, np.ndarray]:
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
    max_vertices : float, keyword-only
        Most vertices allowed (default :data:`DEFAULT_MAX_POSITIONS`); counted in float64
        before anything is allocated.

    Returns
    -------
    vertices : ndarray of shape (k, 3), float64
        Chord end points, arc after arc, the start excluded and the end included exactly.
        Between them the radius and the normal coordinate vary linearly with the angle (so
        a circle's vertices lie on it; a helix's on the helix).
    arc : ndarray of shape (k,), int64
        Arc index of each vertex.

    Raises
    ------
    zmap.errors.PathError
        A non-finite input (``PathTooLargeError``: more than ``max_vertices``).

    Examples
    --------
    >>> v, _ = arc_chords([[1, 0, 0]], [[-1, 0, 0]], [[0, 0, 0]], [17], [np.pi], chord_tol=0.3)
    >>> np.round(v, 6).tolist()
    [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
    """
    tol = _check_positive("chord_tol", chord_tol)
    cap = _check_cap(max_vertices)
    s = np.asarray(start, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(end, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(center, dtype=np.float64).reshape(-1, 3)
    pl = np.asarray(plane).reshape(-1)
    sw = np.asarray(sweep, dtype=np.float64).reshape(-1)
    bad = ~np.isin(pl, list(_PLANE_AXES))
    if bad.any():
        raise ValueError(f"plane must be 17, 18 or 19, got {pl[bad][0].item()!r}")
    bad = ~(np.isfinite(s).all(axis=1) & np.isfinite(e).all(axis=1)
            & np.isfinite(c).all(axis=1) & np.isfinite(sw))
    if bad.any():
        i = int(np.argmax(bad))
        raise PathError("<arc_chords>", 0, f"arc {i} has a non-finite start, end, centre or "
                        f"sweep: {s[i].tolist()}, {e[i].tolist()}, {c[i].tolist()}, {float(sw[i])!r}")
    g = _ArcGeometry(s, e, c, pl, sw, tol)
    total = float(g.nseg.sum())
    if not total <= cap:
        i = int(np.argmax(np.cumsum(g.nseg) > cap))
        raise PathTooLargeError(
            "<arc_chords>", 0, f"arcs need {total:.3g} chords at chord_tol {tol:g} mm, more "
            f"than max_vertices={cap:.3g} (arc {i} alone needs {g.nseg[i]:.3g})", total, cap)
    return g.vertices()


class _ArcGeometry:
    """Per-arc radii, axes and chord counts (float64, uncapped); vertices on demand."""

    def __init__(self, s: np.ndarray, e: np.ndarray, c: np.ndarray, pl: np.ndarray,
                 sw: np.ndarray, tol: float):
        m = s.shape[0]
        ax = np.empty((m, 3), dtype=np.int64)
        for p, axes in _PLANE_AXES.items():
            ax[pl == p] = axes
        rows = np.arange(m)
        ia, ib, inn = ax[:, 0], ax[:, 1], ax[:, 2]
        # extreme finite coordinates may overflow to inf here: inf chords, refused by the cap
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            da0, db0 = s[rows, ia] - c[rows, ia], s[rows, ib] - c[rows, ib]
            da1, db1 = e[rows, ia] - c[rows, ia], e[rows, ib] - c[rows, ib]
            r0 = np.hypot(da0, db0)
            r1 = np.hypot(da1, db1)
            rmax = np.maximum(r0, r1)
            cosv = np.clip(1.0 - tol / rmax, -1.0, 1.0)
            dmax = np.minimum(2.0 * np.arccos(cosv), np.pi / 2)
            # a radius so large that 1 - tol/r rounds to 1: 2 acos(1 - x) = 4 asin(sqrt(x/2))
            dmax = np.where(dmax > 0, dmax, 4.0 * np.arcsin(np.sqrt(0.5 * tol / rmax)))
            dmax = np.where(rmax > 0, dmax, np.pi / 2)
            ratio = np.where(sw == 0, 0.0, np.abs(sw) / dmax)
        ratio = np.where(np.isnan(ratio), np.inf, ratio)
        self.nseg = np.maximum(np.ceil(ratio - 1e-9), 1.0)
        self.s, self.e, self.c, self.sw = s, e, c, sw
        self.ia, self.ib, self.inn = ia, ib, inn
        self.da0, self.db0, self.r0, self.r1 = da0, db0, r0, r1

    def path_steps(self, pitch: float) -> np.ndarray:
        """Positions of each arc at most ``pitch`` apart along the path (float64, >= 1): its
        length is at most ``hypot(|sweep| * max radius, normal travel) + |radius change|``."""
        with np.errstate(over="ignore", invalid="ignore"):
            normal = np.abs(self.e[np.arange(self.e.shape[0]), self.inn]
                            - self.s[np.arange(self.s.shape[0]), self.inn])
            length = (np.hypot(np.abs(self.sw) * np.maximum(self.r0, self.r1), normal)
                      + np.abs(self.r1 - self.r0))
            n = np.ceil(length / pitch - 1e-9)
        n = np.where(np.isnan(n), np.inf, n)
        return np.maximum(n, 1.0)

    def points(self, row: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Points of arcs ``row`` at parameters ``t`` (angle, radius and normal coordinate
        linear in t), as the sweep kernels evaluate them."""
        ia, ib, inn = self.ia[row], self.ib[row], self.inn[row]
        c, s, e = self.c[row], self.s[row], self.e[row]
        ang = np.arctan2(self.db0, self.da0)[row] + self.sw[row] * t
        rad = self.r0[row] + (self.r1 - self.r0)[row] * t
        rr = np.arange(row.shape[0])
        v = np.empty((row.shape[0], 3), dtype=np.float64)
        v[rr, ia] = c[rr, ia] + rad * np.cos(ang)
        v[rr, ib] = c[rr, ib] + rad * np.sin(ang)
        v[rr, inn] = s[rr, inn] + (e[rr, inn] - s[rr, inn]) * t
        return v

    def vertices(self) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(over="ignore", invalid="ignore"):  # extreme finite input: refused later
            return self._vertices()

    def _vertices(self) -> tuple[np.ndarray, np.ndarray]:
        nseg = self.nseg.astype(np.int64)
        s, e, c, sw = self.s, self.e, self.c, self.sw
        ia, ib, inn = self.ia, self.ib, self.inn
        r0, r1 = self.r0, self.r1
        arc = np.repeat(np.arange(s.shape[0]), nseg)
        first = np.cumsum(nseg) - nseg
        k = np.arange(int(nseg.sum()), dtype=np.int64) - first[arc] + 1
        frac = k / nseg[arc]
        ang = np.arctan2(self.db0, self.da0)[arc] + sw[arc] * frac
        rad = r0[arc] + (r1 - r0)[arc] * frac
        v = np.empty((arc.shape[0], 3), dtype=np.float64)
        rr = np.arange(arc.shape[0])
        v[rr, ia[arc]] = c[arc, ia[arc]] + rad * np.cos(ang)
        v[rr, ib[arc]] = c[arc, ib[arc]] + rad * np.sin(ang)
        v[rr, inn[arc]] = s[arc, inn[arc]] + (e[arc, inn[arc]] - s[arc, inn[arc]]) * frac
        last = k == nseg[arc]
        v[last] = e[arc[last]]
        return v, arc


STAGE_MODES = ("pitch", "move")


def positions(program_or_moves: Program | np.ndarray, *, pitch: float = 0.26,
              chord_tol: float | None = None,
              max_positions: float = DEFAULT_MAX_POSITIONS, stages: str = "pitch") -> Positions:
    """Tool-tip positions (the stages) of a program: at most one pitch apart along the path.

    Parameters
    ----------
    program_or_moves : Program or ndarray of MOVE_DTYPE
        Parsed program (see :func:`zmap.sim.gcode.parse`) or its ``moves``. A moves array
        without a ``sweep`` field has its arc angles computed as LinuxCNC does.
    pitch : float, keyword-only
        Largest step between consecutive positions, mm (default 0.26, the paper's ray
        spacing): on a line the dominant axis advances by at most ``pitch`` (3D DDA); on an
        arc or helix the positions split its angle into equal steps no longer than
        ``pitch`` along the path. Rapids (G0) are cut too: a rapid into material is a
        collision to show.
    chord_tol : float, optional, keyword-only
        Kept for compatibility and checked (> 0), but no longer used: arcs are cut as arcs.
    max_positions : float, keyword-only
        Most positions allowed (default :data:`DEFAULT_MAX_POSITIONS`, 2e8; ``math.inf``
        leaves only the memory check). The count is computed in float64 from the moves
        before positions are allocated.
    stages : {"pitch", "move"}, keyword-only
        ``"pitch"`` (default): positions at most one pitch apart, as above; ``"move"``: one
        position per move, at its end (a coarser, smaller history). Either way each stage
        cuts the exact sweep of the path since the previous one
        (:class:`zmap.sim.pieces.Pieces`).

    Returns
    -------
    Positions
        In move order; each move ends exactly on its end point; zero-length moves add none.
        ``moves`` holds the program's moves, the geometry of the pieces.

    Raises
    ------
    zmap.errors.PathError
        A move with a non-finite start, end, centre or sweep, an arc plane other than 17, 18,
        19, or a negative tool number; the message starts ``file:line:``.
    zmap.errors.PathTooLargeError
        More positions than ``max_positions``, or than 80 % of the memory available takes;
        the message gives the estimate and the line of the move that crosses the limit.

    Examples
    --------
    >>> from zmap.sim.gcode import parse
    >>> p = positions(parse("G0 X0 Y0 Z1\\nG1 X0.5 F100\\n"), pitch=0.26)
    >>> len(p), p.move.tolist()[-2:], p.xyz[-1].tolist()
    (6, [1, 1], [0.5, 0.0, 1.0])
    >>> len(positions(parse("G0 X0 Y0 Z1\\nG1 X0.5 F100\\n"), stages="move"))
    2
    >>> positions(parse("G0 X1000\\n", filename="fine.nc"), pitch=1e-6)
    Traceback (most recent call last):
    ...
    zmap.errors.PathTooLargeError: fine.nc:1: this program needs 1e+09 tool positions ...
    """
    pitch = _check_positive("pitch", pitch)
    if chord_tol is not None:
        _check_positive("chord_tol", chord_tol)
    _check_stages(stages)
    cap = _check_cap(max_positions)
    is_program = isinstance(program_or_moves, Program)
    moves = program_or_moves.moves if is_program else program_or_moves
    if not isinstance(moves, np.ndarray) or moves.dtype.names is None:
        raise TypeError("program_or_moves must be a Program or a structured moves array, "
                        f"got {type(program_or_moves).__name__}")
    missing = {"kind", "start", "end", "center", "plane", "tool", "line"} - set(moves.dtype.names)
    if missing:
        raise ValueError(f"moves lack fields {sorted(missing)}; expected {MOVE_DTYPE.names}")
    fname = program_or_moves.filename if is_program else "<moves>"
    kind = moves["kind"]
    start = np.ascontiguousarray(moves["start"], dtype=np.float64)
    end = np.ascontiguousarray(moves["end"], dtype=np.float64)
    is_arc = kind >= ARC_CW
    arcs = np.flatnonzero(is_arc)
    sweep = None
    if arcs.size:
        if "sweep" in moves.dtype.names:
            sweep = np.asarray(moves["sweep"][arcs], dtype=np.float64)
        else:
            sweep = _sweeps(moves[arcs])
    _check_moves(moves, start, end, arcs, sweep, fname)

    # Count before allocating, in float64 so that no count can overflow.
    d, steps = _dda_steps(start, end, pitch)
    geom = None
    if arcs.size:
        geom = _ArcGeometry(start[arcs], end[arcs], np.asarray(moves["center"][arcs], np.float64),
                            np.asarray(moves["plane"][arcs]), sweep, pitch / 10.0)
        steps[arcs] = geom.path_steps(pitch)
    if stages == "move":
        steps = np.minimum(steps, 1.0)
    _check_size(steps, moves["line"], fname, pitch, cap)
    xyz, mv = _dda_fill(start, end, d, steps.astype(np.int64))
    if geom is not None:
        on_arc = is_arc[mv]
        arc_row = np.searchsorted(arcs, mv[on_arc])
        n_arc = steps[arcs].astype(np.int64)
        first = np.cumsum(steps.astype(np.int64)) - steps.astype(np.int64)
        j = np.arange(xyz.shape[0], dtype=np.int64)[on_arc] - first[mv[on_arc]] + 1
        xyz[on_arc] = geom.points(arc_row, j / n_arc[arc_row])
        last = j == n_arc[arc_row]
        rows = np.flatnonzero(on_arc)[last]
        xyz[rows] = end[mv[rows]]
    # a copy with the sweeps: the pieces' geometry
    mv_moves = moves if "sweep" in moves.dtype.names or not arcs.size else _with_sweep(moves, arcs, sweep)
    return Positions(xyz=xyz, tool=moves["tool"][mv], move=mv, line=moves["line"][mv], moves=mv_moves)


def _with_sweep(moves: np.ndarray, arcs: np.ndarray, sweep: np.ndarray) -> np.ndarray:
    out = np.zeros(moves.shape[0], dtype=MOVE_DTYPE)
    for name in moves.dtype.names:
        if name in MOVE_DTYPE.names:
            out[name] = moves[name]
    out["sweep"] = np.nan
    out["sweep"][arcs] = sweep
    if "known" not in moves.dtype.names:  # a moves array of before the field: every move cuts
        out["known"] = KNOWN_ALL
    return out


def _check_stages(stages: Any) -> str:
    if stages not in STAGE_MODES:
        raise ValueError(f"stages={stages!r} is not one of " + ", ".join(repr(m) for m in STAGE_MODES))
    return stages


def _check_cap(v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"max_positions must be a number >= 1, got {v!r}") from None
    if not f >= 1:
        raise ValueError(f"max_positions must be a number >= 1, got {f!r}")
    return f


def _move_name(moves: np.ndarray, i: int) -> str:
    return _MOVE_NAMES.get(int(moves["kind"][i]), f"kind {int(moves['kind'][i])}")


def _where(moves: np.ndarray, i: int, fname: str) -> tuple[str, int, str]:
    """(file, line, prefix) of move ``i``: the prefix names the move when its line is 0."""
    line = int(moves["line"][i])
    return fname, line, "" if line > 0 else f"move {i}: "


def _check_moves(moves: np.ndarray, start: np.ndarray, end: np.ndarray, arcs: np.ndarray,
                 sweep: np.ndarray | None, fname: str) -> None:
    """PathError for the first move with a non-finite input, a bad plane or a negative tool."""
    finite = bool(np.isfinite(start).all() and np.isfinite(end).all())
    if arcs.size:
        center = np.asarray(moves["center"][arcs], dtype=np.float64)
        finite = finite and bool(np.isfinite(center).all() and np.isfinite(sweep).all())
        plane = np.asarray(moves["plane"][arcs])
        badp = ~np.isin(plane, list(_PLANE_AXES))
        if badp.any():
            i = int(arcs[np.argmax(badp)])
            file, line, pre = _where(moves, i, fname)
            raise PathError(file, line, f"{pre}{_move_name(moves, i)} arc in plane "
                            f"{int(moves['plane'][i])}, expected 17, 18 or 19")
    if not finite:
        bad = ~(np.isfinite(start).all(axis=1) & np.isfinite(end).all(axis=1))
        if arcs.size:
            bad[arcs] |= ~(np.isfinite(center).all(axis=1) & np.isfinite(sweep))
        i = int(np.argmax(bad))
        file, line, pre = _where(moves, i, fname)
        parts = [("end", end[i]), ("start", start[i])]
        is_arc_i = bool(np.isin(i, arcs))
        if is_arc_i:
            j = int(np.searchsorted(arcs, i))
            parts += [("centre", moves["center"][i]), ("sweep", np.array([sweep[j]]))]
        what = ", ".join(f"{n} {np.asarray(v).tolist()}" for n, v in parts
                         if not np.isfinite(v).all())
        raise PathError(file, line, f"{pre}{_move_name(moves, i)} {'arc' if is_arc_i else 'move'}"
                        f" with a non-finite {what}; tool positions need finite coordinates")
    tool = moves["tool"]
    if n := int(np.count_nonzero(tool < 0)):
        i = int(np.argmax(tool < 0))
        file, line, pre = _where(moves, i, fname)
        raise PathError(file, line, f"{pre}{_move_name(moves, i)} move with tool number "
                        f"{int(tool[i])} (negative; {n} such moves): tool numbers are >= 0")


def _check_size(per_move: np.ndarray, line: np.ndarray, fname: str, pitch: float,
                cap: float) -> None:
    """PathTooLargeError when the positions estimated per move (float64) exceed the cap or
    80 % of the memory available, naming the line of the move where the sum crosses it."""
    cum = np.cumsum(per_move)
    total = float(cum[-1]) if cum.size else 0.0
    if math.isnan(total):  # inf - inf or 0 * inf of extreme (finite) coordinates: too many
        per_move = np.where(np.isnan(per_move), np.inf, per_move)
        cum = np.cumsum(per_move)
        total = math.inf
    need = total * _POSITION_BYTES
    if total <= cap and need <= _MEMORY_CHECK_BYTES:
        return
    limit, why = cap, f"more than the cap of {cap:.3g} (max_positions)"
    if total <= cap:
        room, avail = memory_limit()
        if need <= room:
            return
        limit = room / _POSITION_BYTES
        why = (f"more than the {count(limit)} that fit in {MEMORY_SHARE:.0%} of the {size(avail)} of "
               "memory available")
    i = int(np.argmax(cum > limit))
    ln = int(line[i])
    where = "" if ln > 0 else f"move {i}: "
    alone = float(per_move[i])
    raise PathTooLargeError(
        fname, ln,
        f"{where}this program needs {count(total)} tool positions at pitch {pitch:g} mm, {why} "
        f"(about {size(need)}); it crosses that limit at this move, which alone needs "
        f"{count(alone)}: check its coordinates and units, or use a coarser pitch, or raise "
        "max_positions", total, cap)


def _sweeps(arcs: np.ndarray) -> np.ndarray:
    out = np.empty(arcs.shape[0])
    turns = arcs["turns"] if "turns" in arcs.dtype.names else np.zeros(arcs.shape[0], int)
    for i, m in enumerate(arcs):
        a, b, _ = _PLANE_AXES[int(m["plane"])]
        s, e, c = m["start"], m["end"], m["center"]
        out[i] = arc_sweep(s[a], s[b], e[a], e[b], c[a], c[b], int(m["kind"]) == 3,
                           int(turns[i]))
    return out
