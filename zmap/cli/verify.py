"""``zmap compare``: a simulated stock against its design, with report, pictures and regions.

Registered on the ``zmap`` group in :mod:`zmap.cli`; heavy modules load inside the command.
"""

from __future__ import annotations

import os
import sys
import warnings

import click

__all__ = ["compare_cmd"]


@click.command("compare")
@click.argument("run_path", metavar="RUN.zsim", type=click.Path(dir_okay=False))
@click.argument("design_path", metavar="DESIGN.zpm|DESIGN.zmap.npz|DESIGN.step", type=click.Path(dir_okay=False))
@click.option("--stage", default="end", show_default=True, help="Stage: integer, 'end' or a fraction like 1/2.")
@click.option("--tol", type=float, default=0.01, show_default=True, help="Tolerance band +-tol, mm (>= 0).")
@click.option("--offset", type=float, default=0.0, show_default=True,
              help="Design offset (stock allowance), mm: the target is design + offset.")
@click.option("--format", "fmt", type=click.Choice(["markdown", "csv", "json"]), default="markdown",
              show_default=True, help="Report format on stdout (and in -o unless its suffix says).")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Write the report here (.md, .csv or .json).")
@click.option("--png", type=click.Path(dir_okay=False), default=None, help="Deviation picture (top view).")
@click.option("--3d", "png3d", type=click.Path(dir_okay=False), default=None, help="pyvista 3D picture.")
@click.option("--regions", type=click.Path(dir_okay=False), default=None, help="Regions as CSV.")
@click.option("--program", type=click.Path(dir_okay=False), default=None,
              help="The run's G-code: quotes the offending lines; needed for --collisions.")
@click.option("--collisions", is_flag=True, help="Check rapids that cut, plunges, shank and holder contacts.")
@click.option("--holders", type=click.Path(dir_okay=False), default=None,
              help="TOML with [holder.N] tables (stickout, diameter, length); the tool table may hold them.")
@click.option("--no-holder", is_flag=True, help="With --collisions: skip the holder check (no holder data).")
def compare_cmd(run_path, design_path, stage, tol, offset, fmt, output, png, png3d, regions, program,
                collisions, holders, no_holder) -> None:
    """Compare the stock of RUN.zsim at a stage with DESIGN: gouges, excesses, first offending lines."""
    from ..errors import ZMapFileError
    from ..verify.deviation import compare
    from ..verify.report import deviation_3d, deviation_png, format_csv, format_json, format_markdown, regions_csv, write_report

    for p in (run_path, design_path, program, holders):
        if p is not None and not os.path.exists(p):
            raise ZMapFileError(p, "no such file")
    if tol < 0:
        raise click.BadParameter(f"tolerance must be >= 0 mm, got {tol:g}", param_hint="--tol")
    if collisions and not program:
        raise click.BadParameter("collision checks need the run's G-code (--program PROGRAM.nc)",
                                 param_hint="--collisions")
    from ..sim.session import Run

    run = Run.load(run_path)
    click.echo(f"comparing {run_path} ({run.stock.nx} x {run.stock.ny} rays) with {design_path} ...", err=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        c = compare(run, design_path, stage=stage, tol=tol, offset=offset)
    for w in caught:
        click.echo(f"zmap: warning: {w.message}", err=True)
    hits = None
    if collisions:
        from ..verify.clash import COLLISION_KINDS, collisions as find

        kinds = [k for k in COLLISION_KINDS if not (no_holder and k == "holder")]
        hits = find(run, program, holders=holders, kinds=kinds)
    lines = None
    if program:
        with open(program, encoding="utf-8", errors="replace", newline="") as fh:
            lines = fh.read().splitlines()
    name = os.path.basename(run_path)
    dname = os.path.basename(design_path)
    if fmt == "markdown":
        text = format_markdown(c, name=name, design=dname, program_lines=lines, collisions=hits)
    elif fmt == "json":
        text = format_json(c, collisions=hits)
    else:
        text = format_csv(c)
    sys.stdout.write(text)
    if output:
        kw = {"name": name, "design": dname, "program_lines": lines, "collisions": hits}
        suffix_fmt = {".md": "markdown", ".csv": "csv", ".json": "json"}.get(os.path.splitext(output)[1].lower())
        write_report(c, output, fmt=suffix_fmt or fmt, **({} if (suffix_fmt or fmt) == "csv" else kw))
    if regions:
        from ..grid import atomic_write_text

        atomic_write_text(regions, regions_csv(c))
    if png:
        deviation_png(c, png, title=f"{name} at stage {c.stage}/{c.n_stages} against {dname}: deviation (mm)")
    if png3d:
        deviation_3d(c, png3d)
    for p in (output, regions, png, png3d):
        if p:
            click.echo(f"wrote {p}", err=True)
