"""Milling cutters as solids of revolution: flat end, ball end and bull nose.

A :class:`Cutter` stands on its tip: the lowest point of the cutter is the tool-tip position
the programme moves, the axis is vertical (+z up), and the cutter reaches ``length`` above
the tip. Its lower envelope ``h(r)`` is the height of the bottom above the tip at radial
distance ``r``; along a vertical ray at offset ``(dx, dy)`` from the axis the cutter occupies
``[tip_z + h(r), tip_z + length]``.

Tool tables: :func:`load_tool_table` reads TOML (``[tool.N]`` tables) and LinuxCNC ``.tbl``
files (:func:`load_linuxcnc_tool_table`: diameters for cutter compensation, Z offsets for
G43), and :func:`load_camotics_project` reads the tools and stock of a CAMotics ``.camotics``
project.

Examples
--------
>>> c = parse_tool_spec("ball:6")
>>> float(c.lower_envelope(3.0)), float(c.lower_envelope(0.0))
(3.0, 0.0)
>>> c.ray_interval(0.0, 0.0, 10.0)
(10.0, 60.0)
"""

from __future__ import annotations

import json
import math
import os
import re
import tomllib
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ToolError

__all__ = [
    "Cutter",
    "CUTTER_KINDS",
    "parse_tool_spec",
    "load_tool_table",
    "load_linuxcnc_tool_table",
    "TableTool",
    "load_camotics_project",
]

#: Valid cutter kinds and their kernel codes.
CUTTER_KINDS = {"flat": 0, "ball": 1, "bull": 2}
_MM_PER_INCH = 25.4


def _num(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ToolError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ToolError(f"{name} must be finite, got {v!r}")
    return v


@dataclass(frozen=True)
class Cutter:
    """A cutter of revolution standing on its tip.

    Parameters
    ----------
    kind : {"flat", "ball", "bull"}
        Flat end mill, ball end mill or bull nose (torus corner).
    diameter : float
        Cutting diameter in mm, > 0.
    corner_radius : float
        Corner radius in mm: 0 for flat; the radius for ball (0 given means "the radius");
        ``0 < corner_radius <= radius`` for bull.
    length : float
        Cutting length above the tip in mm, >= the corner radius (default 50).

    Examples
    --------
    >>> Cutter("bull", 10, corner_radius=1).code
    2
    >>> Cutter("ball", 3).corner_radius
    1.5
    """

    kind: str
    diameter: float
    corner_radius: float = 0.0
    length: float = 50.0

    def __post_init__(self) -> None:
        if self.kind not in CUTTER_KINDS:
            raise ToolError(f"kind={self.kind!r} is not one of 'flat', 'ball', 'bull'")
        d = _num("diameter", self.diameter)
        rc = _num("corner_radius", self.corner_radius)
        length = _num("length", self.length)
        if d <= 0:
            raise ToolError(f"diameter must be positive, got {d!r}")
        r = d / 2.0
        if self.kind == "flat" and rc != 0.0:
            raise ToolError(f"a flat cutter has corner_radius 0, got {rc!r}")
        if self.kind == "ball":
            if rc == 0.0:
                rc = r
            elif abs(rc - r) > 1e-12 * max(1.0, r):
                raise ToolError(
                    f"a ball cutter's corner_radius is its radius {r!r}, got {rc!r}")
            rc = r
        if self.kind == "bull" and not (0.0 < rc <= r):
            raise ToolError(
                f"a bull-nose corner_radius must be in (0, {r!r}], got {rc!r}")
        if length <= 0 or length < rc:
            raise ToolError(f"length must be positive and >= the corner radius {rc!r}, "
                            f"got {length!r}")
        object.__setattr__(self, "diameter", d)
        object.__setattr__(self, "corner_radius", rc)
        object.__setattr__(self, "length", length)

    @property
    def radius(self) -> float:
        """Half the diameter, mm."""
        return self.diameter / 2.0

    @property
    def code(self) -> int:
        """Kernel code: 0 flat, 1 ball, 2 bull."""
        return CUTTER_KINDS[self.kind]

    def lower_envelope(self, r: Any) -> np.ndarray:
        """Height of the cutter's bottom above its tip at radial distance ``r``.

        Parameters
        ----------
        r : array_like of float
            Radial distance from the axis in mm (any shape).

        Returns
        -------
        ndarray of float64, same shape as ``r``
            Height in mm, 0 on the flat part; NaN where ``r > radius`` or ``r < 0`` or NaN.

        Examples
        --------
        >>> Cutter("bull", 10, corner_radius=1).lower_envelope([0, 4, 5, 6]).tolist()
        [0.0, 0.0, 1.0, nan]
        """
        r = np.asarray(r, dtype=np.float64)
        rad, rc = self.radius, self.corner_radius
        with np.errstate(invalid="ignore"):
            d = np.clip(r - (rad - rc), 0.0, None)
            h = rc - np.sqrt(np.clip(rc * rc - d * d, 0.0, None))
            if self.code == 0:
                h = np.zeros_like(r)
            out = np.where((r <= rad) & (r >= 0.0), h, np.nan)
        return out

    def ray_interval(self, dx: Any, dy: Any, tip_z: Any) -> tuple[Any, Any]:
        """Interval the cutter occupies along a vertical ray offset ``(dx, dy)`` from its axis.

        Parameters
        ----------
        dx, dy : array_like of float
            Offset of the ray from the cutter axis, mm.
        tip_z : array_like of float
            Height of the tool tip, mm. The three broadcast together.

        Returns
        -------
        zlo, zhi : float or ndarray of float64
            ``tip_z + lower_envelope(hypot(dx, dy))`` and ``tip_z + length``; both NaN where
            the ray misses the cutter. Scalars for scalar input.

        Examples
        --------
        >>> Cutter("ball", 2, length=10).ray_interval(1.0, 0.0, 0.0)
        (1.0, 10.0)
        >>> Cutter("flat", 2).ray_interval(2.0, 0.0, 0.0)
        (nan, nan)
        """
        dx, dy, tz = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64)
                                           for v in (dx, dy, tip_z)))
        h = self.lower_envelope(np.hypot(dx, dy))
        zlo = tz + h
        zhi = np.where(np.isnan(h), np.nan, tz + self.length)
        if zlo.ndim == 0:
            return float(zlo), float(zhi)
        return zlo, zhi


