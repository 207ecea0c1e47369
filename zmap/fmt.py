"""Numbers for people: sizes in B/KB/MB/GB/TB, counts with thousands separators.

Every size or count that zmap prints (the command line, error messages, ``repr``) goes
through these, so that 292 KB reads ``292 KB``, not ``0.0 MB``, and a damaged file's
absurd grid reads ``3e+104 points``, not a hundred digits.

>>> from zmap.fmt import count, size
>>> size(299_008), size(2_233_382_400_000_000), size(512)
('292 KB', '2,031 TB', '512 B')
>>> count(32_361), count(1_930_000_000), count(10**104)
('32,361', '1.93e+09', '1e+104')
"""

from __future__ import annotations

import math

__all__ = ["count", "size"]

_UNITS = ("B", "KB", "MB", "GB", "TB")
_BIG = 1e9  # counts from here on are printed in scientific notation


def _number(value: float) -> str:
    """A float at 3 significant figures, thousands separators from 1,000 on."""
    if value >= 1000:
        return f"{round(value):,}"
    if value >= 100:
        return f"{value:.0f}"
    if value >= 10:
        return f"{value:.1f}".rstrip("0").rstrip(".")
    return f"{value:.2f}".rstrip("0").rstrip(".")


def count(n: float) -> str:
    """A count (points, tiles, moves) for people.

    Parameters
    ----------
    n : int or float
        The count; a float is rounded to the nearest integer below 1e9.

    Returns
    -------
    str
        ``'32,361'`` below 1e9 (thousands separators), ``'1.93e+09'`` from 1e9 on (three
        significant figures), ``'inf'`` or ``'nan'`` as Python writes them.

    Examples
    --------
    >>> count(7), count(1_234_567), count(2.5e10), count(-4_000)
    ('7', '1,234,567', '2.5e+10', '-4,000')
    """
    x = float(n)
    if not math.isfinite(x):
        return str(x)
    if abs(x) >= _BIG:
        return f"{x:.3g}"
    return f"{round(x):,}"


def size(nbytes: float) -> str:
    """A size in bytes for people, in the unit that keeps it between 1 and 1,024.

    Parameters
    ----------
    nbytes : int or float
        Bytes (1 KB = 1,024 B).

    Returns
    -------
    str
        Three significant figures and a unit among B, KB, MB, GB, TB: ``'292 KB'``,
        ``'1.5 GB'``; beyond 1e9 TB, ``'2.1e+12 TB'``.

    Examples
    --------
    >>> size(0), size(1536), size(3.5 * 1024**3), size(10**40)
    ('0 B', '1.5 KB', '3.5 GB', '9.09e+27 TB')
    """
    x = float(nbytes)
    if not math.isfinite(x):
        return f"{x} B"
    sign, x = ("-", -x) if x < 0 else ("", x)
    if x < 1024:
        return f"{sign}{round(x)} B"
    unit = 0
    while x >= 1024 and unit < len(_UNITS) - 1:
        x /= 1024
        unit += 1
    if x >= _BIG:
        return f"{sign}{x:.3g} {_UNITS[unit]}"
    return f"{sign}{_number(x)} {_UNITS[unit]}"
