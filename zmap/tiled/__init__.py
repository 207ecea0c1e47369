"""Tiled z-maps in zarr stores, read lazily as dask arrays.

``zmap.tiled.TiledZMap`` keeps the :class:`zmap.ZMap` grid contract on a chunked zarr
store; :func:`bezier` and :func:`bilinear` query it tile by tile with the in-memory answers.
Tiled conversion of STEP parts is :mod:`cad_io.tiled`; tiled simulation
:mod:`zmap.sim.tiled`. zarr and dask load only when a store is opened or queried.
"""

from __future__ import annotations

from .store import (FORMAT_NAME, FORMAT_VERSION, HALO, TiledZMap, bezier, bilinear, is_tiled_store,
                    remove_store, tile_grid)

__all__ = ["TiledZMap", "FORMAT_NAME", "FORMAT_VERSION", "HALO", "bezier", "bilinear", "is_tiled_store",
           "remove_store", "tile_grid"]
