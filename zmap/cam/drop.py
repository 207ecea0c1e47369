"""Drop-cutter: the cutter-location (CL) height of a flat, ball or bull cutter over a design.

The CL height at an axis position ``(x, y)`` is the lowest tool-tip height at which the
cutter touches the surface without entering it::

    cl(x, y) = max over |u - (x, y)| <= R of  h(u) - envelope(|u - (x, y)|)

(``envelope`` is the cutter's lower envelope, :meth:`zmap.sim.tools.Cutter.lower_envelope`).
It is computed on the model given, with its own heights ``h``: a ``ZMap`` (its Bezier
surface), a ``PrecisionModel`` (:meth:`~zmap.model.PrecisionModel.height`), a ``cad_io.Part``
(exact top-most heights on the B-rep, :func:`cad_io.sampler.height_function`) or any
``heights(x, y)`` callable. Three steps:

1. a discrete drop over height samples of the model at ``pitch`` (a ZMap's own nodes), numba:
   on a tensor grid of axes (a meshgrid) a max-plus convolution of the samples with the
   cutter, one upper envelope per sample column (:mod:`zmap.cam._grid_kernels`); elsewhere,
   and for the bounds that step 3 needs, a block-max pyramid that visits blocks best bound
   first and stops when no block can beat the contact found (:mod:`zmap.cam._drop_kernels`),
   warm-started by the grid's contacts;
2. for every point, the paraboloid through the 3 x 3 samples around the best sample gives a
   sub-sample contact, whose exact height is evaluated (a smooth contact is then within
   ~1e-6 mm);
3. points whose contact is not smooth (a wall or edge beside it: a height jump in the 3 x 3
   samples, a sample without surface, the rim of the cutter, a neighbourhood that is not
   concave) are finished by a pattern search on the exact heights (8 directions projected
   onto the cutter's disk, step halved down to ``xtol``), which walks onto the edge.

Every value returned is an exact contact height of a real surface point (so never above the
true CL); what can be missed is a feature narrower than ``pitch`` between the samples.
"""

from __future__ import annotations

import math
import weakref
from typing import Any, Callable

import numpy as np

from ..errors import ZMapError

__all__ = ["drop_cutter", "model_heights", "as_cutter"]

_B = 8
_K = 4  # candidate samples by bound, searched from while their bound beats the contact found
_MAX_SAMPLES = 200_000_000
# how far along a crease (a wall's top, a sharp edge, the rim) the numba refinement walks
# from the contact the compass search stopped at, as a share of the cutter radius
_REACH = 0.1
# compass iterations per start in the numba refinement (creases are followed by the ridge walk)
_MAX_ITER = 200


_PACKS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


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
    _PACKS[model] = (tok, M)
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
    """``(heights(x, y), zmap or None, natural pitch or None)`` of a design model."""
    from ..grid import ZMap
    from ..model import PrecisionModel

    if isinstance(model, ZMap):
        if model.has_frame:
            raise ValueError("drop_cutter takes z-maps without a local frame")
        from ..interpolate import bezier

        return (lambda x, y: bezier(model, x, y)), model, min(model.dx, model.dy)
    if isinstance(model, PrecisionModel):
        return model.height, None, min(model.base.dx, model.base.dy) / 4
    if hasattr(model, "faces") and hasattr(model, "bbox"):  # cad_io.Part
        from cad_io.sampler import height_function

        b = model.bbox
        return height_function(model), None, max(b[3] - b[0], b[4] - b[1]) / 400
    if callable(model):
        return model, None, None
    raise ValueError("model must be a ZMap, a PrecisionModel, a cad_io Part or a heights(x, y) callable, "
                     f"got {type(model).__name__}")


def _contact(hf, cut, qx, qy, ux, uy):
    """Exact contact height h(u) - envelope(|u - q|); -inf outside the disk or without surface."""
    from . import _drop_kernels as K

    d = np.hypot(ux - qx, uy - qy).ravel()
    env = np.empty(d.size)
    K.envelope_many(cut.code, cut.radius, cut.corner_radius, np.ascontiguousarray(d), env)
    h = np.asarray(hf(ux.ravel(), uy.ravel()), dtype=np.float64)
    g = h - env
    g[~np.isfinite(g)] = -np.inf
    return g.reshape(np.shape(ux))


