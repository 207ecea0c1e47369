"""Tests reach the library by its public names, except the internals they check on purpose.

A test may import from a private module (``zmap.refine._ecodec``) or an underscore name only
for what has no public place: numba kernels and the helpers that build their inputs, file
layouts written by hand, monkeypatch targets. Where a public module exports the same object
under the same name (its ``__all__``), the test must import it from there, so that the
library can move its internals without touching the tests.
"""

from __future__ import annotations

import ast
import importlib
import pkgutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("zmap", "cad_io")


def _is_private(dotted: str) -> bool:
    return any(part.startswith("_") for part in dotted.split("."))


def public_exports() -> dict[tuple[str, int], str]:
    """``(name, id(object)) -> "public.module"`` for every name in a public module's ``__all__``."""
    found: dict[tuple[str, int], str] = {}
    for package_name in PACKAGES:
        package = importlib.import_module(package_name)
        names = [package_name] + [info.name for info in pkgutil.walk_packages(package.__path__, f"{package_name}.")]
        for module_name in names:
            if _is_private(module_name):
                continue
            module = importlib.import_module(module_name)
            for name in getattr(module, "__all__", ()):
                obj = getattr(module, name, None)
                if obj is not None:
                    found.setdefault((name, id(obj)), module_name)
    return found


def private_imports() -> list[tuple[str, int, str, str]]:
    """``(test file, line, module, name)`` of each ``from zmap/cad_io... import`` of a private
    module or an underscore name in the tests (the reference oracles are the tests' own)."""
    out = []
    for path in sorted((ROOT / "tests").rglob("*.py")):
        if "reference" in path.relative_to(ROOT / "tests").parts:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not (isinstance(node, ast.ImportFrom) and node.module and node.level == 0
                    and node.module.split(".")[0] in PACKAGES):
                continue
            for alias in node.names:
                if _is_private(node.module) or alias.name.startswith("_"):
                    out.append((str(path.relative_to(ROOT)), node.lineno, node.module, alias.name))
    return out


def test_no_test_imports_privately_what_a_public_module_exports():
    exports = public_exports()
    assert len(exports) > 300  # the walk found the library, not an empty package
    found = private_imports()
    assert found, "the scan finds the kernel tests' private imports"
    misplaced = []
    for path, line, module, name in found:
        obj = getattr(importlib.import_module(module), name, None)
        if obj is None:  # a submodule imported by name
            continue
        public = exports.get((name, id(obj)))
        if public is not None:
            misplaced.append(f"{path}:{line}: from {module} import {name}  ->  from {public} import {name}")
    assert not misplaced, "import these from their public module:\n" + "\n".join(misplaced)
