"""Collisions found from a run's history: rapids that cut, the shank or holder in the stock,
flat cutters plunging straight down into material.

* ``rapid``: a G0 position at whose stage the history records a change of the stock (the
  Interval Treap creates nodes only where material is removed).
* ``plunge``: a flat end mill fed straight down (no xy motion) while material stands under
  its axis above the tip: a flat bottom that is not centre cutting cannot do that.
* ``shank``: material above the cutting length (``tip z + cutter.length``) within the shank
  radius at a position's stage: the non-cutting shank rubs the stock (the simulator removes
  material only up to the cutting length, so it is still there).
* ``holder``: material above ``tip z + stickout`` within the holder's radius. Needs holder
  data: ``[holder.N]`` tables (``stickout``, ``diameter``, ``length``, optional
  ``shank_diameter``, ``units``) in a TOML file, which may be the tool table itself.

Each finding is one :class:`Collision` per move (its first stage), with stage, G-code line
and tip position. Stage-0 tops screen the positions (no cut raises a ray), and the exact
top at the position's stage comes from the treap, ray by ray.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ToolError, ZMapError
from ..sim.tools import numbered_tables

__all__ = ["Collision", "Holder", "collisions", "load_holders", "COLLISION_KINDS"]

COLLISION_KINDS = ("rapid", "plunge", "shank", "holder")
_HOLDER_KEYS = {"stickout", "diameter", "length", "shank_diameter", "units", "description"}


@dataclass(frozen=True)
class Holder:
    """Tool holder and shank of one tool, mm.

    Attributes
    ----------
    stickout : float
        From the tool tip to the holder's face (>= the cutting length).
    diameter : float
        Holder diameter.
    length : float
        Holder length above its face.
    shank_diameter : float or None
        Default: the cutter's diameter.
    """

    stickout: float
    diameter: float
    length: float = 50.0
    shank_diameter: float | None = None

    def __post_init__(self) -> None:
        for name in ("stickout", "diameter", "length"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ToolError(f"holder {name} must be a positive number of mm, got {v!r}")
        if self.shank_diameter is not None and not (math.isfinite(self.shank_diameter) and self.shank_diameter > 0):
            raise ToolError(f"holder shank_diameter must be a positive number of mm, got {self.shank_diameter!r}")


@dataclass(frozen=True)
class Collision:
    """One collision: ``kind`` (rapid, plunge, shank, holder), the first ``stage`` of the move,
    its G-code ``line``, the tip ``x, y, z`` (mm), ``depth`` (mm of material in the way, the
    largest over the move) and ``detail``."""

    kind: str
    stage: int
    line: int
    x: float
    y: float
    z: float
    depth: float
    detail: str

    def as_dict(self) -> dict:
        return {"kind": self.kind, "stage": self.stage, "line": self.line, "x": self.x, "y": self.y,
                "z": self.z, "depth_mm": self.depth, "detail": self.detail}


def load_holders(path: str | os.PathLike) -> dict[int, Holder]:
    """Read ``[holder.N]`` tables of a TOML file (the tool table may hold them too).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.toml"
    >>> _ = p.write_text('[holder.1]\\nstickout = 30\\ndiameter = 20\\nlength = 40\\n')
    >>> load_holders(p)[1].diameter
    20.0
    """
    out: dict[int, Holder] = {}
    for num, e, where, f in numbered_tables(os.fspath(path), "holder", _HOLDER_KEYS, "holder table",
                                            " (stickout, diameter, length)"):
        if "stickout" not in e or "diameter" not in e:
            raise ToolError(f"{where}: needs 'stickout' and 'diameter'")
        try:
            vals = {k: float(e[k]) * f for k in ("stickout", "diameter", "length", "shank_diameter") if k in e}
        except (TypeError, ValueError):
            raise ToolError(f"{where}: values must be numbers") from None
        try:
            out[num] = Holder(**vals)
        except ToolError as err:
            raise ToolError(f"{where}: {err}") from None
    return out


def _move_kinds(run: Any, program: Any) -> tuple[np.ndarray, np.ndarray]:
    """Per position: the move kind (0 rapid, 1 line, 2/3 arcs) and the move index."""
    from ..sim.gcode import parse
    from ..sim.path import positions

    prog = parse(program) if isinstance(program, (str, os.PathLike)) else program
    stages = run.summary.get("stages", "pitch") if isinstance(run.summary, dict) else "pitch"
    pos = positions(prog, pitch=run.stock.pitch, stages=stages)
    if pos.n != run.n_stages or not np.allclose(pos.xyz, run.xyz, atol=1e-9):
        name = getattr(prog, "filename", "the program")
        raise ZMapError(f"{name} does not match the run: it makes {pos.n} tool positions at pitch "
                        f"{run.stock.pitch:g} mm, the run has {run.n_stages}")
    return prog.moves["kind"][pos.move].astype(np.int8), pos.move


def _group(kind: str, idx: np.ndarray, depth: np.ndarray, run: Any, move: np.ndarray, detail: str) -> list:
    """One Collision per move among positions ``idx`` (sorted), at the move's first one."""
    out = []
    if idx.size == 0:
        return out
    mv = move[idx]
    starts = np.flatnonzero(np.r_[True, mv[1:] != mv[:-1]])
    ends = np.r_[starts[1:], idx.size]
    for a, b in zip(starts, ends):
        p = int(idx[a])
        x, y, z = (float(v) for v in run.xyz[p])
        out.append(Collision(kind, p + 1, int(run.line[p]), x, y, z, float(depth[a:b].max()), detail))
    return out


