"""Raster (zig-zag) finishing programs from the CL surface of a design.

Passes run along the direction ``angle`` (radians from +x) and step across by ``stepover``;
each pass is sampled every ``step`` mm, dropped onto the design with :func:`drop_cutter`
(never below the true CL height: the CL points do not gouge), then thinned with a chord
tolerance: a point is left out only if the straight feed that replaces it stays within ``tol``
above every dropped CL height it spans and never below one. Between two CL points a feed can
still pass under the CL surface (by ``chord**2 / (8 r)`` over a convex edge for a cutter of
corner radius ``r``): where it would by more than ``sag`` at a quarter, half or three
quarters of the way (a steep stretch, a wall's top edge), the middle is dropped and added. Where no surface lies under the
cutter a pass is broken, or the empty space is a floor (``outside``). Two pass ends within two
stepovers are joined by a feed along the CL surface (the cutter dropped every ``step`` across,
sag-tested and thinned like a pass) where design lies under all of the way; otherwise by a
safe retract: G0 up to the clearance height, G0 across, and a feed down at the plunge rate.

The program is plain RS274 that LinuxCNC and GRBL both take: G21 G90 G17, G0/G1 with X Y Z,
F and S words, M3/M5/M2, comments in parentheses naming the tool, the parameters and the
predicted scallop height.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..grid import ZMap, atomic_write
from ..gridspec import lines_within
from .drop import as_cutter, drop_cutter

__all__ = ["raster_program", "RasterProgram", "scallop_height", "simplify_chords"]


def scallop_height(cutter: Any, stepover: float) -> float:
    """Scallop (cusp) height in mm left between two parallel passes on a flat floor.

    Ball: ``R - sqrt(R^2 - (s/2)^2)``; flat: 0 (for ``s <= D``); bull: 0 while ``s`` is within
    the flat bottom ``2 (R - r)``, then the torus' cusp.

    Examples
    --------
    >>> round(scallop_height("ball:6", 0.4), 6)
    0.006674
    >>> scallop_height("flat:6", 2.0)
    0.0
    """
    c = as_cutter(cutter)
    s = float(stepover)
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"stepover must be a positive number of mm, got {stepover!r}")
    if s > c.diameter:
        raise ValueError(f"stepover {s:g} mm is more than the cutter diameter {c.diameter:g} mm")
    R, rc = c.radius, c.corner_radius
    flat = 2.0 * (R - rc)
    if c.code == 0 or s <= flat:
        return 0.0
    h = (s - flat) / 2.0
    return float(rc - math.sqrt(max(rc * rc - h * h, 0.0)))


def simplify_chords(u: np.ndarray, z: np.ndarray, tol: float, below: float | None = None) -> np.ndarray:
    """Indices of the points to keep so that each straight chord between kept points stays
    within ``tol`` above and ``below`` below (default ``tol``) every point it spans
    (Douglas-Peucker on (u, z)); a finishing program passes ``below=0``: no chord under a CL
    point.

    Examples
    --------
    >>> u = np.linspace(0, 1, 11)
    >>> simplify_chords(u, 0 * u, 1e-3).tolist()
    [0, 10]
    >>> simplify_chords(u, -np.abs(u - 0.5), 1.0, below=0.0).tolist()   # a ridge stays
    [0, 5, 10]
    """
    below = tol if below is None else below
    n = len(u)
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        uu = u[a + 1:b]
        t = (uu - u[a]) / (u[b] - u[a])
        dev = z[a] + t * (z[b] - z[a]) - z[a + 1:b]  # chord minus point: > 0 above
        over = np.maximum(dev - tol, -dev - below)
        k = int(np.argmax(over))
        if over[k] > 0:
            m = a + 1 + k
            keep[m] = True
            stack.append((a, m))
            stack.append((m, b))
    return np.flatnonzero(keep)


@dataclass
class RasterProgram:
    """A finishing program: its text and what made it.

    Attributes
    ----------
    text : str
        The G-code.
    passes : list of ndarray of shape (m, 3)
        The CL points kept on each pass (tool tip, mm), in cutting order.
    scallop : float
        Predicted scallop height on a flat floor, mm.
    params : dict
        Tool, stepover, angle, tol, step, feeds, spindle, clearance.
    stats : dict
        Passes, points dropped, points kept, retracts, links, seconds.
    """

    text: str
    passes: list
    scallop: float
    params: dict
    stats: dict = field(default_factory=dict)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the program atomically."""
        def write(tmp: str) -> None:
            with open(tmp, "w", encoding="ascii", newline="\n") as fh:
                fh.write(self.text)

        return atomic_write(path, write, suffix=Path(path).suffix or ".nc")


