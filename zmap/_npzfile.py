"""One container for every zmap file: an ``.npz`` with a versioned JSON header.

ZMaps (``.zmap.npz``), simulation runs (``.zsim``) and precision models share it: arrays by
name plus a ``header`` array holding JSON with ``format`` and ``version``. Writes are atomic
(:func:`atomic_write`, which the PNG, GIF and text writers use too; it is re-exported as
``zmap.grid.atomic_write``). This module imports nothing else of zmap but its errors.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import ZMapFileError

__all__ = ["atomic_write", "atomic_write_text", "write_npz", "read_npz"]


def atomic_write(path: str | os.PathLike, write: Callable[[str], None], suffix: str = "") -> Path:
    """Write a file through a temporary name in the same folder, then rename it.

    Parameters
    ----------
    path : str or PathLike
        Final file name.
    write : callable
        ``write(tmp_path)`` writes the whole file to ``tmp_path``.
    suffix : str
        Suffix of the temporary name (some writers, like ``np.savez``, append one).

    Returns
    -------
    Path
        The final path. An exception inside ``write`` leaves no file behind.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + suffix, dir=folder)
    os.close(fd)
    try:
        write(tmp)
        # mkstemp creates 0600; give the file the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        # Clean up on any interruption (KeyboardInterrupt too), then re-raise it unchanged.
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8, line ends as given) to ``path`` through :func:`atomic_write`."""
    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)

    return atomic_write(path, write, suffix=Path(path).suffix or ".txt")


def write_npz(path: str | os.PathLike, header: dict, arrays: dict[str, np.ndarray], *, compress: bool = False) -> Path:
    """Write ``arrays`` and the JSON ``header`` to ``path`` atomically."""
    payload = dict(arrays)
    payload["header"] = np.array(json.dumps(header))
    save = np.savez_compressed if compress else np.savez

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            save(fh, **payload)

    return atomic_write(path, write)


#: what each zmap format holds, to name a zmap file given where another kind is expected
_FORMATS = {
    "zmap.ZMap": "a z-map (.zmap.npz; zmap info describes it)",
    "zmap.sim.Run": "a simulation run (.zsim; zmap replay reads it)",
    "zmap.PrecisionModel": "a precision model (.zpm)",
}
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # as numpy's np.load tells an .npz archive


def _sniff(head: bytes, size: int) -> tuple[str, bool]:
    """What a file that is not an .npz archive holds, from its first bytes, and whether
    that was recognised (else it may also be a corrupt archive)."""
    if size == 0:
        return "an empty file", False
    if head.startswith(b"\x93NUMPY"):
        return "a single .npy array, not an .npz archive", True
    if head.lstrip(b"\xef\xbb\xbf \t\r\n").upper().startswith(b"ISO-10303-21"):
        return "a STEP file", True
    if b"\x00" in head:
        return f"a binary file of {size} bytes, not an .npz archive", False
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff").strip()
    first = text.splitlines()[0] if text else ""
    return f"a text file starting {first[:40]!r}", False


def read_npz(path: str | os.PathLike, format_name: str, max_version: int,
             error: type[ZMapFileError] = ZMapFileError, *, what: str = "zmap") -> tuple[dict, dict[str, np.ndarray]]:
    """Read a file written by :func:`write_npz`, checking its format name and version.

    Raises ``error(path, problem)`` (a :class:`ZMapFileError`) for a missing, unreadable,
    corrupt or foreign file, or one of a newer version. A foreign file is named where it is
    cheap to tell: a STEP file, a text file, or a zmap file of another kind (a ``.zsim``
    where a z-map is expected). The header is checked before the arrays are read.
    """
    path = Path(path)
    where = str(path)
    if not path.exists():
        raise error(where, "no such file")
    if path.is_dir():
        raise error(where, "is a folder, not a file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(512)
        size = path.stat().st_size
    except OSError as exc:
        raise error(where, f"cannot be read ({exc.strerror or exc})") from None
    if not head.startswith(_ZIP_MAGIC):
        desc, known = _sniff(head, size)
        raise error(where, f"not a {what} file ({desc})" if known else f"not a {what} file, or a corrupt one ({desc})")
    try:
        with np.load(path, allow_pickle=False) as npz:
            names = list(npz.files)
            if "header" not in names:
                raise error(where, f"not a {what} file (arrays {sorted(names)}, no 'header')")
            try:
                header = json.loads(str(npz["header"][()]))
            except ValueError as exc:
                raise error(where, f"not a {what} file (unreadable header: {exc})") from None
            if not isinstance(header, dict) or header.get("format") != format_name:
                got = header.get("format") if isinstance(header, dict) else type(header).__name__
                kind = _FORMATS.get(got) if isinstance(got, str) else None
                raise error(where, (f"not a {what} file: it holds {kind}; " if kind else "")
                            + f"format is {got!r}, expected {format_name!r}")
            version = header.get("version")
            if not isinstance(version, int) or not 1 <= version <= max_version:
                raise error(where, f"format version {version!r} is not supported (this zmap reads 1..{max_version})")
            arrays = {}
            for k in names:
                if k == "header":
                    continue
                try:
                    arrays[k] = npz[k]
                except ValueError as exc:
                    problem = "it holds Python objects" if "pickle" in str(exc) else f"ValueError: {exc}"
                    raise error(where, f"corrupt: array {k!r} cannot be read ({problem})") from None
    except ZMapFileError:
        raise
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError) as exc:
        raise error(where, f"corrupt .npz archive ({type(exc).__name__}: {exc})") from None
    return header, arrays