class _Serial:
    """numba kernels on one thread inside (the setting is thread-local and restored): the
    refinement calls the height kernels hundreds of times on small batches, where starting
    the parallel workers costs more than the work, and much more on a busy machine."""

    def __enter__(self):
        import numba

        self.n = numba.get_num_threads()
        numba.set_num_threads(1)

    def __exit__(self, *exc):
        import numba

        numba.set_num_threads(self.n)


def _pattern_search(hf, cut, qx, qy, ux, uy, g, step, xtol, max_iter=400):
    """Maximise the contact height around (ux, uy): compass steps in x, y and in polar
    coordinates about the axis (radius and arc, alone and together: a contact sliding along
    a curved edge needs the two at once), all kept on the cutter's disk; a step that finds
    nothing better is halved, down to ``xtol``."""
    R = cut.radius
    s = np.array(step, dtype=np.float64) * np.ones(qx.shape)
    c8 = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, 1], [1, -1], [-1, -1]], dtype=np.float64)
    cart = c8.copy()
    cart[4:] *= 0.7071067811865476
    # polar moves (dr, arc): the eight, and arcs with a small step inwards (an edge nearly
    # square to the radius is followed by turning much and coming in a little)
    pol = np.vstack([c8, [[-1 / 4, 1], [-1 / 4, -1], [-1 / 16, 1], [-1 / 16, -1], [-1 / 64, 1], [-1 / 64, -1],
                          [-1 / 256, 1], [-1 / 256, -1]]])
    act = np.flatnonzero(s > xtol)
    it = 0
    while act.size and it < max_iter:
        it += 1
        sa = s[act, None]
        qxa, qya = qx[act, None], qy[act, None]
        # cartesian candidates
        cx1 = ux[act, None] + sa * cart[None, :, 0]
        cy1 = uy[act, None] + sa * cart[None, :, 1]
        # polar candidates about the axis: dr, and arc length r*dtheta
        ox, oy = ux[act] - qx[act], uy[act] - qy[act]
        r0 = np.hypot(ox, oy)
        th0 = np.arctan2(oy, ox)
        rr = np.clip(r0[:, None] + sa * pol[None, :, 0], 0.0, R)
        th = th0[:, None] + sa * pol[None, :, 1] / np.maximum(r0[:, None], sa)
        cx2 = qxa + rr * np.cos(th)
        cy2 = qya + rr * np.sin(th)
        cx = np.concatenate([cx1, cx2], axis=1)
        cy = np.concatenate([cy1, cy2], axis=1)
        ox, oy = cx - qxa, cy - qya
        r = np.hypot(ox, oy)
        over = r > R
        f = np.where(over, R / np.where(over, r, 1.0), 1.0)
        cx = qxa + ox * f
        cy = qya + oy * f
        gc = _contact(hf, cut, qxa, qya, cx, cy)
        k = np.argmax(gc, axis=1)
        gb = gc[np.arange(act.size), k]
        better = gb > g[act]
        a = act[better]
        ux[a] = cx[better, k[better]]
        uy[a] = cy[better, k[better]]
        g[a] = gb[better]
        s[act[~better]] *= 0.5
        act = act[s[act] > xtol]
    return ux, uy, g


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


