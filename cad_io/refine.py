"""Precision refinements of a z-map against its STEP part, and their accuracy report.

:func:`refine_models` builds EZ and CZ precision models of a base z-map from the exact
surface, as :class:`RefineOptions` say; :func:`report_rows` measures the base and the models
against the B-rep (paper 004's Table 2), as :class:`ReportOptions` say; :func:`format_report`
writes that as markdown. The commands ``zmap refine`` and ``zmap report``
(:mod:`cad_io.commands`) parse their options into these, call and print.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from zmap.errors import RefineError
from zmap.gridspec import lines_within

__all__ = ["RefineOptions", "ReportOptions", "OptionError", "refine_models", "report_rows", "format_report",
           "cz_curves", "check_tol", "METHODS", "CZ_DELTA_Y_SHARE", "REPORT_DEFLECTION_SHARE",
           "REPORT_DISTANCE_DEFLECTION_SHARE"]

#: the precision models :func:`refine_models` builds
METHODS = ("ez", "cz")


class OptionError(RefineError):
    """An option of :class:`RefineOptions` or :class:`ReportOptions` out of its range;
    ``option`` names the field (the commands turn it into their own option's name)."""

    def __init__(self, option: str, message: str):
        super().__init__(message)
        self.option = option


def _positive_mm(name: str, value, *, optional: bool = False) -> float | None:
    """``value`` as a float, OptionError unless a positive finite number of mm (or None where optional)."""
    if value is None and optional:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (v > 0 and math.isfinite(v)):
        raise OptionError(name, f"{name} must be a positive number of mm, got {value!r}")
    return v


def _methods(value) -> tuple[str, ...]:
    methods = (value,) if isinstance(value, str) else tuple(value)
    for m in methods:
        if m not in METHODS:
            raise OptionError("methods", f"method {m!r} is not one of {', '.join(map(repr, METHODS))}")
    return methods


@dataclass(frozen=True)
class RefineOptions:
    """How :func:`refine_models` refines a base z-map.

    Parameters
    ----------
    tol : float
        Tolerance in mm, below the base's grid interval (checked against the base by
        :func:`refine_models`).
    methods : sequence of {'ez', 'cz'}
        The models to build (a single name is taken as one method).
    theta_x : float
        CZ-maps: the largest angle (radians) between a domain's x axis and its curve.
    deflection : float, optional
        Mesh deflection (mm) of the exact sampler's Newton starts and facets; default ``tol / 2``.

    Raises
    ------
    OptionError
        A tolerance or deflection that is not a positive number of mm, an unknown method.

    Examples
    --------
    >>> RefineOptions(0.01, "ez").mesh_deflection
    0.005
    >>> RefineOptions(-1)
    Traceback (most recent call last):
    ...
    cad_io.refine.OptionError: tol must be a positive number of mm, got -1
    """

    tol: float
    methods: tuple[str, ...] = METHODS
    theta_x: float = math.radians(20.0)
    deflection: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "tol", _positive_mm("tol", self.tol))
        object.__setattr__(self, "methods", _methods(self.methods))
        object.__setattr__(self, "deflection", _positive_mm("deflection", self.deflection, optional=True))
        if not (0 < self.theta_x < math.pi / 2):
            raise OptionError("theta_x", f"theta_x must lie between 0 and pi/2 radians, got {self.theta_x!r}")

    @property
    def mesh_deflection(self) -> float:
        """The deflection in mm: the one given, or ``tol / 2``."""
        return self.tol / 2.0 if self.deflection is None else self.deflection


#: report_rows: default mesh deflection of the reference heights, as a share of the tolerance
#: (the same as refine_models', so one meshed face set serves the models and the reference)
REPORT_DEFLECTION_SHARE = 0.5
#: report_rows: default mesh deflection of the 3D distances, as a share of the tolerance
REPORT_DISTANCE_DEFLECTION_SHARE = 0.5