def parse_tool_spec(spec: str) -> Cutter:
    """A cutter from a short spec: ``kind:diameter[:corner_radius][:length]`` (mm).

    ``flat:D[:L]``, ``ball:D[:L]`` and ``bull:D:RC[:L]``.

    Parameters
    ----------
    spec : str
        E.g. ``"ball:3"``, ``"flat:6"``, ``"bull:10:1"``, ``"ball:3:40"`` (length 40).

    Returns
    -------
    Cutter

    Raises
    ------
    ToolError
        An unknown kind, a missing or non-numeric field, or invalid dimensions.

    Examples
    --------
    >>> parse_tool_spec("bull:10:1:30")
    Cutter(kind='bull', diameter=10.0, corner_radius=1.0, length=30.0)
    """
    if not isinstance(spec, str):
        raise ToolError(f"tool spec must be a string like 'ball:3', got {spec!r}")
    parts = [p.strip() for p in spec.strip().split(":")]
    kind = parts[0].lower()
    if kind not in CUTTER_KINDS:
        raise ToolError(f"tool spec {spec!r}: kind {parts[0]!r} is not one of "
                        "'flat', 'ball', 'bull'")
    want = (3, 4) if kind == "bull" else (2, 3)
    if len(parts) not in want:
        form = "bull:D:RC[:L]" if kind == "bull" else f"{kind}:D[:L]"
        raise ToolError(f"tool spec {spec!r} must read {form}, got {len(parts)} fields")
    try:
        nums = [float(p) for p in parts[1:]]
    except ValueError:
        raise ToolError(f"tool spec {spec!r}: fields after the kind must be numbers") from None
    try:
        if kind == "bull":
            return Cutter(kind, nums[0], corner_radius=nums[1],
                          **({"length": nums[2]} if len(nums) == 3 else {}))
        return Cutter(kind, nums[0], **({"length": nums[1]} if len(nums) == 2 else {}))
    except ToolError as e:
        raise ToolError(f"tool spec {spec!r}: {e}") from None


