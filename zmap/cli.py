"""The ``zmap`` command."""

from __future__ import annotations

import os
import sys

import click

from .errors import ZMapError
from .extras import missing_extra_message
from .fmt import count, size

__all__ = ["main", "cli"]


class _Raised(Exception):
    """Carries an interrupt or an ``EOFError`` out of a subcommand past click's own handler
    (which turns both into ``Abort``: an EOFError from a truncated file would read "aborted")."""

    def __init__(self, exc: BaseException):
        super().__init__(exc)
        self.exc = exc


class _Group(click.Group):
    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except (KeyboardInterrupt, EOFError) as exc:
            raise _Raised(exc) from None


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="zmap")
def cli() -> None:
    """Precision z-map modelling of die and mould surfaces."""


@cli.command()
@click.option("--surface", "surfaces", multiple=True, metavar="NAME",
              help="Analytic surface (repeatable); default: the three rows of Table 1.")
@click.option("--grid", "grids", multiple=True, type=float, metavar="MM",
              help="Grid interval in mm (repeatable); default 1.")
@click.option("--scheme", "schemes", multiple=True, metavar="NAME", help="Scheme (repeatable); default: all.")
@click.option("--points", default=1_000_000, show_default=True, type=int, help="Random query points per row.")
@click.option("--seed", default=0, show_default=True, type=int)
@click.option("--format", "fmt", type=click.Choice(["markdown", "csv"]), default="markdown", show_default=True)
def accuracy(surfaces, grids, schemes, points, seed, fmt) -> None:
    """Interpolation accuracy against exact surfaces (a table shaped like paper 004's Table 1)."""
    from . import accuracy as acc
    from .surfaces import SURFACES, TABLE1

    for name in surfaces:
        if name not in SURFACES:
            raise click.BadParameter(f"{name!r} is not one of {', '.join(SURFACES)}", param_hint="--surface")
    rows = acc.accuracy_rows(surfaces or TABLE1, grids or (1.0,), schemes or None, n_points=points, seed=seed)
    click.echo(acc.format_csv(rows) if fmt == "csv" else acc.format_markdown(rows), nl=fmt != "csv")


@cli.command()
@click.argument("path", type=click.Path())
def info(path: str) -> None:
    """Describe a saved z-map (.zmap.npz or a tiled .zarr store): grid, domain, heights, memory, metadata."""
    import json

    import numpy as np

    from .grid import ZMap

    if os.path.isdir(path):  # tiled store (zmap/tiled): described from its metadata and tile markers
        from .tiled import TiledZMap

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


# ---- subcommands: each lives in the module of its feature and registers here --------------
# sim commands (zmap/sim/commands.py): simulate, replay
from .sim.commands import replay_cmd, simulate_cmd  # noqa: E402  (sim commands)
cli.add_command(simulate_cmd)  # sim commands
cli.add_command(replay_cmd)  # sim commands
# view command (zmap/view/commands.py): pyvista and trame load only when it runs
from .view.commands import view_cmd  # noqa: E402  (view command)
cli.add_command(view_cmd)  # view command
# verify command (zmap/verify/commands.py): compare a run's stock with its design
from .verify.commands import compare_cmd  # noqa: E402  (verify command)
cli.add_command(compare_cmd)  # verify command
# cam command (zmap/cam/commands.py): raster finishing programs from a design
from .cam.commands import toolpath_cmd  # noqa: E402  (cam command)
cli.add_command(toolpath_cmd)  # cam command


def add_plugin_commands(group: click.Group = cli) -> list[str]:
    """Add the commands other packages declare under the ``zmap.commands`` entry point (a
    sequence of click commands each); returns their names.

    cad_io declares convert, refine, report and access this way (they import OCP only when
    run), so zmap never imports the layer above it. A package whose commands fail to load
    is named in one warning line on stderr and the other commands still run.
    """
    from importlib.metadata import entry_points

    names = []
    for ep in entry_points(group="zmap.commands"):
        try:
            commands = list(ep.load())
        except Exception as exc:  # a broken extra must not take the core's commands down with it
            click.echo(f"zmap: warning: the commands of {ep.value} did not load ({type(exc).__name__}: "
                       f"{' '.join(str(exc).split())})", err=True)
            continue
        for command in commands:
            group.add_command(command)
            names.append(command.name)
    return names


