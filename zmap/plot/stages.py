"""Pictures of simulation stages: PNG frames and GIF animations with axes, scale and title.

A height image ``z[i, j]`` (x along i, y along j, NaN = no material) becomes an RGB image
seen from above: hue from height, Lambert shading from a light at the upper left, as the
papers display the machined part (:func:`shade`). :class:`StageFigure` puts that image on
axes in mm beside a colour bar "height (mm)" under a title naming the run, the stage and the
G-code line that made it (:func:`stage_title`); one figure is reused for every frame, with
one colour range, so the frames of an animation compare. matplotlib (Agg) and Pillow (files)
are imported inside the functions that use them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from ..grid import atomic_write

__all__ = ["shade", "save_png", "save_gif", "stage_line", "stage_title", "program_lines",
           "height_range", "StageFigure"]

_BACKGROUND = np.array([235, 238, 242], dtype=np.uint8)
_MAX_TEXT = 60  # characters of G-code shown in a title


def shade(z: np.ndarray, pitch: float, zrange: tuple[float, float] | None = None,
          cmap: str = "viridis") -> np.ndarray:
    """Shaded RGB top view of a height image.

    Parameters
    ----------
    z : ndarray of shape (nx, ny), float64
        Heights in mm, NaN = background.
    pitch : float
        Ray spacing in mm (for the slopes).
    zrange : (zmin, zmax), optional
        Colour scale; default the finite range of ``z``.
    cmap : str
        Matplotlib colour map.

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


# ---- titles ------------------------------------------------------------------------------------

def stage_line(run: Any, stage: int) -> int:
    """1-based G-code line of the position that made ``stage`` (0 for the stock or unknown).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> run = SimpleNamespace(line=np.array([5, 5, 7]))
    >>> stage_line(run, 0), stage_line(run, 3)
    (0, 7)
    """
    k = int(stage)
    line = getattr(run, "line", None)
    if k <= 0 or line is None or k > len(line):
        return 0
    return int(line[k - 1])


def program_lines(path: str | os.PathLike | None) -> list[str] | None:
    """The lines of a G-code file (for titles), or None when there is no file to read."""
    if path is None or not os.path.isfile(path):
        return None
    with open(path, encoding="utf-8", errors="replace") as f:
        return f.read().splitlines()


def stage_title(name: str, stage: int, n_stages: int, line: int = 0, text: str | Sequence[str] | None = None) -> str:
    """Title of a stage picture: ``"NAME: stage k/n, line L: G1 X8 Y2"``.

    Parameters
    ----------
    name : str
        The run (file name or part).
    stage, n_stages : int
        The stage shown and the last stage.
    line : int
        1-based G-code line that made the stage (0: stock or unknown).
    text : str or list of str, optional
        That line's text, or all lines of the program (indexed by ``line``); without it the title
        gives the line number alone.

    Examples
    --------
    >>> stage_title("pocket", 5, 10, 7, "G1 X8 Y2")
    'pocket: stage 5/10, line 7: G1 X8 Y2'
    >>> stage_title("pocket", 5, 10, 7)
    'pocket: stage 5/10, line 7'
    >>> stage_title("pocket", 0, 10)
    'pocket: stage 0/10, stock'
    """
    head = f"{name}: stage {int(stage)}/{int(n_stages)}"
    if int(stage) == 0:
        return head + ", stock"
    if not line:
        return head + ", line unknown"
    if text is not None and not isinstance(text, str):
        text = text[line - 1] if 0 < line <= len(text) else None
    text = " ".join(str(text).split()) if text is not None else ""
    if len(text) > _MAX_TEXT:
        text = text[:_MAX_TEXT - 3] + "..."
    return f"{head}, line {line}" + (f": {text}" if text else "")


def height_range(run: Any) -> tuple[float, float]:
    """One colour range (mm) for every stage of a run: lowest final top .. highest stock top."""
    top0, top1 = run.stock.top(), run.final.top()
    vals = np.concatenate([top0[np.isfinite(top0)], top1[np.isfinite(top1)]])
    if not vals.size:
        return (0.0, 1.0)
    lo, hi = float(vals.min()), float(vals.max())
    return (lo, hi) if hi > lo else (lo - 0.5, hi + 0.5)


# ---- the figure ----------------------------------------------------------------------------------