@dataclass(frozen=True)
class ReportOptions:
    """What :func:`report_rows` measures, and how.

    Parameters
    ----------
    grid : float
        Base grid interval in mm (the base is sampled at it when none is given).
    tol : float
        Tolerance in mm, below the grid interval.
    n_points : int
        Random query points, uniform over the base's domain.
    seed : int
        The seed of their generator.
    methods : sequence of {'ez', 'cz'}
        Models to build when none are given (empty: the base alone).
    deflection : float, optional
        Mesh deflection (mm) of the exact reference heights (and of the models built here);
        default ``tol / 2``, as :class:`RefineOptions`, so that both use one meshed face set.
        The mesh only gives the Jacobian inversion its starts, whose heights are exact
        whatever the deflection; only points answered by facets (where the inversion failed)
        are off by up to the deflection. They are counted in ``reference_facet_points``.
    distance_deflection : float, optional
        Mesh deflection (mm) of the KD-tree and fallback of :func:`cad_io.distance_to_part`;
        default ``tol / 2`` (no second meshing of the part). Exact NURBS feet do not depend
        on it; a distance measured to the mesh may under-report by up to it, so every point
        whose distance plus that slack exceeds ``tol / 2`` is measured again by OCC: above
        ``tol / 2`` the figures are exact (up to 2000 points a model), below it they are
        within the deflection.

    Raises
    ------
    OptionError
        A grid, tolerance or deflection that is not a positive number of mm, a tolerance not
        below the grid interval, fewer than one point, an unknown method.

    Examples
    --------
    >>> o = ReportOptions(1.0, 0.05, n_points=500, methods=("ez",))
    >>> o.height_deflection, o.refine_options().methods
    (0.025, ('ez',))
    >>> ReportOptions(1.0, 2.0)
    Traceback (most recent call last):
    ...
    cad_io.refine.OptionError: tolerance 2 mm must be smaller than the grid interval 1 mm
    """

    grid: float
    tol: float
    n_points: int = 100_000
    seed: int = 0
    methods: tuple[str, ...] = METHODS
    deflection: float | None = None
    distance_deflection: float | None = None

    def __post_init__(self) -> None:
        grid = _positive_mm("grid", self.grid)
        tol = _positive_mm("tol", self.tol)
        if tol >= grid:
            raise OptionError("tol", f"tolerance {tol:g} mm must be smaller than the grid interval {grid:g} mm")
        if isinstance(self.n_points, bool) or int(self.n_points) != self.n_points or self.n_points < 1:
            raise OptionError("n_points", f"n_points must be a whole number of at least 1, got {self.n_points!r}")
        object.__setattr__(self, "grid", grid)
        object.__setattr__(self, "tol", tol)
        object.__setattr__(self, "n_points", int(self.n_points))
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "methods", _methods(self.methods))
        object.__setattr__(self, "deflection", _positive_mm("deflection", self.deflection, optional=True))
        object.__setattr__(self, "distance_deflection",
                           _positive_mm("distance_deflection", self.distance_deflection, optional=True))

    @property
    def height_deflection(self) -> float:
        """The reference heights' deflection in mm: the one given, or ``tol / 2``."""
        return self.tol * REPORT_DEFLECTION_SHARE if self.deflection is None else self.deflection

    @property
    def distance_mesh_deflection(self) -> float:
        """The distance index's deflection in mm: the one given, or ``tol / 2``."""
        return (self.tol * REPORT_DISTANCE_DEFLECTION_SHARE if self.distance_deflection is None
                else self.distance_deflection)

    def refine_options(self) -> RefineOptions:
        """The :class:`RefineOptions` of the models this report builds (one meshed face set)."""
        return RefineOptions(self.tol, self.methods, deflection=self.height_deflection)


def check_tol(tol: float, base) -> None:
    """OptionError unless ``tol`` is a positive number of mm below the base's grid interval."""
    _positive_mm("tol", tol)
    if tol >= min(base.dx, base.dy):
        raise OptionError("tol", f"tolerance {tol:g} mm is not smaller than the grid interval "
                                 f"(dx={base.dx:g}, dy={base.dy:g} mm); use a smaller tol or a finer grid")


class _CountingHeights:
    """``heights(x, y)`` from the exact sampler that counts the points answered by facets."""

    def __init__(self, part, deflection: float, *, base=None, tol: float = 0.0):
        from cad_io.sampler import FACET

        self._part = part
        self._deflection = deflection
        self._facet = FACET
        self._base = base
        self._tol = float(tol)
        self._face_tol = np.array([float(getattr(f, "tolerance", 0.0) or 0.0) for f in part.faces])
        self.points = 0
        self.facet = 0
        self.empty = 0
        self.bridged = 0

    def _sampled(self, x, y):
        from cad_io.sampler import sample_points

        z, face, m = sample_points(self._part, x, y, deflection=self._deflection)
        self.points += int(m.size)
        self.facet += int(np.count_nonzero(m == self._facet))
        self.empty += int(np.count_nonzero(m == 0))
        return z, face

    def span_base(self):
        """The base with its nodes in cracks spanned (:func:`cad_io.cracks.span_node_cracks`);
        the later heights' cells are this copy's. The nodes spanned count in ``bridged``."""
        from cad_io.cracks import span_node_cracks

        self._base, n = span_node_cracks(self._sampled, self._base, self._tol, self._face_tol)
        self.bridged += n
        return self._base

    def __call__(self, x, y):
        z, _face = self._sampled(x, y)
        if self._base is not None and self._tol > 0:
            # gaps between faces that meet within their edges' tolerance: the model spans
            # them (:mod:`cad_io.cracks`)
            from cad_io.cracks import bridge_cracks

            xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
            z, n = bridge_cracks(self._sampled, self._base, xb, yb, z, self._tol, self._face_tol)
            self.bridged += n
        return z


