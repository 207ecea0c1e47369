"""Running a G-code program's lines: source files, O-word control flow, subroutine calls.

:class:`Source` prepares one file (comments blanked, block delete, ``%`` tape marks, O-word
statements paired by :func:`zmap.sim.ngc.program_structure`); :class:`Runner` walks its lines,
hands each block to the interpreter (:func:`zmap.sim._gcode_motion.fast_block` when it can,
else :func:`zmap.sim._gcode_modal.run_block`), follows ``while``/``do``/``repeat``/``if``
and ``O<name> call`` or ``M98`` into subroutines (in this file, or in ``<name>.ngc`` found as
LinuxCNC finds it), and under ``lenient`` undoes and records each failing block.

Examples
--------
>>> from zmap.sim._gcode_state import InterpState
>>> lines = split_lines("o100 repeat [3]\\nG91 G0 X1\\no100 endrepeat\\n")
>>> st, warnings = InterpState("x.nc", None), []
>>> src = Source.from_lines(lines, "x.nc", True, False, warnings)
>>> Runner(st, src, False, warnings, 100, 1000).run()
>>> [row[1] for row in st.rows]
[1.0, 2.0, 3.0]
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ..errors import GCodeError
from ._gcode_codes import TOKEN, plain_words
from ._gcode_modal import run_block
from ._gcode_motion import fast_block as _fast_block
from ._gcode_state import InterpState
from .ngc import NgcError, OWord, Structure, compact, program_structure, scan_line

__all__ = ["Source", "Runner", "read_source", "split_lines", "subroutine_dirs"]

_COMMENT = re.compile(r"\([^)]*\)|;.*")
_LINE_END = re.compile(r"\r*\n|\r")
_OWORD_KEYWORDS = (r"ENDSUB|ENDWHILE|ENDREPEAT|ENDIF|ELSEIF|ELSE|SUB|CALL|DO|WHILE|IF|BREAK|"
                   r"CONTINUE|RETURN|REPEAT")
_OWORD_HEAD = re.compile(rf"(?:N\d+(?:\.\d*)?)?O(?:<([^>]*)>|(\d+))({_OWORD_KEYWORDS})?")
_OWORD_EXPR_HEAD = re.compile(r"(?:N\d+(?:\.\d*)?)?O\[")
_M99 = re.compile(r"M0*99(?![\d.])")
#: deepest nesting of O-word calls (an endless recursion stops here)
_MAX_CALL_DEPTH = 100


def read_source(source: str | os.PathLike, filename: str | None) -> tuple[str, str]:
    """The text of a program and the name for messages.

    ``source`` is a path (a path-like, or a one-line string under 4 KiB naming an existing
    file), read as UTF-8 with line ends kept, or else the program text itself.
    """
    if isinstance(source, os.PathLike) or (
        isinstance(source, str) and "\n" not in source and "\r" not in source
        and len(source) < 4096 and os.path.isfile(source)
    ):
        path = Path(source)
        with open(path, encoding="utf-8", errors="replace", newline="") as fh:
            text = fh.read()
        return text, filename if filename is not None else str(path)
    if not isinstance(source, str):
        raise TypeError(f"source must be a path or G-code text, got {type(source).__name__}")
    return source, filename if filename is not None else "<string>"


def split_lines(text: str) -> list[str]:
    """Lines as an editor shows them: a UTF-8 BOM dropped, LF, CRLF, CR and ``\\r\\r\\n`` ends."""
    if text.startswith("\ufeff"):
        text = text[1:]
    lines = _LINE_END.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def subroutine_dirs(path: Any, fname: str) -> list[Path]:
    """The folders of ``parse(subroutine_path=...)``, relative ones from the program's folder."""
    if path is None:
        return []
    if isinstance(path, (str, os.PathLike)):
        items = str(path).split(":") if isinstance(path, str) else [path]
    else:
        items = list(path)
    base = Path(fname).parent if os.path.isfile(fname) else Path.cwd()
    out = []
    for item in items:
        if not isinstance(item, (str, os.PathLike)):
            raise TypeError(f"subroutine_path must hold folder names, got {item!r}")
        if str(item):
            d = Path(item)
            out.append(d if d.is_absolute() else base / d)
    return out


