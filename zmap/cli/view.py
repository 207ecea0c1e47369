"""``zmap view``: serve the web viewer of a simulation run on this machine."""

from __future__ import annotations

import os

import click

__all__ = ["view_cmd"]


@click.command("view")
@click.argument("run_path", metavar="RUN.zsim", type=click.Path(dir_okay=False))
@click.option("--design", type=click.Path(dir_okay=False), default=None,
              help="Design to compare with: PART.zpm (precision model) or PART.zmap.npz; the stock "
                   "is then coloured by its deviation (mm).")
@click.option("--program", type=click.Path(dir_okay=False), default=None,
              help="G-code file of the run: the caption quotes each stage's line (default: the program "
                   "kept in RUN.zsim).")
@click.option("--tol", type=float, default=0.01, show_default=True,
              help="With --design: tolerance of the deviation colours, mm (green within +-tol, bands of tol "
                   "to +-3 tol, other colours beyond).")
@click.option("--allowance", type=float, default=0.01, show_default=True,
              help="Vertical error allowed in the drawn stock mesh, mm (0: exact).")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to serve on.")
@click.option("--port", type=int, default=0, help="Port (default: a free one).")
@click.option("--browser/--no-browser", default=True, show_default=True, help="Open a browser tab.")
def view_cmd(run_path, design, program, tol, allowance, host, port, browser) -> None:
    """Serve a 3D view of RUN.zsim with a stage slider, play and rewind, in the browser."""
    from ..sim.session import Run
    from ..view.app import free_port, make_viewer

    for path in (run_path, design, program):
        if path is not None and not os.path.isfile(path):
            raise click.BadParameter(f"{path}: no such file")
    if not tol > 0:
        raise click.BadParameter(f"--tol must be a positive number of mm, got {tol}")
    if not 0 <= port <= 65535:
        raise click.BadParameter(f"--port must be 0..65535, got {port}")
    run = Run.load(run_path)
    model = None
    if design is not None:
        if design.endswith(".zpm"):
            from ..model import PrecisionModel

            model = PrecisionModel.load(design)
        else:
            from ..grid import ZMap

            model = ZMap.load(design)
    server, _ = make_viewer(run, design=model, program=program, allowance=allowance, tol=tol)
    port = port or free_port(host)
    click.echo(f"zmap view: {run_path}, {run.n_stages} stages, at http://{host}:{port}/ "
               "(Ctrl-C stops it)", err=True)
    server.start(host=host, port=port, open_browser=browser, show_connection_info=False)