#: CZ-maps' delta_y as a share of the tolerance (paper 004: 1; see refine_models)
CZ_DELTA_Y_SHARE = 0.8


def cz_curves(base, eps_r: float, se_curves) -> list:
    """The feature curves CZ domains are laid along: the VW curves of ``base`` (slope at
    least ``max(eps_r, 1)``, the walls) and the SE curves ``se_curves``."""
    from zmap.features import vertical_wall_curves

    return vertical_wall_curves(base, max(eps_r, 1.0)) + list(se_curves)


def refine_models(part, base, options: RefineOptions) -> dict:
    """Build the EZ and/or CZ precision models of ``base`` from the exact ``part``.

    EZ: e-points on the steep grid edges and on those crossed by SE curves. CZ: domains
    along the VW curves (slope at least ``max(eps_r, 1)``, the walls) and the SE curves.

    Parameters
    ----------
    part : cad_io.Part
        The exact surface, in the view frame of ``base`` (see :func:`cad_io.view.view_part`).
    base : ZMap
        The master z-map to refine.
    options : RefineOptions
        Tolerance, methods, CZ angle and mesh deflection.

    Returns
    -------
    dict
        ``{method: (PrecisionModel, info)}``; ``info`` has the counts of sampled points,
        of those answered by facets (where the Jacobian inversion failed), and the seconds.

    Raises
    ------
    OptionError
        A tolerance not below the base's grid interval.
    """
    import time

    from zmap.features import default_eps_r, sharp_edge_curves
    from zmap.model import PrecisionModel

    check_tol(options.tol, base)
    tol, deflection = options.tol, options.mesh_deflection
    se = sharp_edge_curves(part.edges)
    eps_r = default_eps_r(tol, base.dx, base.dy)
    out = {}
    for method in options.methods:
        h = _CountingHeights(part, deflection, base=base if method == "ez" else None, tol=tol)
        t0 = time.perf_counter()
        if method == "ez":
            from zmap.refine.ez import build_ez

            # nodes in cracks between faces take the surface across them in the model's own
            # base (the master z-map keeps OCC's heights): a crack through a node made a funnel
            base_ez = h.span_base()
            ez = build_ez(base_ez, h, tol=tol, eps_r=eps_r, se_curves=se)
            model = PrecisionModel(base_ez, ez=ez, meta={"method": "ez", "tol": tol, "eps_r": eps_r})
        elif method == "cz":
            from zmap.refine.cz import build_cz

            curves = cz_curves(base, eps_r, se)
            # delta_y = CZ_DELTA_Y_SHARE * tol: at the paper's delta_y = tol the ramp across a
            # wall inside one CZ cell measured 0.0102 (pocket) and 0.0105 mm (boss) at tol 0.01
            cz = build_cz(base, h, tol=CZ_DELTA_Y_SHARE * tol, curves=curves, theta_x=options.theta_x)
            model = PrecisionModel(base, cz=cz, meta={"method": "cz", "tol": tol, "theta_x": options.theta_x,
                                                      "curves": len(curves)})
        info = {"sampled": h.points, "facet": h.facet, "empty": h.empty, "bridged": h.bridged,
                "seconds": round(time.perf_counter() - t0, 3)}
        model.meta.update({"source": str(getattr(part, "source", "")), "facet_points": h.facet,
                           "deflection": deflection})
        out[method] = (model, info)
    return out


