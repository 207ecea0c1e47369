"""How much memory this process may still allocate, and the one rule every size check follows.

Work that would need more than :data:`MEMORY_SHARE` of :func:`available_bytes` is refused
before it allocates: the sampler's grid (``cad_io.sample``), a tiled map's window read
(:meth:`zmap.tiled.store.TiledZMap.window`) through :func:`check_room`, and a program's
position estimate (:mod:`zmap.sim.path`), which names the G-code line where the sum crosses
:func:`memory_limit`.
"""

from __future__ import annotations

import os

from .errors import GridTooLargeError
from .fmt import size

__all__ = ["MEMORY_SHARE", "available_bytes", "memory_limit", "check_room"]

#: the share of the available memory one piece of work may take (the rest: the interpreter,
#: the arrays already held, the operating system's caches)
MEMORY_SHARE = 0.8

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


def memory_limit() -> tuple[float, int]:
    """``(limit, available)``: the bytes one piece of work may take (:data:`MEMORY_SHARE` of
    :func:`available_bytes`) and the bytes available.

    Examples
    --------
    >>> limit, avail = memory_limit()
    >>> limit == MEMORY_SHARE * avail
    True
    """
    avail = available_bytes()
    return MEMORY_SHARE * avail, avail


def check_room(need: float, what: str, advice: str, *, error: type[Exception] = GridTooLargeError) -> float:
    """``need`` (bytes) back when it fits in :func:`memory_limit`, else ``error`` saying so.

    Parameters
    ----------
    need : float
        Bytes the work would allocate.
    what : str
        The work, as the message's subject (``"grid of 100 x 100 = 10,000 points"``).
    advice : str
        What the caller can do instead (``"use a coarser grid"``).
    error : type
        The exception to raise (one argument, the message).

    Examples
    --------
    >>> check_room(1024, "a small array", "")
    1024
    >>> check_room(1e30, "grid of 1e+15 x 1e+15 = 1e+30 points", "use a coarser grid")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    zmap.errors.GridTooLargeError: grid of 1e+15 x 1e+15 = 1e+30 points needs about ...
    """
    limit, avail = memory_limit()
    if need > limit:
        raise error(f"{what} needs about {size(need)}, more than {MEMORY_SHARE:.0%} of the {size(avail)} of "
                    f"memory available; {advice}")
    return need
