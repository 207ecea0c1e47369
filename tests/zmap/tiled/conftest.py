"""A real 2-worker LocalCluster (worker processes) shared by the tiled tests of one module."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def dask_client():
    from zmap.tiled.cluster import dask_client as make_client

    with make_client(workers=2) as client:
        yield client