def _steep(part, x, y, h0, deflection: float, step: float = 0.01, max_slope: float = 1.0) -> np.ndarray:
    """True where the exact surface is steeper than ``max_slope``, or jumps, within ``step``.

    Probes the four directions +-x, +-y: a point within ``step`` of a wall on any side
    counts as steep (the models may place a wall up to the tolerance off).
    """
    from cad_io.sampler import sample_points

    steep = np.zeros(np.shape(x), dtype=bool)
    for ox, oy in ((step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)):
        h = sample_points(part, x + ox, y + oy, deflection=deflection)[0]
        with np.errstate(invalid="ignore"):
            steep |= ~(np.abs(h - h0) / step <= max_slope)
    return steep


def report_rows(part, options: ReportOptions, *, models: dict | None = None, base=None) -> dict:
    """Accuracy and memory of the base z-map and its EZ and CZ models (a Table 2 analogue).

    Parameters
    ----------
    part : cad_io.Part
        The exact surface, in the view frame of ``base`` (see :func:`cad_io.view.view_part`).
    options : ReportOptions
        Grid, tolerance, random points and their seed, methods, mesh deflections.
    models : dict, optional
        ``{method: (PrecisionModel, info)}`` from :func:`refine_models`, built here (with
        ``options.refine_options()``) if None.
    base : ZMap, optional
        The base z-map, sampled here at ``options.grid`` if None.

    Returns
    -------
    dict
        ``grid``, ``tol``, ``points``, ``deflection``, ``distance_deflection``,
        ``reference_facet_points`` and ``reference_empty_points`` (random points whose
        reference height came from facets, or that have none), ``plain_fine_bytes`` (a plain
        z-map at the e-map interval, computed) and ``rows``: for ``base``, ``ez``, ``cz`` the
        memory in bytes (``zmap``, ``extra``, ``total``), the e-map ratio, the largest
        vertical deviation where the surface is not steep, the largest 3D distance to the
        B-rep everywhere, and (CZ) inside the CZ domains; ``max_dist_topmost`` and
        ``p999_dist_topmost`` measure to the top-most surface instead (:func:`_skirt_bound`):
        the B-rep's faces plus the vertical skirts where the top-most height jumps without a
        wall (an overhang, a hole through to a face far below). A z-map holds that surface,
        not the faces under an overhang; on a height field (a die) the two agree.
        ``max_dist_own_tolerance`` (refined models) measures to the shape as valid within the
        file's tolerances (:func:`cad_io.distance.occ_distance_own_tolerance`: a point within
        the tolerance of its nearest edge is on it; :func:`cad_io.distance.occ_band_distance`:
        a face's surface reaches its edges' tolerance beyond its trim curves, where the sampler
        and OCC's ray cast answer), ``largest_tolerance_used`` the largest edge tolerance that
        moved a point's distance, ``max_dist_topmost_own_tolerance`` the top-most surface of
        that shape (the smaller of the two distances).

    Examples
    --------
    >>> from pathlib import Path
    >>> import cad_io
    >>> part = cad_io.read_step(Path(cad_io.__file__).parents[1] / "data" / "boss.step")
    >>> rep = report_rows(part, ReportOptions(1.0, 0.05, n_points=500, methods=("ez",)))
    >>> sorted(rep["rows"]), rep["deflection"], rep["reference_facet_points"]
    (['base', 'ez'], 0.025, 0)
    """
    from cad_io.distance import confirm_with_occ, distance_to_part, occ_band_distance, occ_distance_own_tolerance
    from cad_io.sampler import FACET, sample, sample_points
    from zmap.model import PrecisionModel

    if base is None:
        base = sample(part, options.grid)
    tol, n_points = options.tol, options.n_points
    check_tol(tol, base)
    defl, ddefl = options.height_deflection, options.distance_mesh_deflection
    if models is None:
        models = refine_models(part, base, options.refine_options())
    all_models = {"base": (PrecisionModel(base), {})} | dict(models)
    rng = np.random.default_rng(options.seed)
    x0, y0, x1, y1 = base.bounds
    xs = rng.uniform(x0, x1, n_points)
    ys = rng.uniform(y0, y1, n_points)
    zex, _face, how = sample_points(part, xs, ys, deflection=defl)
    steep = _steep(part, xs, ys, zex, defl, step=tol)
    nx_f, ny_f = lines_within(x0, x1, tol), lines_within(y0, y1, tol)
    rows = {}
    for name, (model, info) in all_models.items():
        h = model.height(xs, ys)
        ok = np.isfinite(h)
        d = np.full(n_points, np.nan)
        pts = np.c_[xs[ok], ys[ok], h[ok]]
        dist, exact = distance_to_part(part, pts, deflection=ddefl, return_exact=True)
        # a mesh distance may under-report by up to the deflection: those near tol/2 go to OCC too
        d[ok], n_occ, n_unchecked = confirm_with_occ(part, pts, dist, above=tol / 2, slack=np.where(exact, 0.0, ddefl))
        # the shape as valid within its tolerances: a point within the file's tolerance of the
        # nearest edge (a face reaches that far beyond its curve, and the sampler answers there,
        # as OCC's ray cast does) is on it
        d_own = d.copy()
        above = np.flatnonzero(np.nan_to_num(d, nan=-1.0) > tol / 2)
        above = above[np.argsort(-d[above], kind="stable")][:2000]  # as confirm_with_occ, largest first
        own_tol = 0.0
        if name != "base" and above.size and part.shape is not None:
            p_above = np.c_[xs[above], ys[above], h[above]]
            do, to = occ_distance_own_tolerance(part.shape, p_above)
            d_own[above] = np.maximum(do - to, 0.0)
            # or on a face's surface within the band its edges' tolerance gives it beyond
            # its trim curves, where OCC's ray cast and the sampler still answer on it
            # (trj8: up to 0.27 mm past a trim curve whose nearest edge carries 0.12 mm)
            db, tb = occ_band_distance(part.shape, p_above, d_own[above])
            banded = db < d_own[above]
            d_own[above] = np.where(banded, db, d_own[above])
            moved = d[above] - d_own[above] > 1e-9
            own_tol = float(np.max(np.where(banded, tb, to)[moved], initial=0.0))
        flat = ok & np.isfinite(zex) & ~steep
        nb = model.nbytes
        dtop = d.copy()
        far = np.flatnonzero(np.nan_to_num(d, nan=-1.0) > tol / 2)
        if far.size:
            dtop[far] = np.minimum(d[far], _skirt_bound(part, xs[far], ys[far], h[far], zex[far], defl, tol,
                                                        base.dx))
        row = {"zmap_bytes": nb["base"], "extra_bytes": nb["cz"] + nb["ez"], "total_bytes": nb["total"],
               "emap_ratio": float(model.ez.edge_ratio) if model.ez is not None else None,
               "n_cz": len(model.cz),
               "max_vertical_flat": float(np.max(np.abs(h[flat] - zex[flat]), initial=0.0)),
               "max_dist": float(np.nanmax(d)) if ok.any() else None,
               "max_dist_own_tolerance": float(np.nanmax(d_own)) if ok.any() else None,
               "largest_tolerance_used": own_tol,
               "p999_dist": float(np.nanpercentile(d, 99.9)) if ok.any() else None,
               "max_dist_topmost": float(np.nanmax(dtop)) if ok.any() else None,
               "max_dist_topmost_own_tolerance": float(np.nanmax(np.fmin(dtop, d_own))) if ok.any() else None,
               "p999_dist_topmost": float(np.nanpercentile(dtop, 99.9)) if ok.any() else None,
               "points_with_height": int(ok.sum()), "points_flat": int(flat.sum()),
               "occ_confirmed": n_occ, "above_half_tol_unconfirmed": n_unchecked,
               "mesh_distance_points": int(np.count_nonzero(~exact))}
        if model.cz:
            inside = model.source(xs, ys) == 2
            row["cz_points"] = int(inside.sum())
            row["max_dist_in_cz"] = float(np.nanmax(d[inside])) if inside.any() else None
        if model.ez is not None:
            row.update(ez_patches=model.ez.n_patches, ez_lattices=model.ez.n_lattices, ez_unresolved=model.ez.unresolved,
                       ez_pruned=model.ez.pruned)
        if info:
            row["facet_points"] = info["facet"]
            row["build_seconds"] = info["seconds"]
        rows[name] = row
    return {"part": str(getattr(part, "source", "")), "grid": float(base.dx), "tol": float(tol),
            "points": n_points, "deflection": defl, "distance_deflection": ddefl,
            "reference_facet_points": int(np.count_nonzero(how == FACET)),
            "reference_empty_points": int(np.count_nonzero(how == 0)),
            "plain_fine_bytes": nx_f * ny_f * 8, "plain_fine_shape": [nx_f, ny_f], "rows": rows}


