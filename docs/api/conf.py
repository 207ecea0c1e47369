"""Sphinx configuration of the API reference (``make docs``; warnings are errors).

The pages are built from the numpy-style docstrings by autodoc, autosummary and napoleon.
Each object is documented once, in the public module whose ``__all__`` lists it; the
package pages list what each package exports in a summary table that links there, and a
reference by the package path (``zmap.ZMap``, ``cad_io.sample``) resolves to it too
(:func:`_resolve_alias`). The notebooks are not executed: ``gallery.rst`` links them.
"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import pkgutil
import re
import sys
from pathlib import Path

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.ext.autodoc import ModuleDocumenter, Options
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")  # some modules import matplotlib; no window here

import zmap  # noqa: E402  (light: submodules load on first use)

project = "zmap"
author = "the zmap authors"
copyright = "the zmap authors"  # noqa: A001  (Sphinx's name)
release = version = zmap.__version__

extensions = ["sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.napoleon"]

exclude_patterns = ["_build"]
nitpicky = False
html_theme = "alabaster"
html_title = f"zmap {release} API reference"
html_static_path: list[str] = []

# --- autodoc: what __all__ lists, in its order, signatures with their annotations
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True  # `tol=DEFAULT_TOL`, not the value it had at import
autodoc_class_signature = "mixed"
autodoc_inherit_docstrings = False  # a subclass without a docstring does not repeat its base's

# --- autosummary: tables only (the package pages); no generated stub pages
autosummary_generate = False

# --- napoleon: numpy style only
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_preprocess_types = False
# "Attributes" as a field list like "Parameters" (not one attribute directive each, which
# would describe again what autodoc documents of the class); the histories' "Attributes
# (finalised)" likewise
napoleon_custom_sections = [("Attributes", "params_style"), ("Attributes (finalised)", "params_style")]

#: public modules that have no place in the reference: the halves of zmap.access.voxelmap,
#: which re-exports their public names
UNDOCUMENTED = {"zmap.access.build", "zmap.access.casting", "zmap.access.result", "zmap.access.tool"}
#: packages of which only what ``__init__`` exports is documented (refine.rst)
EXPORTS_ONLY = ("zmap.refine",)

logger = logging.getLogger(__name__)


def _public_modules() -> set[str]:
    """Every module of zmap and cad_io without an underscore in its dotted name."""
    found = set()
    for name in ("zmap", "cad_io"):
        package = importlib.import_module(name)
        found.add(name)
        for info in pkgutil.walk_packages(package.__path__, f"{name}."):
            if not any(part.startswith("_") for part in info.name.split(".")):
                found.add(info.name)
    return found


def _check_every_module(app, env) -> None:
    """Warn (an error under -W) about a public module that no page documents."""
    documented = set(env.domains["py"].modules)
    for name in sorted(_public_modules() - documented - UNDOCUMENTED):
        if name.startswith(tuple(f"{package}." for package in EXPORTS_ONLY)):
            continue
        logger.warning("public module %s is on no page of the API reference (docs/api/*.rst); "
                       "add it to a page or to UNDOCUMENTED in docs/api/conf.py", name)


def _lookup(path: str):
    """The object at a dotted path (``zmap.cam.drop_cutter``), or None."""
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        return obj
    return None


#: id of each documented object -> the names it is documented under (filled on first use)
_HOMES: dict[int, list[str]] = {}


def _resolve_alias(app, env, node, contnode):
    """A Python reference by another public path of a documented object: link it there.

    ``:class:`zmap.ZMap``` finds ``zmap.grid.ZMap``, ``:func:`cad_io.sample``` finds
    ``cad_io.sampler.sample``: the same object, reached through the package's exports.
    """
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    if "." not in target or not target.startswith(("zmap.", "cad_io.")):
        return None
    obj = _lookup(target)
    if obj is None or isinstance(obj, (str, int, float, tuple, frozenset, bool)):
        return None  # plain values are shared by many names: no unique home
    domain = env.domains["py"]
    if not _HOMES:  # this process's objects, by id: never kept in the pickled environment
        for name, entry in domain.objects.items():
            if entry.aliased or entry.objtype not in ("class", "function", "exception", "method",
                                                     "attribute", "property", "module", "data"):
                continue
            found = _lookup(name)
            if found is not None and not isinstance(found, (str, int, float, tuple, frozenset, bool)):
                _HOMES.setdefault(id(found), []).append(name)
    names = _HOMES.get(id(obj), [])
    if len(names) != 1:
        return None
    return domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], names[0], node, contnode)


class AllNamesModuleDocumenter(ModuleDocumenter):
    """``automodule`` that documents every name of the module's ``__all__``, a constant or a
    click command without a docstring too; a class's undocumented members stay out (a
    dataclass's fields are described by its "Attributes" section)."""

    def filter_members(self, members, want_all):
        own = self.options
        self.options = Options({**own, "undoc-members": True})
        try:
            kept = super().filter_members(members, want_all)
        finally:
            self.options = own
        # a value without a ``#:`` comment is data all the same (autodoc drops it otherwise)
        return [(name, member, isattr or not (inspect.isclass(member) or inspect.isroutine(member)
                                              or inspect.ismodule(member)))
                for name, member, isattr in kept]


