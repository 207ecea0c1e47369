"""CLI commands of the simulation: ``zmap simulate`` and ``zmap replay``.

Registered on the ``zmap`` group in :mod:`zmap.cli`. Heavy modules are imported inside the
commands, so ``zmap --help`` stays fast.
"""

from __future__ import annotations

import json
import os
import re

import click

__all__ = ["simulate_cmd", "replay_cmd"]

_HISTORIES = ("none", "ztrace", "ttrace", "treap")


def _need_file(path: str | None) -> None:
    """A missing input file is bad input (exit 1, "FILE: no such file"), as in every command."""
    if path is not None and not os.path.exists(path):
        from ..errors import ZMapFileError

        raise ZMapFileError(path, "no such file")


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
@click.option("--pitch", type=float, default=0.26, show_default=True, help="Ray pitch and DDA step, mm.")
@click.option("--history", type=click.Choice(_HISTORIES), default="treap", show_default=True)
@click.option("--lenient", is_flag=True, help="Skip unsupported G-code blocks with a warning count.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="RUN.zsim to write.")
@click.option("--progress/--no-progress", default=True, show_default=True)
def simulate_cmd(program, stock, tool, tools_path, project, pitch, history, lenient, output, progress) -> None:
    """Simulate PROGRAM on a dexel stock, recording a history, and save the run."""
    import warnings

    from .gcode import parse
    from .session import simulate
    from .tools import load_tool_table

    for path in (program, tools_path, project):
        _need_file(path)
    tools = {}
    if project:
        from .tools import load_camotics_project

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
    prog = parse(program, lenient=lenient, tool_table=tools or None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = simulate(prog, stock, tool=tool, tools=tools or None, pitch=pitch, history=history, progress=progress)
    for w in caught:
        click.echo(f"warning: {' '.join(str(w.message).split())}", err=True)
    run.save(output)
    s = run.summary
    if getattr(prog, "warnings", None):
        click.echo(f"warnings         {len(prog.warnings)} blocks skipped (--lenient)")
    click.echo(f"moves            {s['moves']}")
    click.echo(f"positions        {s['positions']}")
    click.echo(f"rays             {s['rays']} ({run.stock.nx} x {run.stock.ny} at {run.stock.pitch:g} mm)")
    click.echo(f"dexels created   {s['dexels_created']}")
    click.echo(f"dexels deleted   {s['dexels_deleted']}")
    click.echo(f"history          {s['history']}: {s['history_bytes'] / 1e6:.2f} MB "
               f"({s['history_elements']} elements)")
    click.echo(f"seconds          {s['seconds']:.2f}")
    click.echo(f"wrote            {output}")


@click.command("replay")
@click.argument("run_path", metavar="RUN.zsim", type=click.Path(dir_okay=False))
@click.option("--stage", default=None, metavar="K", help="Stage: integer, 'end' or fraction like 1/2.")
@click.option("--png", type=click.Path(dir_okay=False), default=None, help="Shaded top view of --stage.")
@click.option("--animate", "span", default=None, metavar="S1:S2", help="Stages to animate, e.g. 0:end, end:1/2.")
@click.option("--gif", type=click.Path(dir_okay=False), default=None, help="Animated GIF of --animate.")
@click.option("--frames", type=int, default=60, show_default=True, help="Frames in the GIF.")
@click.option("--fps", type=float, default=12.0, show_default=True)
@click.option("--scale", type=int, default=1, show_default=True, help="Pixels per ray in images.")
def replay_cmd(run_path, stage, png, span, gif, frames, fps, scale) -> None:
    """Show a saved run at a stage (PNG) or between two stages (GIF), or print its summary."""
    import numpy as np

    from .render import save_gif, save_png, shade
    from .session import Run

    run = Run.load(run_path)
    if png and stage is None:
        raise click.UsageError("--png needs --stage")
    if gif and span is None:
        raise click.UsageError("--gif needs --animate S1:S2")
    stock_top = run.stock.top()
    fin = np.isfinite(stock_top)
    lo = float(np.nanmin(run.final.top())) if np.isfinite(run.final.top()).any() else 0.0
    zrange = (min(lo, float(stock_top[fin].min()) if fin.any() else lo),
              float(stock_top[fin].max()) if fin.any() else 1.0)
    if stage is not None:
        k = run.stage(stage)
        img = run.display(k)
        if png:
            save_png(png, shade(img, run.stock.pitch, zrange), scale)
            click.echo(f"stage {k}/{run.n_stages} -> {png}")
        else:
            f = np.isfinite(img)
            click.echo(f"stage {k}/{run.n_stages}: top {np.nanmin(img) if f.any() else float('nan'):.4f} .. "
                       f"{np.nanmax(img) if f.any() else float('nan'):.4f} mm, {int(f.sum())} rays with material")
    if span is not None:
        m = re.fullmatch(r"\s*([^:]+)\s*:\s*([^:]+)\s*", span)
        if not m:
            raise click.BadParameter(f"{span!r} is not S1:S2", param_hint="--animate")
        s1, s2 = run.stage(m.group(1)), run.stage(m.group(2))
        nfr = max(2, int(frames))
        step = max(1, abs(s2 - s1) // (nfr - 1))
        imgs = [shade(img, run.stock.pitch, zrange) for _, img in run.animate(s1, s2, step)]
        if gif:
            save_gif(gif, imgs, fps, scale)
            click.echo(f"stages {s1}..{s2} ({len(imgs)} frames) -> {gif}")
        else:
            click.echo(f"stages {s1}..{s2}: {len(imgs)} frames")
    if stage is None and span is None:
        click.echo(json.dumps({"file": str(run_path), "n_stages": run.n_stages, **run.summary}, indent=2))