class StageFigure:
    """One matplotlib (Agg) figure that draws height images as framed RGB pictures.

    Parameters
    ----------
    x0, y0 : float
        Centre of ray (0, 0), mm.
    pitch : float
        Ray spacing, mm.
    nx, ny : int
        Rays along x and y.
    zrange : (zmin, zmax)
        Colour range in mm, fixed for every frame.
    scale : int
        About this many pixels per ray in the picture (within 360..1400 px).
    cmap : str
        Matplotlib colour map.

    Examples
    --------
    >>> fig = StageFigure(0.0, 0.0, 0.5, 20, 10, (-1.0, 0.0))
    >>> rgb = fig.frame(np.full((20, 10), -0.5), "a title")
    >>> rgb.dtype, rgb.shape[2]
    (dtype('uint8'), 3)
    >>> fig.close()
    """

    def __init__(self, x0: float, y0: float, pitch: float, nx: int, ny: int,
                 zrange: tuple[float, float], *, scale: int = 1, cmap: str = "viridis") -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import Normalize
        from matplotlib.figure import Figure

        self.pitch, self.zrange, self.cmap = float(pitch), (float(zrange[0]), float(zrange[1])), cmap
        nx, ny = max(int(nx), 1), max(int(ny), 1)
        # plot area in pixels: about `scale` per ray, 360..1400 px a side, the grid's aspect kept
        w = float(np.clip(nx * max(int(scale), 1), 360, 1400))
        h = w * ny / nx
        if h > 1000:
            w, h = w * 1000 / h, 1000.0
        if h < 160:
            h = 160.0
        left, right, bottom, top = 72.0, 120.0, 52.0, 40.0
        W, H = w + left + right, h + bottom + top
        W, H = 2 * round(W / 2), 2 * round(H / 2)  # even sizes suit video encoders
        dpi = 100.0
        self.fig = Figure(figsize=(W / dpi, H / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.fig)
        self.ax = self.fig.add_axes((left / W, bottom / H, w / W, h / H))
        cax = self.fig.add_axes(((left + w + 14) / W, bottom / H, 16 / W, h / H))
        ext = (x0 - pitch / 2, x0 + (nx - 1) * pitch + pitch / 2, y0 - pitch / 2, y0 + (ny - 1) * pitch + pitch / 2)
        self.im = self.ax.imshow(np.zeros((ny, nx, 3), dtype=np.uint8), origin="upper", extent=ext,
                                 interpolation="nearest", aspect="auto")
        self.ax.set_xlabel("x (mm)")
        self.ax.set_ylabel("y (mm)")
        sm = ScalarMappable(norm=Normalize(*self.zrange), cmap=cmap)
        self.fig.colorbar(sm, cax=cax, label="height (mm)")
        self.title = self.ax.set_title("", fontsize=10, loc="left")
        # axes, labels and colour bar are drawn once; each frame redraws only image and title
        self.im.set_animated(True)
        self.title.set_animated(True)
        self.canvas.draw()
        self._background = self.canvas.copy_from_bbox(self.fig.bbox)

    def frame(self, z: np.ndarray, title: str) -> np.ndarray:
        """The picture of heights ``z`` (nx, ny) under ``title``: RGB, uint8, (H, W, 3)."""
        self.im.set_data(shade(z, self.pitch, self.zrange, self.cmap))
        self.title.set_text(title)
        self.canvas.restore_region(self._background)
        self.ax.draw_artist(self.im)
        for spine in self.ax.spines.values():
            self.ax.draw_artist(spine)
        self.fig.draw_artist(self.title)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        """Free the figure."""
        self.fig.clear()

    @classmethod
    def for_run(cls, run: Any, *, scale: int = 1, zrange: tuple[float, float] | None = None,
                cmap: str = "viridis") -> "StageFigure":
        """A figure on the ray grid of ``run`` with the colour range of :func:`height_range`."""
        s = run.stock
        return cls(s.x0, s.y0, s.pitch, s.nx, s.ny, height_range(run) if zrange is None else zrange,
                   scale=scale, cmap=cmap)


# ---- files ----------------------------------------------------------------------------------------

def save_png(path: str | os.PathLike, rgb: np.ndarray, scale: int = 1) -> Path:
    """Write an RGB image (uint8, (h, w, 3)) as PNG, atomically; ``scale`` repeats pixels."""
    from PIL import Image

    img = Image.fromarray(_upscale(rgb, scale))

    def write(tmp: str) -> None:
        img.save(tmp, format="PNG")

    return atomic_write(path, write)


def save_gif(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float = 10.0, scale: int = 1) -> Path:
    """Write RGB frames as a looping GIF, atomically; every frame given is a frame of the file.

    Pillow merges a frame identical to the one before into it (longer duration); a frame
    that repeats its predecessor gets one pixel of its corner nudged so that none is lost.
    """
    from PIL import Image

    imgs, prev = [], None
    for f in frames:
        f = _upscale(np.asarray(f, dtype=np.uint8), scale)
        if prev is not None and np.array_equal(f, prev):
            f = f.copy()
            f[-1, -1] ^= 1
        imgs.append(Image.fromarray(f))
        prev = f
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
