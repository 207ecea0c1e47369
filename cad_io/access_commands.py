"""CLI command ``zmap access``: tool access directions of a STEP part or a design (paper 002).

A STEP part is sampled on its exact faces (:func:`cad_io.access.analyse`); a z-map, precision
model or tiled z-map on its top-most surface, the material below it
(:func:`zmap.access.analyse_design`). It lives in cad_io because it reads STEP with OCP; the
voxel map itself is :mod:`zmap.access`.

Registered on the ``zmap`` group in :mod:`zmap.cli`; OCP, numba and pyvista load only when
the command runs.
"""

from __future__ import annotations

import os

import click

__all__ = ["access_cmd"]


@click.command("access")
@click.argument("part_path", metavar="PART.step|DESIGN", type=click.Path())
@click.option("--voxel", "d", default=0.5, show_default=True, type=float, metavar="MM", help="Voxel edge d.")
@click.option("--step", default=None, type=float, metavar="MM", help="Sampling step d' (default d/4; < d).")
@click.option("--q", default=4, show_default=True, type=int, help="Direction set frequency (k = 20 q^2).")
@click.option("--tool", "tool_spec", default="ball:6", show_default=True, metavar="ball:DIAMETER",
              help="Ball-end cutter, diameter in mm.")
@click.option("--holder", default=None, metavar="DxL", help="Holder cylinder diameter x length, mm (e.g. 20x40).")
@click.option("--stickout", default=25.0, show_default=True, type=float, metavar="MM",
              help="Tool tip to holder face, mm (with --holder).")
