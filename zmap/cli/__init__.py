"""The ``zmap`` command line: one module per command group, on top of the library.

Each command module parses its options, calls the library and prints; none holds library
code. :mod:`zmap.cli.app` gathers them into the ``zmap`` group with the commands other
packages declare under the ``zmap.commands`` entry point (cad_io's convert, refine, report
and access), and runs it with one-line errors (:func:`main`).

======================  ==========================
module                  commands
======================  ==========================
:mod:`zmap.cli.maps`    ``accuracy``, ``info``
:mod:`zmap.cli.sim`     ``simulate``, ``replay``
:mod:`zmap.cli.view`    ``view``
:mod:`zmap.cli.verify`  ``compare``
:mod:`zmap.cli.cam`     ``toolpath``
======================  ==========================
"""

from __future__ import annotations

from .app import add_plugin_commands, cli, main

__all__ = ["main", "cli", "add_plugin_commands"]
