"""Raster (zig-zag) finishing programs from the CL surface of a design.

Passes run along the direction ``angle`` (radians from +x) and step across by ``stepover``;
each pass is sampled every ``step`` mm, dropped onto the design with :func:`drop_cutter`
(never below the true CL height: the CL points do not gouge), then thinned with a chord
tolerance: a point is left out only if the straight feed that replaces it stays within ``tol``
above every dropped CL height it spans and never below one. Between two CL points a feed can
still pass under the CL surface (by ``chord**2 / (8 r)`` over a convex edge for a cutter of
corner radius ``r``): where it would by more than ``sag`` at a quarter, half or three
quarters of the way (a steep stretch, a wall's top edge), the middle is dropped and added. Where no surface lies under the
cutter a pass is broken, or the empty space is a floor (``outside``). Two pass ends are joined by a straight
feed when that link stays above the CL surface along it (checked by dropping the cutter
every ``step``); otherwise by a safe retract: G0 up to the clearance height, G0 across, and
a feed down at the plunge rate.

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
    text : str — the G-code.
    passes : list of ndarray of shape (m, 3) — the CL points kept on each pass (tool tip, mm),
        in cutting order.
    scallop : float — predicted scallop height on a flat floor, mm.
    params : dict — tool, stepover, angle, tol, step, feeds, spindle, clearance.
    stats : dict — passes, points dropped, points kept, retracts, links, seconds.
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
    from ..grid import ZMap
    from ..model import PrecisionModel

    if isinstance(model, PrecisionModel):
        return model.base.bounds
    if isinstance(model, ZMap):
        return model.bounds
    if hasattr(model, "bbox"):
        b = model.bbox
        return (b[0], b[1], b[3], b[4])
    raise ValueError("bounds must be given for a heights callable")


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
    model : ZMap, PrecisionModel, cad_io.Part or callable — the design (see :func:`drop_cutter`).
    cutter : Cutter or str — e.g. ``"ball:6"``.
    stepover : float — mm between passes (0 < stepover <= diameter).
    angle : float — pass direction in radians from +x.
    tol : float — chord tolerance, mm (> 0).
    bounds : (xmin, ymin, xmax, ymax), optional — region the tool axis covers; default the
        model's extent.
    step : float, optional — CL sampling along a pass, mm; default ``min(stepover / 2, 0.1)``.
    feed, plunge_feed, spindle : float — mm/min (plunge default feed / 3), rev/min.
    clearance : float — mm above the highest CL point for rapids.
    name : str — the design's name for the header comment.
    pitch : float, optional — sample pitch of a design that is not a z-map (see
        :func:`drop_cutter`).
    outside : {"skip", "lowest"} or float — where the design has no height (outside the
        part's outline, a hole): "skip" breaks a pass where no design lies under the cutter
        (the tool is dropped on the design alone wherever some of it is under the cutter);
        "lowest" treats the empty space as a floor at the lowest CL height of the passes, a
        number as a floor at that z: every CL point is then at least the floor and passes run
        on across gaps. The design itself is never cut into either way.
    sag : float — mm; where the straight feed between two CL points would pass more than this
        under the CL surface at a quarter, half or three quarters of the way (a steep or sharply
        curved stretch: over a wall's top edge), the middle is dropped and added, down to
        ``step / 256``.
    progress : callable, optional — ``progress(done, total)`` after each block of passes.

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
    nu = int(math.floor((u_c.max() - u_c.min()) / step + 1e-9)) + 1
    nv = int(math.floor((v_c.max() - v_c.min()) / stepover + 1e-9)) + 1
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
    runs = []
    for j in range(nv):
        ok = np.isfinite(Z[:, j])
        edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
        runs += [(j, us[a:e].copy(), Z[a:e, j].copy()) for a, e in zip(edges[::2], edges[1::2])]
    added = _refine_sag(model, cut, runs, ca, sa, vs, pitch, floor, sag)
    passes = []
    by_line: dict = {}
    for j, u, z in runs:
        by_line.setdefault(j, []).append((u, z))
    for j in sorted(by_line):
        flip = len(passes) % 2 == 1  # zig-zag: every other pass runs back
        for u, z in (by_line[j][::-1] if flip else by_line[j]):
            if flip:
                u, z = u[::-1], z[::-1]
            keep = simplify_chords(u, z, tol, below=0.0)
            uu = u[keep]
            passes.append(np.column_stack([uu * ca - vs[j] * sa, uu * sa + vs[j] * ca, z[keep]]))
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

    # links between consecutive passes: a straight feed where it stays above the CL surface
    # (all candidate links dropped in one call)
    link_ok = np.zeros(len(passes), dtype=bool)
    lx_all, ly_all, lz_all, owner = [], [], [], []
    for q in range(1, len(passes)):
        a, e = passes[q - 1][-1], passes[q][0]
        d = float(np.hypot(e[0] - a[0], e[1] - a[1]))
        if d <= 2.0 * stepover + 1e-9:
            m = max(2, int(math.ceil(d / step)) + 1)
            t = np.linspace(0.0, 1.0, m)
            lx_all.append(a[0] + t * (e[0] - a[0]))
            ly_all.append(a[1] + t * (e[1] - a[1]))
            lz_all.append(a[2] + t * (e[2] - a[2]))
            owner.append(np.full(m, q))
    if owner:
        own = np.concatenate(owner)
        need = drop_cutter(model, cut, np.concatenate(lx_all), np.concatenate(ly_all), pitch=pitch)
        if floor is not None:
            need = np.fmax(need, floor)
        good = np.isfinite(need) & (np.concatenate(lz_all) >= need - 1e-9)
        bad = np.zeros(len(passes), dtype=bool)
        np.logical_or.at(bad, own, ~good)
        link_ok[np.unique(own)] = True
        link_ok &= ~bad
    for q, pts in enumerate(passes):
        start = pts[0]
        if cur is None:
            lines.append(f"G0 X{_f(start[0])} Y{_f(start[1])}")
            lines.append(f"G0 Z{_f(start[2] + min(clearance, 1.0))}")
            feed_to(start, plunge_feed)
        else:
            if link_ok[q]:
                links += 1
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


def _refine_sag(model: Any, cut: Any, runs: list, ca: float, sa: float, vs: np.ndarray, pitch: Any,
                floor: float | None, sag: float, rounds: int = 8) -> int:
    """Add CL points in place where a feed between two would pass more than ``sag`` under the
    CL surface at a quarter, the middle or three quarters of the way (all runs' tests dropped
    together, ``rounds`` times at most; the middle is added); the number added.

    A segment that passed is not tested again: only the two halves of a failed one are."""
    added = 0
    fr = np.array([0.25, 0.5, 0.75])
    # per run, per segment: still to be tested (where the CL bends or climbs steeply)
    todo = [_bent(u, z, sag) if len(u) >= 2 else np.zeros(0, dtype=bool) for _j, u, z in runs]
    for _ in range(rounds):
        segs = [(q, len(u) - 1) for q, (_j, u, _z) in enumerate(runs) if len(u) >= 2]
        if not segs:
            break
        test = np.concatenate([todo[q] for q, _m in segs])
        if not test.any():
            break
        ua = np.concatenate([runs[q][1][:-1] for q, _m in segs])[test]
        ub = np.concatenate([runs[q][1][1:] for q, _m in segs])[test]
        za = np.concatenate([runs[q][2][:-1] for q, _m in segs])[test]
        zb = np.concatenate([runs[q][2][1:] for q, _m in segs])[test]
        v = np.concatenate([np.full(m, vs[runs[q][0]]) for q, m in segs])[test]
        ut = ua[:, None] + fr[None, :] * (ub - ua)[:, None]
        vt = np.broadcast_to(v[:, None], ut.shape)
        cl = drop_cutter(model, cut, ut * ca - vt * sa, ut * sa + vt * ca, pitch=pitch)
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
                j, u, z = runs[q]
                w = at[start + k]
                runs[q] = (j, np.insert(u, k + 1, ut[w, 1]), np.insert(z, k + 1, cl[w, 1]))
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
