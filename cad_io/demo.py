"""Demo step of the STEP converter (run by ``make demo`` through :mod:`zmap.demo`).

Converts the bundled free-form die face and the filleted pocket, and one real third-party
part (``data/step/bug27693_cornetta-step.stp``) at a coarse
grid, and writes each master z-map with a shaded picture.
"""

from __future__ import annotations

import time
from pathlib import Path

__all__ = ["run_demo", "DATA", "STEP_DIR"]

#: the bundled samples (``data/`` of the repository)
DATA = Path(__file__).resolve().parents[1] / "data"
#: the real third-party parts bundled with the repository (``data/step``, see ``data/SOURCES.md``)
STEP_DIR = DATA / "step"


def run_demo(out_dir: str | Path) -> list[Path]:
    """Convert STEP parts to master z-maps under ``out_dir``; return the files written.

    Writes ``<name>.zmap.npz`` and ``<name>.png`` (shaded top view, heights coloured, facet
    cells outlined in the title's counts) for each part.
    """
    import matplotlib.pyplot as plt  # figures are saved, never shown: any backend will do

    from zmap.grid import atomic_write
    from zmap.plot import plot_zmap

    from .sampler import sample, summary
    from .step import read_step

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(DATA / "freeform_die.step", 0.5, "+z"), (DATA / "pocket.step", 0.5, "+z")]
    jobs.append((STEP_DIR / "bug27693_cornetta-step.stp", 1.0, "+z"))
    written: list[Path] = []
    for path, grid, axis in jobs:
        t = time.perf_counter()
        part = read_step(path)
        zm = sample(part, grid, axis=axis)
        s = summary(zm)
        name = path.name.split(".")[0]
        written.append(zm.save(out / f"{name}.zmap.npz"))
        fig, ax = plt.subplots(figsize=(6.5, 5))
        plot_zmap(zm, title=f"{path.name}: heights, grid {grid:g} mm\n{100 * s['share_jacobian']:.1f} % Jacobian, "
                            f"{100 * s['share_facet']:.1f} % facet", ax=ax)
        written.append(atomic_write(out / f"{name}.png", lambda tmp, fig=fig: fig.savefig(tmp, dpi=110, format="png",
                                                                                        bbox_inches="tight")))
        plt.close(fig)
        print(f"   {path.name}: {len(part.faces)} faces, {zm.nx} x {zm.ny} points, "
              f"jacobian {100 * s['share_jacobian']:.1f} %, facet {100 * s['share_facet']:.1f} %, "
              f"empty {100 * s['share_empty']:.1f} %, {time.perf_counter() - t:.1f} s", flush=True)
    return written
