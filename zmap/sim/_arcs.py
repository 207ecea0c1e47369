"""Arc geometry shared by the G-code reader and cutter compensation (no imports of either)."""

from __future__ import annotations

import math

__all__ = ["arc_sweep"]


def arc_sweep(a0: float, b0: float, a1: float, b1: float, ca: float, cb: float,
              ccw: bool, turns: int = 0) -> float:
    """Signed swept angle of an arc (radians, positive counter-clockwise), as LinuxCNC.

    Parameters
    ----------
    a0, b0, a1, b1 : float
        Start and end in plane coordinates (mm).
    ca, cb : float
        Centre in plane coordinates (mm).
    ccw : bool
        True for G3, False for G2.
    turns : int
        Extra full turns (P word minus one).

    Returns
    -------
    float
        In ``(0, 2*pi*(turns+1)]`` for G3, in ``[-2*pi*(turns+1), 0)`` for G2; an arc whose
        end angle equals its start angle is a full circle.

    Examples
    --------
    >>> round(arc_sweep(1, 0, 0, 1, 0, 0, True), 6)
    1.570796
    >>> round(arc_sweep(1, 0, 1, 0, 0, 0, False), 6)
    -6.283185
    """
    alpha = math.atan2(b0 - cb, a0 - ca)
    beta = math.atan2(b1 - cb, a1 - ca)
    if ccw:
        if beta <= alpha:
            beta += 2.0 * math.pi
        return (beta - alpha) + turns * 2.0 * math.pi
    if alpha <= beta:
        alpha += 2.0 * math.pi
    return (beta - alpha) - turns * 2.0 * math.pi
