"""The independent reference of the exact swept volume, shared with the benchmark.

It lives in ``bench/exact_sweep.py`` (plain numpy, no code of the kernels: its own cutter
envelope, line and arc paths from the program's G-code data, and a brute-force search: the
path sampled every 1 um, the best sample refined three times, 1000-fold each, so a bottom
is exact to about ``|slope| * 1e-12`` mm even at the edge of the tool's reach). Loaded by
path: ``bench/`` is scripts, not a package.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

_PATH = Path(__file__).resolve().parents[3] / "bench" / "exact_sweep.py"
_spec = importlib.util.spec_from_file_location("zmap_bench_exact_sweep", _PATH)
_mod = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_mod)

arc_path = _mod.arc_path
line_path = _mod.line_path
sweep_interval = _mod.sweep_interval

__all__ = ["arc_path", "line_path", "sweep_interval"]