class _LimitError(GCodeError):
    """A limit of the whole parse was crossed: fatal even under ``lenient=True``."""


@dataclass
class Source:
    """One program file prepared for the runner: cleaned lines and paired O-words."""

    name: str
    lines: list  # per line: upper-cased comment-free text, a GCodeError to raise, or None
    special: list[bool]  # the line needs the LinuxCNC scanner (#, [ or O in it)
    owords: dict[int, OWord]
    structure: Structure | None

    @classmethod
    def from_lines(cls, lines: list[str], fname: str, block_delete: bool, lenient: bool,
                   warnings: list[str]) -> "Source":
        """Prepare the lines of a file (see :func:`split_lines`).

        Parameters
        ----------
        lines : list of str
            The file's lines.
        fname : str
            The file's name in messages.
        block_delete : bool
            Skip lines that start with ``/`` (else run them without it).
        lenient : bool
            An O-word statement that cannot be paired is dropped with a warning instead of
            raising GCodeError.
        warnings : list of str
            Where those warnings go.
        """
        out: list = [None] * len(lines)
        special = [False] * len(lines)
        percent_open = False
        seen_block = False
        comment_sub = _COMMENT.sub
        for idx, raw in enumerate(lines):
            if not raw or raw.isspace():
                continue
            s = raw
            if "(" in s or ";" in s or ")" in s:
                # blanked, not cut out: columns in messages stay those of the source line
                s = comment_sub(lambda mt: " " * len(mt.group()), s)
                if "(" in s or ")" in s:
                    col = s.find("(") if "(" in s else s.find(")")
                    out[idx] = GCodeError(fname, idx + 1, col + 1, s[col],
                                          "unbalanced comment parenthesis")
                    continue
            s = s.upper()
            stripped = s.strip()
            if not stripped:
                continue
            if stripped == "%":
                if not seen_block and not percent_open:
                    percent_open = True
                    continue
                if percent_open:
                    del out[idx:], special[idx:]  # the closing tape mark ends the program
                    break
                continue
            seen_block = True
            if stripped[0] == "/":
                if block_delete:
                    continue
                s = s.replace("/", " ", 1)
            out[idx] = s
            special[idx] = "#" in s or "[" in s or "O" in s
        src = cls(fname, out, special, {}, None)
        src._pair_owords(lenient, warnings)
        return src

    def _pair_owords(self, lenient: bool, warnings: list[str]) -> None:
        """Find the O-word statements and M99s, and pair them into ``structure``."""
        m99: list[int] = []
        for idx, s in enumerate(self.lines):
            if not isinstance(s, str):
                continue
            if "O" in s:
                c, cols = compact(s)
                m = _OWORD_HEAD.match(c)
                if m:
                    label = f"<{m.group(1)}>" if m.group(1) is not None else str(int(m.group(2)))
                    self.owords[idx] = OWord(label, m.group(3) or "", (), cols[0])
                elif _OWORD_EXPR_HEAD.match(c):
                    # O[expression]: LinuxCNC's computed label (the runner evaluates it); the
                    # text pairs statements that share it
                    label, kw = _bracketed_label(c)
                    if label is not None:
                        self.owords[idx] = OWord(label, kw, (), cols[0])
            if "M" in s and "99" in s and _M99.search(compact(s)[0]):
                m99.append(idx)
        while True:
            try:
                self.structure = program_structure(self.owords, m99)
                return
            except NgcError as e:
                ow = self.owords[e.pos]
                err = GCodeError(self.name, e.pos + 1, ow.col, e.word, e.problem)
                if not lenient:
                    raise err from None
                warnings.append(str(err))
                del self.owords[e.pos]
                self.lines[e.pos] = None


