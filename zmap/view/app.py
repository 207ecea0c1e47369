"""The viewer app: a run's stock in 3D, rendered by pyvista on the server, in a trame page.

The page has the 3D view (height, or deviation from a design, with a colour bar in mm and
axes in mm), a stage slider, rewind / step back / play-pause / step forward / end buttons and
a caption with the stage, the G-code line that made it and, when the program is known, its
text. Rendering is remote (the server renders with VTK off-screen and sends pictures), so the
page needs no WebGL.

Examples
--------
>>> import numpy as np
>>> from zmap.sim import simulate
>>> run = simulate(np.array([[1.0, 1.0, -0.5], [2.0, 1.0, -0.5]]), (0, 0, -2, 3, 2, 0),
...                tool="ball:1", pitch=0.25, history="treap")
>>> stage_caption(run, 1, None)
'stage 1 / 2'
"""

from __future__ import annotations

import asyncio
import os
import socket
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StageError

__all__ = ["Viewer", "make_viewer", "stage_caption", "free_port"]


def _quiet_vtk() -> None:
    """VTK warns on stderr that there is no X server before it renders off-screen anyway."""
    try:
        from vtkmodules.vtkCommonCore import vtkLogger
    except ImportError:  # pragma: no cover - older VTK
        return
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)  # errors still show


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def stage_caption(run: Any, stage: int, program_lines: list[str] | None) -> str:
    """``"stage k / n"``, plus ``", line L: <text>"`` for the position that made stage k."""
    n = run.n_stages
    text = f"stage {stage} / {n}"
    if stage <= 0 or stage > len(run.line):
        return text
    line = int(run.line[stage - 1])
    if line <= 0:
        return text
    text += f", line {line}"
    if program_lines is not None and line <= len(program_lines):
        code = program_lines[line - 1].strip()
        if code:
            text += f": {code[:80]}"
    return text


class Viewer:
    """The state behind one viewer page: a run, optional design, the pyvista scene.

    The stock is drawn as the decimated mesh of :class:`zmap.mesh.LocalMesh` (paper 003):
    every node of the stock's top within ``allowance`` of its true height, and moving to a
    stage re-meshes only the regions the tool touched in between.

    Parameters
    ----------
    run : zmap.sim.session.Run
        The simulation to show.
    design : ZMap or PrecisionModel, optional
        When given, the stock is coloured by its deviation from the design (stock top minus
        design height, mm; blue below the design: gouge, red above: stock left).
    program : path, optional
        The G-code file, to show the text of each stage's line.
    allowance : float
        Vertical error allowed in the drawn mesh, mm (0: every ray's height exactly).
    region : int
        Region size of the local re-meshing, in rays.
    """

    def __init__(self, run: Any, *, design: Any = None, program: str | os.PathLike | None = None,
                 allowance: float = 0.01, region: int = 16):
        import pyvista as pv

        from ..mesh import LocalMesh

        _quiet_vtk()
        self.run = run
        self.design = design
        self.program_lines = (Path(program).read_text(errors="replace").splitlines()
                              if program is not None else None)
        self.local = LocalMesh(run, allowance=allowance, region=region)
        self.local.goto(run.n_stages)
        self.scalar_name = "deviation (mm)" if design is not None else "height (mm)"
        self.poly = self._polydata()
        self.plotter = pv.Plotter(off_screen=True, window_size=(900, 650))
        values = self.poly[self.scalar_name]
        if design is not None:
            c = float(np.nanpercentile(np.abs(values), 99)) if values.size else 0.1
            clim, cmap = (-max(c, 1e-3), max(c, 1e-3)), "RdBu_r"
        else:
            stock_top = np.nanmax(run.display(0)) if run.stock.cnt.any() else 0.0
            lo = float(np.nanmin(values)) if values.size else stock_top - 1.0
            clim, cmap = (min(lo, stock_top - 1e-3), float(stock_top)), "viridis"
        self.plotter.add_mesh(self.poly, scalars=self.scalar_name, cmap=cmap, clim=clim,
                              scalar_bar_args={"title": self.scalar_name, "vertical": True})
        self.plotter.show_grid(xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)")
        self.plotter.add_text(self._title(), font_size=10, name="title")
        self.plotter.view_isometric()

    def _title(self) -> str:
        kind = "deviation from the design" if self.design is not None else "stock"
        return (f"simulated {kind} (mesh within {self.local.allowance:g} mm), "
                f"{self.run.summary.get('history', self.run.history)} history")

    def _polydata(self) -> Any:
        poly = self.local.mesh.to_pyvista()
        z = np.asarray(poly.points[:, 2], dtype=np.float64)
        if self.design is None:
            poly[self.scalar_name] = z
        else:
            x, y = poly.points[:, 0], poly.points[:, 1]
            if hasattr(self.design, "height"):
                h = self.design.height(x, y)
            else:
                from ..interpolate import bezier

                h = bezier(self.design, x, y)
            poly[self.scalar_name] = z - np.asarray(h, dtype=np.float64)
        return poly

    def show_stage(self, stage: int) -> str:
        """Move the scene to ``stage`` (re-meshing the touched regions); return its caption."""
        k = self.run.stage(int(stage))
        info = self.local.goto(k)
        self.poly.copy_from(self._polydata(), deep=True)
        return (stage_caption(self.run, k, self.program_lines)
                + f" ({info['regions_touched']} regions re-meshed, {info['triangles']} triangles, "
                  f"{info['ms']:.1f} ms)")


