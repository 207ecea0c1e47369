"""The main job on bundled data, run by ``make demo``: ``python -m zmap.demo OUT_DIR``.

Writes under OUT_DIR: the Table 1 reproduction (markdown and CSV), the Fig. 5 error maps,
a master z-map of an analytic die surface with its shaded picture and 3D view, and, where the feature
is installed, the steps of the other features (STEP conversion, NC simulation).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import time
from pathlib import Path

__all__ = ["run"]


def _step(title: str) -> float:
    print(f"== {title}", flush=True)
    return time.perf_counter()


def run(out_dir: str | Path) -> list[Path]:
    """Run every demo step; return the files written."""
    import matplotlib.pyplot as plt  # figures are saved, never shown: any backend will do

    from .accuracy import accuracy_rows, format_csv, format_markdown, zmap_of
    from .grid import atomic_write
    from .plot.maps import plot_error_maps, plot_zmap
    from .surfaces import get

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    t = _step("accuracy table (paper 004 Table 1, 10^6 points per surface)")
    rows = accuracy_rows(n_points=1_000_000, seed=0)
    md = format_markdown(rows)
    print(md)
    for name, text in (("accuracy.md", md + "\n"), ("accuracy.csv", format_csv(rows))):
        written.append(atomic_write(out / name, lambda tmp, text=text: Path(tmp).write_text(text)))
    print(f"   {time.perf_counter() - t:.1f} s")

    _step("error maps (paper 004 Fig. 5)")
    sine, sphere = get("sine100"), get("sphere")
    zs, zp = zmap_of(sine, 1.0), zmap_of(sphere, 1.0)
    # Windows where the errors peak: the sine's crest and the cap's flank.
    panels = [(zs, sine, "bezier", (88, 0)), (zs, sine, "bilinear", (88, 0)),
              (zp, sphere, "bezier", (30, 30)), (zp, sphere, "bilinear", (30, 30))]
    fig = plot_error_maps(panels)
    written.append(atomic_write(out / "error_maps.png", lambda tmp: fig.savefig(tmp, dpi=110, format="png")))
    plt.close(fig)

    _step("master z-map of an analytic surface (Gaussian bump, grid 0.5 mm)")
    bump = zmap_of(get("gaussian"), 0.5, margin=0)
    written.append(bump.save(out / "gaussian.zmap.npz"))
    fig, ax = plt.subplots(figsize=(6, 5))
    plot_zmap(bump, title="gaussian bump, grid 0.5 mm: shaded heights", ax=ax)
    written.append(atomic_write(out / "gaussian.png",
                                lambda tmp: fig.savefig(tmp, dpi=110, format="png", bbox_inches="tight")))
    plt.close(fig)
    from .plot.scene import zmap_3d

    written.append(zmap_3d(bump, out / "gaussian_3d.png", title="gaussian bump, grid 0.5 mm: heights (3D view)"))

    # Features that live in their own subpackages add their demo step here.
    for module, title in (("cad_io.demo", "STEP to master z-map (paper 004 §2.1)"), ("zmap.sim.demo", "NC simulation with history (papers 000, 001)"),):
        if importlib.util.find_spec(module) is None:
            continue
        mod = importlib.import_module(module)
        t = _step(title)
        written.extend(mod.run_demo(out))
        print(f"   {time.perf_counter() - t:.1f} s")

    if (out / "demo_pocket.zsim") in written:
        _step("3D view of the simulated stock (pyvista, off-screen)")
        from .plot.scene import stock_3d
        from .sim.demo import DEMO_PROGRAM
        from .sim.session import Run

        run = Run.load(out / "demo_pocket.zsim")
        written.append(stock_3d(run, "1/2", out / "demo_pocket_half_3d.png", name="demo_pocket.zsim",
                                program=DEMO_PROGRAM))

    print("wrote:")
    for p in written:
        print(f"  {p}")
    return written


if __name__ == "__main__":  # draws off screen on a machine without a display (matplotlib's own fallback)
    run(sys.argv[1] if len(sys.argv) > 1 else "out")
