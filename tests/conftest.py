"""Shared fixtures: where the real third-party sample data lives."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

#: ../shared/data beside the repository (CI clones main with shared/ beside it);
#: ZMAP_SHARED_DATA overrides it.
SHARED_DATA = Path(os.environ.get("ZMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder with ``step/`` and ``gcode/``; a missing folder fails the test loudly."""
    if not (SHARED_DATA / "gcode").is_dir():
        pytest.fail(f"sample data not found at {SHARED_DATA}; set ZMAP_SHARED_DATA")
    return SHARED_DATA
