"""The viewer app: a run's stock in 3D, rendered by pyvista on the server, in a trame page.

The page has the 3D view of the stock as a closed solid (its top coloured by height, or by
deviation from a design in tolerance bands, with a colour bar and legend in mm and axes in mm),
a stage slider, rewind / step back / play-pause / step forward / end buttons and a caption
with the stage, the G-code line that made it and its text (from the ``.zsim``, which keeps the
program, or from ``program``). Rendering is remote (the server renders with VTK off-screen and
sends pictures), so the page needs no WebGL.

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

__all__ = ["Viewer", "make_viewer", "stage_caption", "free_port", "deviation_bands"]

#: colours of the deviation bands, in tol steps from -3 tol to +3 tol, and beyond either end
BAND_COLOURS = ("#2166ac", "#67a9cf", "#4dac26", "#4dac26", "#f4a582", "#d6604d")
GOUGE_BEYOND, EXCESS_BEYOND = "#40004b", "#e7298a"  # below -3 tol: deep purple; above +3 tol: magenta
SIDES_COLOUR = "#b8b8b8"


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


def deviation_bands(tol: float) -> dict:
    """Colour map arguments of the deviation view: bands of ``tol`` from -3 tol to +3 tol.

    Green within +-tol, blues below (gouge), reds above (stock left), and two other colours
    beyond the range: deep purple below -3 tol, magenta above +3 tol.

    >>> b = deviation_bands(0.01)
    >>> b["clim"], b["n_colors"], b["below_color"], b["above_color"]
    ((-0.03, 0.03), 6, '#40004b', '#e7298a')
    """
    from matplotlib.colors import ListedColormap

    tol = float(tol)
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a positive number of mm, got {tol!r}")
    return {"cmap": ListedColormap(list(BAND_COLOURS)), "clim": (-3 * tol, 3 * tol), "n_colors": 6,
            "below_color": GOUGE_BEYOND, "above_color": EXCESS_BEYOND}


def _program_lines(run: Any, program: str | os.PathLike | None) -> list[str] | None:
    if program is not None:
        return Path(program).read_text(errors="replace").splitlines()
    text = getattr(run, "program_text", None)
    return text.splitlines() if text else None


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
        design height, mm) in bands of ``tol`` (:func:`deviation_bands`): green within
        +-tol, blues below the design (gouge), reds above (stock left), with their own
        colours beyond +-3 tol, and a legend.
    program : path, optional
        The G-code file, to show the text of each stage's line; by default the program kept
        in the run (``run.program_text``).
    tol : float
        Tolerance of the deviation colours, mm.
    allowance : float
        Vertical error allowed in the drawn mesh, mm (0: every ray's height exactly).
    region : int
        Region size of the local re-meshing, in rays.
    """

    def __init__(self, run: Any, *, design: Any = None, program: str | os.PathLike | None = None,
                 allowance: float = 0.01, region: int = 16, tol: float = 0.01):
        import pyvista as pv

        from ..mesh import LocalMesh

        _quiet_vtk()
        self.run = run
        self.design = design
        self.program_lines = _program_lines(run, program)
        self.tol = float(tol)
        self.local = LocalMesh(run, allowance=allowance, region=region)
        self.local.goto(run.n_stages)
        self.scalar_name = "deviation (mm)" if design is not None else "height (mm)"
        self.poly = self._polydata()
        _, near, _ = run.stock.to_csr()
        self.bottom = float(near.min()) if near.size else 0.0
        self.sides = self._sides()
        self.plotter = pv.Plotter(off_screen=True, window_size=(900, 650))
        self.plotter.set_background("white")
        bar = {"title": self.scalar_name, "vertical": True, "color": "black", "fmt": "%.3g",
               "position_x": 0.87, "position_y": 0.2, "height": 0.6, "width": 0.05}
        if design is not None:
            colours = deviation_bands(self.tol)
            bar.update(n_labels=7)
            self.plotter.add_mesh(self.poly, scalars=self.scalar_name, scalar_bar_args=bar, **colours)
            t = f"{self.tol:g}"
            self.plotter.add_legend([[f"within +-{t} mm", BAND_COLOURS[2]],
                                     ["gouge (below the design)", BAND_COLOURS[0]],
                                     ["stock left (above)", BAND_COLOURS[5]],
                                     [f"gouge beyond -{3 * self.tol:g} mm", GOUGE_BEYOND],
                                     [f"stock beyond +{3 * self.tol:g} mm", EXCESS_BEYOND]],
                                    bcolor="white", border=True, size=(0.24, 0.15), loc="lower right", face="rectangle")
        else:
            stock_top = np.nanmax(run.display(0)) if run.stock.cnt.any() else 0.0
            values = self.poly[self.scalar_name]
            lo = float(np.nanmin(values)) if values.size else stock_top - 1.0
            clim = (min(lo, self.bottom, stock_top - 1e-3), float(stock_top))
            self.plotter.add_mesh(self.poly, scalars=self.scalar_name, cmap="viridis", clim=clim,
                                  scalar_bar_args=bar)
        self.plotter.add_mesh(self.sides, color=SIDES_COLOUR, name="sides")
        from ..plot.scene import axes_in_mm

        b = self.poly.bounds
        axes_in_mm(self.plotter, (b[0], b[1], b[2], b[3], min(b[4], self.bottom), max(b[5], self.bottom)))
        self.plotter.add_text(self._title(), font_size=10, name="title", color="black")
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

    def _sides(self) -> Any:
        """The stock's sides and bottom under the top mesh: walls from every boundary edge of
        the top down to the stock's bottom, and the bottom face, so that the stock is drawn
        closed (a drilled hole is a hole in a solid, not a spike hanging below a sheet)."""
        import pyvista as pv

        pts = np.asarray(self.poly.points, dtype=np.float64)
        tri = np.asarray(self.poly.faces).reshape(-1, 4)[:, 1:]
        e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        uniq, counts = np.unique(e, axis=0, return_counts=True)
        border = uniq[counts == 1]
        n = len(pts)
        low = pts.copy()
        low[:, 2] = self.bottom
        quads = np.column_stack([np.full(len(border), 4), border[:, 0], border[:, 1],
                                 border[:, 1] + n, border[:, 0] + n])
        # the bottom: the walls' lower vertices triangulated in xy (they share its edges)
        ids = np.unique(border) if len(border) else np.zeros(0, dtype=np.int64)
        bottom = []
        if len(ids) >= 3:
            tri_b = pv.PolyData(low[ids]).delaunay_2d()
            tb = np.asarray(tri_b.faces).reshape(-1, 4)
            bottom = np.column_stack([tb[:, 0], ids[tb[:, 1:]] + n]).ravel()
        faces = np.concatenate([quads.ravel(), np.asarray(bottom, dtype=np.int64)])
        return pv.PolyData(np.vstack([pts, low]), faces=faces.astype(np.int64))

    def show_stage(self, stage: int) -> str:
        """Move the scene to ``stage`` (re-meshing the touched regions); return its caption."""
        k = self.run.stage(int(stage))
        info = self.local.goto(k)
        self.poly.copy_from(self._polydata(), deep=True)
        self.sides.copy_from(self._sides(), deep=True)
        return (stage_caption(self.run, k, self.program_lines)
                + f" ({info['regions_touched']} regions re-meshed, {info['triangles']} triangles, "
                  f"{info['ms']:.1f} ms)")


