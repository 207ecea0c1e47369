"""CLI commands of the STEP side: ``zmap convert``, ``zmap refine``, ``zmap report``.

Registered on the ``zmap`` group in :mod:`zmap.cli`. They parse, call the library
(:mod:`cad_io.sampler`, :mod:`cad_io.refine`) and print. OCP, numba and the sampler are
imported inside the commands, so ``zmap --help`` and ``zmap accuracy`` never load them.
"""

from __future__ import annotations

import contextlib
import os
import time

import click

from zmap.fmt import count, size

from cad_io.refine import OptionError, RefineOptions, ReportOptions, check_tol, format_report, refine_models, report_rows

from .access_commands import access_cmd

__all__ = ["convert_cmd", "refine_cmd", "report_cmd"]

_AXES = ("+z", "-z", "+x", "-x", "+y", "-y")

_STRICT_HELP = ("Refuse a damaged STEP file (entities that failed to load or transfer, faces missing); "
                "faults that change no face are notes, never refused.")
_PARTIAL_HELP = "Read a damaged STEP file that lost most of its faces (refused by default)."


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
@click.option("-o", "--output", required=True, type=click.Path(),
              help="PART.zmap.npz to write (with --tiles: the PART.zarr store).")
@click.option("--progress/--no-progress", default=True, show_default=True)
@click.option("--strict", is_flag=True, default=False, help=_STRICT_HELP)
@click.option("--partial", is_flag=True, default=False, help=_PARTIAL_HELP)
@click.option("--tiles", type=int, default=None, metavar="N",
              help="Convert in N x N-node tiles as Dask tasks into a zarr store (-o PART.zarr); resumes.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="With --tiles: a running Dask scheduler (tcp://host:port); default a local cluster.")
@click.option("--workers", type=int, default=2, show_default=True, help="With --tiles: local worker processes.")
def convert_cmd(part_path, grid, bounds, method, axis, deflection, output, progress, strict=False, partial=False,
                tiles=None, scheduler=None, workers=2) -> None:
    """Convert a STEP part to a master z-map (paper 004 §2.1) and save it."""
    if tiles is not None or scheduler is not None:  # tiled conversion on Dask (cad_io/tiled.py)
        return _convert_tiled(part_path, grid=grid, bounds=bounds, method=method, axis=axis, deflection=deflection,
                              output=output, progress=progress, tiles=tiles, scheduler=scheduler, workers=workers)
    import sys
    import warnings

    from cad_io.reading import explain_extent, read_part
    from cad_io.sampler import estimate_bytes, grid_shape, sample, summary
    from zmap.errors import GridTooLargeError, StepImportError

    t0 = time.perf_counter()
    if not os.path.exists(part_path):
        raise StepImportError(f"{part_path}: no such file")
    if grid <= 0:
        raise click.BadParameter(f"must be positive, got {grid!r}", param_hint="--grid")
    from tqdm import tqdm

    # one bar from the first second: reading, meshing, sampling, facets as its stages (on a
    # terminal: a log or a pipe gets the summary and a one-line error only)
    progress = progress and sys.stderr.isatty()
    with tqdm(total=100, unit="%", desc="reading: ", leave=False, disable=not progress,
              bar_format="{desc}{percentage:3.0f}%|{bar}| {elapsed}") as bar:
        # the damage warnings print as soon as the file is read; the bar ticks while OCC reads
        part = read_part(part_path, strict=strict, partial=partial, bar=bar if progress else None)
        if not part.faces:
            raise StepImportError(f"{part_path}: no faces in the file")
        bar.update(10)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                zm = sample(part, grid, bounds=bounds, method=method, axis=axis, deflection=deflection,
                            progress=bar if progress else False)
            except GridTooLargeError as err:
                raise explain_extent(part, err) from None
    zm.meta["source"] = os.path.basename(part_path)
    zm.save(output)
    s = summary(zm)
    seconds = time.perf_counter() - t0
    for w in [str(c.message) for c in caught]:
        click.echo(f"warning: {' '.join(w.split())}", err=True)
    click.echo(f"wrote    {output}")
    click.echo(f"part     {os.path.basename(part_path)}: {len(part.faces)} faces, axis {axis}")
    click.echo(f"grid     {zm.nx:,} x {zm.ny:,} = {count(s['points'])} points, dx={zm.dx:g} dy={zm.dy:g} mm, "
               f"x {zm.x0:g} .. {zm.x1:g}, y {zm.y0:g} .. {zm.y1:g}")
    click.echo(f"method   {method}: jacobian {100 * s['share_jacobian']:.2f} %, facet {100 * s['share_facet']:.2f} %, "
               f"empty {100 * s['share_empty']:.2f} %")
    click.echo(f"time     {seconds:.2f} s (sampling {zm.meta['seconds']:.2f} s)")
    click.echo(f"memory   {size(zm.nbytes)} map, {size(estimate_bytes(*grid_shape(zm.bounds, zm.dx, zm.dy)))} "
               f"working estimate")


# ---- the tiled conversion: zmap convert --tiles N ------------------------------------------------

def _zarr_name(output: str) -> str:
    """The store's folder name for ``-o``: ``.zarr`` required for an ``.npz`` name, appended to others.

    >>> _zarr_name("die.zarr"), _zarr_name("die.zarr/"), _zarr_name("die")
    ('die.zarr', 'die.zarr', 'die.zarr')
    """
    name = str(output).rstrip("/\\")
    if name.endswith(".zarr"):
        return name
    if name.endswith(".npz"):
        stem = name[:-len(".zmap.npz")] if name.endswith(".zmap.npz") else name[:-len(".npz")]
        raise click.BadParameter(f"a tiled conversion writes a zarr store (a folder), not {output!r}: "
                                 f"name it {stem + '.zarr'!r}", param_hint="-o")
    click.echo(f"note: writing the tiled store to {name}.zarr", err=True)
    return name + ".zarr"


def _convert_tiled(part_path: str, *, grid: float, bounds, method: str, axis: str, deflection, output: str,
                   progress: bool, tiles: int | None, scheduler: str | None, workers: int) -> None:
    """``zmap convert ... --tiles N [--scheduler ADDRESS]``: the tiled branch of the command."""
    from cad_io.tiled import convert_tiled, dask_client
    from zmap.errors import StepImportError
    from zmap.tiled.store import check_tile

    t0 = time.perf_counter()
    if tiles is None:
        raise click.BadParameter("--scheduler needs --tiles N (the tiled conversion)", param_hint="--scheduler")
    try:
        check_tile(tiles)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--tiles") from None
    if grid <= 0:
        raise click.BadParameter(f"must be positive, got {grid!r}", param_hint="--grid")
    output = _zarr_name(output)
    if not os.path.exists(part_path):
        raise StepImportError(f"{part_path}: no such file")
    if scheduler:
        # fail fast, before reading and meshing the part, when the address does not answer
        with dask_client(scheduler):
            pass
    click.echo(f"reading  {part_path}", err=True)
    store, rep = convert_tiled(part_path, grid, output, tile=tiles, bounds=bounds, method=method, axis=axis,
                               deflection=deflection, scheduler=scheduler, workers=workers, progress=progress,
                               echo=lambda line: click.echo(line, err=True))
    for w in store.meta.get("warnings", []):
        click.echo(f"warning: {' '.join(str(w).split())}", err=True)
    st = store.tile_stats()
    n = store.nx * store.ny
    click.echo(f"wrote    {output} (tiled zarr store, complete)")
    click.echo(f"part     {os.path.basename(part_path)}: {store.meta.get('faces')} faces, axis {axis}")
    click.echo(f"grid     {store.nx:,} x {store.ny:,} = {count(n)} points, dx={store.dx:g} dy={store.dy:g} mm, "
               f"x {store.x0:g} .. {store.x1:g}, y {store.y0:g} .. {store.y1:g}")
    click.echo(f"tiles    {store.n_tiles} of {store.tile} x {store.tile} nodes: {rep['tiles_done_now']} sampled now, "
               f"{rep['tiles_skipped']} finished before; {count(st['filled'])} points with surface")
    click.echo(f"time     {time.perf_counter() - t0:.2f} s (tiles {rep['seconds']:.2f} s on {rep['workers']} workers, "
               f"{rep['nodes_per_s'] / 1e6:.3f} M nodes/s)")
    click.echo(f"memory   peak {rep['peak_rss_mb_per_worker']:.0f} MB per worker; "
               f"store {size(store.disk_bytes())} "
               f"on disk, {size(store.nbytes)} in memory")


# ---- precision refinements: zmap refine, zmap report ------------------------------------------

_NEEDS_PART = ("refinement needs the exact surface: pass --part PART.step, the STEP file the z-map "
               "was converted from")


def _view_part_checked(part, axis: str, base, part_path: str):
    """``part`` in the view frame of ``axis`` (:func:`cad_io.view.view_part`), checked against ``base``.

    The refinement samples the part where the z-map lies: a z-map of another part, or of
    this one seen along another axis, would find no surface, so a domain that misses the
    part's extents seen from ``axis`` is an error.
    """
    from cad_io.view import view_part

    vpart = view_part(part, axis)
    px0, py0, _, px1, py1, _ = vpart.bbox
    x0, y0, x1, y1 = base.bounds
    if x1 < px0 or x0 > px1 or y1 < py0 or y0 > py1:
        raise click.BadParameter(
            f"the z-map's domain x {x0:g} .. {x1:g}, y {y0:g} .. {y1:g} misses {os.path.basename(part_path)} seen "
            f"from {axis} (x {px0:g} .. {px1:g}, y {py0:g} .. {py1:g}): not the part or axis it was converted from",
            param_hint="PART.zmap.npz")
    return vpart


#: the command-line option of each field of RefineOptions / ReportOptions
_OPTION_NAMES = {"tol": "--tol", "grid": "--grid", "n_points": "--points", "methods": "--method",
                 "deflection": "--deflection", "distance_deflection": "--deflection"}


@contextlib.contextmanager
def _as_bad_parameter():
    """An OptionError of the library as click's BadParameter on the option it came from."""
    try:
        yield
    except OptionError as exc:
        raise click.BadParameter(str(exc), param_hint=_OPTION_NAMES.get(exc.option, exc.option)) from None


@click.command("refine")
@click.argument("zmap_path", metavar="PART.zmap.npz", type=click.Path(dir_okay=False))
@click.option("--part", "part_path", default=None, metavar="PART.step", help="The exact surface (STEP).")
@click.option("--tol", required=True, type=float, metavar="MM", help="Tolerance in mm (below the grid interval).")
@click.option("--method", type=click.Choice(["ez", "cz"]), default="ez", show_default=True)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="PART.zpm to write.")
@click.option("--strict", is_flag=True, default=False, help=_STRICT_HELP)
@click.option("--partial", is_flag=True, default=False, help=_PARTIAL_HELP)
def refine_cmd(zmap_path, part_path, tol, method, output, strict=False, partial=False) -> None:
    """Refine a master z-map by an EZ-map or CZ-maps sampled from the exact part (paper 004 §3)."""

    from cad_io.reading import read_part
    from zmap.errors import StepImportError
    from zmap.grid import ZMap

    if part_path is None:
        raise click.UsageError(_NEEDS_PART)
    base = ZMap.load(zmap_path)
    with _as_bad_parameter():
        options = RefineOptions(tol, (method,))
        check_tol(tol, base)
    if not os.path.exists(part_path):
        raise StepImportError(f"{part_path}: no such file; {_NEEDS_PART}")
    part = read_part(part_path, strict=strict, partial=partial)
    if not part.faces:
        raise StepImportError(f"{part_path}: no faces in the file; {_NEEDS_PART}")
    axis = base.meta.get("axis", "+z")
    if axis not in _AXES:
        raise click.BadParameter(f"the z-map's axis {axis!r} is not one of {', '.join(_AXES)}",
                                 param_hint="PART.zmap.npz")
    part = _view_part_checked(part, axis, base, part_path)
    model, info = refine_models(part, base, options)[method]
    model.meta["source"] = os.path.basename(part_path)
    model.save(output)
    nb = model.nbytes
    click.echo(f"wrote    {output}")
    if method == "ez":
        ez = model.ez
        click.echo(f"ez       {ez.n_edges:,} edges ({100 * ez.edge_ratio:.2f} %), "
                   f"{ez.n_points:,} e-points at <= {ez.interval:g} mm; {ez.pruned:,} candidate edges dropped "
                   f"(the base holds them)")
        click.echo(f"check    {ez.n_patches:,} cells patched ({ez.n_lattices:,} by a lattice, "
                   f"{size(ez.patch_nbytes)}), "
                   f"{ez.unresolved:,} still off the exact surface at a test point")
    else:
        click.echo(f"cz       {len(model.cz)} CZ-maps, {sum(c.z.size for c in model.cz):,} points")
    click.echo(f"memory   base {size(nb['base'])}, {method} {size(nb[method])}, total {size(nb['total'])}")
    click.echo(f"sampled  {info['sampled']:,} points in {info['seconds']:.2f} s; "
               f"{info['facet']:,} from facet heights where the Jacobian inversion failed, "
               f"{info['empty']:,} without surface")


@click.command("report")
@click.argument("part_path", metavar="PART.step", type=click.Path(dir_okay=False))
@click.option("--grid", required=True, type=float, metavar="MM", help="Base grid interval in mm.")
@click.option("--tol", required=True, type=float, metavar="MM", help="Tolerance in mm.")
@click.option("--points", default=100_000, show_default=True, type=int, help="Random query points.")
@click.option("--seed", default=0, show_default=True, type=int)
@click.option("--method", "methods", multiple=True, type=click.Choice(["ez", "cz"]),
              help="Refinements to build (repeatable); default both.")
@click.option("--axis", type=click.Choice(_AXES), default="+z", show_default=True,
              help="World direction that becomes the map's +z (the part is rotated into that view).")
@click.option("--deflection", type=float, default=None, metavar="MM",
              help="Mesh deflection of the sampled heights and of the distance index (default tol/2): "
                   "Newton heights and NURBS feet are exact whatever it is; smaller is slower.")
@click.option("--format", "fmt", type=click.Choice(["markdown", "json"]), default="markdown", show_default=True)
@click.option("--strict", is_flag=True, default=False, help=_STRICT_HELP)
@click.option("--partial", is_flag=True, default=False, help=_PARTIAL_HELP)
def report_cmd(part_path, grid, tol, points, seed, methods, axis, deflection, fmt, strict=False, partial=False) -> None:
    """Memory and accuracy of the base z-map, the CZ model and the EZ model (paper 004 Table 2)."""
    import json

    from cad_io.reading import read_part
    from zmap.errors import StepImportError

    if not os.path.exists(part_path):
        raise StepImportError(f"{part_path}: no such file")
    with _as_bad_parameter():
        options = ReportOptions(grid, tol, n_points=points, seed=seed, methods=methods or ("ez", "cz"),
                                deflection=deflection, distance_deflection=deflection)
    part = read_part(part_path, strict=strict, partial=partial)
    if not part.faces:
        raise StepImportError(f"{part_path}: no faces in the file")
    from cad_io.view import view_part

    rep = report_rows(view_part(part, axis), options)
    rep["part"] = os.path.basename(part_path)
    rep["axis"] = axis
    rep["warnings"] = list(part.warnings)
    click.echo(json.dumps(rep, indent=1) if fmt == "json" else format_report(rep))


#: the commands cad_io adds to ``zmap`` (the ``zmap.commands`` entry point in pyproject.toml)
COMMANDS = (convert_cmd, refine_cmd, report_cmd, access_cmd)
