"""One container for every zmap file: an ``.npz`` with a versioned JSON header.

ZMaps (``.zmap.npz``), simulation runs (``.zsim``) and precision models share it: arrays by
name plus a ``header`` array holding JSON with ``format`` and ``version``. Writes are atomic.
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from .errors import ZMapFileError
from .grid import atomic_write

__all__ = ["write_npz", "read_npz"]


def write_npz(path: str | os.PathLike, header: dict, arrays: dict[str, np.ndarray], *, compress: bool = False) -> Path:
    """Write ``arrays`` and the JSON ``header`` to ``path`` atomically."""
    payload = dict(arrays)
    payload["header"] = np.array(json.dumps(header))
    save = np.savez_compressed if compress else np.savez

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            save(fh, **payload)

    return atomic_write(path, write)


def read_npz(path: str | os.PathLike, format_name: str, max_version: int,
             error: type[ZMapFileError] = ZMapFileError, *, what: str = "zmap") -> tuple[dict, dict[str, np.ndarray]]:
    """Read a file written by :func:`write_npz`, checking its format name and version.

    Raises ``error(path, problem)`` (a :class:`ZMapFileError`) for a missing, corrupt or
    foreign file, or one of a newer version.
    """
    path = Path(path)
    where = str(path)
    if not path.exists():
        raise error(where, "no such file")
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError) as exc:
        raise error(where, f"corrupt or not an .npz file ({type(exc).__name__}: {exc})") from None
    if "header" not in arrays:
        raise error(where, f"not a {what} file (arrays {sorted(arrays)}, no 'header')")
    try:
        header = json.loads(str(arrays.pop("header")[()]))
    except ValueError as exc:
        raise error(where, f"not a {what} file (unreadable header: {exc})") from None
    if not isinstance(header, dict) or header.get("format") != format_name:
        got = header.get("format") if isinstance(header, dict) else type(header).__name__
        raise error(where, f"format is {got!r}, expected {format_name!r}")
    version = header.get("version")
    if not isinstance(version, int) or not 1 <= version <= max_version:
        raise error(where, f"format version {version!r} is not supported (this zmap reads 1..{max_version})")
    return header, arrays