#: radii (in tol) and directions of the probes of :func:`_skirt_bound`
_SKIRT_RADII = (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 20.0, 50.0)
_SKIRT_DIRECTIONS = 16


def _skirt_bound(part, x, y, h, z0, deflection: float, tol: float, grid: float) -> np.ndarray:
    """Upper bound of the distance from (x, y, h) to the top-most surface, skirts included.

    The top-most height along a segment from (x, y) to a probe at radius ``r`` passes every
    height between its ends (on a face, or on the vertical skirt where it jumps); so where
    the exact heights at (x, y) and at a probe bracket ``h`` the surface point at height
    ``h`` lies within ``r`` horizontally of the point. Radii up to a grid interval;
    ``inf`` where none brackets, and for points within ``tol`` of the exact height ``z0``
    (they belong on the B-rep's face there; the sampler's height would bracket them itself).
    """
    from cad_io.sampler import sample_points

    out = np.full(x.shape, np.inf)
    ang = np.arange(_SKIRT_DIRECTIONS) * (2 * math.pi / _SKIRT_DIRECTIONS)
    with np.errstate(invalid="ignore"):
        left = np.flatnonzero(~(np.abs(h - z0) <= tol))
    for r in (f * tol for f in _SKIRT_RADII):
        if r > grid or left.size == 0:
            break
        px = (x[left, None] + r * np.cos(ang)).ravel()
        py = (y[left, None] + r * np.sin(ang)).ravel()
        zp = sample_points(part, px, py, deflection=deflection)[0].reshape(left.size, -1)
        lo = np.minimum(zp, z0[left, None])
        hi = np.maximum(zp, z0[left, None])
        with np.errstate(invalid="ignore"):
            hit = ((lo <= h[left, None]) & (h[left, None] <= hi)).any(axis=1)
        out[left[hit]] = r
        left = left[~hit]
    return out