def make_viewer(run: Any, *, design: Any = None, program: str | os.PathLike | None = None,
                allowance: float = 0.01, name: str = "zmap-view") -> tuple[Any, Viewer]:
    """Build the trame server of a viewer page (not started). Returns ``(server, viewer)``.

    Start it with ``server.start(host="127.0.0.1", port=..., open_browser=False)``.
    """
    from trame_pyvista.ui import get_viewer
    from trame.app import get_server
    from trame.ui.vuetify3 import SinglePageLayout
    from trame.widgets import html
    from trame.widgets import vuetify3 as v

    viewer = Viewer(run, design=design, program=program, allowance=allowance)
    n = run.n_stages
    server = get_server(name, client_type="vue3")
    state, ctrl = server.state, server.controller
    state.stage = n
    state.n_stages = n
    state.playing = False
    state.caption = viewer.show_stage(n)
    state.trame__title = "zmap view"

    @state.change("stage")
    def _on_stage(stage: Any, **_: Any) -> None:
        try:
            k = int(round(float(stage)))
            state.caption = viewer.show_stage(k)
        except (StageError, ValueError, TypeError):
            return
        ctrl.view_update()

    def _set(k: int) -> None:
        state.stage = max(0, min(n, int(k)))

    step = max(1, n // 100)
    ctrl.rewind = lambda: _set(0)
    ctrl.back = lambda: _set(int(state.stage) - step)
    ctrl.forward = lambda: _set(int(state.stage) + step)
    ctrl.end = lambda: _set(n)

    async def _play() -> None:
        while state.playing and int(state.stage) < n:
            with state:
                _set(int(state.stage) + step)
            await asyncio.sleep(0.15)
        with state:
            state.playing = False

    @state.change("playing")
    def _on_play(playing: bool, **_: Any) -> None:
        if playing:
            if int(state.stage) >= n:
                state.stage = 0
            asyncio.ensure_future(_play())

    with SinglePageLayout(server) as layout:
        layout.title.set_text("zmap view")
        with layout.toolbar:
            v.VSpacer()
            v.VBtn(icon="mdi-skip-previous", click=ctrl.rewind, id="rewind", title="rewind")
            v.VBtn(icon="mdi-step-backward", click=ctrl.back, id="back", title="step back")
            v.VBtn(icon=("playing ? 'mdi-pause' : 'mdi-play'",), id="play", title="play / pause",
                   click="playing = !playing")
            v.VBtn(icon="mdi-step-forward", click=ctrl.forward, id="forward", title="step forward")
            v.VBtn(icon="mdi-skip-next", click=ctrl.end, id="end", title="end")
            v.VSlider(v_model=("stage", n), min=0, max=n, step=1, hide_details=True,
                      density="compact", style="max-width: 45%", id="stage-slider")
        with layout.content:
            with v.VContainer(fluid=True, classes="pa-0 fill-height", id="view"):
                # the viewer must belong to this server, so that its vtk widgets load here
                view = get_viewer(viewer.plotter, server=server).ui(mode="server", add_menu=False)
                ctrl.view_update = view.update
        with layout.footer:
            html.Div("{{ caption }}", id="caption", classes="text-body-1")
    return server, viewer
