"""What the access modules share below them all: their exception and a list of ids in short."""

from __future__ import annotations

from ..errors import ZMapError

__all__ = ["AccessModelError"]


class AccessModelError(ZMapError, ValueError):
    """A part whose voxel model fails the paper's checks (open shell, pieces, faces with two
    outward sides) or an access request that cannot be answered (bad d, d', q or tool)."""


def _ranges(ids) -> str:
    ids = sorted(int(i) for i in ids)
    out = []
    start = prev = ids[0]
    for i in ids[1:] + [None]:
        if i is not None and i == prev + 1:
            prev = i
            continue
        out.append(str(start) if start == prev else f"{start}-{prev}")
        if i is not None:
            start = prev = i
    return ",".join(out[:8]) + (",..." if len(out) > 8 else "")
