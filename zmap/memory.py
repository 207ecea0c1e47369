"""How much memory this process may still allocate: the one answer every size check asks.

The sampler's grid check (``cad_io.sample``), a tiled map's window read
(:meth:`zmap.tiled.store.TiledZMap.window`) and a program's position estimate
(:mod:`zmap.sim.path`) refuse work above 80 % of :func:`available_bytes`.
"""

from __future__ import annotations

import os

__all__ = ["available_bytes"]

#: the answer where the system says nothing (no /proc/meminfo, no sysconf)
UNKNOWN_BYTES = 8 * 1024**3


def available_bytes() -> int:
    """Bytes this process may still allocate: the system's available memory (MemAvailable,
    else free physical pages, else :data:`UNKNOWN_BYTES`), less where an address-space limit
    (RLIMIT_AS) leaves less room.

    Examples
    --------
    >>> available_bytes() > 0
    True
    """
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for row in fh:
                if row.startswith("MemAvailable:"):
                    avail = int(row.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail is None:
        try:
            avail = int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            avail = UNKNOWN_BYTES
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as fh:
                used = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            avail = min(avail, int(soft - used))
    except (ImportError, OSError, ValueError):
        pass
    return avail
