"""Shared fixtures: where the bundled sample data lives (``data/`` in the repository)."""

from __future__ import annotations

from pathlib import Path

import pytest

#: The repository's ``data/`` folder: small made samples at its top, real third-party parts in
#: ``step/`` and programs in ``gcode/`` (origins and licences in ``data/SOURCES.md``).
DATA = Path(__file__).resolve().parents[1] / "data"
STEP_DATA = DATA / "step"
GCODE_DATA = DATA / "gcode"


@pytest.fixture(scope="session")
def sample_data() -> Path:
    """The repository's ``data/`` folder, with ``step/`` and ``gcode/`` beside the made samples."""
    return DATA


# Test families that compile the same large numba kernels go to one xdist worker
# (`pytest -n 2 --dist loadgroup`, as `make test` runs it): on a fresh clone the numba cache
# is cold, and two workers compiling the drop-cutter's kernels or the access kernels side by
# side each pay for it; one after the other, the second loads the cache. Each such test module
# says so itself (``pytestmark = pytest.mark.xdist_group("cam")`` or ``"access"``), the
# notebooks that use them in tests/test_notebooks.py. pytest 9.2 breaks the grouping (its
# node ids drop xdist's group suffix), hence pyproject's pin below it.
