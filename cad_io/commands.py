"""CLI command of the STEP converter: ``zmap convert``.

Registered on the ``zmap`` group in :mod:`zmap.cli`. OCP, numba and the sampler are
imported inside the command, so ``zmap --help`` and ``zmap accuracy`` never load them.
"""

from __future__ import annotations

import click

__all__ = ["convert_cmd"]

_AXES = ("+z", "-z", "+x", "-x", "+y", "-y")


@click.command("convert")
@click.argument("part_path", metavar="PART.step", type=click.Path(dir_okay=False))
@click.option("--grid", required=True, type=float, metavar="MM", help="Grid interval in mm.")
@click.option("--bounds", nargs=4, type=float, default=None, metavar="X0 Y0 X1 Y1",
              help="Domain in the view frame, mm (default: the part's bounding box).")
@click.option("--method", type=click.Choice(["auto", "jacobian", "facet"]), default="auto", show_default=True,
              help="Jacobian inversion with facet fallback, or one path only.")
@click.option("--axis", type=click.Choice(_AXES), default="+z", show_default=True,
              help="World direction that becomes the map's +z.")
@click.option("--deflection", type=float, default=None, metavar="MM",
              help="Mesh deflection for starts and facets (default grid/20).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="PART.zmap.npz to write.")
@click.option("--progress/--no-progress", default=True, show_default=True)
def convert_cmd(part_path, grid, bounds, method, axis, deflection, output, progress) -> None:
    """Convert a STEP part to a master z-map (paper 004 §2.1) and save it."""
    import os
    import time
    import warnings

    from cad_io.sampler import estimate_bytes, grid_shape, sample, summary
    from cad_io.step import read_step
    from zmap.errors import StepImportError

    t0 = time.perf_counter()
    if not os.path.exists(part_path):
        raise StepImportError(f"{part_path}: no such file")
    if grid <= 0:
        raise click.BadParameter(f"must be positive, got {grid!r}", param_hint="--grid")
    part = read_step(part_path)
    if not part.faces:
        raise StepImportError(f"{part_path}: no faces in the file")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        zm = sample(part, grid, bounds=bounds, method=method, axis=axis, deflection=deflection, progress=progress)
    zm.meta["source"] = os.path.basename(part_path)
    zm.save(output)
    s = summary(zm)
    seconds = time.perf_counter() - t0
    for w in list(part.warnings) + [str(c.message) for c in caught]:
        click.echo(f"warning: {' '.join(w.split())}", err=True)
    click.echo(f"wrote    {output}")
    click.echo(f"part     {os.path.basename(part_path)}: {len(part.faces)} faces, axis {axis}")
    click.echo(f"grid     {zm.nx} x {zm.ny} = {s['points']:,} points, dx={zm.dx:g} dy={zm.dy:g} mm, "
               f"x {zm.x0:g} .. {zm.x1:g}, y {zm.y0:g} .. {zm.y1:g}")
    click.echo(f"method   {method}: jacobian {100 * s['share_jacobian']:.2f} %, facet {100 * s['share_facet']:.2f} %, "
               f"empty {100 * s['share_empty']:.2f} %")
    click.echo(f"time     {seconds:.2f} s (sampling {zm.meta['seconds']:.2f} s)")
    click.echo(f"memory   {zm.nbytes / 1e6:.2f} MB map, {estimate_bytes(*grid_shape(zm.bounds, zm.dx, zm.dy)) / 1e6:.2f} MB "
               f"working estimate")
