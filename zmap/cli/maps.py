"""``zmap accuracy`` and ``zmap info``: the commands of the maps themselves."""

from __future__ import annotations

import os

import click

from ..fmt import count, size

__all__ = ["accuracy_cmd", "info_cmd"]


@click.command("accuracy")
@click.option("--surface", "surfaces", multiple=True, metavar="NAME",
              help="Analytic surface (repeatable); default: the three rows of Table 1.")
@click.option("--grid", "grids", multiple=True, type=float, metavar="MM",
              help="Grid interval in mm (repeatable); default 1.")
@click.option("--scheme", "schemes", multiple=True, metavar="NAME", help="Scheme (repeatable); default: all.")
@click.option("--points", default=1_000_000, show_default=True, type=int, help="Random query points per row.")
@click.option("--seed", default=0, show_default=True, type=int)
@click.option("--format", "fmt", type=click.Choice(["markdown", "csv"]), default="markdown", show_default=True)
def accuracy_cmd(surfaces, grids, schemes, points, seed, fmt) -> None:
    """Interpolation accuracy against exact surfaces (a table shaped like paper 004's Table 1)."""
    from .. import accuracy as acc
    from ..surfaces import SURFACES, TABLE1

    for name in surfaces:
        if name not in SURFACES:
            raise click.BadParameter(f"{name!r} is not one of {', '.join(SURFACES)}", param_hint="--surface")
    rows = acc.accuracy_rows(surfaces or TABLE1, grids or (1.0,), schemes or None, n_points=points, seed=seed)
    click.echo(acc.format_csv(rows) if fmt == "csv" else acc.format_markdown(rows), nl=fmt != "csv")


@click.command("info")
@click.argument("path", type=click.Path())
def info_cmd(path: str) -> None:
    """Describe a saved z-map (.zmap.npz or a tiled .zarr store): grid, domain, heights, memory, metadata."""
    import json

    import numpy as np

    from ..grid import ZMap

    if os.path.isdir(path):  # tiled store (zmap/tiled): described from its metadata and tile markers
        from ..tiled import TiledZMap

        click.echo("\n".join(TiledZMap.open(path, incomplete=True).describe()))
        return
    zm = ZMap.load(path)
    z = zm.z
    filled = np.isfinite(z)
    click.echo(f"file     {path}")
    click.echo(f"grid     {zm.nx:,} x {zm.ny:,} points, dx={zm.dx:g} dy={zm.dy:g} mm")
    click.echo(f"domain   x {zm.x0:g} .. {zm.x1:g}, y {zm.y0:g} .. {zm.y1:g} mm"
               + (f" (local frame: angle {zm.angle:g} rad, origin {zm.origin})" if zm.has_frame else ""))
    if filled.any():
        click.echo(f"heights  {z[filled].min():.6g} .. {z[filled].max():.6g} mm, "
                   f"{count(filled.sum())} with surface, {count((~filled).sum())} empty")
    else:
        click.echo("heights  none: every grid point is empty")
    click.echo(f"memory   {size(zm.nbytes)} (heights and {len(zm.layers)} layers: {', '.join(zm.layers) or '-'})")
    click.echo(f"meta     {json.dumps(zm.meta, sort_keys=True)}")
