"""``zmap toolpath``: a raster finishing program from a design's drop-cutter CL surface.

Registered on the ``zmap`` group in :mod:`zmap.cli`; heavy modules load inside the command.
"""

from __future__ import annotations

import math
import os

import click

from ..fmt import count

__all__ = ["toolpath_cmd"]


@click.command("toolpath")
@click.argument("design_path", metavar="DESIGN.zpm|DESIGN.zmap.npz|DESIGN.step", type=click.Path(dir_okay=False))
@click.option("--tool", required=True, metavar="SPEC", help="Cutter: ball:6, flat:10, bull:10:1 (mm).")
@click.option("--stepover", required=True, type=float, metavar="MM", help="Distance between passes, mm.")
@click.option("--angle", type=float, default=0.0, show_default=True, help="Pass direction, degrees from +x.")
@click.option("--tol", type=float, default=0.005, show_default=True, help="Chord tolerance, mm.")
@click.option("--step", type=float, default=None, metavar="MM", help="CL sampling along a pass (default min(stepover/2, 0.1)).")
@click.option("--bounds", type=float, nargs=4, default=None, metavar="X0 Y0 X1 Y1",
              help="Region the tool axis covers (default: the design's extent).")
@click.option("--feed", type=float, default=1000.0, show_default=True, help="Feed rate, mm/min.")
@click.option("--plunge-feed", type=float, default=None, help="Plunge feed, mm/min (default feed/3).")
@click.option("--spindle", type=float, default=10000.0, show_default=True, help="Spindle speed, rpm.")
@click.option("--clearance", type=float, default=5.0, show_default=True, help="Rapids this far above the highest CL point, mm.")
@click.option("--outside", default="skip", show_default=True, metavar="skip|lowest|Z",
              help="Where the design has no height: 'skip' breaks the pass where no design is under the cutter; "
                   "'lowest' is a floor at the lowest CL height; a number is a floor at that Z (mm).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Program to write (.nc, .ngc).")
def toolpath_cmd(design_path, tool, stepover, angle, tol, step, bounds, feed, plunge_feed, spindle, clearance,
                 outside, output) -> None:
    """Write a zig-zag finishing program over DESIGN (drop-cutter CL surface, chord tolerance)."""
    from ..errors import ZMapFileError
    from ..verify.deviation import load_design
    from ..cam.raster import raster_program

    if not os.path.exists(design_path):
        raise ZMapFileError(design_path, "no such file")
    for name, v in (("--stepover", stepover), ("--tol", tol), ("--feed", feed), ("--spindle", spindle),
                    ("--clearance", clearance)):
        if not (math.isfinite(v) and v > 0):
            raise click.BadParameter(f"must be a positive number, got {v:g}", param_hint=name)
    if outside not in ("skip", "lowest"):
        try:
            outside = float(outside)
        except ValueError:
            raise click.BadParameter(f"must be skip, lowest or a height in mm, got {outside!r}",
                                     param_hint="--outside") from None
        if not math.isfinite(outside):
            raise click.BadParameter(f"must be a finite height in mm, got {outside!r}", param_hint="--outside")
    from ..cam.drop import as_cutter

    cut = as_cutter(tool)
    model = load_design(design_path)
    click.echo(f"dropping a {cut.kind} D{cut.diameter:g} cutter on {design_path} ...", err=True)

    def progress(done: int, total: int) -> None:
        click.echo(f"  passes {done}/{total}", err=True)

    prog = raster_program(model, cut, stepover=stepover, angle=math.radians(angle), tol=tol, step=step,
                          bounds=bounds, feed=feed, plunge_feed=plunge_feed, spindle=spindle, clearance=clearance,
                          name=os.path.basename(design_path), outside=outside, progress=progress)
    prog.save(output)
    s = prog.stats
    click.echo(f"wrote {output}: {s['passes']} passes, {count(s['kept_points'])} of {count(s['cl_points'])} CL points kept "
               f"(chord tol {tol:g} mm), {s['retracts']} retracts, predicted scallop {prog.scallop:.4f} mm, "
               f"{s['seconds']:.1f} s", err=True)
