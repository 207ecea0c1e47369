"""The ``zmap`` command."""

from __future__ import annotations

import sys

import click

from .errors import ZMapError

__all__ = ["main", "cli"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="zmap")
def cli() -> None:
    """Precision z-map modelling of die and mould surfaces."""


def main(argv: list[str] | None = None) -> int:
    """Run the ``zmap`` command; errors are printed in one line with a non-zero exit."""
    try:
        cli.main(args=argv, prog_name="zmap", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("zmap: aborted", err=True)
        return 130
    except click.ClickException as exc:
        click.echo(f"zmap: error: {exc.format_message()}", err=True)
        return exc.exit_code
    except (ZMapError, ValueError, OSError) as exc:
        click.echo(f"zmap: error: {' '.join(str(exc).split())}", err=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
