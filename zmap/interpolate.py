"""Height queries on a z-map: the paper's cubic Bezier scheme and bilinear interpolation.

All functions broadcast over arrays of world x and y (scalars work too) and return float64
heights: NaN outside the map or where a corner of the cell holding the point has no height,
NaN for NaN or infinite query coordinates. ``strict=True`` raises
:class:`zmap.errors.OutOfDomainError` naming the first such point instead.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from . import _interp_kernels as _k
from .errors import OutOfDomainError
from .grid import ZMap

__all__ = ["bezier", "bilinear", "evaluate", "SCHEMES", "TANGENTS", "BOUNDARIES"]

TANGENTS = {"circle": _k.TANGENT_CIRCLE, "central": _k.TANGENT_CENTRAL, "quartic": _k.TANGENT_QUARTIC}
BOUNDARIES = {"dummy": _k.BOUNDARY_DUMMY, "one-sided": _k.BOUNDARY_ONE_SIDED}


def _choice(name: str, value: str, valid: dict):
    if value not in valid:
        options = ", ".join(repr(v) for v in valid)
        raise ValueError(f"{name}={value!r} is not one of {options}")
    return valid[value]


def _prepare(zm: ZMap, x, y) -> tuple[np.ndarray, np.ndarray, tuple]:
    if not isinstance(zm, ZMap):
        raise TypeError(f"zm must be a zmap.ZMap, got {type(zm).__name__}")
    xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    return np.ascontiguousarray(xb).ravel(), np.ascontiguousarray(yb).ravel(), xb.shape


def _finish(out: np.ndarray, xs: np.ndarray, ys: np.ndarray, shape: tuple, strict: bool, zm: ZMap):
    if strict:
        bad = np.flatnonzero(np.isnan(out))
        if bad.size:
            k = int(bad[0])
            where = "a non-finite coordinate" if not (np.isfinite(xs[k]) and np.isfinite(ys[k])) else (
                "outside the map" if not zm.contains(xs[k], ys[k]) else "in a cell with a missing corner height")
            raise OutOfDomainError(
                f"no height at point {k} (x={float(xs[k])!r}, y={float(ys[k])!r}): {where}; "
                f"{bad.size} of {out.size} points have none")
    out = out.reshape(shape)
    return out[()] if out.ndim == 0 else out


def bezier(zm: ZMap, x, y, *, tangent: str = "circle", boundary: str = "dummy", strict: bool = False):
    """Non-parametric cubic Bezier interpolation (paper 004, Eq. 4-7).

    The 12 grid points around the cell give two x-direction curves (W1, W2) evaluated at u,
    two y-direction curves (V3, V4) between those values evaluated at v, and the blend
    ``Zp = (1-u)*w3 + u*w4``. Control points are ``v1 = v0 + s*d/3`` and
    ``v2 = v3 - t*d/3`` with slopes s, t from the chosen tangent scheme.

    Parameters
    ----------
    zm : ZMap
        The map; its local frame is honoured.
    x, y : array_like of float, broadcastable
        World coordinates in mm.
    tangent : {'circle', 'central', 'quartic'}
        Slope at a grid point: 'circle' is the paper's tangent of the circle through three
        consecutive heights; 'central' the central difference (slope of the parabola);
        'quartic' the fourth-order five-point difference, the most accurate local scheme
        offered (falls back to 'central' where two neighbours are not both present).
    boundary : {'dummy', 'one-sided'}
        At the map's edge: 'dummy' grid points by linear extrapolation (paper §2.2), or
        one-sided three-point tangents.
    strict : bool
        Raise OutOfDomainError instead of returning NaN.

    Returns
    -------
    ndarray of float64 (broadcast shape of x and y), or float for scalar input
        Heights in mm. Where a stencil point other than a cell corner is missing the slope
        falls back to a one-sided tangent, then to the secant (the bilinear limit).

    Examples
    --------
    >>> import numpy as np
    >>> from zmap import ZMap
    >>> zm = ZMap.from_function(lambda x, y: 0.5 * x - y, (0, 0, 4, 4), 1.0)
    >>> float(bezier(zm, 1.25, 2.5))
    -1.875
    """
    tcode = _choice("tangent", tangent, TANGENTS)
    bcode = _choice("boundary", boundary, BOUNDARIES)
    xs, ys, shape = _prepare(zm, x, y)
    out = np.empty(xs.shape[0], dtype=np.float64)
    c, s, ox, oy = zm.frame
    _k.bezier_kernel(zm.z, zm.x0, zm.y0, zm.dx, zm.dy, c, s, ox, oy, xs, ys, tcode, bcode, out)
    return _finish(out, xs, ys, shape, strict, zm)


def bilinear(zm: ZMap, x, y, *, strict: bool = False):
    """Bilinear interpolation from the four corners of the cell holding each point.

    Parameters
    ----------
    zm : ZMap
    x, y : array_like of float, broadcastable
        World coordinates in mm.
    strict : bool
        Raise OutOfDomainError instead of returning NaN.

    Returns
    -------
    ndarray of float64, or float for scalar input

    Examples
    --------
    >>> from zmap import ZMap
    >>> zm = ZMap.from_function(lambda x, y: x * y, (0, 0, 2, 2), 1.0)
    >>> float(bilinear(zm, 0.5, 0.5))
    0.25
    """
    xs, ys, shape = _prepare(zm, x, y)
    out = np.empty(xs.shape[0], dtype=np.float64)
    c, s, ox, oy = zm.frame
    _k.bilinear_kernel(zm.z, zm.x0, zm.y0, zm.dx, zm.dy, c, s, ox, oy, xs, ys, out)
    return _finish(out, xs, ys, shape, strict, zm)


def _bezier_with(tangent: str) -> Callable:
    def scheme(zm: ZMap, x, y, *, strict: bool = False, boundary: str = "dummy"):
        return bezier(zm, x, y, tangent=tangent, boundary=boundary, strict=strict)

    scheme.__name__ = f"bezier_{tangent}"
    return scheme


#: Every interpolation scheme by name, as the accuracy tables and the CLI list them.
SCHEMES: dict[str, Callable] = {
    "bilinear": bilinear,
    "bezier": _bezier_with("circle"),
    "bezier-central": _bezier_with("central"),
    "bezier-quartic": _bezier_with("quartic"),
}


def evaluate(zm: ZMap, x, y, *, scheme: str = "bezier", strict: bool = False):
    """Heights by the named scheme (one of :data:`SCHEMES`).

    Examples
    --------
    >>> from zmap import ZMap
    >>> zm = ZMap.from_function(lambda x, y: x + y, (0, 0, 3, 3), 1.0)
    >>> float(evaluate(zm, 1.5, 1.5, scheme="bezier-quartic"))
    3.0
    """
    return _choice("scheme", scheme, SCHEMES)(zm, x, y, strict=strict)
