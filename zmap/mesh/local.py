"""Local mesh decimation that follows a simulation run (paper 003, sections 2.2 and 3).

:class:`LocalMesh` keeps one decimated mesh per region of ``region x region`` cells
(:mod:`zmap.mesh.decimate`); :meth:`LocalMesh.goto` moves to another stage of a run and
re-meshes only the regions whose rays the stage range touched, forwards or backwards.

Which rays a stage range touched comes from the run's history, not from comparing images:
every time-element (time-trace), Z-element creation or deletion (z-trace) or treap node
(Interval Treap) carries its stage and its ray, so the events with a stage in
``(min(a, b), max(a, b)]`` name the rays; they are sorted by stage once, and a range is two
binary searches. The z-trace and the treap also record changes below the top surface, so
the regions those rays fall in are then checked against the display images and skipped
when their heights did not change. A run without history (``history='none'``) falls back
to comparing the two display images node by node.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .decimate import _grid, _Regions, check_allowance, check_region

__all__ = ["LocalMesh"]


def _is_run(source: Any) -> bool:
    return hasattr(source, "display") and hasattr(source, "n_stages") and hasattr(source, "stock")


def _events(run: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(stage, ray) of every history event, sorted by stage; None without a history."""
    s = run.structure
    if s is None:
        return None
    kind = getattr(s, "kind", run.history)
    if kind == "ttrace":
        counts = np.diff(s.offsets)
        rays = np.repeat(np.arange(s.n_rays, dtype=np.int64), counts)
        stage = np.asarray(s.stage, dtype=np.int64)
    elif kind == "treap":
        counts = np.diff(s.node_off)
        rays = np.repeat(np.arange(s.n_rays, dtype=np.int64), counts)
        stage = np.asarray(s.stage, dtype=np.int64)
    elif kind == "ztrace":
        counts = np.diff(s.offsets)
        r1 = np.repeat(np.arange(s.n_rays, dtype=np.int64), counts)
        dele = np.asarray(s.deleted, dtype=np.int64)
        alive = dele < np.iinfo(np.int32).max
        rays = np.concatenate([r1, r1[alive]])
        stage = np.concatenate([np.asarray(s.created, dtype=np.int64), dele[alive]])
    else:
        return None
    keep = stage > 0
    stage, rays = stage[keep], rays[keep]
    order = np.argsort(stage, kind="stable")
    return stage[order], rays[order]


