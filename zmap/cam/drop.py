"""Drop-cutter: the cutter-location (CL) height of a flat, ball or bull cutter over a design.

The CL height at an axis position ``(x, y)`` is the lowest tool-tip height at which the
cutter touches the design without entering it::

    cl(x, y) = max over |u - (x, y)| <= R of  h(u) - envelope(|u - (x, y)|)

(``envelope`` is the cutter's lower envelope, :meth:`zmap.sim.tools.Cutter.lower_envelope`).
:func:`drop_cutter` computes it by branch and bound on the design's Bezier patches
(:mod:`zmap.cam.bounds`): a lower bound from exact points of the design, an upper bound per
cell from its control net, cells split until no cell can beat the lower bound by more than
``eps`` (1e-5 mm). The value returned is the largest bound left: never below the true height
and never above it by more than ``eps``, which is what a finishing program needs (a CL point
below the true height is a gouge).

* A :class:`~zmap.ZMap` is dropped on exactly: its own Bezier surface
  (:func:`zmap.interpolate.bezier`) and its nodes. The answer is certified.
* A :class:`~zmap.model.PrecisionModel`, a STEP part (``cad_io.Part``, exact top-most heights
  of the B-rep) or a ``heights(x, y)`` callable is sampled on a grid over the region the
  cutter can reach (every ``pitch``, and ``check`` times finer for the margins of
  :func:`zmap.cam.bounds.from_heights`); the answer is as sure as those samples: a feature
  narrower than the fine spacing can be under-rated.

``refine=False`` gives the discrete drop alone (the samples at ``pitch`` and a max-plus
convolution, :mod:`zmap.cam._grid_kernels`): fast and never above the true height, but low by up
to the surface's rise between samples.
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from typing import Any, Callable

import numpy as np

from ..errors import ZMapError
from ..gridspec import lines_covering

__all__ = ["drop_cutter", "model_heights", "as_cutter"]

_B = 8
_MAX_SAMPLES = 200_000_000


class _ModelCache:
    """Values kept per design object while it lives, keyed by identity: a STEP part is a
    dataclass (equal parts compare equal and are unhashable), so a WeakKeyDictionary cannot
    hold it."""

    def __init__(self) -> None:
        self._items: dict[int, tuple] = {}

    def get(self, obj: Any) -> Any:
        hit = self._items.get(id(obj))
        return hit[1] if hit is not None and hit[0]() is obj else None

    def put(self, obj: Any, value: Any) -> None:
        key = id(obj)
        try:
            ref = weakref.ref(obj, lambda _r, k=key, d=self._items: d.pop(k, None))
        except TypeError:  # no weak reference to it: not kept
            return
        self._items[key] = (ref, value)

    def clear(self) -> None:
        self._items.clear()


_PACKS = _ModelCache()


def _packed(model: Any) -> tuple:
    """:func:`zmap.cam._model_eval.pack_model`, kept per PrecisionModel (packing an EZ model
    gathers its tables and patches: seconds, paid once rather than per call; a model has no
    mutating method, and the arrays' identities are checked)."""
    from ..model import PrecisionModel
    from . import _model_eval as ME

    if not isinstance(model, PrecisionModel):
        return ME.pack_model(model)
    tok = (id(model.base), id(model.base.z), id(model.ez), id(getattr(model, "_cz_z", None)))
    hit = _PACKS.get(model)
    if hit is not None and hit[0] == tok:
        return hit[1]
    M = ME.pack_model(model)
    _PACKS.put(model, (tok, M))
    return M


def as_cutter(cutter: Any) -> Any:
    """A :class:`zmap.sim.tools.Cutter` from a Cutter or a spec like ``"ball:6"``."""
    from ..sim.tools import Cutter, parse_tool_spec

    if isinstance(cutter, str):
        return parse_tool_spec(cutter)
    if isinstance(cutter, Cutter):
        return cutter
    raise ValueError(f"cutter must be a Cutter or a spec like 'ball:6', got {cutter!r}")


def model_heights(model: Any) -> tuple[Callable, Any, float | None]:
    """``(heights(x, y), zmap or None, natural pitch or None)`` of a design model
    (:func:`zmap.design.as_design`)."""
    from ..design import as_design
    from ..grid import ZMap

    if isinstance(model, ZMap) and model.has_frame:
        raise ValueError("drop_cutter takes z-maps without a local frame")
    d = as_design(model)
    return d.heights, (model if d.kind == "zmap" else None), d.pitch


def _tensor_grid(xb: np.ndarray) -> int | None:
    """0 where the axes form a tensor grid with equal x along each row (``indexing='ij'``),
    1 where equal x down each column (``indexing='xy'``), None otherwise (or too small)."""
    if xb.ndim != 2 or xb.shape[0] < 2 or xb.shape[1] < 2 or xb.size < 64:
        return None
    if (xb == xb[:, :1]).all():
        return 0
    if (xb == xb[:1, :]).all():
        return 1
    return None


def _grid_drop(Z, x0, y0, dx, dy, cut, xb, yb, kind):
    """The discrete drop on a tensor grid of axes: flat ``(val, oi, oj)`` in the order of
    ``xb.ravel()`` (``val`` -inf / ``oi`` -1 where no sample is under the cutter), or None
    when the axes are not a tensor grid (y must repeat across rows as x repeats along them)."""
    from . import _grid_kernels as G

    if kind == 1:  # rows of equal y: swap the axes' roles (and the samples')
        xb, yb = yb.T, xb.T
        Z, x0, y0, dx, dy = Z.T, y0, x0, dy, dx
    qxs = np.ascontiguousarray(xb[:, 0])
    qy = yb[0]
    if not (yb == qy[None, :]).all():
        return None, None, None
    order = np.argsort(qy, kind="stable")
    qys = np.ascontiguousarray(qy[order])
    shp = (qxs.size, qys.size)
    out = np.empty(shp)
    oi = np.empty(shp, dtype=np.int64)
    oj = np.empty(shp, dtype=np.int64)
    G.drop_grid(np.ascontiguousarray(Z), x0, y0, dx, dy, cut.code, cut.radius, cut.corner_radius, qxs, qys,
                out, oi, oj)
    inv = np.empty_like(order)
    inv[order] = np.arange(order.size)
    out, oi, oj = out[:, inv], oi[:, inv], oj[:, inv]
    if kind == 1:
        out, oi, oj = out.T, oj.T, oi.T
    return (np.ascontiguousarray(out).ravel(), np.ascontiguousarray(oi).ravel(), np.ascontiguousarray(oj).ravel())


def _sampler(design: Any, hf: Callable) -> Callable:
    """``sample(x0, y0, h, nx, ny) -> (nx, ny)`` heights of a :class:`zmap.design.Design` on a
    grid: its own grid sampler where it has one (a STEP part), else ``hf`` at every node."""
    return design.grid if design.grid is not None else dataclasses.replace(design, heights=hf).sample_grid


_BOUNDS = _ModelCache()


def bounding_surface(model: Any, region: tuple, *, pitch: float | None = None, check: int | None = None) -> Any:
    """The :class:`zmap.cam.bounds.BoundingSurface` the drop-cutter uses for ``model`` over
    ``region`` ``(xmin, ymin, xmax, ymax)``: a z-map's own (kept per z-map), else the design
    sampled every ``pitch`` (default: a precision model's base grid / 4, a part's 0.25 mm) with
    ``check`` (default 4; a part 2) fine samples per interval, kept per model while later
    regions fall inside it."""
    from ..grid import ZMap
    from . import bounds as BD

    if isinstance(model, ZMap):
        tok = (id(model.z), model.z.ctypes.data, model.z.shape)
        hit = _BOUNDS.get(model)
        if hit is not None and hit[0] == tok:
            return hit[1]
        bs = BD.from_zmap(model)
        _BOUNDS.put(model, (tok, bs))
        return bs
    from ..design import as_design

    design = as_design(model)
    hf = design.heights
    if pitch is None:
        pitch = design.drop_pitch or design.pitch or 0.1
    if check is None:
        check = design.drop_check
    pitch = float(pitch)
    hit = _BOUNDS.get(model)
    if hit is not None and hit[0] == (pitch, check) and hit[1].covers(*region):
        return hit[1]
    if design.grid is None:
        M = _fast_heights(model)
        if M is not None:
            hf = M
    x0, y0 = region[0], region[1]
    nx = lines_covering(x0, region[2], pitch, at_least=1)
    ny = lines_covering(y0, region[3], pitch, at_least=1)
    if nx * ny * check * check > _MAX_SAMPLES:
        raise ZMapError(f"the drop-cutter would sample {nx * check} x {ny * check} heights at "
                        f"{pitch / check:g} mm (cap {_MAX_SAMPLES:.0e}): give a coarser pitch or a smaller region")
    F = _sampler(design, hf)(x0, y0, pitch / check, (nx - 1) * check + 1, (ny - 1) * check + 1)
    bs = BD.from_samples(F, x0, y0, pitch, check, source=type(model).__name__)
    _BOUNDS.put(model, ((pitch, check), bs))
    return bs


def _fast_heights(model: Any) -> Callable | None:
    """A precision model's heights through its numba kernel (:mod:`zmap.cam._model_eval`), or None."""
    from . import _model_eval as ME

    if not ME.supported(model) or not hasattr(model, "base"):
        return None
    M = _packed(model)

    def hf(x, y, M=M):
        xs = np.ascontiguousarray(np.ravel(np.asarray(x, dtype=np.float64)))
        ys = np.ascontiguousarray(np.ravel(np.asarray(y, dtype=np.float64)))
        out = np.empty(xs.size)
        ME.threaded(ME.heights, xs.size, M, xs, ys, out, chunk=16384)
        return out.reshape(np.shape(x))
    return hf


def drop_cutter(model: Any, cutter: Any, x: Any, y: Any, *, pitch: float | None = None,
                return_contact: bool = False, refine: bool = True, eps: float = 1e-5) -> Any:
    """Cutter-location heights of a cutter dropped onto a design at axis positions (x, y).

    Parameters
    ----------
    model : ZMap, PrecisionModel, cad_io.Part or callable ``heights(x, y)``
        The design; NaN heights are "no surface" (the cutter falls past them).
    cutter : Cutter or str
        e.g. ``"ball:6"``, ``"flat:10"``, ``"bull:10:1"``.
    x, y : array_like of float
        Axis positions in mm (broadcast together).
    pitch : float, optional
        Spacing of the design's samples, mm, for a design that is not a z-map (a z-map is dropped on
        its own surface and ignores it); default a precision model's base grid / 4, a part's 0.25
        mm, a callable's cutter radius / 8. With ``refine=False``, the spacing of the discrete
        drop's samples for every design.
    return_contact : bool
        Also return the contact points ``(cx, cy, cz)``.
    refine : bool
        True: the certified drop (:mod:`zmap.cam.bounds`); False: the discrete drop over samples
        alone (never above the true height, low by up to the rise between samples).
    eps : float
        mm; the certified drop's answer is never below the true height, and never above it by more
        on exact cells.

    Returns
    -------
    cl : ndarray, float64, mm (shape of the broadcast x, y; a float for scalars)
        Tool-tip heights; NaN where no surface lies under the cutter.
    (cl, cx, cy, cz) with ``return_contact``.

    Examples
    --------
    >>> import numpy as np
    >>> step = lambda x, y: np.where(x > 0.01, 2.0, 0.0)      # a wall at x = 0.01, 2 mm high
    >>> cl = float(drop_cutter(step, "ball:6", -1.0, 0.0, pitch=0.1))
    >>> exact = 2 - (3 - float(np.sqrt(9 - 1.01 ** 2)))        # the ball on the wall's top edge
    >>> 0 <= cl - exact < 0.01                                   # sampled: never below, within a cell
    True
    >>> from zmap import ZMap
    >>> dome = ZMap.from_function(lambda x, y: 5 - 0.01 * (x * x + y * y), (-10, -10, 10, 10), 0.5)
    >>> round(float(drop_cutter(dome, "ball:6", 0.0, 0.0)), 4)   # a z-map: exact
    5.0
    """
    from . import _drop_kernels as K

    cut = as_cutter(cutter)
    if not (isinstance(eps, (int, float)) and math.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number of mm, got {eps!r}")
    xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    shape = xb.shape
    qx = np.ascontiguousarray(xb.ravel())
    qy = np.ascontiguousarray(yb.ravel())
    if not (np.isfinite(qx).all() and np.isfinite(qy).all()):
        raise ValueError("x and y must be finite axis positions in mm")
    R = cut.radius
    if pitch is not None:
        pitch = float(pitch)
        if not (math.isfinite(pitch) and pitch > 0):
            raise ValueError(f"pitch must be a positive number of mm, got {pitch!r}")
    hf, zm, natural = model_heights(model)
    n = qx.size
    if n == 0:
        out = np.zeros(shape)
        return (out, out.copy(), out.copy(), out.copy()) if return_contact else out
    if refine:
        if zm is None and pitch is None and natural is None:
            pitch = R / 8
        p = pitch or natural or R / 8
        region = (qx.min() - R - p, qy.min() - R - p, qx.max() + R + 2 * p, qy.max() + R + 2 * p)
        from .bounds import drop_bound

        bs = bounding_surface(model, region, pitch=pitch)
        cl, ux, uy, _kept = drop_bound(bs, cut, qx, qy, eps=eps)
        ok = np.isfinite(cl)
    else:
        if zm is not None and pitch is None:
            Z, x0, y0, dx, dy = np.ascontiguousarray(zm.z, dtype=np.float64), zm.x0, zm.y0, zm.dx, zm.dy
        else:
            if zm is None:  # a precision model: sampled through its numba kernel
                hf = _fast_heights(model) or hf
            p = pitch or min(natural or R / 8, R / 8)
            x0, y0 = qx.min() - R - p, qy.min() - R - p
            nx = int(math.ceil((qx.max() + R + p - x0) / p)) + 1
            ny = int(math.ceil((qy.max() + R + p - y0) / p)) + 1
            if nx * ny > _MAX_SAMPLES:
                raise ZMapError(f"drop_cutter would sample {nx} x {ny} heights at pitch {p:g} mm "
                                f"(cap {_MAX_SAMPLES:.0e}): give a coarser pitch or fewer points")
            dx = dy = p
            from ..design import as_design

            Z = np.ascontiguousarray(_sampler(as_design(model), hf)(x0, y0, p, nx, ny))
        cl, ux, uy = _discrete(Z, float(x0), float(y0), float(dx), float(dy), cut, xb, yb, qx, qy)
        ok = np.isfinite(cl)
    cl = np.where(ok, cl, np.nan).reshape(shape)
    if not return_contact:
        return cl[()] if cl.ndim == 0 else cl
    d = np.hypot(ux - qx, uy - qy)
    env = np.empty(d.size)
    K.envelope_many(cut.code, R, cut.corner_radius, np.ascontiguousarray(np.nan_to_num(np.minimum(d, R), nan=R)),
                    env)
    cz = (cl.ravel() + np.where(ok, env, np.nan)).reshape(shape)
    return cl, np.where(ok, ux, np.nan).reshape(shape), np.where(ok, uy, np.nan).reshape(shape), cz


def _discrete(Z, x0, y0, dx, dy, cut, xb, yb, qx, qy):
    """The discrete drop over samples: ``(val, contact x, contact y)`` flat (-inf: none)."""
    from . import _drop_kernels as K

    n = qx.size
    nx, ny = Z.shape
    tg = _tensor_grid(xb)
    if tg is not None:
        gv, gi, gj = _grid_drop(Z, x0, y0, dx, dy, cut, xb, yb, tg)
        if gv is not None:
            ok = gi >= 0
            return gv, np.where(ok, x0 + gi * dx, np.nan), np.where(ok, y0 + gj * dy, np.nan)
    bm = np.empty(((nx + _B - 1) // _B, (ny + _B - 1) // _B))
    K.block_max(Z, _B, bm)
    val = np.empty(n)
    oi = np.empty(n, dtype=np.int64)
    oj = np.empty(n, dtype=np.int64)
    uval = np.empty((n, 1))
    ui = np.empty((n, 1), dtype=np.int64)
    uj = np.empty((n, 1), dtype=np.int64)
    band = np.empty(n)
    w0, wi, wj = np.full(n, -np.inf), np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64)
    K.drop_samples(Z, Z, x0, y0, dx, dy, bm, _B, cut.code, cut.radius, cut.corner_radius, 0.0, 0.0, qx, qy, val,
                   oi, oj, uval, ui, uj, band, w0, wi, wj)
    ok = oi >= 0
    return val, np.where(ok, x0 + oi * dx, np.nan), np.where(ok, y0 + oj * dy, np.nan)