@click.option("--cone", default=None, type=float, metavar="DEG",
              help="Set-ups only within this tilt from +z (a 3+2 head's range).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="PART.access.npz to write.")
@click.option("--png", "png", default=None, metavar="PREFIX",
              help="Write PREFIX_count.png, PREFIX_setups.png and PREFIX_sphere.png (default: beside -o).")
@click.option("--no-png", is_flag=True, default=False, help="Write no pictures.")
@click.option("--grid", default=None, type=float, metavar="MM",
              help="Also store per z-map node (this grid over the part's xy box) its top-most voxel and "
                   "number of accessible directions.")
@click.option("--rays", default=2, show_default=True, type=int,
              help="Casting lines per voxel edge (the depth buffers' pitch is d / rays).")
@click.option("--refine/--no-refine", default=True, show_default=True,
              help="Cast half-voxel pieces again where a voxel's cylinder is blocked (--no-refine: the "
                   "paper's casting alone, about half the visibility time, more conservative near "
                   "silhouettes).")
@click.option("--solid", type=click.Choice(["auto", "closed", "below"]), default="auto", show_default=True,
              help="The material: 'closed' the closed shell's inside (paint spreading); 'below' what lies below "
                   "the top surface seen from +z, down to the lowest point or --floor (an open die face); "
                   "'auto' below for an open model (free boundary edges), else closed.")
@click.option("--floor", default=None, type=float, metavar="Z",
              help="Lowest z of the material below the top surface, mm (default: the part's lowest point).")
@click.option("--max-uncertain", default=25.0, show_default=True, type=float, metavar="PCT",
              help="Refuse the map when more than this share of the boundary area is uncertain (walls or gaps "
                   "thinner than the voxel), percent.")
def access_cmd(part_path, d, step, q, tool_spec, holder, stickout, cone, output, png, no_png, grid=None, rays=2,
               refine=True, solid="auto", floor=None, max_uncertain=25.0) -> None:
    """Tool access directions from a visibility voxel map (paper 002): 3-axis verdict and set-ups.

    PART.step is sampled on its exact faces; a DESIGN (.zmap.npz, .zpm, .zarr) on its top-most
    surface, as a die seen from +z with the material below it.
    """
    import math
    import time

    from cad_io.access import analyse
    from cad_io.step import read_step
    from zmap.access import analyse_design
    from zmap.design import as_design, read_design
    from zmap.errors import StepImportError, ZMapFileError

    from zmap.access.voxelmap import AccessModelError, Tool, parse_holder, parse_tool

    t0 = time.perf_counter()
    is_step = part_path.lower().endswith((".step", ".stp"))
    if not os.path.exists(part_path):
        raise (StepImportError if is_step else ZMapFileError)(f"{part_path}: no such file")
    dia = parse_tool(tool_spec)
    hd, hl = parse_holder(holder) if holder else (0.0, 0.0)
    tool = Tool(dia, stickout=stickout, holder_diameter=hd, holder_length=hl)
    if cone is not None and not (0 < cone <= 180):
        raise AccessModelError(f"--cone must be an angle in (0, 180] degrees, got {cone!r}")
    if d <= 0 or not math.isfinite(d):
        raise AccessModelError(f"voxel size d must be a positive number of mm, got {d!r}")
    if step is not None and not (0 < step < d):
        raise AccessModelError(f"sampling step d' must be positive and smaller than the voxel d = {d:g} mm, "
                               f"got d' = {step!r} mm")
    if q < 1:
        raise AccessModelError(f"q must be an integer >= 1, got {q!r}")
    # checked before the minutes of analysis, not after
    if grid is not None and not (grid > 0 and math.isfinite(grid)):
        raise AccessModelError(f"--grid must be a positive number of mm, got {grid!r}")
    if rays < 1:
        raise AccessModelError(f"--rays must be an integer >= 1, got {rays!r}")
    if not (0 <= max_uncertain <= 100):
        raise AccessModelError(f"--max-uncertain must be a percentage in [0, 100], got {max_uncertain!r}")
    if floor is not None and (solid == "closed" or not math.isfinite(floor)):
        raise AccessModelError(f"--floor {floor!r} needs a finite z and --solid below or auto")

    def say(msg: str) -> None:
        click.echo(f"[{time.perf_counter() - t0:6.1f} s] {msg}", err=True)

    if not is_step and solid == "closed":
        raise AccessModelError(f"{part_path}: a design gives heights, not a closed shell: its material is what "
                               "lies below its surface (--solid below or auto)")
    say(f"reading {part_path}")
    common = dict(d=d, q=q, tool=tool, step=step, cone=None if cone is None else math.radians(cone), rays=rays,
                  refine=refine, progress=say, floor=floor, max_uncertain=max_uncertain / 100.0)
    if is_step:
        part = read_step(part_path)
        result = analyse(part, solid=solid, **common)
        b = part.bbox
        box = (b[0], b[1], b[3], b[4])
    else:
        design = read_design(part_path)
        result = analyse_design(design, source=os.path.basename(part_path.rstrip("/\\")), **common)
        box = as_design(design).bounds
    if grid is not None:
        import numpy as np

        from zmap.access.voxelmap import node_directions

        xs = np.arange(box[0], box[2] + grid / 2, grid)
        ys = np.arange(box[1], box[3] + grid / 2, grid)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        vox, cnt = node_directions(result.vm, result.amap, X, Y)
        result.nodes = {"node_x0": float(xs[0]), "node_y0": float(ys[0]), "node_grid": float(grid),
                        "node_voxel": vox, "node_count": cnt}
    result.save(output)
    click.echo(result.summary())
    if not no_png:
        from zmap.plot.access import sphere_3d, voxels_3d

        prefix = png or (output[:-len(".access.npz")] if output.endswith(".access.npz") else os.path.splitext(output)[0])
        say("pictures")
        for path in (voxels_3d(result, f"{prefix}_count.png", by="count"),
                     voxels_3d(result, f"{prefix}_setups.png", by="setup"),
                     sphere_3d(result, f"{prefix}_sphere.png")):
            click.echo(f"wrote {path}")
    s = result.seconds
    click.echo(f"wrote {output}  ({result.vm.n_boundary:,} boundary voxels x k = {result.vm.directions.k}; "
               f"pipeline {s['total']:.1f} s)")
