"""CLI commands of the simulation: ``zmap simulate`` and ``zmap replay``.

Registered on the ``zmap`` group in :mod:`zmap.cli`. Heavy modules are imported inside the
commands, so ``zmap --help`` stays fast.
"""

from __future__ import annotations

import contextlib
import json
import os
import re

import click

from ..fmt import count, size
from ..sim.path import STAGE_MODES

__all__ = ["simulate_cmd", "replay_cmd"]

_HISTORIES = ("none", "ztrace", "ttrace", "treap")


def _need_file(path: str | None) -> None:
    """A missing input file is bad input (exit 1, "FILE: no such file"), as in every command."""
    if path is not None and not os.path.exists(path):
        from ..errors import ZMapFileError

        raise ZMapFileError(path, "no such file")


@contextlib.contextmanager
def _cluster(tiles, scheduler, workers):
    """With --tiles: the Dask cluster (local or at ``scheduler``), its dashboard printed; yields its address."""
    if tiles is None:
        yield scheduler
        return
    from zmap.tiled.cluster import dask_client

    from ..sim.tiled import check_tiles

    check_tiles(tiles)  # before starting a cluster
    with dask_client(scheduler, workers=workers) as cl:
        n = len(cl.scheduler_info().get("workers", {}))
        click.echo(f"dask     {n} workers at {cl.scheduler.address}, dashboard {cl.dashboard_link}", err=True)
        yield cl.scheduler.address


@click.command("simulate")
@click.argument("program", type=click.Path(dir_okay=False))
@click.option("--stock", default=None, metavar="SPEC",
              help="box:LxWxH (top at z=0, centred on the program's xy extent), "
                   "box:X0,Y0,Z0,X1,Y1,Z1, or FILE.zmap.npz (material below the surface). "
                   "Default: the stock of --camotics.")
@click.option("--tool", default=None, metavar="SPEC",
              help="Cutter for tool numbers not in the table, e.g. ball:3, flat:6, bull:10:1.")
@click.option("--tools", "tools_path", type=click.Path(dir_okay=False), default=None,
              help="Tool table: TOML, or LinuxCNC .tbl (inches, as LinuxCNC's rs274 reads it; "
                   "flat end mills of its diameters).")
@click.option("--camotics", "project", type=click.Path(dir_okay=False), default=None,
              help="CAMotics project: its tools, and its stock unless --stock is given.")
@click.option("--pitch", type=float, default=0.26, show_default=True,
              help="Ray pitch and stage spacing, mm (the lateral resolution; each stage cuts the exact sweep "
                   "of the path since the last, so the pitch never sets the depth).")
@click.option("--stages", type=click.Choice(list(STAGE_MODES)), default="pitch", show_default=True,
              help="A stage every pitch along the path, or one per G-code move (a coarser, smaller history; "
                   "the same stock at each move's end).")