class LocalMesh:
    """Decimated mesh of a map or of a run's workpiece, re-meshed region by region.

    Parameters
    ----------
    source : ZMap, ndarray of shape (nx, ny) or zmap.sim.session.Run
        Heights in mm (NaN = no surface); a run is meshed from its display image
        (``run.display(stage)``, rays at ``run.stock.pitch``) and starts at stage 0.
    allowance : float
        Largest vertical error in mm at any node, >= 0 (0: full mesh).
    region : int
        Region size in cells, >= 2.
    period : int
        Decimation period in updates (paper 003, step 4). Between decimations a touched
        region is updated incrementally: its triangulation is kept, the triangles over the
        changed nodes get their worst node again and vertices are inserted until every node
        is within the allowance (vertices are only added, so the bound always holds, and
        the cost follows the changed area, not the region). Every ``period``-th update
        decimates afresh every region touched since the last decimation. ``period=1``
        decimates the touched regions afresh at every update (the mesh then equals a fresh
        one of that stage); ``period=-1`` decimates once, when the mesh is made, and only
        updates incrementally after that. Default 8.
    Attributes
    ----------
    stage : int or None
        Current stage of the run (None for a map).
    last : dict
        Counters of the last update: ``stage``, ``regions_touched``, ``triangles``,
        ``ms`` (re-meshing time), ``display_ms`` (reading the run's display image).
    updates : list of dict
        The counters of every update so far.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.fromfunction(lambda i, j: np.sin(i / 9) + j / 50, (129, 129))
    >>> lm = LocalMesh(z, allowance=0.01, region=32)
    >>> lm.mesh.n_faces < 2 * 128 * 128, lm.max_error() <= 0.01
    (True, True)
    """

    def __init__(self, source: Any, *, allowance: float = 0.01, region: int = 64, period: int = 8):
        a = check_allowance(allowance)
        r = check_region(region)
        if (isinstance(period, bool) or not isinstance(period, (int, np.integer))
                or not (period >= 1 or period == -1)):
            raise ValueError(f"period must be an integer >= 1, or -1 (decimate once), got {period!r}")
        self.allowance, self.region, self.period = a, r, int(period)
        self.updates: list[dict] = []
        self._count = 0
        if _is_run(source):
            self.run = source
            s = source.stock
            self._grid = (float(s.x0), float(s.y0), float(s.pitch), float(s.pitch))
            self.stage = 0
            t = time.perf_counter()
            z = np.ascontiguousarray(source.display(0), dtype=np.float64)
            dms = 1000 * (time.perf_counter() - t)
            zs = float(np.nanmax(np.abs(z))) if z.size and not np.isnan(z).all() else 0.0
            self._events = None
            self._events_done = False
        else:
            self.run = None
            z, x0, y0, dx, dy = _grid(source)
            self._grid = (x0, y0, dx, dy)
            self.stage = None
            dms = 0.0
            zs = None
        self._reg = _Regions(z, a, r, zscale=zs, stateful=self.run is not None and self.period != 1)
        self._pending = np.zeros((self._reg.nrx, self._reg.nry), dtype=np.bool_)
        t = time.perf_counter()
        n = self._reg.remesh(self._reg.all_regions())
        self.last = {"stage": self.stage, "regions_touched": n, "triangles": self._reg.triangles(),
                     "ms": round(1000 * (time.perf_counter() - t), 4), "display_ms": round(dms, 4)}
        self.updates.append(self.last)

    # ---- reading -------------------------------------------------------------------------

    @property
    def z(self) -> np.ndarray:
        """Heights the mesh was made from, (nx, ny) float64 mm."""
        return self._reg.z

    @property
    def mesh(self) -> Any:
        """The whole mesh (all regions) as a :class:`zmap.mesh.triangulate.TriMesh`."""
        return self._reg.mesh(*self._grid)

    @property
    def n_triangles(self) -> int:
        return self._reg.triangles()

    def max_error(self) -> float:
        """Largest ``|mesh height - z|`` over every valid node of the map it came from, mm."""
        return self._reg.max_error()

    # ---- following a run -----------------------------------------------------------------

    def _touched(self, a: int, b: int, z_new: np.ndarray) -> np.ndarray:
        K = self._reg.K
        reg = self._reg
        hit = np.zeros((reg.nrx, reg.nry), dtype=np.bool_)
        if a == b or reg.nrx == 0:
            return hit
        if not self._events_done:
            self._events = _events(self.run)
            self._events_done = True
        if self._events is None:
            K.changed_regions(reg.z, z_new, reg.r, reg.nrx, reg.nry, hit)
        else:
            stage, rays = self._events
            lo, hi = min(a, b), max(a, b)
            i, j = np.searchsorted(stage, [lo, hi], side="right")
            K.rays_to_regions(rays[i:j], reg.ny, reg.r, reg.nrx, reg.nry, hit)
        # the box of the changed nodes per region; events below the top surface change nothing
        K.changed_boxes(reg.z, z_new, reg.r, hit, reg.box)
        return hit

    def goto(self, stage: Any) -> dict:
        """Move to ``stage`` of the run, re-meshing only the regions it changes.

        Parameters
        ----------
        stage : int, 'end' or fraction text
            As :meth:`zmap.sim.session.Run.stage` reads it; out of range raises
            :class:`zmap.errors.StageError`.

        Returns
        -------
        dict
            ``stage``, ``regions_touched``, ``triangles``, ``ms``, ``display_ms``.
        """
        if self.run is None:
            raise TypeError("goto needs a LocalMesh made from a zmap.sim.session.Run, "
                            "this one was made from a map")
        k = self.run.stage(stage)
        t = time.perf_counter()
        z_new = np.ascontiguousarray(self.run.display(k), dtype=np.float64)
        dms = 1000 * (time.perf_counter() - t)
        t = time.perf_counter()
        hit = self._touched(self.stage, k, z_new)
        reg = self._reg
        reg.z = z_new
        n = 0
        if k != self.stage:
            self._count += 1
            todo = np.argwhere(hit).astype(np.int64)
            if self.period == 1:
                n = reg.remesh(todo)
            elif self.period == -1 or self._count % self.period:
                n = reg.remesh(todo, fresh=False)
                self._pending |= hit
            else:
                n = reg.remesh(np.argwhere(hit | self._pending).astype(np.int64))
                self._pending[:] = False
        self.stage = k
        self.last = {"stage": k, "regions_touched": n, "triangles": reg.triangles(),
                     "ms": round(1000 * (time.perf_counter() - t), 4), "display_ms": round(dms, 4)}
        self.updates.append(self.last)
        return self.last