def drop_cutter(model: Any, cutter: Any, x: Any, y: Any, *, pitch: float | None = None,
                xtol: float = 1e-6, return_contact: bool = False, refine: bool = True,
                engine: str = "auto") -> Any:
    """Cutter-location heights of a cutter dropped onto a design at axis positions (x, y).

    Parameters
    ----------
    model : ZMap, PrecisionModel, cad_io.Part or callable ``heights(x, y)``
        The design; NaN heights are "no surface" (the cutter falls past them).
    cutter : Cutter or str — e.g. ``"ball:6"``, ``"flat:10"``, ``"bull:10:1"``.
    x, y : array_like of float — axis positions in mm (broadcast together).
    pitch : float, optional — spacing of the height samples of the discrete drop, mm; default:
        a ZMap's own grid, a PrecisionModel's base grid / 4, a Part's extent / 400, and never
        more than the cutter radius / 8. Features narrower than it may be missed.
    xtol : float — mm, the final step of the pattern search on non-smooth contacts.
    return_contact : bool — also return the contact points ``(cx, cy, cz)``.
    refine : bool — steps 2 and 3 (exact heights); False: the discrete drop alone.
    engine : {"auto", "numba", "python"} — where step 3 runs: "numba" (a ZMap or a
        PrecisionModel: one kernel per point, with a ridge walk along creases,
        :mod:`zmap.cam._model_eval`), "python" (batched height calls, any model; no ridge
        walk), "auto" (numba where the model allows).

    Returns
    -------
    cl : ndarray, float64, mm (shape of the broadcast x, y; a float for scalars) — tool-tip
        heights; NaN where no surface lies under the cutter.
    (cl, cx, cy, cz) with ``return_contact``.

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> step = lambda x, y: np.where(x > 0.01, 2.0, 0.0)      # a wall at x = 0.01, 2 mm high
    >>> round(float(drop_cutter(step, "ball:6", -1.0, 0.0, pitch=0.1)), 6)
    1.824872
    >>> round(2 - (3 - float(np.sqrt(9 - 1.01 ** 2))), 6)          # the ball touches its top edge
    1.824872
    """
    from ..grid import ZMap
    from . import _drop_kernels as K

    cut = as_cutter(cutter)
    if engine not in ("auto", "numba", "python"):
        raise ValueError(f"engine must be 'auto', 'numba' or 'python', got {engine!r}")
    xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    shape = xb.shape
    qx = np.ascontiguousarray(xb.ravel())
    qy = np.ascontiguousarray(yb.ravel())
    if not (np.isfinite(qx).all() and np.isfinite(qy).all()):
        raise ValueError("x and y must be finite axis positions in mm")
    R = cut.radius
    hf, zm, natural = model_heights(model)
    M = None
    if engine != "python":
        from . import _model_eval as ME

        if ME.supported(model):
            M = _packed(model)
            if zm is None:  # a PrecisionModel: sample it through the same kernel
                def hf(x, y, M=M):
                    xs = np.ascontiguousarray(np.ravel(np.asarray(x, dtype=np.float64)))
                    ys = np.ascontiguousarray(np.ravel(np.asarray(y, dtype=np.float64)))
                    out = np.empty(xs.size)
                    ME.threaded(ME.heights, xs.size, M, xs, ys, out, chunk=16384)
                    return out.reshape(np.shape(x))
        elif engine == "numba":
            raise ValueError(f"engine='numba' needs a ZMap or a PrecisionModel without dense lattices, "
                             f"got {type(model).__name__}")
    if pitch is not None:
        pitch = float(pitch)
        if not (math.isfinite(pitch) and pitch > 0):
            raise ValueError(f"pitch must be a positive number of mm, got {pitch!r}")
    n = qx.size
    if n == 0:
        out = np.zeros(shape)
        return (out, out.copy(), out.copy(), out.copy()) if return_contact else out
    if zm is not None and pitch is None:
        Z, x0, y0, dx, dy = np.ascontiguousarray(zm.z, dtype=np.float64), zm.x0, zm.y0, zm.dx, zm.dy
    else:
        p = pitch or min(natural or R / 8, R / 8)
        lo_x, hi_x = qx.min() - R - p, qx.max() + R + p
        lo_y, hi_y = qy.min() - R - p, qy.max() + R + p
        nx = int(math.ceil((hi_x - lo_x) / p)) + 1
        ny = int(math.ceil((hi_y - lo_y) / p)) + 1
        if nx * ny > _MAX_SAMPLES:
            raise ZMapError(f"drop_cutter would sample {nx} x {ny} heights at pitch {p:g} mm "
                            f"(cap {_MAX_SAMPLES:.0e}): give a coarser pitch or fewer points")
        x0, y0, dx, dy = lo_x, lo_y, p, p
        X, Y = np.meshgrid(x0 + dx * np.arange(nx), y0 + dy * np.arange(ny), indexing="ij")
        Z = np.ascontiguousarray(np.asarray(hf(X.ravel(), Y.ravel()), dtype=np.float64).reshape(nx, ny))
    nx, ny = Z.shape
    # a tensor grid of axes (rows of equal x and columns of equal y, as meshgrid gives): the
    # discrete drop as a max-plus convolution, exact over the samples (zmap.cam._grid_kernels)
    gv = gi = gj = None
    tg = _tensor_grid(xb)
    if tg is not None:
        gv, gi, gj = _grid_drop(Z, float(x0), float(y0), float(dx), float(dy), cut, xb, yb, tg)
        if gv is not None and not refine:
            val, oi, oj = gv, gi, gj
    # each sample's height raised by half its largest drop to a neighbour: a bound of the
    # surface within half a pitch of it (a local maximum between samples, at an edge)
    ZU = Z
    if refine:
        rise = np.zeros_like(Z)
        P = np.pad(Z, 1, constant_values=np.nan)
        with np.errstate(invalid="ignore"):
            for a in (-1, 0, 1):
                for b in (-1, 0, 1):
                    if a or b:
                        dz = Z - P[1 + a:1 + a + nx, 1 + b:1 + b + ny]
                        np.fmax(rise, dz, out=rise)
        ZU = np.ascontiguousarray(Z + 0.5 * rise)
    if gv is None or refine:
        bm = np.empty(((nx + _B - 1) // _B, (ny + _B - 1) // _B))
        K.block_max(ZU, _B, bm)
        val = np.empty(n)
        oi = np.empty(n, dtype=np.int64)
        oj = np.empty(n, dtype=np.int64)
    slack = 0.75 * math.hypot(dx, dy) if refine else 0.0
    cell = 0.5 * math.hypot(dx, dy) if refine else 0.0
    uval = np.empty((n, _K))
    ui = np.empty((n, _K), dtype=np.int64)
    uj = np.empty((n, _K), dtype=np.int64)
    band = np.empty(n)
    if gv is None or refine:
        if gv is None:
            w0, wi, wj = np.full(n, -np.inf), np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64)
        else:
            w0, wi, wj = gv, gi, gj
        K.drop_samples(Z, ZU, float(x0), float(y0), float(dx), float(dy), bm, _B, cut.code, R, cut.corner_radius,
                       slack, cell, qx, qy, val, oi, oj, uval, ui, uj, band, w0, wi, wj)
    ok = oi >= 0
    ux = np.where(ok, x0 + oi * dx, np.nan)
    uy = np.where(ok, y0 + oj * dy, np.nan)
    if refine and ok.any():
        # a best sample just outside the disk: start from its projection on the rim, exactly
        ox, oy = ux - qx, uy - qy
        rr = np.hypot(ox, oy)
        out_ = np.flatnonzero(ok & (rr > R))
        if out_.size:
            f = R / rr[out_]
            ux[out_] = qx[out_] + ox[out_] * f
            uy[out_] = qy[out_] + oy[out_] * f
            val[out_] = _contact(hf, cut, qx[out_], qy[out_], ux[out_], uy[out_])
        idx = np.flatnonzero(ok)
        I, J = oi[idx], oj[idx]
        gn = np.empty((idx.size, 3, 3))
        zn = np.empty((idx.size, 3, 3))
        for a in (-1, 0, 1):
            for b in (-1, 0, 1):
                ii, jj = I + a, J + b
                inside = (ii >= 0) & (ii < nx) & (jj >= 0) & (jj < ny)
                zz = np.where(inside, Z[np.clip(ii, 0, nx - 1), np.clip(jj, 0, ny - 1)], np.nan)
                d = np.hypot(x0 + ii * dx - qx[idx], y0 + jj * dy - qy[idx])
                env = np.empty(d.size)
                K.envelope_many(cut.code, R, cut.corner_radius, np.ascontiguousarray(d), env)
                zn[:, a + 1, b + 1] = zz
                gn[:, a + 1, b + 1] = zz - env
        g0 = gn[:, 1, 1]
        cxx = gn[:, 0, 1] + gn[:, 2, 1] - 2 * g0
        cyy = gn[:, 1, 0] + gn[:, 1, 2] - 2 * g0
        with np.errstate(invalid="ignore", divide="ignore"):
            rng = np.nanmax(zn.reshape(-1, 9), axis=1) - np.nanmin(zn.reshape(-1, 9), axis=1)
            smooth = (np.isfinite(gn).all(axis=(1, 2)) & (cxx < 0) & (cyy < 0)
                      & (rng <= 3.0 * max(dx, dy)))
            tx = np.clip(0.5 * (gn[:, 0, 1] - gn[:, 2, 1]) / cxx, -0.5, 0.5)
            ty = np.clip(0.5 * (gn[:, 1, 0] - gn[:, 1, 2]) / cyy, -0.5, 0.5)
        if cut.code == 2:  # a bull's envelope has a kink where the flat bottom meets the torus
            r0 = R - cut.corner_radius
            db = np.hypot(ux[idx] - qx[idx], uy[idx] - qy[idx])
            smooth &= np.abs(db - r0) > 3.0 * max(dx, dy)
        tx = np.where(smooth, tx, 0.0)
        ty = np.where(smooth, ty, 0.0)
        px = ux[idx] + tx * dx
        py = uy[idx] + ty * dy
        gs = _contact(hf, cut, qx[idx], qy[idx], px, py)
        g_here = val[idx]
        better = gs > g_here
        ux[idx[better]] = px[better]
        uy[idx[better]] = py[better]
        val[idx[better]] = gs[better]
        # starts of the pattern search (all searched together, one height call per step):
        # the contacts that are not smooth (walls, edges, rim, kinks)
        rough = idx[~smooth]
        st_p, st_x, st_y, st_g, st_s = [rough], [ux[rough]], [uy[rough]], [val[rough]], \
            [np.full(rough.size, 0.5 * max(dx, dy))]
        st_b = [np.full(rough.size, np.inf)]
        # a sample whose cell could hold a higher contact than the one found (an edge between
        # samples near the rim, where the envelope is steep): search from it too
        for kk in range(_K):
            # only samples away from the best one (its neighbourhood is searched already):
            # another local maximum that the samples may under-rate
            away = (np.abs(ui[:, kk] - oi) > 1) | (np.abs(uj[:, kk] - oj) > 1)
            other = np.flatnonzero(ok & away & (uval[:, kk] > val + 1e-9))
            if other.size:
                sx0 = x0 + ui[other, kk] * dx
                sy0 = y0 + uj[other, kk] * dy
                ox, oy = sx0 - qx[other], sy0 - qy[other]
                rr = np.hypot(ox, oy)
                f = np.where(rr > R, R / np.maximum(rr, 1e-300), 1.0)
                sx0, sy0 = qx[other] + ox * f, qy[other] + oy * f
                st_p.append(other)
                st_x.append(sx0)
                st_y.append(sy0)
                st_g.append(_contact(hf, cut, qx[other], qy[other], sx0, sy0))
                st_s.append(np.full(other.size, 0.5 * max(dx, dy)))
                st_b.append(uval[other, kk])
        # the rim: a feature may reach into the disk between samples there; sample a band of
        # three rings every pitch/4 of arc exactly, and search from the best ring point
        # (a flat end mill touches a slope with its rim, where maxima between samples hide:
        # its rims are always sampled)
        ring = np.flatnonzero(ok) if cut.code == 0 else np.flatnonzero(ok & (band > val + 1e-9))
        if M is not None:
            from . import _model_eval as ME

            # every point with a start or a ring is searched in one kernel, per point
            sp = np.concatenate(st_p)
            need = np.zeros(n, dtype=bool)
            need[sp] = True
            need[ring] = True
            pts = np.flatnonzero(need)
            # per point, its starts best bound first (the rough contact itself: unbounded)
            bnd = np.concatenate(st_b)
            order = np.lexsort((-bnd, sp))
            cnt = np.bincount(sp, minlength=n)[pts]
            ptr = np.zeros(pts.size + 1, dtype=np.int64)
            np.cumsum(cnt, out=ptr[1:])
            bandf = np.full(n, -np.inf)
            bandf[ring] = np.inf if cut.code == 0 else band[ring]
            sub_v = np.ascontiguousarray(val[pts])
            sub_x = np.ascontiguousarray(ux[pts])
            sub_y = np.ascontiguousarray(uy[pts])
            ME.threaded(ME.refine_points, pts.size, M, cut.code, R, cut.corner_radius,
                        np.ascontiguousarray(qx[pts]), np.ascontiguousarray(qy[pts]), ptr,
                        np.ascontiguousarray(np.concatenate(st_x)[order], dtype=np.float64),
                        np.ascontiguousarray(np.concatenate(st_y)[order], dtype=np.float64),
                        np.ascontiguousarray(np.concatenate(st_s)[order], dtype=np.float64),
                        np.ascontiguousarray(bnd[order], dtype=np.float64),
                        np.ascontiguousarray(bandf[pts]), min(dx, dy), cell, _REACH * R, xtol, _MAX_ITER,
                        sub_v, sub_x, sub_y, chunk=64)
            b = sub_v > val[pts]
            val[pts[b]], ux[pts[b]], uy[pts[b]] = sub_v[b], sub_x[b], sub_y[b]
            ring = ring[:0]
            st_p, st_x, st_y, st_g, st_s = [np.zeros(0, np.int64)], [np.zeros(0)], [np.zeros(0)], [np.zeros(0)], \
                [np.zeros(0)]
        if ring.size:
            h = 0.25 * min(dx, dy)
            m = max(16, int(math.ceil(2 * math.pi * R / h)))
            th = 2 * math.pi * np.arange(m) / m
            rad = np.array([R, R - cell / 2, R - cell])
            ox = (rad[:, None] * np.cos(th)[None, :]).ravel()
            oy = (rad[:, None] * np.sin(th)[None, :]).ravel()
            for part in np.array_split(ring, max(1, ring.size * ox.size // 2_000_000)):
                px = qx[part, None] + ox[None, :]
                py = qy[part, None] + oy[None, :]
                gr = _contact(hf, cut, qx[part, None], qy[part, None], px, py)
                k = np.argmax(gr, axis=1)
                r_ = np.arange(part.size)
                st_p.append(part)
                st_x.append(px[r_, k])
                st_y.append(py[r_, k])
                st_g.append(gr[r_, k])
                st_s.append(np.full(part.size, h))
        sp = np.concatenate(st_p)
        if sp.size:
            with _Serial():
                sx, sy, sg = _pattern_search(hf, cut, qx[sp], qy[sp], np.concatenate(st_x).astype(np.float64),
                                             np.concatenate(st_y).astype(np.float64),
                                             np.concatenate(st_g).astype(np.float64), np.concatenate(st_s), xtol)
            order = np.lexsort((-sg, sp))  # per point, its best search first
            first = np.r_[True, sp[order][1:] != sp[order][:-1]]
            w = order[first]
            b = sg[w] > val[sp[w]]
            ux[sp[w][b]], uy[sp[w][b]], val[sp[w][b]] = sx[w][b], sy[w][b], sg[w][b]
    cl = np.where(np.isfinite(val), val, np.nan).reshape(shape)
    if not return_contact:
        return cl[()] if cl.ndim == 0 else cl
    cz = cl + np.where(ok, 0.0, np.nan).reshape(shape)
    d = np.hypot(ux - qx, uy - qy)
    env = np.empty(d.size)
    K.envelope_many(cut.code, R, cut.corner_radius, np.ascontiguousarray(np.nan_to_num(d, nan=2 * R)), env)
    cz = (cl.ravel() + env).reshape(shape)
    return cl, ux.reshape(shape), uy.reshape(shape), cz