add_plugin_commands()


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def _by_interrupt(exc: BaseException) -> bool:
    """True if ``exc`` is, or was raised while handling or from, a KeyboardInterrupt: a
    Ctrl-C during the import of a C extension comes out as ``ImportError: initialization
    failed`` (pybind11 raises it from the interrupt: OCP, in the first seconds of
    ``zmap convert``)."""
    seen = 0
    while exc is not None and seen < 32:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return False


def _report(exc: BaseException, command: str) -> int:
    """Print ``exc`` in one line on stderr; returns the exit status.

    1: bad input (a missing or unreadable file, a bad option value, a G-code or STEP error)
    and every other failure; 2: the command line itself (unknown option, missing
    argument: click's usage errors); 130: interrupted (an error raised from a Ctrl-C too).
    """
    if isinstance(exc, KeyboardInterrupt) or _by_interrupt(exc):
        click.echo("zmap: interrupted", err=True)
        return 130
    if isinstance(exc, click.BadParameter) and not isinstance(exc, click.MissingParameter):
        # a value click or the command refused (a missing file, a number out of range, a
        # choice not offered) is bad input, not a malformed command line
        click.echo(f"zmap: error: {_one_line(exc.format_message())}", err=True)
        return 1
    if isinstance(exc, click.ClickException):
        click.echo(f"zmap: error: {_one_line(exc.format_message())}", err=True)
        return exc.exit_code
    if isinstance(exc, (ZMapError, ValueError, OSError, EOFError)):
        click.echo(f"zmap: error: {_one_line(exc)}", err=True)
        return 1
    missing = missing_extra_message(exc, command.strip("'"))
    if missing is not None:
        click.echo(f"zmap: error: {missing}", err=True)
        return 1
    if isinstance(exc, MemoryError):
        detail = _one_line(exc)
        click.echo(f"zmap: error: out of memory while running {command}"
                   + (f" ({detail})" if detail else "") + ": MemoryError", err=True)
        return 1
    click.echo(f"zmap: error: internal error while running {command}: {type(exc).__name__}: {_one_line(exc)} "
               f"(ZMAP_TRACEBACK=1 shows the traceback)", err=True)
    return 1


def main(argv: list[str] | None = None) -> int:
    """Run the ``zmap`` command; errors are printed in one line on stderr, no traceback.

    Exit status: 0 done; 1 bad input (missing or unreadable file, bad option value, G-code
    or STEP error) or any other failure, out of memory included; 2 a malformed command
    line (click's usage errors: unknown option, missing argument); 130 interrupted. With
    the environment variable ``ZMAP_TRACEBACK=1`` unexpected errors raise as usual.
    """
    args = sys.argv[1:] if argv is None else list(argv)
    name = next((a for a in args if a in cli.commands), None)
    command = f"'zmap {name}'" if name else "'zmap'"
    try:
        cli.main(args=args, prog_name="zmap", standalone_mode=False)
    except _Raised as raised:
        return _report(raised.exc, command)
    except click.exceptions.Abort as exc:
        if isinstance(exc.__cause__, KeyboardInterrupt):
            return _report(exc.__cause__, command)
        click.echo("zmap: aborted", err=True)
        return 130
    except (ZMapError, ValueError, OSError, click.ClickException) as exc:
        return _report(exc, command)
    except Exception as exc:  # MemoryError included; never BaseException (KeyboardInterrupt, SystemExit)
        if os.environ.get("ZMAP_TRACEBACK") and not _by_interrupt(exc):
            raise
        return _report(exc, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())
