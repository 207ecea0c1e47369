"""Every notebook runs top to bottom on the public API, keeps its figures and tells its numbers.

The notebooks are stored with their outputs (so the repository shows them); the test runs
each again from a clean kernel and checks, cell by cell, that every figure stored is drawn
again (a figure lost, e.g. to a library call that switched matplotlib's backend, fails), and
that the key numbers of its story hold.
"""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def _number(pattern: str, text: str) -> float:
    m = re.search(pattern, text)
    assert m, f"{pattern!r} not in the notebook's output:\n{text[-3000:]}"
    return float(m.group(1).replace(",", ""))


def _accuracy(text: str) -> None:
    # Table 1 of paper 004: bilinear = column B; the Bezier within 2x of column A on the sphere
    assert 3.6e-3 <= _number(r"sphere\s+bilinear\s+max \|dev\| (\S+)", text) <= 3.8e-3
    assert _number(r"sphere\s+bezier\s+max \|dev\| (\S+)", text) <= 3.0e-6
    assert _number(r"sine100\s+bezier-quartic\s+max \|dev\| (\S+)", text) <= 1e-7


def _surface_analysis(text: str) -> None:
    assert _number(r"(\d[\d,]*) steep grid edges of", text) > 1000  # along the pocket's walls
    assert _number(r"plain z-map (\S+) mm", text) > 10.0  # the 15 mm wall smeared over a grid interval
    assert _number(r"EZ model (\S+) mm", text) <= 0.01  # held within the tolerance
    assert _number(r"(\d+) faces answer grid points", text) >= 5


def _verify(text: str) -> None:
    assert _number(r"max gouge (\S+) mm", text) <= 0.005
    assert 1.0 <= _number(r"max excess / predicted flat-floor scallop = (\S+)", text) <= 2.0
    line = _number(r"dropped line (\d+):", text)
    assert _number(r"\| first_gouge_line \| (\d+) \|", text) == line
    assert 0.19 <= _number(r"\| max_gouge_mm \| (\S+) \|", text) <= 0.21


def _workpiece_3d(text: str) -> None:
    for allowance, err in re.findall(r"allowance\s+(\S+) mm:.*true max vertical error (\S+) mm", text):
        assert float(err) <= float(allowance) + 1e-4, (allowance, err)
    assert len(re.findall(r"allowance\s+\S+ mm:", text)) == 4
    assert _number(r"1/2 -> end: .*max error (\S+) mm", text) <= 0.0100


CHECKS = {"accuracy.ipynb": _accuracy, "surface_analysis.ipynb": _surface_analysis, "verify.ipynb": _verify,
          "workpiece_3d.ipynb": _workpiece_3d}


def _images(nb) -> list[int]:
    """Figures per code cell."""
    return [sum("image/png" in o.get("data", {}) for o in c.get("outputs", []))
            for c in nb.cells if c.cell_type == "code"]


def _text(nb) -> str:
    parts = []
    for c in nb.cells:
        for o in c.get("outputs", []) if c.cell_type == "code" else []:
            if o.output_type == "stream":
                parts.append(o.text)
            elif "text/markdown" in o.get("data", {}):
                parts.append(o.data["text/markdown"])
            elif "text/plain" in o.get("data", {}):
                parts.append(o.data["text/plain"])
    return "\n".join(parts)


# a notebook that runs the cam or access kernels goes to the worker of their tests, which
# leaves their numba cache on disk for it (tests/conftest.py)
_GROUP = {"verify.ipynb": "cam", "accessibility.ipynb": "access"}


@pytest.mark.slow
@pytest.mark.parametrize("path", [pytest.param(p, marks=[pytest.mark.xdist_group(_GROUP[p.name])] if p.name in _GROUP
                                               else []) for p in NOTEBOOKS], ids=[p.name for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path):
    stored = nbformat.read(path, as_version=4)
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors, errors[0].get("evalue")
    got, want = _images(nb), _images(stored)
    if any(want):  # stored with its outputs: every stored figure must be drawn again
        assert got == want, f"figures per code cell: got {got}, stored {want}"
    if path.name in CHECKS:
        assert sum(want) >= 2, f"{path.name} is stored without its figures"
        CHECKS[path.name](_text(nb))


def test_the_checks_read_the_stored_outputs():
    """The stored notebooks pass their own checks (fast: no kernel), and a lost figure is seen."""
    for path in NOTEBOOKS:
        if path.name in CHECKS:
            nb = nbformat.read(path, as_version=4)
            CHECKS[path.name](_text(nb))
            assert sum(_images(nb)) >= 2, path.name
    nb = nbformat.read(NOTEBOOKS[0], as_version=4)
    before = _images(nb)
    for c in nb.cells:
        if c.cell_type == "code":
            c.outputs = [o for o in c.get("outputs", []) if "image/png" not in o.get("data", {})]
    assert _images(nb) != before or not any(before)
