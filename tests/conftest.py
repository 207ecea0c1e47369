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
