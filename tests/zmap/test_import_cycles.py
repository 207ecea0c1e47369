"""No import cycles: none at all, and the layers that once had one (file container, EZ-map,
G-code reader and cutter compensation).

The graph holds every import statement of the ``zmap`` and ``cad_io`` modules, those inside
functions too (a lazy import is still a cycle: each module needs the other loaded to work).
Package ``__init__`` files are left out: they only re-export lazily.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in ("zmap", "cad_io"):
        for f in (ROOT / pkg).rglob("*.py"):
            parts = f.relative_to(ROOT).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return mods


def import_graph() -> dict[str, set[str]]:
    mods = _modules()
    packages = {name for name, f in mods.items() if f.name == "__init__.py"}
    graph: dict[str, set[str]] = {}
    for name, f in mods.items():
        if name in packages:
            continue
        here = name.split(".")[:-1]
        out = set()
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = here[:len(here) - node.level + 1] if node.level else []
                mod = ".".join(base + (node.module.split(".") if node.module else []))
                targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
            else:
                continue
            out |= {t for t in targets if t in mods and t not in packages and t != name}
        graph[name] = out
    return graph


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for m in graph.get(todo.pop(), ()):
            if m not in seen:
                seen.add(m)
                todo.append(m)
    return seen


@pytest.mark.slow
def test_graph_sees_imports_inside_functions():
    g = import_graph()
    assert "zmap.refine._ez_kernels" in g["zmap.refine.ez"]      # from . import _ez_kernels as _k (in a function)
    assert "zmap.interpolate" in g["zmap.refine._emap"]           # from ..interpolate import bezier (in a method)


@pytest.mark.parametrize("module", ["zmap._npzfile", "zmap.grid", "zmap.refine.ez", "zmap.refine.patch",
                                    "zmap.refine._emap"])
@pytest.mark.slow
def test_no_cycle_through(module):
    g = import_graph()
    back = sorted(m for m in reachable(g, module) if module in reachable(g, m) or m == module)
    assert not back, f"{module} is on an import cycle with {back}"


@pytest.mark.slow
def test_no_cycle_anywhere():
    g = import_graph()
    assert sorted(m for m in g if m in reachable(g, m)) == []


@pytest.mark.slow
def test_layers():
    g = import_graph()
    assert g["zmap._npzfile"] <= {"zmap.errors"}
    assert "zmap.refine.ez" not in reachable(g, "zmap.refine.patch")
    assert not {"zmap.refine.ez", "zmap.refine.patch"} & reachable(g, "zmap.refine._emap")
    assert "zmap.sim.gcode" not in reachable(g, "zmap.sim.cutter_comp")  # arcs live in _arcs


def test_public_names_stay_where_they_were():
    from zmap import _npzfile, grid
    from zmap.refine import _emap, ez, patch

    assert grid.atomic_write is _npzfile.atomic_write
    for name in ("EZMap", "NAN_CODE", "edge_count", "encode_heights", "BREAK_RATIO", "SERIAL_BELOW",
                 "FORMAT_VERSION"):
        assert getattr(ez, name) is getattr(_emap, name)
    for name in ("CellPatches", "sub_grid", "all_edges"):
        assert getattr(patch, name) is getattr(_emap, name)


def test_zmap_never_imports_cad_io():
    # zmap is the core; cad_io (OCP) is the layer above: it registers its Part and .step files
    # with zmap.design and its commands with zmap.cli through entry points
    graph = import_graph()
    up = sorted((m, t) for m, ts in graph.items() if m.startswith("zmap") for t in ts if t.startswith("cad_io"))
    assert up == []


def test_cad_io_commands_plug_into_zmap_and_a_broken_plugin_leaves_the_rest(monkeypatch, capsys):
    import click

    import zmap.cli as cli

    assert {"convert", "refine", "report", "access"} <= set(cli.cli.commands)

    class Broken:
        value = "broken_pkg.commands:COMMANDS"

        def load(self):
            raise ImportError("no module named 'broken_pkg'")

    import importlib.metadata as md

    monkeypatch.setattr(md, "entry_points", lambda group: [Broken()])
    group = click.Group()
    assert cli.add_plugin_commands(group) == [] and not group.commands
    assert "the commands of broken_pkg.commands:COMMANDS did not load (ImportError" in capsys.readouterr().err


def test_pictures_are_drawn_only_where_they_are_shown():
    # plotting lives in zmap.plot; the computing packages never import it (only the commands,
    # the demos, the viewer and the verify report, which draw what they show)
    graph = import_graph()
    drawers = {m for m, ts in graph.items() if not m.startswith("zmap.plot") for t in ts if t.startswith("zmap.plot.")}
    allowed = {m for m in drawers if m.startswith("zmap.cli.") or m.endswith(("commands", ".demo"))
               or m in {"zmap.demo", "zmap.view.app", "zmap.verify.report"}}
    assert drawers and drawers == allowed, sorted(drawers - allowed)