@click.option("--history", type=click.Choice(_HISTORIES), default="treap", show_default=True)
@click.option("--lenient", is_flag=True, help="Skip unsupported G-code blocks with a warning count.")
@click.option("--max-blocks", type=click.IntRange(min=0), default=None, metavar="N",
              help="Blocks that loops and subroutine calls may run again (default 100000).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="RUN.zsim to write.")
@click.option("--progress/--no-progress", default=True, show_default=True)
@click.option("--tiles", type=int, default=None, metavar="N",
              help="Simulate in N x N-ray tiles as Dask tasks, a history per tile (same result).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="With --tiles: a running Dask scheduler (tcp://host:port); default a local cluster.")
@click.option("--workers", type=int, default=2, show_default=True, help="With --tiles: local worker processes.")
def simulate_cmd(program, stock, tool, tools_path, project, pitch, stages, history, lenient, max_blocks, output,
                 progress, tiles=None, scheduler=None, workers=2) -> None:
    """Simulate PROGRAM on a dexel stock, recording a history, and save the run."""
    import warnings

    from ..sim.gcode import parse
    from ..sim.session import simulate
    from ..sim.tools import load_tool_table

    for path in (program, tools_path, project):
        _need_file(path)
    tools = {}
    if project:
        from ..sim.tools import load_camotics_project

        ptools, bounds, _units = load_camotics_project(project)
        tools.update(ptools)
        if tool is None and ptools:
            tool = ptools[min(ptools)]  # CAMotics cuts with its first tool until a T word says otherwise
        if stock is None:
            stock = "box:" + ",".join(f"{v:.9g}" for v in bounds)
    if tools_path:
        tools.update(load_tool_table(tools_path))
    if stock is None:
        raise click.UsageError("give --stock (or --camotics with a stock)")
    limits = {} if max_blocks is None else {"max_blocks": max_blocks}
    prog = parse(program, lenient=lenient, tool_table=tools or None, **limits)
    with warnings.catch_warnings(record=True) as caught, _cluster(tiles, scheduler, workers) as address:
        warnings.simplefilter("always")
        run = simulate(prog, stock, tool=tool, tools=tools or None, pitch=pitch, history=history, progress=progress,
                       stages=stages,
                       **({} if tiles is None and scheduler is None else  # tiled on Dask: zmap/sim/tiled.py
                          {"tiles": tiles, "scheduler": address, "workers": workers}))
    for w in caught:
        click.echo(f"warning: {' '.join(str(w.message).split())}", err=True)
    run.save(output)
    s = run.summary
    if getattr(prog, "warnings", None):
        click.echo(f"warnings         {len(prog.warnings)} blocks skipped (--lenient)")
    click.echo(f"moves            {count(s['moves'])}")
    click.echo(f"positions        {count(s['positions'])}")
    click.echo(f"rays             {count(s['rays'])} ({run.stock.nx} x {run.stock.ny} at {run.stock.pitch:g} mm)")
    click.echo(f"dexels created   {count(s['dexels_created'])}")
    click.echo(f"dexels deleted   {count(s['dexels_deleted'])}")
    click.echo(f"history          {s['history']}: {size(s['history_bytes'])} "
               f"({count(s['history_elements'])} elements)")
    click.echo(f"seconds          {s['seconds']:.2f}")
    if "tiles" in s:
        t = s["tiles"]
        click.echo(f"tiles            {count(t['tiles'])} of {t['tile']} x {t['tile']} rays on {t['workers']} workers, "
                   f"peak {t['peak_rss_mb_per_worker']:.0f} MB per worker")
    click.echo(f"wrote            {output}")


@click.command("replay")
@click.argument("run_path", metavar="RUN.zsim", type=click.Path(dir_okay=False))
@click.option("--stage", default=None, metavar="K", help="Stage: integer, 'end' or fraction like 1/2.")
@click.option("--png", type=click.Path(dir_okay=False), default=None,
              help="Picture of --stage: top view (or --3d view) with axes in mm, colour bar and title.")
@click.option("--3d", "view3d", is_flag=True, help="With --png: a 3D view of the stock (pyvista, off-screen).")
@click.option("--animate", "span", default=None, metavar="S1:S2", help="Stages to animate, e.g. 0:end, end:1/2.")
@click.option("--gif", type=click.Path(dir_okay=False), default=None, help="Animated GIF of --animate.")
@click.option("--frames", type=int, default=60, show_default=True, help="Frames in the GIF (at most).")
@click.option("--fps", type=float, default=12.0, show_default=True)
@click.option("--scale", type=int, default=1, show_default=True, help="About this many pixels per ray in images.")
@click.option("--program", type=click.Path(dir_okay=False), default=None,
              help="G-code file of the run: titles then quote each stage's line.")
@click.option("--progress/--no-progress", default=True, show_default=True)
def replay_cmd(run_path, stage, png, view3d, span, gif, frames, fps, scale, program, progress) -> None:
    """Show a saved run at a stage (PNG) or between two stages (GIF), or print its summary."""
    import numpy as np

    from ..plot.stages import StageFigure, program_lines, save_gif, save_png, stage_line, stage_title
    from ..sim.session import Run

    _need_file(program)
    if png and stage is None:
        raise click.UsageError("--png needs --stage")
    if view3d and not png:
        raise click.UsageError("--3d needs --png")
    if gif and span is None:
        raise click.UsageError("--gif needs --animate S1:S2")
    run = Run.load(run_path)
    name = os.path.basename(str(run_path))
    text = getattr(run, "program_text", None)  # the .zsim keeps the program it was made from
    lines = program_lines(program) if program is not None else (text.splitlines() if text else None)

    def title(k: int) -> str:
        return stage_title(name, k, run.n_stages, stage_line(run, k), lines)

    if stage is not None:
        k = run.stage(stage)
        if png and view3d:
            from ..plot.scene import stock_3d

            stock_3d(run, k, png, name=name, program=program)
            click.echo(f"stage {k}/{run.n_stages} (3D) -> {png}")
        elif png:
            fig = StageFigure.for_run(run, scale=scale)
            save_png(png, fig.frame(run.display(k), title(k)))
            fig.close()
            click.echo(f"stage {k}/{run.n_stages} -> {png}")
        else:
            img = run.display(k)
            f = np.isfinite(img)
            click.echo(f"{title(k)}: top {np.nanmin(img) if f.any() else float('nan'):.4f} .. "
                       f"{np.nanmax(img) if f.any() else float('nan'):.4f} mm, {int(f.sum())} rays with material")
    if span is not None:
        m = re.fullmatch(r"\s*([^:]+)\s*:\s*([^:]+)\s*", span)
        if not m:
            raise click.BadParameter(f"{span!r} is not S1:S2", param_hint="--animate")
        s1, s2 = run.stage(m.group(1)), run.stage(m.group(2))
        # at most --frames stages, evenly spread, both ends included, none twice
        nfr = max(2, int(frames))
        stages = [int(v) for v in dict.fromkeys(np.rint(np.linspace(s1, s2, min(nfr, abs(s2 - s1) + 1))).astype(int))]
        click.echo(f"stages {s1}..{s2}: {len(stages)} frames" + (f" -> {gif}" if gif else ""))
        if gif:
            fig = StageFigure.for_run(run, scale=scale)
            bar = None
            if progress:
                from tqdm import tqdm

                bar = tqdm(total=len(stages), unit="frame", desc="replay", leave=False)

            def pictures():
                for k in stages:
                    yield fig.frame(run.display(k), title(k))
                    if bar is not None:
                        bar.update(1)

            try:
                save_gif(gif, pictures(), fps)
            finally:
                if bar is not None:
                    bar.close()
                fig.close()
            click.echo(f"wrote {gif} ({len(stages)} frames)")
    if stage is None and span is None:
        click.echo(json.dumps({"file": str(run_path), "n_stages": run.n_stages, **run.summary}, indent=2))
