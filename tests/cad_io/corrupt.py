"""Seeded corrupt copies of real STEP files, for the tests of damaged input.

Each function writes a copy of ``source`` into ``folder`` with one kind of damage and returns
its path; the same seed gives the same bytes.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

_POINT = re.compile(rb"^#(\d+)\s*=\s*CARTESIAN_POINT\s*\(\s*'[^']*'\s*,\s*\(([^)]*)\)\s*\)\s*;", re.M)


def flip_bytes(source: Path, folder: Path, n_bytes: int, seed: int) -> Path:
    """``n_bytes`` printable bytes of the DATA section changed at random places."""
    data = source.read_bytes()
    start = data.index(b"DATA;") + 5
    rng = np.random.default_rng(seed)
    b = bytearray(data)
    for p in rng.integers(start, len(b) - 20, n_bytes):
        b[p] = int(rng.integers(33, 127))
    out = folder / f"{source.stem}_{n_bytes}_{seed}.stp"
    out.write_bytes(bytes(b))
    return out


def control_points(data: bytes) -> list[int]:
    """Entity ids of the CARTESIAN_POINTs that B_SPLINE surfaces list as control points."""
    ids: set[int] = set()
    for m in re.finditer(rb"B_SPLINE_SURFACE[A-Z_]*\s*\([^;]*?\(\s*(\(\s*#[^;]*?\))\s*\)", data):
        ids.update(int(x) for x in re.findall(rb"#(\d+)", m.group(1)))
    return sorted(ids)


def scaled_control_point(source: Path, folder: Path, seed: int, *, exponent: str = "E1",
                         broken_keywords: int = 3) -> Path:
    """One coordinate of one B-spline control point given an exponent (``89.032349001`` becomes
    ``89.032349001E1``, ten times as far), and ``broken_keywords`` other CARTESIAN_POINT
    keywords misspelt (those entities fail to load)."""
    data = source.read_bytes()
    rng = np.random.default_rng(seed)
    points = {int(m.group(1)): m for m in _POINT.finditer(data)}
    cps = [i for i in control_points(data) if i in points]
    target = points[cps[int(rng.integers(len(cps)))]]
    coords = target.group(2).split(b",")
    k = int(rng.integers(len(coords)))
    coords[k] = coords[k].strip().rstrip(b".") + (b"." if b"." not in coords[k] else b"") + exponent.encode()
    line = target.group(0).replace(target.group(2), b",".join(coords))
    out = bytearray(data[:target.start()] + line + data[target.end():])
    others = [i for i in points if i != int(target.group(1))]
    for i in rng.choice(others, broken_keywords, replace=False):
        m = re.search(rb"^#%d\s*=\s*CARTESIAN_POINT" % int(i), out, re.M)
        j = m.end() - 1
        out[j:j + 1] = b"X"
    path = folder / f"{source.stem}_cp{seed}.stp"
    path.write_bytes(bytes(out))
    return path


def shell_cut(source: Path, folder: Path, keep: int, seed: int) -> Path:
    """The first CLOSED_SHELL cut down to ``keep`` of its faces (drawn at random): the file's
    other faces never reach the shape."""
    data = source.read_bytes()
    m = re.search(rb"(CLOSED_SHELL\s*\(\s*'[^']*'\s*,\s*\()([^)]*)(\))", data)
    refs = m.group(2).split(b",")
    rng = np.random.default_rng(seed)
    kept = [refs[int(i)].strip() for i in sorted(rng.choice(len(refs), keep, replace=False))]
    out = data[:m.start(2)] + b", ".join(kept) + data[m.end(2):]
    path = folder / f"{source.stem}_shell{keep}_{seed}.stp"
    path.write_bytes(out)
    return path


def harmless_faults(source: Path, folder: Path) -> dict[str, Path]:
    """Copies of a STEP file with one fault each that changes no face: ``seam``, its first
    SEAM_CURVE listing its first pcurve twice; ``name``, its first ADVANCED_FACE named by a
    number, not a quoted string."""
    data = source.read_bytes()
    out = {}
    m = re.search(rb"SEAM_CURVE\s*\(\s*'[^']*'\s*,\s*#\d+\s*,\s*\(\s*(#\d+)\s*,\s*(#\d+)\s*\)", data)
    seam = data[:m.start(2)] + m.group(1) + data[m.end(2):]
    m = re.search(rb"ADVANCED_FACE\s*\(\s*('[^']*')", data)
    name = data[:m.start(1)] + b"17" + data[m.end(1):]
    for key, text in (("seam", seam), ("name", name)):
        out[key] = folder / f"{source.stem}_{key}.step"
        out[key].write_bytes(text)
    return out