_TABLE_KEYS = {"kind", "diameter", "corner_radius", "length", "units", "description"}


def numbered_tables(path: str, section: str, keys: set[str], what: str,
                    hint: str = "") -> list[tuple[int, dict, str, float]]:
    """The ``[section.N]`` tables of a TOML file, checked: ``(N, table, where, mm per unit)``.

    The one reader of zmap's numbered TOML tables (the tool table, the holder table): ``N``
    an integer >= 0, each a table of ``keys`` only, ``units`` ``"mm"`` (default) or
    ``"inch"``; ``where`` names the file and table for the caller's own errors.

    Raises
    ------
    ToolError
        The file unreadable or not TOML, no such tables, or one of them malformed; the
        message names the file and the table.
    """
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as e:
        raise ToolError(f"{path}: cannot read {what}: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ToolError(f"{path}: not a valid TOML {what}: {e}") from None
    tables = data.get(section)
    if not isinstance(tables, dict) or not tables:
        raise ToolError(f"{path}: no [{section}.N] tables{hint} found")
    out = []
    for key, entry in tables.items():
        where = f"{path}: {section}.{key}"
        try:
            num = int(key)
        except ValueError:
            raise ToolError(f"{where}: tool number must be an integer, got {key!r}") from None
        if num < 0:
            raise ToolError(f"{where}: tool number must be >= 0, got {num}")
        if not isinstance(entry, dict):
            raise ToolError(f"{where}: must be a table, got {entry!r}")
        extra = set(entry) - keys
        if extra:
            raise ToolError(f"{where}: unknown keys {sorted(extra)}; valid keys are {sorted(keys)}")
        units = entry.get("units", "mm")
        if units not in ("mm", "inch"):
            raise ToolError(f"{where}: units={units!r} is not one of 'mm', 'inch'")
        out.append((num, entry, where, _MM_PER_INCH if units == "inch" else 1.0))
    return out


def load_tool_table(path: str | os.PathLike) -> dict[int, Cutter]:
    """Read a TOML tool table (a ``.tbl`` file goes to :func:`load_linuxcnc_tool_table`).

    The file holds one table per tool number::

        [tool.1]
        kind = "ball"        # flat | ball | bull
        diameter = 3         # mm unless units = "inch"
        length = 40          # optional, default 50
        corner_radius = 0.5  # bull only
        units = "mm"         # optional: "mm" (default) or "inch"

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` file.

    Returns
    -------
    dict of int to Cutter
        Dimensions in mm.

    Raises
    ------
    ToolError
        Unreadable file, bad TOML, or an invalid entry; the message names the file and the
        entry (``tool.N``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.toml"
    >>> _ = p.write_text('[tool.2]\\nkind = "flat"\\ndiameter = 6\\n')
    >>> load_tool_table(p)
    {2: Cutter(kind='flat', diameter=6.0, corner_radius=0.0, length=50.0)}
    """
    path = os.fspath(path)
    if str(path).lower().endswith(".tbl"):
        return load_linuxcnc_tool_table(path)  # type: ignore[return-value]
    out: dict[int, Cutter] = {}
    for num, entry, where, scale in numbered_tables(path, "tool", _TABLE_KEYS, "tool table"):
        if "kind" not in entry or "diameter" not in entry:
            raise ToolError(f"{where}: needs 'kind' and 'diameter'")
        try:
            kw = {k: _num(k, entry[k]) * scale
                  for k in ("diameter", "corner_radius", "length") if k in entry}
            out[num] = Cutter(str(entry["kind"]), **kw)
        except ToolError as e:
            raise ToolError(f"{where}: {e}") from None
    return out


@dataclass(frozen=True)
class TableTool:
    """One entry of a LinuxCNC tool table, in mm.

    Attributes
    ----------
    number : int
        The T number.
    diameter : float
        Cutter diameter (G41/G42 compensate by half of it), mm; may be 0.
    length_offset : float
        Tool length offset (the ``Z`` column, applied by G43), mm.
    pocket : int
        The ``P`` column.
    comment : str
        Text after ``;``.
    """

    number: int
    diameter: float
    length_offset: float = 0.0
    pocket: int = 0
    comment: str = ""

    def cutter(self, kind: str = "flat", length: float = 50.0) -> Cutter:
        """The cutter for simulation (a table has no shape: flat unless told), mm."""
        return Cutter(kind, self.diameter, length=length)


_TBL_FIELD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")


def load_linuxcnc_tool_table(path: str | os.PathLike, *, units: str = "inch") -> dict[int, TableTool]:
    """Read a LinuxCNC tool table (``.tbl``): ``T1 P1 Z0.5 D0.0625 ;comment`` per line.

    Parameters
    ----------
    path : str or path-like
        The ``.tbl`` file.
    units : {"inch", "mm"}, keyword-only
        Units of the table's numbers. LinuxCNC keeps the table in the machine's units; its
        standalone interpreter ``rs274`` (whose ``.expected`` outputs are the reference here)
        reads them as inches, hence the default. Give ``"mm"`` for a metric machine's table.

    Returns
    -------
    dict of int to TableTool
        Diameters and Z offsets in mm. Columns other than T, P, Z, D (X Y A B C U V W I J Q)
        are read and ignored: a 3-axis mill has no use for them.

    Raises
    ------
    ToolError
        Unreadable file or a bad line, naming the file and line.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.tbl"
    >>> _ = p.write_text("T1 P1 Z0.5 D0.0625 ;first tool\\n")
    >>> load_linuxcnc_tool_table(p)[1].diameter
    1.5875
    """
    path = os.fspath(path)
    if units not in ("inch", "mm"):
        raise ToolError(f"units={units!r} is not one of 'inch', 'mm'")
    scale = _MM_PER_INCH if units == "inch" else 1.0
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            text = fh.read()
    except OSError as e:
        raise ToolError(f"{path}: cannot read tool table: {e.strerror or e}") from None
    out: dict[int, TableTool] = {}
    for lineno, raw in enumerate(text.splitlines(), 1):
        body, _, comment = raw.partition(";")
        if not body.strip():
            continue
        fields: dict[str, float] = {}
        pos = 0
        for m in _TBL_FIELD.finditer(body):
            if body[pos:m.start()].strip():
                break
            fields[m.group(1).upper()] = float(m.group(2))
            pos = m.end()
        rest = body[pos:].strip()
        where = f"{path}:{lineno}"
        if rest:
            raise ToolError(f"{where}: cannot read {rest[:20]!r} (fields are a letter and a number)")
        if "T" not in fields:
            raise ToolError(f"{where}: a tool line needs a T word")
        t = fields["T"]
        if t != int(t) or not 0 <= t <= 2**31 - 1:
            raise ToolError(f"{where}: tool number must be an integer 0..2147483647, got {t:g}")
        if any(not math.isfinite(v) or abs(v) > 1e6 for v in fields.values()):
            raise ToolError(f"{where}: a value is out of range")
        d = fields.get("D", 0.0) * scale
        if d < 0:
            raise ToolError(f"{where}: diameter must not be negative, got {fields['D']:g}")
        out[int(t)] = TableTool(int(t), d, fields.get("Z", 0.0) * scale,
                                int(fields.get("P", t)), comment.strip())
    if not out:
        raise ToolError(f"{path}: no tools found (lines like 'T1 P1 Z0.5 D0.25')")
    return out


_JSON_COMMENT = re.compile(r'("(?:\\.|[^"\\])*")|//[^\n]*|/\*.*?\*/|#[^\n]*', re.S)
_TRAILING_COMMA = re.compile(r'("(?:\\.|[^"\\])*")|,(\s*[}\]])')
_CAMOTICS_SHAPES = {"cylindrical": "flat", "ballnose": "ball"}


def load_camotics_project(
    path: str | os.PathLike,
) -> tuple[dict[int, Cutter], tuple[float, float, float, float, float, float], str]:
    """Read the tools and stock of a CAMotics ``.camotics`` project (JSON, comments allowed).

    Parameters
    ----------
    path : str or path-like
        The project file.

    Returns
    -------
    tools : dict of int to Cutter
        The tool table in mm ("cylindrical" is a flat end mill, "ballnose" a ball end mill;
        each tool's own ``units`` apply).
    bounds : tuple of 6 float
        Stock ``(xmin, ymin, zmin, xmax, ymax, zmax)`` in mm.
    units : {"mm", "inch"}
        The project's display units ("metric" or "imperial").

    Raises
    ------
    ToolError
        Unreadable or malformed file, or a tool shape zmap does not model (conical,
        spheroid, snubnose); the message names the file and the entry.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "p.camotics"
    >>> _ = p.write_text('{"units": "metric", // comment\\n "tools": {"1": {"units": "metric",'
    ...     ' "shape": "ballnose", "length": 10, "diameter": 2}}, "workpiece": {"bounds":'
    ...     ' {"min": [0, 0, -5], "max": [10, 20, 0]}}}')
    >>> tools, box, units = load_camotics_project(p)
    >>> tools[1].kind, box, units
    ('ball', (0.0, 0.0, -5.0, 10.0, 20.0, 0.0), 'mm')
    """
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as e:
        raise ToolError(f"{path}: cannot read CAMotics project: {e}") from None
    text = _JSON_COMMENT.sub(lambda m: m.group(1) or "", text)
    text = _TRAILING_COMMA.sub(lambda m: m.group(1) or m.group(2), text)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ToolError(f"{path}: not a valid CAMotics project (JSON): {e}") from None
    if not isinstance(data, dict):
        raise ToolError(f"{path}: a CAMotics project must be a JSON object")

    def unit_scale(u: Any, where: str) -> float:
        if u in (None, "metric"):
            return 1.0
        if u == "imperial":
            return _MM_PER_INCH
        raise ToolError(f"{path}: {where}: units={u!r} is not one of 'metric', 'imperial'")

    proj_scale = unit_scale(data.get("units"), "project")
    units = "inch" if proj_scale != 1.0 else "mm"
    tools: dict[int, Cutter] = {}
    for key, t in (data.get("tools") or {}).items():
        where = f"tools.{key}"
        try:
            num = int(key)
        except ValueError:
            raise ToolError(f"{path}: {where}: tool number must be an integer") from None
        if not isinstance(t, dict):
            raise ToolError(f"{path}: {where}: must be an object, got {t!r}")
        shape = t.get("shape", "cylindrical")
        if shape not in _CAMOTICS_SHAPES:
            raise ToolError(f"{path}: {where}: shape {shape!r} is not supported (only "
                            "'cylindrical' and 'ballnose')")
        s = unit_scale(t.get("units"), where)
        try:
            d = _num("diameter", t.get("diameter")) * s
            kw = {"length": _num("length", t["length"]) * s} if "length" in t else {}
            tools[num] = Cutter(_CAMOTICS_SHAPES[shape], d, **kw)
        except ToolError as e:
            raise ToolError(f"{path}: {where}: {e}") from None
    try:
        b = data["workpiece"]["bounds"]
        lo = [_num("bounds.min", v) * proj_scale for v in b["min"]]
        hi = [_num("bounds.max", v) * proj_scale for v in b["max"]]
    except (KeyError, TypeError):
        raise ToolError(f"{path}: workpiece.bounds with 'min' and 'max' is missing") from None
    except ToolError as e:
        raise ToolError(f"{path}: workpiece: {e}") from None
    if len(lo) != 3 or len(hi) != 3:
        raise ToolError(f"{path}: workpiece.bounds min and max must have 3 values, got "
                        f"{len(lo)} and {len(hi)}")
    if any(h <= lw for lw, h in zip(lo, hi)):
        raise ToolError(f"{path}: workpiece.bounds max {hi} must exceed min {lo}")
    return tools, (lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]), units