def _bounds_of(model: Any) -> tuple:
    from ..design import as_design

    b = as_design(model).bounds
    if b is None:
        raise ValueError("bounds must be given for a heights callable")
    return b


def _f(v: float) -> str:
    s = f"{v:.5f}"
    return "0.00000" if s == "-0.00000" else s


def _fz(v: float) -> str:
    """A height rounded up to 1e-5 mm, so the tool never goes below the CL point it stands for."""
    return _f(math.ceil(v * 1e5 - 1e-6) / 1e5)


def raster_program(model: Any, cutter: Any, *, stepover: float, angle: float = 0.0, tol: float = 0.005,
                   bounds: Any = None, step: float | None = None, feed: float = 1000.0,
                   plunge_feed: float | None = None, spindle: float = 10000.0, clearance: float = 5.0,
                   name: str = "design", pitch: float | None = None, outside: str | float = "skip",
                   sag: float = 1e-3, progress: Any = None) -> RasterProgram:
    """A zig-zag finishing program over a design, from its drop-cutter CL surface.

    Parameters
    ----------
    model : ZMap, PrecisionModel, cad_io.Part or callable
        The design (see :func:`drop_cutter`).
    cutter : Cutter or str
        e.g. ``"ball:6"``.
    stepover : float
        mm between passes (0 < stepover <= diameter).
    angle : float
        Pass direction in radians from +x.
    tol : float
        Chord tolerance, mm (> 0).
    bounds : (xmin, ymin, xmax, ymax), optional
        Region the tool axis covers; default the model's extent.
    step : float, optional
        CL sampling along a pass, mm; default ``min(stepover / 2, 0.1)``.
    feed, plunge_feed, spindle : float
        mm/min (plunge default feed / 3), rev/min.
    clearance : float
        mm above the highest CL point for rapids.
    name : str
        The design's name for the header comment.
    pitch : float, optional
        Sample pitch of a design that is not a z-map (see :func:`drop_cutter`).
    outside : {"skip", "lowest"} or float
        Where the design has no height (outside the part's outline, a hole): "skip" breaks a pass
        where no design lies under the cutter (the tool is dropped on the design alone wherever some
        of it is under the cutter); "lowest" treats the empty space as a floor at the lowest CL
        height of the passes, a number as a floor at that z: every CL point is then at least the
        floor and passes run on across gaps. The design itself is never cut into either way.
    sag : float
        mm; where the straight feed between two CL points would pass more than this under the CL
        surface at a quarter, half or three quarters of the way (a steep or sharply curved stretch:
        over a wall's top edge), the middle is dropped and added, down to ``step / 256``.
    progress : callable, optional
        ``progress(done, total)`` after each block of passes.

    Returns
    -------
    RasterProgram

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> dome = ZMap.from_function(lambda x, y: 5 - 0.01 * (x * x + y * y), (-10, -10, 10, 10), 0.25)
    >>> prog = raster_program(dome, "ball:6", stepover=2.0, bounds=(-5, -5, 5, 5))
    >>> prog.stats["passes"], prog.text.splitlines()[0]
    (6, '(zmap toolpath: raster finishing of design)')
    """
    import time

    t0 = time.perf_counter()
    cut = as_cutter(cutter)
    for nm, v in (("stepover", stepover), ("tol", tol), ("feed", feed), ("spindle", spindle)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{nm} must be a positive number, got {v!r}")
    if not (math.isfinite(angle)):
        raise ValueError(f"angle must be a finite number of radians, got {angle!r}")
    if not (math.isfinite(clearance) and clearance > 0):
        raise ValueError(f"clearance must be a positive number of mm, got {clearance!r}")
    if not (outside in ("skip", "lowest") or (isinstance(outside, (int, float)) and math.isfinite(outside))):
        raise ValueError(f"outside must be 'skip', 'lowest' or a floor height in mm, got {outside!r}")
    scallop = scallop_height(cut, stepover)
    step = float(step) if step is not None else min(stepover / 2.0, 0.1)
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be a positive number of mm, got {step!r}")
    plunge_feed = feed / 3.0 if plunge_feed is None else float(plunge_feed)
    b = tuple(float(v) for v in (bounds if bounds is not None else _bounds_of(model)))
    if len(b) != 4 or not (b[2] > b[0] and b[3] > b[1]):
        raise ValueError(f"bounds must be (xmin, ymin, xmax, ymax) with xmin < xmax, ymin < ymax, got {b}")
    ca, sa = math.cos(angle), math.sin(angle)
    # the region's corners in the pass frame (u along, v across)
    cx = np.array([b[0], b[2], b[2], b[0]])
    cy = np.array([b[1], b[1], b[3], b[3]])
    u_c = cx * ca + cy * sa
    v_c = -cx * sa + cy * ca
    nu = lines_within(u_c.min(), u_c.max(), step)
    nv = lines_within(v_c.min(), v_c.max(), stepover)
    us = u_c.min() + step * np.arange(nu)
    vs = v_c.min() + stepover * np.arange(nv)
    U, V = np.meshgrid(us, vs, indexing="ij")
    X = U * ca - V * sa
    Y = U * sa + V * ca
    inside = (X >= b[0] - 1e-9) & (X <= b[2] + 1e-9) & (Y >= b[1] - 1e-9) & (Y <= b[3] + 1e-9)
    Z = np.full(X.shape, np.nan)
    if not isinstance(model, ZMap):
        # one bounding surface over the whole region (a design that is sampled: every drop
        # below, passes, links and the sag test, then reuses it)
        from .drop import bounding_surface

        pad = cut.radius + 2.0 * max(pitch or 0.0, 1.0)
        bounding_surface(model, (b[0] - pad, b[1] - pad, b[2] + pad, b[3] + pad), pitch=pitch)
    cols = np.array_split(np.arange(nv), max(1, min(nv, 10, int(np.ceil(X.size / 200_000)))))
    for q, cidx in enumerate(cols):
        sel = inside[:, cidx]
        if sel.all():  # the block whole: a tensor grid where the passes run along x or y
            zc = drop_cutter(model, cut, X[:, cidx], Y[:, cidx], pitch=pitch).ravel()
        else:
            zc = drop_cutter(model, cut, X[:, cidx][sel], Y[:, cidx][sel], pitch=pitch)
        block = Z[:, cidx]
        block[sel] = zc
        Z[:, cidx] = block
        if progress is not None:
            progress(int(cidx[-1]) + 1, nv)
    if not np.isfinite(Z).any():
        raise ValueError(f"no surface under the cutter anywhere in bounds {b}")
    floor = None
    if outside != "skip":
        floor = float(np.nanmin(Z)) if outside == "lowest" else float(outside)
        Z = np.where(inside, np.fmax(Z, floor), np.nan)
    safe = float(np.nanmax(Z)) + clearance
    # runs of finite CL along each pass, then points added where a feed would sag under the
    # CL surface, then thinned; zig-zag
    runs, line_of = [], []
    for j in range(nv):
        ok = np.isfinite(Z[:, j])
        edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
        for a, e in zip(edges[::2], edges[1::2]):
            runs.append((-vs[j] * sa, vs[j] * ca, ca, sa, us[a:e].copy(), Z[a:e, j].copy()))
            line_of.append(j)
    added = _refine_sag(model, cut, runs, pitch, floor, sag)
    passes = []
    by_line: dict = {}
    for j, run in zip(line_of, runs):
        by_line.setdefault(j, []).append(run)
    for j in sorted(by_line):
        flip = len(passes) % 2 == 1  # zig-zag: every other pass runs back
        for ox, oy, dx, dy, u, z in (by_line[j][::-1] if flip else by_line[j]):
            if flip:
                u, z = u[::-1], z[::-1]
            keep = simplify_chords(u, z, tol, below=0.0)
            uu = u[keep]
            passes.append(np.column_stack([ox + uu * dx, oy + uu * dy, z[keep]]))
    c = cut
    kind = {"flat": "flat end mill", "ball": "ball end mill", "bull": "bull nose"}[c.kind]
    head = [f"(zmap toolpath: raster finishing of {name})",
            f"(tool: {kind} D{c.diameter:g} mm, corner radius {c.corner_radius:g} mm, spec {c.kind}:{c.diameter:g}"
            + (f":{c.corner_radius:g}" if c.kind == "bull" else "") + ")",
            f"(stepover {stepover:g} mm, angle {math.degrees(angle):g} deg, chord tolerance {tol:g} mm, "
            f"CL step {step:g} mm)",
            f"(bounds x {b[0]:g}..{b[2]:g} y {b[1]:g}..{b[3]:g} mm, clearance Z {safe:.5f})",
            f"(predicted scallop height {scallop:.6f} mm on a flat floor)",
            "(outside the design: " + ("passes break where no design is under the cutter)" if floor is None
                                       else f"a floor at Z{floor:.5f})"),
            f"(feed {feed:g} mm/min, plunge {plunge_feed:g} mm/min, spindle {spindle:g} rpm)",
            "G21 G90 G17",
            f"G0 Z{_f(safe)}",
            f"S{spindle:g} M3"]
    lines = list(head)
    retracts = links = 0
    cur = None
    cur_f = None

    def feed_to(p, f):
        nonlocal cur_f
        w = f"G1 X{_f(p[0])} Y{_f(p[1])} Z{_fz(p[2])}"
        if f != cur_f:
            w += f" F{f:g}"
            cur_f = f
        lines.append(w)

    # links between consecutive passes: a feed along the CL surface (the cutter dropped every
    # step across, sag-tested and thinned like a pass) where design lies under all of it
    links_path, n_link = _links(model, cut, passes, stepover, step, tol, pitch, floor, sag)
    added += n_link
    for q, pts in enumerate(passes):
        start = pts[0]
        if cur is None:
            lines.append(f"G0 X{_f(start[0])} Y{_f(start[1])}")
            lines.append(f"G0 Z{_f(start[2] + min(clearance, 1.0))}")
            feed_to(start, plunge_feed)
        else:
            if links_path[q] is not None:
                links += 1
                for p in links_path[q]:
                    feed_to(p, feed)
                feed_to(start, feed)
            else:
                retracts += 1
                lines.append(f"G0 Z{_f(safe)}")
                lines.append(f"G0 X{_f(start[0])} Y{_f(start[1])}")
                lines.append(f"G0 Z{_f(start[2] + min(clearance, 1.0))}")
                feed_to(start, plunge_feed)
        for p in pts[1:]:
            feed_to(p, feed)
        cur = pts[-1]
    lines += [f"G0 Z{_f(safe)}", "M5", "M2"]
    text = "\n".join(lines) + "\n"
    params = {"tool": f"{c.kind}:{c.diameter:g}", "diameter": c.diameter, "corner_radius": c.corner_radius,
              "stepover": stepover, "angle": angle, "tol": tol, "step": step, "feed": feed,
              "plunge_feed": plunge_feed, "spindle": spindle, "clearance_z": safe, "bounds": b,
              "outside": outside if floor is None else {"rule": outside if outside == "lowest" else "floor",
                                                        "floor_z": floor}}
    stats = {"passes": len(passes), "cl_points": int(np.isfinite(Z).sum()) + added,
             "kept_points": int(sum(len(p) for p in passes)), "retracts": retracts, "links": links,
             "seconds": round(time.perf_counter() - t0, 3)}
    return RasterProgram(text, passes, scallop, params, stats)


def _links(model: Any, cut: Any, passes: list, stepover: float, step: float, tol: float, pitch: Any,
           floor: float | None, sag: float) -> tuple[list, int]:
    """Per pass, the feed points (m, 3) from the end of the one before to its start, or None
    where they must be joined by a retract (further apart than two stepovers, or no design
    under some of the way); and the CL points added by the sag test."""
    path: list = [None] * len(passes)
    runs, owner = [], []
    for q in range(1, len(passes)):
        a, e = passes[q - 1][-1], passes[q][0]
        d = float(np.hypot(e[0] - a[0], e[1] - a[1]))
        if d <= 2.0 * stepover + 1e-9 and d > 0:
            m = max(2, int(math.ceil(d / step)) + 1)
            runs.append((a[0], a[1], (e[0] - a[0]) / d, (e[1] - a[1]) / d, np.linspace(0.0, d, m), np.full(m, np.nan)))
            owner.append(q)
    if not runs:
        return path, 0
    inner = [r[4][1:-1] for r in runs]
    lx = np.concatenate([r[0] + u * r[2] for r, u in zip(runs, inner)])
    ly = np.concatenate([r[1] + u * r[3] for r, u in zip(runs, inner)])
    cl = drop_cutter(model, cut, lx, ly, pitch=pitch) if lx.size else np.zeros(0)
    if floor is not None:
        cl = np.fmax(cl, floor)
    at = 0
    good, good_q = [], []
    for r, u, q in zip(runs, inner, owner):
        z = r[5]
        z[0], z[-1] = passes[q - 1][-1][2], passes[q][0][2]
        z[1:-1] = cl[at:at + u.size]
        at += u.size
        if np.isfinite(z).all():
            good.append(r)
            good_q.append(q)
    added = _refine_sag(model, cut, good, pitch, floor, sag)
    for (ox, oy, dx, dy, u, z), q in zip(good, good_q):
        keep = simplify_chords(u, z, tol, below=0.0)[1:-1]
        path[q] = np.column_stack([ox + u[keep] * dx, oy + u[keep] * dy, z[keep]])
    return path, added


def _refine_sag(model: Any, cut: Any, runs: list, pitch: Any, floor: float | None, sag: float,
                rounds: int = 8) -> int:
    """Add CL points in place where a feed between two would pass more than ``sag`` under the
    CL surface at a quarter, the middle or three quarters of the way (all runs' tests dropped
    together, ``rounds`` times at most; the middle is added); the number added. A run is
    ``(ox, oy, dx, dy, u, z)``: CL heights ``z`` at ``(ox + u dx, oy + u dy)``.

    A segment that passed is not tested again: only the two halves of a failed one are."""
    added = 0
    fr = np.array([0.25, 0.5, 0.75])
    # per run, per segment: still to be tested (where the CL bends or climbs steeply)
    todo = [_bent(r[4], r[5], sag) if len(r[4]) >= 2 else np.zeros(0, dtype=bool) for r in runs]
    for _ in range(rounds):
        segs = [(q, len(r[4]) - 1) for q, r in enumerate(runs) if len(r[4]) >= 2]
        if not segs:
            break
        test = np.concatenate([todo[q] for q, _m in segs])
        if not test.any():
            break
        ua = np.concatenate([runs[q][4][:-1] for q, _m in segs])[test]
        ub = np.concatenate([runs[q][4][1:] for q, _m in segs])[test]
        za = np.concatenate([runs[q][5][:-1] for q, _m in segs])[test]
        zb = np.concatenate([runs[q][5][1:] for q, _m in segs])[test]
        geo = np.concatenate([np.broadcast_to(np.array(runs[q][:4], dtype=np.float64), (m, 4)) for q, m in segs])[test]
        ut = ua[:, None] + fr[None, :] * (ub - ua)[:, None]
        cl = drop_cutter(model, cut, geo[:, :1] + ut * geo[:, 2:3], geo[:, 1:2] + ut * geo[:, 3:4], pitch=pitch)
        if floor is not None:
            cl = np.fmax(cl, floor)
        chord = za[:, None] + fr[None, :] * (zb - za)[:, None]
        bad = (np.isfinite(cl) & (cl > chord + sag)).any(axis=1)
        need = np.zeros(test.size, dtype=bool)
        need[test] = bad
        at = np.full(test.size, -1)
        at[test] = np.arange(int(test.sum()))
        start = 0
        for q, m in segs:
            sel = need[start:start + m]
            todo[q] = sel.copy()
            if sel.any():
                k = np.flatnonzero(sel)
                ox, oy, dx, dy, u, z = runs[q]
                w = at[start + k]
                runs[q] = (ox, oy, dx, dy, np.insert(u, k + 1, ut[w, 1]), np.insert(z, k + 1, cl[w, 1]))
                todo[q] = np.insert(todo[q], k + 1, True)  # both halves of a failed segment
            start += m
        added += int(bad.sum())
        if not bad.any():
            break
    return added


def _bent(u: np.ndarray, z: np.ndarray, sag: float) -> np.ndarray:
    """Per segment of a run: whether the CL bends at either end (second difference over sag) or
    climbs steeper than 1:1 (where a feed could leave the CL surface by more than ``sag``)."""
    d2 = np.zeros(len(u))
    if len(u) >= 3:
        d2[1:-1] = np.abs(z[:-2] - 2 * z[1:-1] + z[2:])
    steep = np.abs(np.diff(z)) > np.abs(np.diff(u))
    return steep | (d2[:-1] > sag) | (d2[1:] > sag)
