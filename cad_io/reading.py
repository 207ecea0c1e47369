"""Reading a STEP file for a command: its warnings at once, a bar that moves meanwhile.

:func:`read_part` is what ``zmap convert``, ``zmap report`` and ``zmap refine`` call: the
same damage warnings, printed as soon as the file is read (before any face is converted or
sampled), the same notes for faults that change no face, the same ``--strict`` and
``--partial``. While OCC reads (seconds on a large part, in a child process) the bar's
elapsed time keeps moving (:func:`ticking`).
"""

from __future__ import annotations

import sys
import threading
from contextlib import contextmanager
from typing import Any, Callable

__all__ = ["TICK", "read_part", "ticking", "explain_extent"]

#: seconds between two redraws of the bar while OCC reads
TICK = 0.2


@contextmanager
def ticking(bar: Any, interval: float = TICK):
    """Redraw ``bar`` (a tqdm bar, or None) every ``interval`` seconds while in the block, so
    that its elapsed time moves while a long call (OCC's reader) holds the main thread.

    Examples
    --------
    >>> import time
    >>> class Bar:
    ...     n = 0
    ...     def refresh(self):
    ...         self.n += 1
    >>> bar = Bar()
    >>> with ticking(bar, 0.01):
    ...     time.sleep(0.2)
    >>> bar.n >= 5
    True
    """
    if bar is None or getattr(bar, "disable", False):
        yield
        return
    stop = threading.Event()

    def run() -> None:
        while not stop.wait(interval):
            try:
                bar.refresh()
            except Exception:  # noqa: BLE001 (a redraw must never end the read)
                return

    t = threading.Thread(target=run, name="zmap-reading-bar", daemon=True)
    t.start()
    try:
        yield
    finally:
        stop.set()
        t.join()


def read_part(part_path: str, *, strict: bool = False, partial: bool = False, bar: Any = None,
              echo: Callable[[str], Any] | None = None):
    """:func:`cad_io.read_step` for a command: each warning and note goes to ``echo`` (default
    stderr, through the bar where there is one) as soon as it is known, as one line
    (``warning: ...``, ``note: ...``), and the bar ticks while OCC reads.

    Returns the part; ``part.warnings`` are already told.
    """
    import click

    from cad_io.step import read_step

    def say(line: str) -> None:
        line = " ".join(line.split())
        if echo is not None:
            echo(line)
        elif bar is not None and not getattr(bar, "disable", True):
            bar.write(line, file=sys.stderr)
        else:
            click.echo(line, err=True)

    with ticking(bar):
        part = read_step(part_path, strict=strict, partial=partial, warn=lambda w: say(f"warning: {w}"))
    for note in part.notes:
        say(f"note: {note}")
    return part


def explain_extent(part: Any, err: Exception) -> Exception:
    """The grid-size refusal ``err`` on a damaged part, said as what it is: the part's extent
    is absurd because the file is damaged (its first warning). ``err`` itself elsewhere."""
    if not getattr(part, "damaged", False) or not part.warnings:
        return err
    import os

    b = part.bbox
    box = ", ".join(f"{a} {b[k]:.4g} .. {b[k + 3]:.4g}" for k, a in enumerate("xyz"))
    return type(err)(f"{os.path.basename(str(part.source))}: the part's extent ({box} mm) is absurd: the file "
                     f"is damaged ({part.warnings[0]}); the grid it asks for: {err}")