def _bracketed_label(c: str) -> tuple[str | None, str]:
    """``("[expr]", keyword)`` of a compact ``O[expr] keyword`` line (None if unbalanced)."""
    i = c.index("[")
    depth = 0
    for k in range(i, len(c)):
        depth += (c[k] == "[") - (c[k] == "]")
        if depth == 0:
            m = re.match(_OWORD_KEYWORDS, c[k + 1:])
            return c[i:k + 1], (m.group() if m else "")
    return None, ""


@dataclass
class _Frame:
    """A subroutine call in progress: where to return, and what kind of call."""

    source: Source
    return_idx: int
    kind: str  # "sub" (O-word call: own #1-#30 and locals) or "m98" (shares parameters)
    start: int  # index of the sub or program header line
    remaining: int = 1  # M98 L repeats still to run
    label: str = ""


class Runner:
    """Runs a program's lines through the interpreter, with O-word control flow and calls.

    Parameters
    ----------
    st : InterpState
        The interpreter's state, which gains the program's moves.
    main : Source
        The program.
    lenient : bool
        Skip a failing block (its state undone) with a warning instead of raising.
    warnings : list of str
        Where those warnings go.
    max_blocks, max_moves : int
        Limits of the parse (see :func:`zmap.sim.gcode.parse`); crossing one raises
        :class:`_LimitError` even under ``lenient``.
    block_delete : bool
        The program's block-delete switch, which subroutine files read later follow.
    fast_block : callable, optional
        The fast path tried first on plain lines (``(st, tokens, lineno) -> bool``); a
        caller may pass another (``lambda *a: False`` runs every block in full).
    """

    def __init__(self, st: InterpState, main: Source, lenient: bool, warnings: list[str],
                 max_blocks: int, max_moves: int, block_delete: bool = True,
                 fast_block: Callable[[InterpState, list, int], bool] = _fast_block):
        self.st = st
        self.main = main
        self.lenient = lenient
        self.block_delete = block_delete
        self.warnings = warnings
        self.max_blocks = max_blocks
        self.max_moves = max_moves
        self.fast_block = fast_block
        st.max_moves = max_moves
        self.files: dict[str, Source | None] = {}
        self.sub_dirs: list[Path] = []
        #: where the program ended: (file, line, column, word) of its M2/M30/M99, or the end
        #: of the file
        self.end_at: tuple[str, int, int, str] = (main.name, max(len(main.lines), 1), 1,
                                                  "end of file")

    def run(self) -> None:
        """Run the program to its end (M2, M30, M99 in the main program, or its last line)."""
        st = self.st
        src, i = self.main, 0
        frames: list[_Frame] = []
        repeats: dict[tuple[int, int], int] = {}
        jumped = False
        executed = 0
        budget = self.max_blocks + len(src.lines)
        while not st.ended:
            if i >= len(src.lines):
                if frames:
                    f = frames[-1]
                    err = GCodeError(src.name, max(len(src.lines), 1), 1, f"O{f.label}",
                                     "subroutine runs off the end of the file")
                    if not self.lenient:
                        raise err
                    self.warnings.append(str(err) + "; the program ends here")
                self.end_at = (src.name, max(len(src.lines), 1), 1, "end of file")
                return
            item = src.lines[i]
            if item is None:
                i += 1
                continue
            executed += 1
            if executed > budget:
                raise _LimitError(src.name, i + 1, 1, "block",
                                 f"more than {self.max_blocks} blocks executed (an endless "
                                 f"loop?); parse(max_blocks=...) or zmap simulate "
                                 f"--max-blocks allows more")
            st.file = src.name
            st.stop = None
            was_jumped, jumped = jumped, False
            snap = st.snapshot(src.special[i]) if self.lenient else None
            try:
                if isinstance(item, GCodeError):
                    raise item
                ow = src.owords.get(i)
                if ow is not None:
                    src, i, jumped = self._oword(src, i, ow, frames, repeats, was_jumped)
                    continue
                self._line(src, i, item)
                if len(st.rows) > self.max_moves:
                    raise _LimitError(src.name, i + 1, 1, "block",
                                     f"the program makes more than {self.max_moves} moves; "
                                     f"parse(max_moves=...) allows more")
            except GCodeError as e:
                if not self.lenient or isinstance(e, _LimitError):
                    raise
                st.restore(snap)
                self.warnings.append(str(e))
                st.call, st.m99 = None, False
                i += 1
                continue
            if st.stop is not None:
                self.end_at = (src.name, i + 1, st.stop[1], st.stop[0])
            i += 1
            if st.call is not None:
                p, count = st.call
                st.call = None
                if count > 0:
                    tsrc, tidx = self._find(src, f"P{p}", i)
                    frames.append(_Frame(src, i, "m98", tidx, count, str(p)))
                    src, i = tsrc, tidx + 1
            elif st.m99:
                st.m99 = False
                if not frames or frames[-1].kind != "m98":
                    st.ended = True  # M99 in the main program ends it, as LinuxCNC by default
                    continue
                f = frames[-1]
                f.remaining -= 1
                if f.remaining > 0:
                    i = f.start + 1
                else:
                    frames.pop()
                    src, i = f.source, f.return_idx

    def _line(self, src: Source, i: int, s: str) -> None:
        """Run the block on line ``i``: its parameters set, then its words interpreted."""
        st = self.st
        lineno = i + 1
        if src.special[i]:
            try:
                line = scan_line(s, st.params)
            except NgcError as e:
                raise GCodeError(src.name, lineno, e.pos, e.word, e.problem) from None
            if line.oword is not None:
                ow = line.oword
                raise GCodeError(src.name, lineno, ow.col, f"O{ow.label}",
                                 "an O-word must start the line")
            for key, v in line.assigns:
                st.params.set(key, v)
            if line.words:
                run_block(st, line.words, lineno)
            return
        toks = TOKEN.findall(s)
        if self.fast_block(st, toks, lineno):
            return
        run_block(st, plain_words(src.name, lineno, s), lineno)

    def _find(self, src: Source, label: str, i: int) -> tuple[Source, int]:
        """The source and line index of subroutine ``label``: defined in this file, the main
        file or a file already read, else in ``<name>.ngc`` (LinuxCNC's find_ngc_file): in a
        folder of ``subroutine_path``, beside the main file, or in a folder below it."""
        for cand in (src, self.main, *(f for f in self.files.values() if f is not None)):
            idx = cand.structure.subs.get(label)
            if idx is not None:
                return cand, idx
        if not label.startswith("P"):
            name = label.strip("<>").lower()  # LinuxCNC reads the line in lower case
            if name not in self.files:
                path = self._sub_file(name)
                cand = None
                if path is not None:
                    text, fname = read_source(path, None)
                    cand = Source.from_lines(split_lines(text), fname, self.block_delete,
                                             self.lenient, self.warnings)
                self.files[name] = cand
            cand = self.files[name]
            if cand is not None and label in cand.structure.subs:
                return cand, cand.structure.subs[label]
        shown = f"O{label}" if not label.startswith("P") else f"program O{label[1:]}"
        raise GCodeError(src.name, i, 1, shown, f"{shown} is not defined"
                         + ("" if label.startswith("P") else
                            " in the file, nor in a file beside it or in subroutine_path"))

    def _sub_file(self, name: str) -> Path | None:
        """``<name>.ngc`` in the subroutine folders, beside the main file, or below it."""
        fname = f"{name}.ngc"
        dirs = list(self.sub_dirs)
        if self.main.name != "<string>" and os.path.isfile(self.main.name):
            dirs.append(Path(self.main.name).parent)
        for d in dirs:
            for cand in (d / fname, d / fname.upper()):
                if cand.is_file():
                    return cand
        if len(dirs) > len(self.sub_dirs):  # LinuxCNC's findFile: the folders below, in turn
            root = dirs[-1]
            for top, subdirs, files in os.walk(root):
                subdirs[:] = sorted(x for x in subdirs if not x.startswith("."))
                if len(Path(top).relative_to(root).parts) >= 4:
                    subdirs[:] = []
                if top != str(root) and fname in files:
                    return Path(top) / fname
        return None

    def _oword(self, src: Source, i: int, ow: OWord, frames: list[_Frame],
               repeats: dict[tuple[int, int], int], jumped: bool) -> tuple[Source, int, bool]:
        """Run one O-word statement; return where to go on (source, index, jumped)."""
        st = self.st
        S = src.structure
        kw = ow.keyword
        if kw == "SUB" or i in S.fanuc:  # a definition met in the flow is skipped
            return src, S.end[i] + 1, False
        try:
            line = scan_line(src.lines[i], st.params)
        except NgcError as e:
            raise GCodeError(src.name, i + 1, e.pos, e.word, e.problem) from None
        args = line.oword.args if line.oword is not None else ()
        word = f"O{ow.label}"

        def cond() -> bool:
            if not args:
                raise GCodeError(src.name, i + 1, ow.col, word,
                                 f"{kw.lower()} needs a condition in [brackets]")
            return args[0] != 0.0

        if kw == "CALL":
            label = line.oword.label if line.oword is not None else ow.label  # O[expr]: evaluated
            tsrc, tidx = self._find(src, label, i + 1)
            if len(frames) >= _MAX_CALL_DEPTH:
                raise GCodeError(src.name, i + 1, ow.col, word, f"subroutine calls nested "
                                                                f"more than {_MAX_CALL_DEPTH} deep")
            frames.append(_Frame(src, i + 1, "sub", tidx, 1, label))
            st.params.push(args)
            return tsrc, tidx + 1, False
        if kw in ("ENDSUB", "RETURN"):
            if not frames or frames[-1].kind != "sub":
                raise GCodeError(src.name, i + 1, ow.col, word,
                                 f"{kw.lower()} without a call in progress")
            f = frames.pop()
            st.params.pop()
            # LinuxCNC's read_o: a value sets #<_value> and #<_value_returned>; none clears both
            st.params.set("<_VALUE_RETURNED>", 1.0 if args else 0.0)
            st.params.set("<_VALUE>", args[0] if args else 0.0)
            return f.source, f.return_idx, False
        if kw == "WHILE":
            if i in S.start:  # the while that closes a do-loop
                return src, (S.start[i] + 1 if cond() else i + 1), False
            return src, (i + 1 if cond() else S.end[i] + 1), False
        if kw == "ENDWHILE":
            return src, S.start[i], False
        if kw == "DO":
            return src, i + 1, False
        if kw == "REPEAT":
            if not args:
                raise GCodeError(src.name, i + 1, ow.col, word, "repeat needs a count in "
                                                                "[brackets]")
            n = round(args[0])
            repeats[(id(src), i)] = n
            return src, (i + 1 if n > 0 else S.end[i] + 1), False
        if kw == "ENDREPEAT":
            s0 = S.start[i]
            left = repeats.get((id(src), s0), 1) - 1
            repeats[(id(src), s0)] = left
            return src, (s0 + 1 if left > 0 else i + 1), False
        if kw == "IF":
            return (src, i + 1, False) if cond() else (src, S.end[i], True)
        if kw == "ELSEIF":
            if not jumped:
                return src, S.endif[i] + 1, False
            return (src, i + 1, False) if cond() else (src, S.end[i], True)
        if kw == "ELSE":
            return src, (i + 1 if jumped else S.endif[i] + 1), False
        if kw == "ENDIF":
            return src, i + 1, False
        if kw in ("BREAK", "CONTINUE"):
            loop = S.loop[i]
            lkw = src.owords[loop].keyword
            if lkw == "REPEAT":  # LinuxCNC's convert_control_functions accepts while/do only
                raise GCodeError(src.name, i + 1, ow.col, word,
                                 f"{kw.lower()} works in while and do loops only, not in "
                                 f"repeat O{ow.label}")
            if kw == "BREAK":
                return src, S.end[loop] + 1, False
            return src, (loop if lkw == "WHILE" else S.end[loop]), False
        raise GCodeError(src.name, i + 1, ow.col, word,
                         f"O-word {kw.lower() or 'program number'} cannot be run here")
