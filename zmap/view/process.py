"""Run the viewer in a child process: from a notebook or a script, without blocking it.

``serve(run_path)`` starts ``zmap view`` on a free port of 127.0.0.1 and returns a handle whose
``url`` the browser opens; in a notebook the handle shows the page in an ``<iframe>``. The
page is the same as ``zmap view``'s.

Examples
--------
>>> handle = serve("RUN.zsim")          # doctest: +SKIP
>>> handle  # a notebook shows the viewer here  # doctest: +SKIP
>>> handle.stop()                       # doctest: +SKIP
"""

from __future__ import annotations

import html
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from ..errors import ZMapError

__all__ = ["ViewerProcess", "serve"]


class ViewerProcess:
    """A ``zmap view`` child process: its URL, an iframe for notebooks, and ``stop()``."""

    def __init__(self, proc: subprocess.Popen, url: str, height: int = 700):
        self.proc = proc
        self.url = url
        self.height = height

    def _repr_html_(self) -> str:
        url = html.escape(self.url, quote=True)
        return (f'<iframe src="{url}" width="100%" height="{int(self.height)}" '
                f'style="border: 0"></iframe>')

    def __repr__(self) -> str:
        state = "running" if self.proc.poll() is None else f"exited ({self.proc.returncode})"
        return f"ViewerProcess({self.url}, {state})"

    def stop(self) -> None:
        """Stop the server (a no-op when it has already stopped)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)


def serve(run_path: str | os.PathLike, *, design: str | os.PathLike | None = None,
          program: str | os.PathLike | None = None, allowance: float = 0.01, tol: float = 0.01,
          port: int = 0, timeout: float = 60.0, height: int = 700) -> ViewerProcess:
    """Start ``zmap view RUN.zsim`` on 127.0.0.1 in a child process and wait until it listens.

    Parameters
    ----------
    run_path : path
        The ``.zsim`` file.
    design, program, allowance, tol :
        As ``zmap view`` takes them.
    port : int
        0 (default) picks a free port.
    timeout : float
        Seconds to wait for the server.
    height : int
        Height of the notebook's iframe, pixels.

    Returns
    -------
    ViewerProcess
        ``url``, ``stop()``; a notebook cell that ends with it shows the page.

    Raises
    ------
    ZMapError
        The server exited or did not listen in time (its last error line is in the message).
    """
    from .app import free_port

    port = int(port) or free_port()
    args = [sys.executable, "-m", "zmap.cli", "view", os.fspath(run_path), "--port", str(port),
            "--no-browser", "--allowance", repr(float(allowance)), "--tol", repr(float(tol))]
    if design is not None:
        args += ["--design", os.fspath(design)]
    if program is not None:
        args += ["--program", os.fspath(program)]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    t = time.monotonic()
    while time.monotonic() - t < timeout:
        if proc.poll() is not None:
            err = proc.stderr.read().decode(errors="replace").strip().splitlines() if proc.stderr else []
            raise ZMapError(f"{Path(run_path).name}: the viewer exited: {err[-1] if err else proc.returncode}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return ViewerProcess(proc, f"http://127.0.0.1:{port}/", height)
        time.sleep(0.2)
    ViewerProcess(proc, "", height).stop()
    raise ZMapError(f"{Path(run_path).name}: the viewer did not listen on port {port} within {timeout:g} s")