def format_report(rep: dict) -> str:
    """Markdown table of :func:`report_rows`."""
    kb = lambda b: f"{b / 1024:,.1f}"  # noqa: E731
    f = lambda v, n=4: "-" if v is None else f"{v:.{n}f}"  # noqa: E731
    lines = [f"part {rep['part']}" + (f" seen from {rep['axis']}" if rep.get("axis", "+z") != "+z" else "")
             + f": grid {rep['grid']:g} mm, tol {rep['tol']:g} mm, {rep['points']:,} random points; "
             f"a plain z-map at {rep['tol']:g} mm ({rep['plain_fine_shape'][0]:,} x {rep['plain_fine_shape'][1]:,}) "
             f"would take {kb(rep['plain_fine_bytes'])} KB",
             "",
             "| model | z-map KB | e-map / CZ KB | total KB | e-map ratio % | CZ-maps | max vertical dev (not steep) mm "
             "| max 3D dist mm | 99.9% 3D dist mm | max 3D dist in CZ mm | max dist to top-most surface mm |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in rep["rows"].items():
        ratio = "-" if r["emap_ratio"] is None else f"{100 * r['emap_ratio']:.2f}"
        lines.append(f"| {name} | {kb(r['zmap_bytes'])} | {kb(r['extra_bytes'])} | {kb(r['total_bytes'])} | {ratio} "
                     f"| {r['n_cz']} | {f(r['max_vertical_flat'])} | {f(r['max_dist'])} | {f(r['p999_dist'])} "
                     f"| {f(r.get('max_dist_in_cz'))} | {f(r.get('max_dist_topmost'))} |")
    lines.append("")
    lines.append("3D distances: exact NURBS projection (cad_io.distance); every distance above tol/2, largest "
                 "first, measured again by OCC BRepExtrema: " + ", ".join(
                     f"{name} {r['occ_confirmed']} (left {r['above_half_tol_unconfirmed']})"
                     for name, r in rep["rows"].items()) + ". Top-most surface: the B-rep's faces plus the vertical "
                 "skirts where the top-most height jumps without a wall (overhangs, holes through to a face below); "
                 "a z-map holds that surface.")
    ez = rep["rows"].get("ez")
    if ez is not None and "ez_patches" in ez:
        lines.append(f"EZ: {ez['ez_pruned']:,} candidate edges dropped (the base holds them), "
                     f"{ez['ez_patches']:,} cells patched after the cell check ({ez['ez_lattices']:,} of them "
                     f"by a lattice), {ez['ez_unresolved']:,} still off.")
    if "deflection" in rep:
        lines.append(f"Mesh deflection {rep['deflection']:g} mm (heights), {rep['distance_deflection']:g} mm "
                     f"(distances); reference heights from facets where the Jacobian inversion failed: "
                     f"{rep['reference_facet_points']:,} of {rep['points']:,} points")
    return "\n".join(lines)
