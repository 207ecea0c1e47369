"""Shaded top views of simulation stages (PNG frames, GIF animations).

A height image ``z[i, j]`` (x along i, y along j, NaN = no material) becomes an RGB image
seen from above: hue from height, Lambert shading from a light at the upper left, as the
papers display the machined part. matplotlib (colour map) and Pillow (files) are imported
inside the functions that use them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

import numpy as np

from ..grid import atomic_write

__all__ = ["shade", "save_png", "save_gif"]

_BACKGROUND = np.array([235, 238, 242], dtype=np.uint8)


def shade(z: np.ndarray, pitch: float, zrange: tuple[float, float] | None = None,
          cmap: str = "viridis") -> np.ndarray:
    """Shaded RGB top view of a height image.

    Parameters
    ----------
    z : ndarray of shape (nx, ny), float64 — heights in mm, NaN = background.
    pitch : float — ray spacing in mm (for the slopes).
    zrange : (zmin, zmax), optional — colour scale; default the finite range of ``z``.
    cmap : str — matplotlib colour map.

    Returns
    -------
    ndarray of shape (ny, nx, 3), uint8 — row 0 is the largest y (north up).

    Examples
    --------
    >>> shade(np.zeros((4, 3)), 0.5).shape
    (3, 4, 3)
    """
    import matplotlib

    z = np.asarray(z, dtype=np.float64)
    finite = np.isfinite(z)
    if zrange is None:
        zrange = (float(z[finite].min()), float(z[finite].max())) if finite.any() else (0.0, 1.0)
    lo, hi = zrange
    span = hi - lo if hi > lo else 1.0
    zf = np.where(finite, z, lo)
    gx, gy = np.gradient(zf, pitch, pitch) if min(z.shape) > 1 else (np.zeros_like(zf), np.zeros_like(zf))
    nrm = np.sqrt(gx * gx + gy * gy + 1.0)
    light = np.array([-1.0, 1.0, 1.5])
    light /= np.linalg.norm(light)
    lam = (-gx * light[0] - gy * light[1] + light[2]) / nrm
    lam = np.clip(0.35 + 0.65 * lam, 0.0, 1.0)
    colours = matplotlib.colormaps[cmap](np.clip((zf - lo) / span, 0, 1))[..., :3]
    rgb = (colours * lam[..., None] * 255).astype(np.uint8)
    rgb[~finite] = _BACKGROUND
    return np.ascontiguousarray(rgb.transpose(1, 0, 2)[::-1])


def save_png(path: str | os.PathLike, rgb: np.ndarray, scale: int = 1) -> Path:
    """Write an RGB image (uint8, (h, w, 3)) as PNG, atomically; ``scale`` repeats pixels."""
    from PIL import Image

    img = Image.fromarray(_upscale(rgb, scale))

    def write(tmp: str) -> None:
        img.save(tmp, format="PNG")

    return atomic_write(path, write)


def save_gif(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float = 10.0, scale: int = 1) -> Path:
    """Write RGB frames as a looping GIF, atomically."""
    from PIL import Image

    imgs = [Image.fromarray(_upscale(f, scale)) for f in frames]
    if not imgs:
        raise ValueError("no frames to write")

    def write(tmp: str) -> None:
        imgs[0].save(tmp, format="GIF", save_all=True, append_images=imgs[1:],
                     duration=max(1, int(round(1000.0 / fps))), loop=0)

    return atomic_write(path, write)


def _upscale(rgb: np.ndarray, scale: int) -> np.ndarray:
    scale = max(1, int(scale))
    if scale == 1:
        return rgb
    return np.repeat(np.repeat(rgb, scale, axis=0), scale, axis=1)