def collisions(run: Any, program: Any, *, holders: Any = None, kinds: Any = COLLISION_KINDS,
               clearance: float = 0.0) -> list[Collision]:
    """Find rapids that cut, plunges of flat cutters, shank and holder contacts.

    Parameters
    ----------
    run : zmap.sim.session.Run
        Simulated with ``history="treap"``.
    program : str, PathLike or Program
        The program of the run (for move kinds).
    holders : dict of int to Holder, or path of a TOML file with ``[holder.N]`` tables —
        needed for the ``holder`` check, for every tool the run uses.
    kinds : sequence of {"rapid", "plunge", "shank", "holder"}
    clearance : float
        mm; material closer than this to the shank or holder counts too.

    Returns
    -------
    list of Collision, by stage.

    Raises
    ------
    ToolError
        ``holder`` asked for and a tool the run uses has no holder data.
    ZMapError
        The run has no treap history, or the program does not match the run.
    """
    from . import _verify_kernels as K

    kinds = tuple(kinds)
    for k in kinds:
        if k not in COLLISION_KINDS:
            raise ValueError(f"collision kind {k!r} is not one of " + ", ".join(map(repr, COLLISION_KINDS)))
    if run.history != "treap":
        raise ZMapError(f"collision checks read the Interval Treap: simulate with history='treap' "
                        f"(this run has {run.history!r})")
    if "holder" in kinds:
        if holders is None:
            raise ToolError("holder collisions need holder data (stickout, diameter, length) for tools "
                            + ", ".join(f"T{n}" for n in run.tool_numbers)
                            + ": give a holder table with [holder.N] tables (zmap compare --holders FILE; "
                            "holders= here), or skip the holder check (zmap compare --no-holder; "
                            "kinds= without 'holder' here)")
        if isinstance(holders, (str, os.PathLike)):
            holders = load_holders(holders)
        missing = [n for n in run.tool_numbers if n not in holders]
        if missing:
            raise ToolError("no holder data for tool " + ", ".join(f"T{n}" for n in missing)
                            + f" (holder tables have {', '.join(f'T{n}' for n in sorted(holders)) or 'none'}): "
                            + "add " + ", ".join(f"[holder.{n}]" for n in missing)
                            + " to the holder table (zmap compare --holders FILE), or skip the holder "
                            "check (zmap compare --no-holder)")
    st = run.structure
    n = run.n_stages
    found: list[Collision] = []
    if n == 0:
        return found
    kind, move = _move_kinds(run, program)
    changed = np.zeros(n + 1, dtype=bool)
    ns = st.stage[st.stage > 0]
    changed[ns[ns <= n]] = True
    stage_of = np.arange(1, n + 1)
    s = run.stock
    m = int(np.diff(st.node_off).max()) + 2
    stacks = (np.empty(m, dtype=np.int64), np.empty(m, dtype=np.float32), np.empty(m, dtype=np.float32))
    targs = (st.node_off, st.root_off, st.root_hi, st.z, st.stage, st.kids)

    if "rapid" in kinds:
        idx = np.flatnonzero((kind == 0) & changed[1:])
        found += _group("rapid", idx, np.zeros(idx.size), run, move, "G0 removes material")
    if "plunge" in kinds:
        xyz = run.xyz
        prev = np.vstack([xyz[:1], xyz[:-1]])
        vertical = (np.abs(xyz[:, 0] - prev[:, 0]) < 1e-9) & (np.abs(xyz[:, 1] - prev[:, 1]) < 1e-9) & \
                   (xyz[:, 2] < prev[:, 2] - 1e-9)
        flat = np.array([c.kind == "flat" for c in run.cutters])[run.slot]
        cand = np.flatnonzero(vertical & flat & (kind != 0) & changed[1:])
        if cand.size:
            out = np.empty(cand.size)
            rad = np.array([run.cutters[run.slot[p]].radius for p in cand])
            # material under the axis before the position, above its tip
            for r in np.unique(rad):
                sel = rad == r
                K.treap_disk_above(*targs, np.ascontiguousarray(xyz[cand[sel]]), (stage_of[cand[sel]] - 1).astype(np.int32),
                                   s.x0, s.y0, s.pitch, s.nx, s.ny, min(0.25 * r, 0.5 * s.pitch + 1e-9) if r > 0 else 0.0,
                                   1e-6, out_ := np.empty(int(sel.sum())), *stacks)
                out[sel] = out_
            hit = out > 0
            found += _group("plunge", cand[hit], out[hit], run, move,
                            "flat end mill fed straight down into material")
    top0 = np.asarray(run.display(0), dtype=np.float64).ravel()
    checks = []
    if "shank" in kinds:
        for q, (num, c) in enumerate(zip(run.tool_numbers, run.cutters)):
            h = holders.get(num) if isinstance(holders, dict) else None
            sd = (h.shank_diameter if h is not None and h.shank_diameter else c.diameter)
            checks.append(("shank", q, sd / 2 + clearance, c.length - clearance,
                           f"shank (d {sd:g} mm) above the cutting length {c.length:g} mm touches the stock"))
    if "holder" in kinds:
        for q, num in enumerate(run.tool_numbers):
            h = holders[num]
            checks.append(("holder", q, h.diameter / 2 + clearance, h.stickout - clearance,
                           f"holder (d {h.diameter:g} mm, stickout {h.stickout:g} mm) touches the stock"))
    for what, q, radius, lift, detail in checks:
        pos = np.flatnonzero(run.slot == q)
        if pos.size == 0:
            continue
        xyz = np.ascontiguousarray(run.xyz[pos])
        screen = np.empty(pos.size)
        K.holder_hits(xyz, top0, s.x0, s.y0, s.pitch, s.nx, s.ny, radius, lift, screen)
        cand = np.flatnonzero(screen > 0)
        if cand.size == 0:
            continue
        exact = np.empty(cand.size)
        K.treap_disk_above(*targs, np.ascontiguousarray(xyz[cand]), stage_of[pos[cand]].astype(np.int32),
                           s.x0, s.y0, s.pitch, s.nx, s.ny, radius, lift, exact, *stacks)
        hit = exact > 0
        found += _group(what, pos[cand[hit]], exact[hit], run, move, detail)
    found.sort(key=lambda c: (c.stage, c.kind))
    return found