def _value_docstrings(app, what, name, obj, options, lines) -> None:
    """A module's value says what it is, never its type's docstring (``str``'s, click's
    ``Command``'s): a click command names the ``zmap`` command, another value says nothing."""
    import click

    if isinstance(obj, click.Command):
        lines[:] = [f"The ``zmap {obj.name}`` command (a :class:`click.Command`); "
                    f"``zmap {obj.name} --help`` lists its options.", ""]
    elif what == "data" and _same_text(lines, inspect.getdoc(type(obj))):
        lines[:] = []


def _same_text(lines: list[str], doc: str | None) -> bool:
    return doc is not None and " ".join("\n".join(lines).split()) == " ".join(doc.split())


class NotebookGallery(SphinxDirective):
    """``.. notebook-gallery::``: each stored notebook of ``notebooks/`` with its title, its
    opening paragraph and a download link; nothing is executed."""

    def run(self) -> list[nodes.Node]:
        folder = ROOT / "notebooks"
        here = Path(self.env.doc2path(self.env.docname)).parent
        rst: list[str] = []
        for path in sorted(folder.glob("*.ipynb")):
            self.env.note_dependency(str(path))
            heading, paragraph = _notebook_intro(path)
            rel = os.path.relpath(path, here).replace(os.sep, "/")
            rst += [heading, "-" * len(heading), ""]
            if paragraph:
                rst += [paragraph, ""]
            rst += [f":download:`{path.name} <{rel}>` (stored with its outputs; open it in Jupyter)", ""]
        node = nodes.section()
        node.document = self.state.document
        self.state.nested_parse(StringList(rst, source=str(folder)), self.content_offset, node,
                                match_titles=True)
        return node.children


def _notebook_intro(path: Path) -> tuple[str, str]:
    """A notebook's title (its first markdown cell's heading) and that cell's first paragraph,
    with markdown's inline code made reST's."""
    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    text = next(("".join(c["source"]) for c in cells if c["cell_type"] == "markdown"), "")
    lines = text.strip().splitlines()
    heading = path.stem
    if lines and lines[0].startswith("#"):
        heading, lines = lines[0].lstrip("#").strip(), lines[1:]
    first: list[str] = []
    for line in lines:
        if line.strip():
            first.append(line.strip())
        elif first:
            break
    pieces = " ".join(first).split("`")
    return heading, "".join(f"``{p}``" if i % 2 and p else p for i, p in enumerate(pieces))


def setup(app):
    app.add_autodocumenter(AllNamesModuleDocumenter, override=True)
    app.connect("missing-reference", _resolve_alias)
    app.connect("env-updated", lambda app, env: _HOMES.clear())
    app.connect("autodoc-process-docstring", _value_docstrings)
    app.connect("env-check-consistency", _check_every_module)
    app.add_directive("notebook-gallery", NotebookGallery)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
