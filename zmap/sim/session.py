"""A simulation run: cut a program into a dexel stock, keep a history, go to any stage.

Stages are integers from 0 (the stock) to ``n_stages`` (the end); stage k is the workpiece
after the cutter has moved along the program up to the k-th tool position: each stage cuts
the exact swept volume of the tool along the path since the previous one
(:mod:`zmap.sim.pieces`), so stage k is the exact sweep of the program up to there. The history chosen per run
decides how a stage is read back:

========  =============================  =================================================
history   reconstruct(k) (dexels)        display(k) (top-surface image)
========  =============================  =================================================
none      replay positions 0..k-1        top of the replay
ztrace    z-trace (paper 001 s.3)        top alive Z-element of the z-trace
ttrace    replay positions 0..k-1        time-trace (paper 001 s.4)
treap     Interval Treap (paper 000)     right-most non-empty leaf of the Interval Treap
========  =============================  =================================================
"""

from __future__ import annotations

import math
import os
import re
import time
import warnings
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from ..errors import SimFileError, StageError, ToolError
from .._npzfile import read_npz, write_npz
from ..grid import ZMap
from .dexel import DexelWorkpiece, cutter_table, run_cut
from .history import HISTORY_KINDS, IntervalTreap, Recorder, TimeTrace, ZTrace
from .path import STAGE_MODES
from .pieces import Pieces

__all__ = ["simulate", "Run", "HISTORY_KINDS", "FORMAT_NAME", "FORMAT_VERSION", "parse_stage",
           "stock_from_spec"]

FORMAT_NAME = "zmap.sim.Run"
FORMAT_VERSION = 1

_STRUCTS = {"ztrace": ZTrace, "ttrace": TimeTrace, "treap": IntervalTreap}


# ---- inputs ----------------------------------------------------------------------------------

@dataclass
class _Path:
    xyz: np.ndarray
    tool: np.ndarray
    line: np.ndarray
    n_moves: int | None
    name: str = "the program"
    pieces: Pieces | None = None


