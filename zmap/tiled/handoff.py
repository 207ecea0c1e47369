"""Arrays handed between the client and workers on the same machine through files.

A tiled simulation's results are large (flower_mold.nc at 0.05 mm: 219 MB of Interval Treap
histories): sent back through Dask they are pickled by the workers, copied through loopback
TCP and unpickled by the client, about 1.6 CPU-s on a 2-core machine that the workers need
for cutting. When every worker sees the client's files (a LocalCluster, or workers on this
host), a task writes its arrays as ``.npy`` files into a shared folder and returns only their
names; the client maps them (copy-on-write ``mmap``) and reads nothing before it is used.
Elsewhere :meth:`Handoff.open` answers None and the arrays travel through Dask as before.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import uuid
from typing import Any

import numpy as np

__all__ = ["Handoff", "load_arrays", "save_arrays"]

#: name of the file whose content proves a worker sees the folder the client made
_TOKEN = "zmap-handoff-token"
#: arrays smaller than this (bytes) travel inside the returned reference instead of a file
_INLINE_BYTES = 65_536


def _sees(path: str, token: str) -> bool:
    try:
        with open(os.path.join(path, _TOKEN)) as fh:
            return fh.read() == token
    except OSError:
        return False


class Handoff:
    """A fresh folder that the client and every worker of a Dask client see.

    Use :meth:`open`; :meth:`close` removes the folder (arrays already mapped stay readable
    on Linux, where an unlinked file lives as long as its mappings).
    """

    def __init__(self, path: str):
        self.path = path

    @classmethod
    def open(cls, client: Any) -> "Handoff | None":
        """A handoff folder if every worker of ``client`` sees this process's files, else None."""
        path = tempfile.mkdtemp(prefix="zmap-handoff-")
        token = uuid.uuid4().hex
        with open(os.path.join(path, _TOKEN), "w") as fh:
            fh.write(token)
        try:
            seen = client.run(_sees, path, token)
        except Exception:  # noqa: BLE001 (a worker that cannot answer: go through Dask)
            seen = {}
        if seen and all(seen.values()):
            return cls(path)
        shutil.rmtree(path, ignore_errors=True)
        return None

    def close(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)

    def __enter__(self) -> "Handoff":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def save_arrays(folder: str, name: str, arrays: dict[str, np.ndarray]) -> dict:
    """Write ``arrays`` into ``folder`` as ``NAME.KEY.npy`` and return their reference.

    Each file is written under a temporary name and renamed into place, so a task rerun
    after its worker died never leaves a half-written file under the final name. Small
    arrays are kept in the reference itself.
    """
    ref: dict = {"folder": folder, "files": {}, "inline": {}}
    for key, arr in arrays.items():
        arr = np.asarray(arr)
        if arr.nbytes < _INLINE_BYTES or arr.size == 0:
            ref["inline"][key] = arr.copy()
            continue
        final = os.path.join(folder, f"{name}.{key}.npy")
        tmp = f"{final}.{uuid.uuid4().hex}.tmp"
        with open(tmp, "wb") as fh:
            np.lib.format.write_array(fh, np.ascontiguousarray(arr), allow_pickle=False)
        os.replace(tmp, final)
        ref["files"][key] = final
    return ref


def load_arrays(ref: dict, *, writeable: bool = True) -> dict[str, np.ndarray]:
    """The arrays of :func:`save_arrays`' reference ``ref``, mapped from their files.

    ``writeable``: copy-on-write mappings (the numba kernels that read histories take them
    as ordinary arrays); else read-only ones.
    """
    out = {k: v for k, v in ref["inline"].items()}
    for key, path in ref["files"].items():
        out[key] = np.asarray(np.load(path, mmap_mode="c" if writeable else "r", allow_pickle=False))
    return out
