"""End-to-end demo of the NC simulation: the bundled pocket program, simulated and replayed.

``run_demo(out_dir)`` simulates ``data/demo_pocket.nc`` (made by ``data/make_demo_program.py``)
on a 40 x 30 x 10 mm block with the tools of ``data/tools.toml`` and an Interval Treap
history, saves the run, and writes shaded top views at stage 1/2 and at the end and a GIF
of the first tool's last layer (axes in mm, colour bar "height (mm)", stage and G-code line
in each title), all through the same code as ``zmap simulate`` and ``zmap replay``.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["run_demo", "DEMO_PROGRAM", "DEMO_TOOLS", "DEMO_STOCK"]

_DATA = Path(__file__).resolve().parents[2] / "data"
DEMO_PROGRAM = _DATA / "demo_pocket.nc"
DEMO_TOOLS = _DATA / "tools.toml"
DEMO_STOCK = "box:0,0,-10,40,30,0"


def run_demo(out_dir: str | os.PathLike = "out", *, echo=print) -> list[Path]:
    """Simulate the demo program and write its replay images under ``out_dir``.

    Parameters
    ----------
    out_dir : str or PathLike
        Folder for ``demo_pocket.zsim``, ``demo_pocket_half.png``, ``demo_pocket_end.png``
        and ``demo_pocket.gif`` (created if missing).
    echo : callable
        Where progress lines go (``print`` by default; ``None`` for silence).

    Returns
    -------
    list of Path
        The run file, the two pictures and the GIF, in that order.
    """
    from ..plot.stages import StageFigure, program_lines, save_gif, save_png, stage_line, stage_title
    from ..fmt import size
    from .session import Run, simulate

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    program = DEMO_PROGRAM
    if not program.exists():  # regenerate it from its script if the file was removed
        import importlib.util

        spec = importlib.util.spec_from_file_location("make_demo_program", _DATA / "make_demo_program.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        program = mod.write_demo_program(program)
    run = simulate(program, DEMO_STOCK, tools=DEMO_TOOLS, pitch=0.26, history="treap")
    zsim = run.save(out / "demo_pocket.zsim")
    run = Run.load(zsim)  # replay from the file, as `zmap replay` does
    # one figure and one colour range for every picture, as `zmap replay` draws them
    fig = StageFigure.for_run(run, scale=3)
    lines = program_lines(program)

    def title(k: int) -> str:
        return stage_title(zsim.name, k, run.n_stages, stage_line(run, k), lines)

    half, end = run.stage("1/2"), run.stage("end")
    p_half = save_png(out / "demo_pocket_half.png", fig.frame(run.display(half), title(half)))
    p_end = save_png(out / "demo_pocket_end.png", fig.frame(run.display(end), title(end)))
    # the whole program, from the stock to the end: pocket, groove, ring and holes
    step = max(1, end // 60)
    frames = [fig.frame(img, title(k)) for k, img in run.animate(0, end, step)]  # the last is the end
    fig.close()
    p_gif = save_gif(out / "demo_pocket.gif", frames, fps=12)
    result = [Path(zsim), Path(p_half), Path(p_end), Path(p_gif)]
    if echo is not None:
        s = run.summary
        echo(f"simulated {program.name}: {s['moves']} moves, {s['positions']} positions, {s['rays']} rays, "
             f"{s['dexels_deleted']} dexels deleted, treap {size(s['history_bytes'])}, {s['seconds']:.2f} s")
        echo(f"wrote {zsim}, {p_half}, {p_end}, {p_gif} ({len(frames)} frames)")
    return result


if __name__ == "__main__":
    import sys

    run_demo(sys.argv[1] if len(sys.argv) > 1 else "out")
