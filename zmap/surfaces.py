"""Exact analytic surfaces ``z = f(x, y)`` with gradients, for accuracy checks.

The first three are the surfaces of Table 1 of paper 004. Heights are NaN where the
surface does not exist (outside the sphere cap or the torus).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = [
    "AnalyticSurface",
    "SURFACES",
    "TABLE1",
    "get",
    "sphere_cap",
    "sine",
    "tilted_plane",
    "saddle",
    "gaussian_bump",
    "torus_patch",
]

Array = np.ndarray


@dataclass(frozen=True)
class AnalyticSurface:
    """A surface ``z = f(x, y)`` known exactly.

    Parameters
    ----------
    name : str
        Short name used by the CLI and tables.
    label : str
        The equation, as a table prints it.
    height : callable
        ``height(x, y) -> z`` (mm), vectorised; NaN where there is no surface.
    gradient : callable
        ``gradient(x, y) -> (dz/dx, dz/dy)``, vectorised.
    domain : tuple of float
        ``(x0, y0, x1, y1)``: the query domain of the accuracy table.

    Examples
    --------
    >>> s = sphere_cap()
    >>> float(s.height(0.0, 0.0))
    100.0
    """

    name: str
    label: str
    height: Callable[[Array, Array], Array]
    gradient: Callable[[Array, Array], tuple[Array, Array]]
    domain: tuple[float, float, float, float]

    def normal(self, x, y) -> Array:
        """Unit upward normal, shape ``broadcast(x, y).shape + (3,)``."""
        gx, gy = self.gradient(np.asarray(x, float), np.asarray(y, float))
        gx, gy = np.broadcast_arrays(gx, gy)
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _f(a) -> Array:
    return np.asarray(a, dtype=np.float64)


def sphere_cap(radius: float = 100.0, z_min: float = 70.0, half_width: float = 40.0) -> AnalyticSurface:
    """Upper sphere ``x^2 + y^2 + z^2 = R^2`` where ``z > z_min`` (Table 1, row 1).

    The paper does not state its query domain; the square ``[-40, 40]^2`` (corners at
    z = 82.5) reproduces its bilinear column (-3.7e-3) and is the default.
    """
    r2 = radius * radius

    def height(x, y):
        x, y = _f(x), _f(y)
        with np.errstate(invalid="ignore"):
            z = np.sqrt(r2 - x * x - y * y)
        return np.where(z > z_min, z, np.nan)

    def gradient(x, y):
        x, y = _f(x), _f(y)
        z = height(x, y)
        return -x / z, -y / z

    label = f"x^2+y^2+z^2={radius:g}^2, z>{z_min:g}"
    return AnalyticSurface("sphere", label, height, gradient, (-half_width, -half_width, half_width, half_width))


def sine(amplitude: float = 100.0, half_period: float = 180.0) -> AnalyticSurface:
    """``z = A sin(pi x / period)`` (Table 1, rows 2 and 3 with A = 100 and 1000)."""
    k = np.pi / half_period

    def height(x, y):
        x, y = np.broadcast_arrays(_f(x), _f(y))
        return amplitude * np.sin(k * x)

    def gradient(x, y):
        x, y = np.broadcast_arrays(_f(x), _f(y))
        return amplitude * k * np.cos(k * x), np.zeros_like(y)

    name = f"sine{amplitude:g}"
    return AnalyticSurface(name, f"z={amplitude:g}*sin(pi*x/{half_period:g})", height, gradient,
                           (-half_period, -50.0, half_period, 50.0))


def tilted_plane(a: float = 0.3, b: float = -0.2, c: float = 5.0) -> AnalyticSurface:
    """``z = a x + b y + c``: every scheme must reproduce it to rounding."""

    def height(x, y):
        x, y = np.broadcast_arrays(_f(x), _f(y))
        return a * x + b * y + c

    def gradient(x, y):
        x, y = np.broadcast_arrays(_f(x), _f(y))
        return np.full_like(x, a), np.full_like(y, b)

    return AnalyticSurface("plane", f"z={a:g}x{b:+g}y{c:+g}", height, gradient, (-50.0, -50.0, 50.0, 50.0))


def saddle(scale: float = 50.0) -> AnalyticSurface:
    """``z = (x^2 - y^2) / (2 * scale)``."""

    def height(x, y):
        x, y = _f(x), _f(y)
        return (x * x - y * y) / (2.0 * scale)

    def gradient(x, y):
        x, y = np.broadcast_arrays(_f(x), _f(y))
        return x / scale, -y / scale

    return AnalyticSurface("saddle", f"z=(x^2-y^2)/{2 * scale:g}", height, gradient, (-50.0, -50.0, 50.0, 50.0))


def gaussian_bump(amplitude: float = 20.0, sigma: float = 15.0) -> AnalyticSurface:
    """``z = A exp(-(x^2 + y^2) / (2 sigma^2))``."""

    def height(x, y):
        x, y = _f(x), _f(y)
        return amplitude * np.exp(-(x * x + y * y) / (2.0 * sigma * sigma))

    def gradient(x, y):
        x, y = _f(x), _f(y)
        z = height(x, y)
        return -x / (sigma * sigma) * z, -y / (sigma * sigma) * z

    return AnalyticSurface("gaussian", f"z={amplitude:g}exp(-r^2/{2 * sigma * sigma:g})", height, gradient,
                           (-40.0, -40.0, 40.0, 40.0))


def torus_patch(major: float = 60.0, minor: float = 20.0) -> AnalyticSurface:
    """Upper half of a torus about the z axis: ``z = sqrt(r^2 - (rho - R)^2)``, ``rho = |xy|``.

    The query domain is the quadrant patch ``x, y in [10, 70]``; heights are NaN off the
    torus.
    """

    def height(x, y):
        x, y = _f(x), _f(y)
        rho = np.hypot(x, y)
        with np.errstate(invalid="ignore"):
            z = np.sqrt(minor * minor - (rho - major) ** 2)
        return z

    def gradient(x, y):
        x, y = _f(x), _f(y)
        rho = np.hypot(x, y)
        z = height(x, y)
        with np.errstate(invalid="ignore", divide="ignore"):
            g = -(rho - major) / (z * rho)
        return g * x, g * y

    return AnalyticSurface("torus", f"torus R={major:g} r={minor:g}", height, gradient, (10.0, 10.0, 70.0, 70.0))


#: Every surface by name, with its default parameters.
SURFACES: dict[str, Callable[[], AnalyticSurface]] = {
    "sphere": sphere_cap,
    "sine100": lambda: sine(100.0),
    "sine1000": lambda: sine(1000.0),
    "plane": tilted_plane,
    "saddle": saddle,
    "gaussian": gaussian_bump,
    "torus": torus_patch,
}

#: The rows of Table 1 of paper 004.
TABLE1 = ("sphere", "sine100", "sine1000")


def get(name: str) -> AnalyticSurface:
    """The named surface (one of :data:`SURFACES`).

    Examples
    --------
    >>> get("sine1000").label
    'z=1000*sin(pi*x/180)'
    """
    if name not in SURFACES:
        raise ValueError(f"surface={name!r} is not one of {', '.join(repr(k) for k in SURFACES)}")
    return SURFACES[name]()
