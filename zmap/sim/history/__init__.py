"""Histories of a simulation run: z-trace, time-trace and Interval Treap (papers 000, 001).

Each history is recorded inside the cutting kernel while the dexel workpiece is cut
(:func:`zmap.sim.dexel.run_cut`), then finalised into compact per-ray arrays that answer
``reconstruct(stage)`` and/or ``display(stage)``.
"""

from __future__ import annotations

from ._recorder import HISTORY_KINDS, Recorder
from .treap import IntervalTreap
from .ttrace import TimeTrace
from .ztrace import ZTrace

__all__ = ["HISTORY_KINDS", "Recorder", "ZTrace", "TimeTrace", "IntervalTreap"]