def _as_positions(obj: Any, pitch: float, stages: str = "pitch") -> _Path:
    """Tool-tip positions from a program file/text, a Program, a Positions or an (n, 3) array."""
    if isinstance(obj, (str, os.PathLike)):
        from .gcode import parse

        obj = parse(obj)
    name = "the program"
    if hasattr(obj, "moves") and not hasattr(obj, "xyz"):  # a Program
        from .path import positions

        name = str(getattr(obj, "filename", name))
        name = "the program" if name == "<string>" else name
        n_moves = int(len(obj.moves))
        obj = positions(obj, pitch=pitch, stages=stages)
    else:
        n_moves = None
    pieces = None
    if hasattr(obj, "xyz"):  # a Positions
        xyz = np.ascontiguousarray(obj.xyz, dtype=np.float64)
        tool = np.ascontiguousarray(getattr(obj, "tool", np.zeros(len(xyz))), dtype=np.int32)
        line = np.ascontiguousarray(getattr(obj, "line", np.zeros(len(xyz))), dtype=np.int32)
        if n_moves is None and getattr(obj, "move", None) is not None and len(obj.move):
            n_moves = int(np.unique(obj.move).size)
        if getattr(obj, "moves", None) is not None:
            pieces = Pieces.of(obj)
    else:
        xyz = np.asarray(obj, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise ValueError(f"positions must be an array of shape (n, 3), got shape {xyz.shape}")
        xyz = np.ascontiguousarray(xyz)
        tool = np.zeros(len(xyz), dtype=np.int32)
        line = np.zeros(len(xyz), dtype=np.int32)
    if not np.isfinite(xyz).all():
        raise ValueError("tool positions hold NaN or infinite coordinates")
    return _Path(xyz, tool, line, n_moves, name, Pieces.stamps(xyz) if pieces is None else pieces)


def _as_cutter(tool: Any) -> Any:
    if tool is None:
        return None
    if isinstance(tool, str):
        from .tools import parse_tool_spec

        return parse_tool_spec(tool)
    if hasattr(tool, "cutter") and hasattr(tool, "length_offset"):  # a LinuxCNC .tbl entry
        if not tool.diameter > 0:
            raise ToolError(f"tool T{tool.number} has diameter {tool.diameter:g} in the tool "
                            "table: no cutter to simulate")
        return tool.cutter()  # a .tbl has no shape: a flat end mill of its diameter
    if not all(hasattr(tool, a) for a in ("code", "radius", "corner_radius", "length")):
        raise ToolError(f"tool must be a Cutter or a spec like 'ball:3', got {tool!r}")
    return tool


def _resolve_tools(path: _Path, tool: Any, tools: Any) -> tuple[list[int], list[Any], np.ndarray]:
    """Cutter per position: table entry for its tool number, else ``tool``."""
    default = _as_cutter(tool)
    if isinstance(tools, (str, os.PathLike)):
        from .tools import load_tool_table

        tools = load_tool_table(tools)
    table = {int(k): v for k, v in dict(tools or {}).items()}  # entries in use become cutters
    numbers = [int(t) for t in np.unique(path.tool)] if len(path.tool) else [0]
    cutters = []
    for t in numbers:
        if t in table:
            cutters.append(_as_cutter(table[t]))
        elif default is not None:
            cutters.append(default)
        else:
            where = np.nonzero(path.tool == t)[0]
            line = int(path.line[where[0]]) if len(where) else 0
            known = ", ".join(f"T{k}" for k in sorted(table)) or "none"
            raise ToolError(f"tool T{t} (first used at line {line}) is not in the tool table "
                            f"(it has {known}) and no default tool was given")
    slot = np.searchsorted(np.array(numbers), path.tool).astype(np.int32) if len(path.tool) else \
        np.zeros(0, dtype=np.int32)
    return numbers, cutters, np.ascontiguousarray(slot)


def stock_from_spec(spec: Any, *, pitch: float = 0.26, xy_extent: Sequence[float] | None = None) -> DexelWorkpiece:
    """A dexel stock from a box, a ZMap, a file or a text spec.

    Parameters
    ----------
    spec : DexelWorkpiece, ZMap, 6 numbers, str or PathLike
        * ``(x0, y0, z0, x1, y1, z1)`` or ``"box:X0,Y0,Z0,X1,Y1,Z1"``: that box;
        * ``"box:LxWxH"``: an L x W x H box, top at z = 0, centred on ``xy_extent``
          ``(xmin, ymin, xmax, ymax)`` (the program's tool-tip extent) when given, else with
          its corner at the origin;
        * a ZMap or a ``.npz`` file of one: material from below the surface up to it
          (:meth:`DexelWorkpiece.from_zmap`);
        * a DexelWorkpiece: a copy of it.
    pitch : float
        Ray pitch in mm for boxes and maps.
    xy_extent : sequence of 4 floats, optional
        Where to centre a ``box:LxWxH``.

    Examples
    --------
    >>> stock_from_spec("box:10x5x2", pitch=1.0).intervals(0, 0).tolist()
    [[-2.0, 0.0]]
    """
    if isinstance(spec, DexelWorkpiece):
        return spec.copy()
    if isinstance(spec, ZMap):
        return DexelWorkpiece.from_zmap(spec, pitch=pitch)
    if isinstance(spec, (tuple, list, np.ndarray)):
        return DexelWorkpiece.from_box(tuple(float(v) for v in spec), pitch=pitch)
    if isinstance(spec, (str, os.PathLike)):
        s = str(spec).strip()
        if s.lower().startswith("box:"):
            body = s[4:]
            m = re.fullmatch(r"\s*([0-9.eE+]+)\s*[xX]\s*([0-9.eE+]+)\s*[xX]\s*([0-9.eE+]+)\s*", body)
            if m:
                L, W, H = (float(v) for v in m.groups())
                if not all(math.isfinite(v) and v > 0 for v in (L, W, H)):
                    raise ValueError(f"box:LxWxH needs positive sizes, got {s!r}")
                if xy_extent is not None:
                    cx = 0.5 * (xy_extent[0] + xy_extent[2])
                    cy = 0.5 * (xy_extent[1] + xy_extent[3])
                    x0, y0 = cx - L / 2, cy - W / 2
                else:
                    x0, y0 = 0.0, 0.0
                return DexelWorkpiece.from_box((x0, y0, -H, x0 + L, y0 + W, 0.0), pitch=pitch)
            parts = body.split(",")
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                vals = []
            if len(vals) != 6:
                raise ValueError(f"stock {s!r} is not 'box:LxWxH' nor 'box:X0,Y0,Z0,X1,Y1,Z1'")
            return DexelWorkpiece.from_box(vals, pitch=pitch)
        return DexelWorkpiece.from_zmap(ZMap.load(s), pitch=pitch)
    raise ValueError(f"stock must be a box, a ZMap, a .zmap.npz file or a DexelWorkpiece, got {type(spec).__name__}")


def parse_stage(text: Any, n_stages: int) -> int:
    """A stage from an int, ``"end"``, or a fraction of the end like ``"1/2"`` or ``"0.25"``.

    Fractions are rounded down: ``"1/2"`` of 7 stages is 3. Range is checked by the Run.

    Examples
    --------
    >>> parse_stage("1/2", 10), parse_stage("end", 10), parse_stage(3, 10)
    (5, 10, 3)
    """
    if isinstance(text, (int, np.integer)):
        return int(text)
    s = str(text).strip().lower()
    if s in ("end", "last"):
        return int(n_stages)
    if re.fullmatch(r"[+-]?\d+", s):
        return int(s)
    try:
        f = Fraction(s)
    except (ValueError, ZeroDivisionError):
        raise StageError(f"stage {text!r} is not an integer, 'end' or a fraction like 1/2") from None
    if not 0 <= f <= 1:
        raise StageError(f"stage fraction {text!r} must lie in 0..1")
    return int(math.floor(f * n_stages))


def _check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    if value not in choices:
        raise ValueError(f"{name}={value!r} is not one of " + ", ".join(repr(c) for c in choices))
    return value


# ---- the run ---------------------------------------------------------------------------------

@dataclass(eq=False)
class Run:
    """A finished simulation: stock, positions, final workpiece and one history.

    Use :func:`simulate` to make one and :meth:`load` to read one back.

    Attributes
    ----------
    history : str
        'none', 'ztrace', 'ttrace' or 'treap'.
    stock, final : DexelWorkpiece
        Workpiece at stage 0 and at stage ``n_stages``.
    xyz : ndarray of shape (n, 3), float64
        Tool-tip positions in mm; position k-1 makes stage k.
    slot : ndarray of shape (n,), int32
        Index into ``cutters`` per position.
    line : ndarray of shape (n,), int32
        Source line per position (0 when unknown).
    tool_numbers : list of int
        Tool number of each cutter.
    cutters : list of Cutter
    structure : ZTrace, TimeTrace, IntervalTreap or None
    summary : dict
    pieces : Pieces
        The path piece each stage sweeps (stamps for bare positions).
        moves, positions, rays, dexels_created, dexels_deleted, dexels_final, history,
        history_bytes, history_elements, history_bytes_per_element, seconds.
    program_text : str or None
        The G-code the run was made from, when it was given as a file or text (saved in the
        ``.zsim``, so a viewer can quote each stage's line without the file).
    """

    history: str
    stock: DexelWorkpiece
    final: DexelWorkpiece
    xyz: np.ndarray
    slot: np.ndarray
    line: np.ndarray
    tool_numbers: list
    cutters: list
    structure: Any
    summary: dict = field(default_factory=dict)
    pieces: Any = None
    program_text: str | None = None

    def __post_init__(self) -> None:
        if self.pieces is None:
            self.pieces = Pieces.stamps(self.xyz)

    @property
    def n_stages(self) -> int:
        """Index of the last stage (= number of elementary positions)."""
        return int(self.xyz.shape[0])

    def stage(self, value: Any) -> int:
        """Check a stage (int, 'end' or fraction text) and return it as an int."""
        k = parse_stage(value, self.n_stages)
        if not 0 <= k <= self.n_stages:
            raise StageError(f"stage {k} is out of range 0..{self.n_stages}")
        return k

    def _replay(self, k: int) -> DexelWorkpiece:
        wp = self.stock.copy()
        run_cut(wp, self.pieces, self.slot, cutter_table(self.cutters), 0, k, 0, None)
        return wp

    def reconstruct(self, stage: Any) -> DexelWorkpiece:
        """The dexel workpiece as it was at ``stage`` (a new object).

        Examples
        --------
        >>> import numpy as np
        >>> run = simulate(np.array([[1.0, 1.0, -1.0]]), (0, 0, -3, 2, 2, 0), tool="ball:2", pitch=0.5)
        >>> run.reconstruct(0).same_as(run.stock), run.reconstruct(1).same_as(run.final)
        (True, True)
        """
        k = self.stage(stage)
        if self.history in ("ztrace", "treap"):
            off, near, far = self.structure.reconstruct(k)
            s = self.stock
            return DexelWorkpiece.from_csr(s.x0, s.y0, s.pitch, s.nx, s.ny, off, near, far)
        if k == 0:
            return self.stock.copy()
        if k == self.n_stages:
            return self.final.copy()
        return self._replay(k)

    def display(self, stage: Any) -> np.ndarray:
        """Top-surface height image at ``stage``: last FarZ per ray, NaN where no material.

        Returns
        -------
        ndarray of shape (nx, ny), float64, mm; ``[i, j]`` at ``(x0 + i*pitch, y0 + j*pitch)``.
        """
        k = self.stage(stage)
        s = self.stock
        if self.structure is not None:
            return self.structure.display(k).reshape(s.nx, s.ny)
        if k == self.n_stages:
            return self.final.top()
        return self.reconstruct(k).top()

    def animate(self, s1: Any = 0, s2: Any = "end", step: int = 1) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(stage, image)`` from ``s1`` to ``s2`` inclusive, backwards if ``s1 > s2``.

        ``step`` (> 0) is the stage increment; the last frame is always ``s2``.
        """
        a, b = self.stage(s1), self.stage(s2)
        step = int(step)
        if step <= 0:
            raise ValueError(f"step must be a positive integer, got {step}")
        stages = list(range(a, b + 1, step)) if a <= b else list(range(a, b - 1, -step))
        if stages[-1] != b:
            stages.append(b)
        for k in stages:
            yield k, self.display(k)

    def branch(self, stage: Any, program: Any, *, tool: Any = None, tools: Any = None,
               history: str | None = None, progress: bool = False) -> "Run":
        """Continue from the workpiece at ``stage`` with another program: a new Run.

        The new run's stage 0 is this run's ``stage``; its tools default to this run's
        (by tool number, and the cutter active at ``stage`` for positions of other numbers).
        """
        k = self.stage(stage)
        wp = self.reconstruct(k)
        if tools is None:
            tools = dict(zip(self.tool_numbers, self.cutters))
        if tool is None and self.cutters:
            tool = self.cutters[int(self.slot[max(k - 1, 0)])] if self.n_stages else self.cutters[0]
        run = simulate(program, wp, tool=tool, tools=tools, pitch=wp.pitch,
                       history=self.history if history is None else history, progress=progress,
                       stages=self.summary.get("stages", "pitch"))
        run.summary["branched_from_stage"] = k
        return run

    # ---- persistence ----------------------------------------------------------------------

    def _header(self) -> dict:
        s = self.stock
        return {
            "format": FORMAT_NAME, "version": FORMAT_VERSION, "history": self.history,
            "grid": {"x0": s.x0, "y0": s.y0, "pitch": s.pitch, "nx": s.nx, "ny": s.ny},
            "cutters": [{"number": int(n), "kind": c.kind, "diameter": float(c.diameter),
                         "corner_radius": float(c.corner_radius), "length": float(c.length)}
                        for n, c in zip(self.tool_numbers, self.cutters)],
            "final_counts": {"created": self.final.created, "deleted": self.final.deleted},
            "summary": self.summary,
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write the run to a ``.zsim`` file (npz + JSON header), atomically."""
        arrays: dict[str, np.ndarray] = {"xyz": self.xyz, "slot": self.slot, "line": self.line}
        arrays.update({"p_" + k: v for k, v in self.pieces.to_arrays().items()})
        for name, wp in (("stock", self.stock), ("final", self.final)):
            off, near, far = wp.to_csr()
            arrays[f"{name}_off"], arrays[f"{name}_near"], arrays[f"{name}_far"] = off, near, far
        if self.structure is not None:
            for k, v in self.structure.to_arrays().items():
                arrays["h_" + k] = np.asarray(v)
        if self.program_text is not None:
            arrays["program_text"] = np.frombuffer(self.program_text.encode("utf-8"), dtype=np.uint8)

        return write_npz(path, self._header(), arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Run":
        """Read a run written by :meth:`save`; a missing, corrupt or foreign file raises SimFileError."""
        header, arrays = read_npz(path, FORMAT_NAME, FORMAT_VERSION, SimFileError, what=".zsim")
        try:
            return cls._from_arrays(header, arrays)
        except SimFileError:
            raise
        except (KeyError, ValueError, TypeError, IndexError, ToolError) as exc:
            raise SimFileError(str(path), f"invalid content ({type(exc).__name__}: {exc})") from None

    @classmethod
    def _from_arrays(cls, header: dict, a: dict) -> "Run":
        from .tools import Cutter

        g = header["grid"]
        kind = header["history"]
        if kind not in HISTORY_KINDS:
            raise ValueError(f"history {kind!r} unknown")
        nx, ny = int(g["nx"]), int(g["ny"])
        wps = {}
        for name in ("stock", "final"):
            off = a[f"{name}_off"]
            if off.shape != (nx * ny + 1,) or off[-1] != a[f"{name}_near"].shape[0]:
                raise ValueError(f"{name} dexel offsets do not match a {nx}x{ny} ray grid")
            wps[name] = DexelWorkpiece.from_csr(g["x0"], g["y0"], g["pitch"], nx, ny, off,
                                                a[f"{name}_near"], a[f"{name}_far"])
        wps["final"].created = int(header["final_counts"]["created"])
        wps["final"].deleted = int(header["final_counts"]["deleted"])
        cutters = [Cutter(c["kind"], c["diameter"], c["corner_radius"], c["length"]) for c in header["cutters"]]
        numbers = [int(c["number"]) for c in header["cutters"]]
        xyz = np.ascontiguousarray(a["xyz"], dtype=np.float64)
        slot = np.ascontiguousarray(a["slot"], dtype=np.int32)
        if xyz.ndim != 2 or xyz.shape[1] != 3 or slot.shape != (xyz.shape[0],):
            raise ValueError(f"positions have shape {xyz.shape} and tool slots {slot.shape}")
        if len(slot) and (slot.min() < 0 or slot.max() >= len(cutters)):
            raise ValueError("tool slots point outside the cutter list")
        structure = None
        if kind != "none":
            h = {k[2:]: v for k, v in a.items() if k.startswith("h_")}
            if "tiles_layout" in h:  # a tiled run (zmap/sim/tiled.py): one history per tile
                from .tiled import TiledHistory

                structure = TiledHistory.from_arrays(kind, h)
                if (structure.nx, structure.ny) != (nx, ny):
                    raise ValueError(f"tiled history covers {structure.nx}x{structure.ny} rays, the run {nx}x{ny}")
            else:
                structure = _STRUCTS[kind].from_arrays(nx * ny, h)
                off = structure.node_off if kind == "treap" else structure.offsets
                if off.shape != (nx * ny + 1,):
                    raise ValueError(f"history offsets have shape {off.shape}, expected ({nx * ny + 1},)")
        pieces = (Pieces.from_arrays({k[2:]: v for k, v in a.items() if k.startswith("p_")}, len(xyz))
                  if "p_kind" in a else Pieces.stamps(xyz))
        text = (bytes(np.asarray(a["program_text"], dtype=np.uint8)).decode("utf-8", errors="replace")
                if "program_text" in a else None)
        return cls(kind, wps["stock"], wps["final"], xyz, slot, np.ascontiguousarray(a["line"], dtype=np.int32),
                   numbers, cutters, structure, dict(header.get("summary", {})), pieces, text)


# ---- the front door ------------------------------------------------------------------------

def simulate(program_or_positions: Any, stock: Any, *, tool: Any = None, tools: Any = None,
             pitch: float = 0.26, history: str = "treap", progress: bool = False, tiles: int | None = None,
             scheduler: str | None = None, workers: int = 2, stages: str = "pitch") -> Run:
    """Cut an NC program into a stock with the extended z-buffer, recording a history.

    Parameters
    ----------
    program_or_positions : str, PathLike, Program, Positions or ndarray of shape (n, 3)
        A G-code file (or text), a parsed :class:`zmap.sim.gcode.Program`, elementary
        positions from :func:`zmap.sim.path.positions`, or tool-tip positions in mm.
    stock : DexelWorkpiece, ZMap, 6 numbers or str
        See :func:`stock_from_spec`; ``"box:LxWxH"`` is centred on the positions' xy extent.
    tool : Cutter or str, optional
        Cutter for positions whose tool number is not in ``tools`` (e.g. ``"ball:3"``).
    tools : dict of int to Cutter, or path of a TOML tool table, optional
    pitch : float
        Ray pitch and stage spacing in mm (paper: 0.26). It sets the lateral resolution
        (the rays) and how far apart the stages are, never the depth: each stage of a
        program cuts the exact sweep of the tool along the path since the previous stage,
        exact at each ray to 1e-6 mm (heights are stored as float32, rounded up).
        Bare positions (an (n, 3) array) are stamps of the tool, with nothing between.
    history : {'none', 'ztrace', 'ttrace', 'treap'}
    progress : bool
        Show a tqdm progress bar.
    tiles : int, optional
        Simulate in xy tiles of ``tiles`` x ``tiles`` rays as Dask tasks, each tile with its
        own history (:mod:`zmap.sim.tiled`); the Run equals the single-process one exactly
        and assembles the tiles when a stage is asked for.
    scheduler : str, optional
        With ``tiles``: a running Dask scheduler's address; default a LocalCluster of
        ``workers`` worker processes.
    workers : int
        With ``tiles`` and no scheduler: worker processes of the LocalCluster.
    stages : {'pitch', 'move'}
        ``'pitch'`` (default): a stage every pitch along the path; ``'move'``: one stage per
        G-code move (a coarser, smaller history; the same final stock).

    Returns
    -------
    Run

    Warns
    -----
    UserWarning
        When there is no tool position to cut (a program without moves): the run is the
        stock alone. When a move made before the program set all three axes (the tool's
        start is unknown: it is taken to be above the stock, and such moves do not cut)
        ends where the tool would cut the stock: the warning names its file and line.

    Examples
    --------
    >>> import numpy as np
    >>> xyz = np.array([[1.0, 1.0, -0.5], [2.0, 1.0, -0.5]])
    >>> run = simulate(xyz, (0, 0, -2, 3, 2, 0), tool="ball:1", pitch=0.25, history="ttrace")
    >>> run.n_stages, float(np.nanmin(run.display("end")))
    (2, -0.5)
    """
    _check_choice("history", history, HISTORY_KINDS)
    if not (isinstance(pitch, (int, float, np.floating)) and math.isfinite(pitch) and pitch > 0):
        got = float(pitch) if isinstance(pitch, (int, float, np.floating)) else pitch
        raise ValueError(f"pitch must be a positive number of mm, got {got!r}")
    _check_choice("stages", stages, STAGE_MODES)
    path = _as_positions(program_or_positions, float(pitch), stages)
    if len(path.xyz) == 0:
        what = "no moves" if not path.n_moves else f"{path.n_moves} moves but no tool positions"
        warnings.warn(f"{path.name} has {what}; the run is the stock alone", UserWarning, stacklevel=2)
    numbers, cutters, slot = _resolve_tools(path, tool, tools)
    if len(path.xyz):
        lo, hi = path.xyz.min(axis=0), path.xyz.max(axis=0)
        extent = (lo[0], lo[1], hi[0], hi[1])
    else:
        extent = None
    wp = stock_from_spec(stock, pitch=float(pitch), xy_extent=extent)
    _warn_unknown_start(path, wp, cutters, slot)
    stock0 = wp.copy()
    created0, deleted0 = wp.created, wp.deleted
    n = len(path.xyz)
    t0 = time.perf_counter()
    rec = None
    tiled = None
    if tiles is not None or scheduler is not None:  # tiled, on Dask (zmap/sim/tiled.py)
        from .tiled import simulate_tiles

        if tiles is None:
            raise ValueError("scheduler needs tiles (the tiled simulation)")
        wp, structure, tiled = simulate_tiles(wp, path.pieces, slot, cutters, history, tiles=tiles,
                                              scheduler=scheduler, workers=workers, progress=progress)
    else:
        if history != "none":
            struct = _STRUCTS[history].start(wp, capacity=_capacity_guess(history, wp, n))
            rec = Recorder(**{history: struct})
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=n, unit="pos", desc="simulate", leave=False)
        try:
            run_cut(wp, path.pieces, slot, cutter_table(cutters), 0, n, 0, rec, progress=bar)
        finally:
            if bar is not None:
                bar.close()
        structure = None
        if rec is not None:
            rec.finalize()
            structure = getattr(rec, history)
    seconds = time.perf_counter() - t0
    n_elem = (int(getattr(structure, "n_nodes", getattr(structure, "n_elements", 0)))
              if structure is not None else 0)
    summary = {
        "moves": path.n_moves,
        "positions": n,
        "rays": wp.n_rays,
        "dexels_created": wp.created - created0,
        "dexels_deleted": wp.deleted - deleted0,
        "dexels_final": wp.n_dexels,
        "history": history,
        "stages": stages,
        "history_bytes": int(structure.nbytes) if structure is not None else 0,
        "history_elements": n_elem,
        "history_bytes_per_element": round(structure.nbytes / n_elem, 3) if n_elem else 0.0,
        "seconds": round(seconds, 4),
    }
    if tiled is not None:
        summary["tiles"] = tiled
    return Run(history, stock0, wp, path.xyz, slot, path.line, numbers, cutters, structure, summary,
               path.pieces, _program_text(program_or_positions))


def _program_text(obj: Any) -> str | None:
    """The G-code text of a program given as a file, as text or parsed from a file; None for anything else."""
    fname = getattr(obj, "filename", None) if hasattr(obj, "moves") else None
    if isinstance(fname, str) and os.path.isfile(fname):  # a Program read from a file
        obj = fname
    if isinstance(obj, os.PathLike) or (isinstance(obj, str) and "\n" not in obj and os.path.isfile(obj)):
        return Path(obj).read_text(errors="replace")
    return obj if isinstance(obj, str) else None


def _warn_unknown_start(path: _Path, wp: DexelWorkpiece, cutters: list, slot: np.ndarray) -> None:
    """Warn, naming its line, of the first move from an unknown start whose end would cut."""
    from . import _sweep_kernels as _sk

    pieces = path.pieces
    if pieces is None or len(pieces) == 0:
        return
    blind = pieces.kind[pieces.move] == _sk.NO_CUT
    if not blind.any():
        return
    top = wp.top()
    for k in np.flatnonzero(blind):
        if k + 1 < len(pieces) and pieces.move[k + 1] == pieces.move[k]:
            continue  # not the move's end
        c = cutters[int(slot[k])]
        x, y, z = path.xyz[k]
        i = np.clip(np.round((np.array([x - c.radius, x + c.radius]) - wp.x0) / wp.pitch).astype(int), 0, wp.nx - 1)
        j = np.clip(np.round((np.array([y - c.radius, y + c.radius]) - wp.y0) / wp.pitch).astype(int), 0, wp.ny - 1)
        I, J = np.meshgrid(np.arange(i[0], i[1] + 1), np.arange(j[0], j[1] + 1), indexing="ij")
        bottom = z + c.lower_envelope(np.hypot(wp.x0 + I * wp.pitch - x, wp.y0 + J * wp.pitch - y))
        with np.errstate(invalid="ignore"):
            hit = top[I, J] > bottom
        if hit.any():
            where = f"{path.name}:{int(path.line[k])}"
            warnings.warn(f"{where}: this move ends {float(np.nanmax(top[I, J] - bottom)):.3g} mm inside the "
                          "stock, but the tool's start is still unknown (the program has not set X, Y and Z "
                          "yet), so it is taken to come from above and nothing is cut up to here; set all "
                          "three axes (e.g. G0 Z.. then G0 X.. Y..) before cutting", UserWarning, stacklevel=3)
            return


def _capacity_guess(history: str, wp: DexelWorkpiece, n: int) -> int:
    # About one event per ray under the cutter per position, plus the stock itself.
    return int(2 * wp.n_dexels + 24 * n + 1024)
