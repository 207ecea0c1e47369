"""One exception family for zmap.

Every error a user can meet derives from :class:`ZMapError`; those caused by a bad value
passed by the caller also derive from :class:`ValueError`. The CLI prints ``str(err)`` in
one line and exits non-zero.
"""

from __future__ import annotations

__all__ = [
    "ZMapError",
    "ZMapFileError",
    "OutOfDomainError",
    "StepImportError",
    "GCodeError",
    "ToolError",
    "StageError",
    "SimFileError",
    "GridTooLargeError",
    "NurbsError",
    "RefineError",
    "PathError",
    "PathTooLargeError",
]


class ZMapError(Exception):
    """Base class of every zmap error."""


class ZMapFileError(ZMapError):
    """A ``.npz`` (or other zmap file) that is missing, corrupt or not a zmap file."""

    def __init__(self, path: str, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class OutOfDomainError(ZMapError, ValueError):
    """A query point where the model has no height, raised under ``strict=True``."""


class StepImportError(ZMapError):
    """A STEP file that cannot be read, or one with no usable faces."""


class GridTooLargeError(ZMapError, ValueError):
    """A grid whose arrays would not fit in memory; the message gives the estimate."""


class GCodeError(ZMapError, ValueError):
    """A G-code block the reader cannot run, located by file, line and column."""

    def __init__(self, file: str, line: int, column: int, word: str, problem: str):
        self.file = str(file)
        self.line = int(line)
        self.column = int(column)
        self.word = word
        self.problem = problem
        super().__init__(f"{self.file}:{self.line}:{self.column}: {word!s}: {problem}")


class ToolError(ZMapError, ValueError):
    """A cutter definition or tool table that is invalid or lacks a tool."""


class StageError(ZMapError, ValueError):
    """A simulation stage outside 0..n_stages."""


class SimFileError(ZMapFileError):
    """A simulation run file that is missing, corrupt or of a foreign format."""


class NurbsError(ZMapError, ValueError):
    """A NURBS surface with inconsistent arrays or a degree the evaluator cannot take."""


class RefineError(ZMapError, ValueError):
    """A precision refinement (CZ-map, EZ-map) that cannot be built: no exact surface to
    sample, or a surface callable that answers with the wrong shape."""


class PathError(ZMapError, ValueError):
    """A toolpath that cannot be cut into tool positions (a non-finite coordinate, a negative
    tool number), located by file and line (``line`` 0: unknown, the message says where)."""

    def __init__(self, file: str, line: int, problem: str):
        self.file = str(file)
        self.line = int(line)
        self.problem = problem
        where = f"{self.file}:{self.line}" if self.line > 0 else self.file
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):
        return type(self), (self.file, self.line, self.problem)


class PathTooLargeError(PathError):
    """A toolpath with more tool positions than the cap (or the memory available) allows; the
    message gives the estimate, the cap and the line of the move that crosses it."""

    def __init__(self, file: str, line: int, problem: str, estimate: float = float("nan"),
                 cap: float = float("nan")):
        super().__init__(file, line, problem)
        self.estimate = float(estimate)
        self.cap = float(cap)

    def __reduce__(self):
        return type(self), (self.file, self.line, self.problem, self.estimate, self.cap)
