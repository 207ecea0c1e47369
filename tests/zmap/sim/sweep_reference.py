"""An independent reference of the exact swept volume: dense sampling of the tool's path.

Shares no code with :mod:`zmap.sim._sweep_kernels`: the cutter's envelope, the path of a
line or arc (from its G-code data: start, end, centre, plane, signed sweep) and the search
are written here again in plain numpy. The path is sampled every ``step`` mm (1 um by
default); the best sample is then refined three times, each by sampling 1000 times finer
around the best so far, so the bottom found is exact to about ``|slope| * step / 1e9``
(1e-12 mm) even where it ends at the edge of the tool's reach.
"""

from __future__ import annotations

import numpy as np

# in-plane first axis, second axis, normal axis (LinuxCNC: G18 is (Z, X), G19 (Y, Z))
PLANES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}


def envelope(kind: str, radius: float, corner: float, r: np.ndarray) -> np.ndarray:
    """Height of a cutter's bottom above its tip at radial distance r; inf beyond the radius."""
    r = np.asarray(r, dtype=np.float64)
    out = np.full(r.shape, np.inf)
    inside = r <= radius
    if kind == "flat":
        out[inside] = 0.0
        return out
    rc = radius if kind == "ball" else corner
    d = np.maximum(r[inside] - (radius - rc), 0.0)
    out[inside] = rc - np.sqrt(np.maximum(rc * rc - d * d, 0.0))
    return out


def line_path(start, end):
    """Tip at parameter t in [0, 1] of a straight move, and its length."""
    s = np.asarray(start, dtype=np.float64)
    e = np.asarray(end, dtype=np.float64)

    def at(t):
        return s + (e - s) * np.asarray(t, dtype=np.float64)[:, None]

    return at, float(np.linalg.norm(e - s))


def arc_path(start, end, center, plane, sweep):
    """Tip at parameter t of an arc or helix (angle, radius, normal coordinate linear in t)."""
    a, b, n = PLANES[int(plane)]
    s = np.asarray(start, dtype=np.float64)
    e = np.asarray(end, dtype=np.float64)
    c = np.asarray(center, dtype=np.float64)
    th0 = np.arctan2(s[b] - c[b], s[a] - c[a])
    r0 = np.hypot(s[a] - c[a], s[b] - c[b])
    r1 = np.hypot(e[a] - c[a], e[b] - c[b])

    def at(t):
        t = np.asarray(t, dtype=np.float64)
        th = th0 + sweep * t
        rad = r0 + (r1 - r0) * t
        p = np.empty((t.shape[0], 3))
        p[:, a] = c[a] + rad * np.cos(th)
        p[:, b] = c[b] + rad * np.sin(th)
        p[:, n] = s[n] + (e[n] - s[n]) * t
        return p

    length = float(np.hypot(abs(sweep) * max(r0, r1), e[n] - s[n]) + abs(r1 - r0))
    return at, length


def sweep_interval(at, length, cutter, qx, qy, t0=0.0, t1=1.0, step=1e-3):
    """``(bottom, top)`` of the material the cutter removes from ray (qx, qy) along
    ``at(t)``, t in [t0, t1]; ``(inf, -inf)`` where it never reaches the ray."""
    kind, R, rc, L = cutter.kind, float(cutter.radius), float(cutter.corner_radius), float(cutter.length)
    n = max(int(np.ceil(length * (t1 - t0) / step)), 1) + 1
    t = np.linspace(t0, t1, n)

    def bottom(tt):
        p = at(tt)
        return p[:, 2] + envelope(kind, R, rc, np.hypot(p[:, 0] - qx, p[:, 1] - qy)), p

    f, p = bottom(t)
    reach = np.isfinite(f)
    if not reach.any():
        # the reach may lie between two samples: look finer around the nearest one
        d = np.hypot(p[:, 0] - qx, p[:, 1] - qy)
        k = int(np.argmin(d))
        if d[k] > R + step:
            return np.inf, -np.inf
        f, p = bottom(np.linspace(t[max(k - 1, 0)], t[min(k + 1, n - 1)], 2001))
        reach = np.isfinite(f)
        if not reach.any():
            return np.inf, -np.inf
        return float(f.min()), float(p[reach, 2].max() + L)
    top = float(p[reach, 2].max() + L)
    best = float(f.min())
    for _ in range(3):  # each round 1000 times finer around the best sample so far
        k = int(np.argmin(f))
        t = np.linspace(t[max(k - 1, 0)], t[min(k + 1, t.shape[0] - 1)], 2001)
        f, _ = bottom(t)
        best = min(best, float(f.min()))
    return best, top
