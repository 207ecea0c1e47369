"""Local web viewer of a simulation run: the stock in 3D with a stage slider (pyvista + trame).

``zmap view RUN.zsim`` serves it on 127.0.0.1; :func:`make_viewer` builds the same app in
Python, and :func:`serve` runs it in a child process for a notebook (an iframe of the same
page). Nothing here is imported by ``import zmap``: pyvista and trame load when a viewer is
made.
"""

from __future__ import annotations

from .._lazy import attach


__all__ = ["Viewer", "make_viewer", "stage_caption", "serve", "ViewerProcess"]

_LAZY = {"Viewer": "app", "make_viewer": "app", "stage_caption": "app", "serve": "process",
         "ViewerProcess": "process"}


__getattr__, __dir__ = attach(__name__, _LAZY)