def make_viewer(run: Any, *, design: Any = None, program: str | os.PathLike | None = None,
                allowance: float = 0.01, tol: float = 0.01, name: str = "zmap-view") -> tuple[Any, Viewer]:
    """Build the trame server of a viewer page (not started). Returns ``(server, viewer)``.

    Start it with ``server.start(host="127.0.0.1", port=..., open_browser=False)``.
    """
    from trame_pyvista.ui import get_viewer
    from trame.app import get_server
    from trame.ui.vuetify3 import SinglePageLayout
    from trame.widgets import html
    from trame.widgets import vuetify3 as v

    viewer = Viewer(run, design=design, program=program, allowance=allowance, tol=tol)
    n = run.n_stages
    server = get_server(name, client_type="vue3")
    state, ctrl = server.state, server.controller
    state.stage = n
    state.n_stages = n
    state.playing = False
    state.caption = viewer.show_stage(n)
    state.trame__title = "zmap view"

    @ctrl.add("on_server_bind")
    def _bind(wslink_server: Any) -> None:
        # the page first asks a ParaView-style launcher for its session (POST /paraview/);
        # answer it with this server's own websocket instead of a 405
        from aiohttp import web

        async def _session(request: Any) -> Any:
            scheme = "wss" if request.secure else "ws"
            return web.json_response({"sessionURL": f"{scheme}://{request.host}/ws"})

        wslink_server.app.router.add_route("POST", "/paraview/", _session)

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
            with v.VContainer(fluid=True, classes="pa-0 fill-height d-flex flex-column align-stretch"):
                # the caption on its own line above the picture, the full width of the page
                html.Div("{{ caption }}", id="caption", classes="text-body-1 px-4 py-2",
                         style="flex: 0 0 auto; width: 100%; border-bottom: 1px solid #ddd;")
                with html.Div(id="view", style="flex: 1 1 auto; width: 100%; position: relative;"):
                    # the viewer must belong to this server, so that its vtk widgets load here
                    view = get_viewer(viewer.plotter, server=server).ui(mode="server", add_menu=False)
                    ctrl.view_update = view.update
        layout.footer.hide()
    return server, viewer
