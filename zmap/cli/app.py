"""The ``zmap`` group: its commands, the plugins' commands, and one-line errors (:func:`main`)."""

from __future__ import annotations

import os
import sys

import click

from ..errors import ZMapError
from ..extras import missing_extra_message

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


# ---- the commands: one module per group in zmap/cli/; each parses, calls the library and prints
from .cam import toolpath_cmd  # noqa: E402
from .maps import accuracy_cmd, info_cmd  # noqa: E402
from .sim import replay_cmd, simulate_cmd  # noqa: E402
from .verify import compare_cmd  # noqa: E402
from .view import view_cmd  # noqa: E402

for _command in (accuracy_cmd, info_cmd, simulate_cmd, replay_cmd, view_cmd, compare_cmd, toolpath_cmd):
    cli.add_command(_command)


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
