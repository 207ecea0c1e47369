"""Fuzz the G-code reader and the path generator with mutants of real programs.

Real programs from ``data/gcode`` (each cut to its first ``--lines`` lines) are mutated with a
seeded RNG: a number replaced by a huge (400 digits), infinite-looking, negative, zero or tiny
one; lines duplicated, deleted, swapped or truncated; random bytes; known troublesome blocks
inserted (``G91 G81 ... L1000000000``, ``G83 ... Q0.0000001``, ``G2 ... P1000000000``,
``T99999999999``, ``G10 L2 P<400 digits>``, ``#1=[1/0]``, ...). Each mutant is read by
``zmap.sim.gcode.parse`` with ``lenient=False`` and ``lenient=True``, and every program read is
cut into tool positions by ``zmap.sim.path.positions``, in a child process with a time limit
(``--timeout``) and an address-space limit (``--memory-gb``, RLIMIT_AS) so that a runaway
allocation shows as MemoryError.

Each mutant is classed by the worst outcome of its two readings:

- ``ok``: a program whose moves are all finite (start, end; centre and sweep of arcs; feed of
  feed moves), with tool numbers >= 0, and its positions;
- ``clean``: a :class:`zmap.errors.ZMapError` (GCodeError, PathError, ...) whose message
  starts ``file:line``;
- ``nonfinite``: parse returned moves with a non-finite value (even when ``positions`` then
  refused them);
- ``wrong``: parse returned a negative tool number (an integer that wrapped);
- ``crash``: any other exception (or a ZMapError without ``file:line``);
- ``hang``: no answer within ``--timeout`` seconds.

Prints one JSON object: counts per class and per program, the distinct kinds of each bad class
(exception type and innermost frame) and the first examples (mutation, mutated line, the
traceback's last line).

Usage: ``python bench/fuzz_gcode.py [--mutants 2000] [--seed 0] [--timeout 10] [--jobs 2]
[--lines 300] [--memory-gb 4] [--examples 3]``
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import re
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
PROGRAMS = (
    "flower_mold.nc",
    "Gates_combined_R12.nc",
    "g17-g99-g81.ngc",
    "tort.ngc",
    "rgh.ngc",
    "botomata_bottom.nc",
    "cam-nisley_cam.ngc",
    "m98m99-05-loops.ngc",
)
CLASSES = ("ok", "clean", "nonfinite", "wrong", "crash", "hang")
BAD = ("crash", "hang", "nonfinite", "wrong")
_RANK = {c: i for i, c in enumerate(CLASSES)}

D400 = "9" * 400
#: Replacements of one number of a block.
NUMBERS = (
    D400, "-" + D400, "1" + "0" * 30, "1E308", "1e400", "INF", "-INF", "NAN", "0", "-0", "0.0",
    "0.0000001", "-0.0000001", "1000000000", "99999999999", "2147483648", "-1", ".", "-", "",
    "1.5.5", "+", "00000000000000000000001",
)
#: Whole blocks inserted at a random place.
BLOCKS = (
    "G91 G81 X1 Z-1 R1 F100 L1000000000",
    "G83 X1 Y1 Z-1 R1 Q0.0000001 F100",
    f"G83 X1 Y1 Z-{D400} R1 Q1 F100",
    "G2 X1 I1 P1000000000 F100",
    "G2 X1 Y0 I0.5 P1000000000 F100",
    "G0 X1000000000",
    f"G0 X{D400}",
    "G1 X2400000000000000000 F100",
    "T99999999999 M6",
    f"T{D400} M6",
    f"G{D400}",
    f"M{D400}",
    f"G43 H{D400}",
    f"G10 L2 P{D400} X1",
    f"G10 L2 P1 X{D400}",
    "G10 L2 P1 X1E308",
    f"G1 X1 F{D400}",
    f"G2 X1 R{D400} F100",
    "#1=[1/0]",
    "#1=[1/0]\nG0 X#1",
    "O100 while [1]\nO100 endwhile",
    "O100 sub\nO100 call\nO100 endsub",
    "M98 P100 L1000000000",
    "G20",
    "G91",
    "G18 G2 X1 Z1 K1 F100",
    "G19 G3 Y1 Z1 R-1 F100",
    "G92 X1E300",
    "G81 X1 Z-1 R1 F100 L0",
    "G82 X1 Z-1 R1 P-1 F100",
)
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)")
_LONG_DIGITS = re.compile(r"\d{13,}")


def short(s: str, width: int = 160) -> str:
    """A line for the report: long digit runs abbreviated, the whole cut to ``width``."""
    s = _LONG_DIGITS.sub(lambda m: f"{m.group()[:3]}...<{len(m.group())} digits>", s)
    return s if len(s) <= width else s[: width - 3] + "..."


def load_programs(n_lines: int) -> dict[str, list[str]]:
    """The fuzzed programs, each cut to its first ``n_lines`` lines."""
    out = {}
    for name in PROGRAMS:
        path = DATA / name
        if path.exists():
            with open(path, encoding="utf-8", errors="replace", newline="") as fh:
                out[name] = fh.read().splitlines()[:n_lines]
    if len(out) < 4:
        raise SystemExit(f"need at least 4 programs of {PROGRAMS} in {DATA}, found {sorted(out)}")
    return out


def mutate(lines: list[str], rng: np.random.Generator) -> tuple[list[str], list[str], int]:
    """One mutant: 1 to 3 mutations. Returns the lines, the mutations described, and the
    (1-based) line of the last mutation."""
    lines = list(lines)
    done: list[str] = []
    at = 1
    for _ in range(int(rng.integers(1, 4))):
        op = rng.choice(("number", "number", "number", "insert", "dup", "delete", "swap",
                         "truncate", "bytes"))
        i = int(rng.integers(len(lines))) if lines else 0
        if op == "number":
            spots = [(j, m) for j in (i, *rng.integers(len(lines), size=8))
                     for m in _NUMBER.finditer(lines[j])] if lines else []
            if not spots:
                op = "insert"
            else:
                j, m = spots[int(rng.integers(len(spots)))]
                new = str(rng.choice(NUMBERS))
                if rng.random() < 0.15 and m.group().lstrip("+-"):
                    new = "-" + m.group().lstrip("+-")
                old = lines[j]
                lines[j] = old[: m.start()] + new + old[m.end():]
                done.append(f"line {j + 1}: number {m.group()!r} -> {short(new, 40)!r}")
                at = j + 1
                continue
        if op == "insert":
            block = str(rng.choice(BLOCKS))
            lines[i:i] = block.split("\n")
            done.append(f"line {i + 1}: insert {short(block, 60)!r}")
        elif op == "dup" and lines:
            lines.insert(i, lines[i])
            done.append(f"line {i + 1}: duplicate")
        elif op == "delete" and lines:
            del lines[i]
            done.append(f"line {i + 1}: delete")
        elif op == "swap" and lines:
            j = int(rng.integers(len(lines)))
            lines[i], lines[j] = lines[j], lines[i]
            done.append(f"lines {i + 1}, {j + 1}: swap")
        elif op == "truncate" and lines:
            k = int(rng.integers(len(lines[i]) + 1))
            lines[i] = lines[i][:k]
            done.append(f"line {i + 1}: truncate at {k}")
        elif op == "bytes" and lines:
            raw = bytes(rng.integers(0, 256, size=int(rng.integers(1, 6)), dtype=np.uint8))
            junk = raw.decode("latin-1")
            k = int(rng.integers(len(lines[i]) + 1))
            lines[i] = lines[i][:k] + junk + lines[i][k:]
            done.append(f"line {i + 1}: insert bytes {raw.hex()} at {k}")
        at = i + 1
    return lines, done, at


# ---------------------------------------------------------------- child side


_LOCATED = re.compile(r"^.+:\d+(?::\d+)?: .+")


def _error(cls: str, exc: BaseException) -> dict:
    tb = traceback.extract_tb(exc.__traceback__)
    frame = f"{Path(tb[-1].filename).name}:{tb[-1].lineno} in {tb[-1].name}" if tb else "?"
    last = traceback.format_exception_only(type(exc), exc)[-1].strip()
    return {"class": cls, "type": type(exc).__name__, "frame": frame, "last": short(last, 240)}


def _moves_problem(moves: np.ndarray) -> tuple[str, str] | None:
    kind = moves["kind"]
    arc = kind >= 2
    checks = (
        ("end", np.isfinite(moves["end"]).all(axis=1)),
        ("center", ~arc | np.isfinite(moves["center"]).all(axis=1)),
        ("sweep", ~arc | np.isfinite(moves["sweep"])),
        ("feed", (kind == 0) | np.isfinite(moves["feed"])),
        ("start", np.isfinite(moves["start"]).all(axis=1)),
    )
    bad = ~np.logical_and.reduce([ok for _, ok in checks])
    if bad.any():  # the first bad move, and the first of its checks that fails
        i = int(np.argmax(bad))
        name = next(n for n, ok in checks if not ok[i])
        return "nonfinite", f"move {i} (line {int(moves['line'][i])}): non-finite {name}"
    if (moves["tool"] < 0).any():
        i = int(np.argmax(moves["tool"] < 0))
        return "wrong", (f"move {i} (line {int(moves['line'][i])}): "
                         f"tool {int(moves['tool'][i])}")
    return None


def run_one(text: str, name: str) -> dict:
    """Read ``text`` both ways and cut the programs into positions; the worst outcome."""
    from zmap.errors import ZMapError
    from zmap.sim.gcode import parse
    from zmap.sim.path import positions

    worst = {"class": "ok"}
    for lenient in (False, True):
        stage = "parse"
        try:
            prog = parse(text, lenient=lenient, filename=name)
            got = _moves_problem(prog.moves)
            stage = "positions"
            if got is not None:
                res = {"class": got[0], "type": "", "frame": "", "last": got[1]}
                try:
                    positions(prog)
                    res["last"] += "; positions accepted it"
                except ZMapError as e:
                    res["last"] += f"; positions: {type(e).__name__}"
                except Exception as e:  # noqa: BLE001 - a crash is what this looks for
                    res["last"] += f"; positions: {type(e).__name__}: {short(str(e), 80)}"
            else:
                positions(prog)
                res = {"class": "ok"}
        except ZMapError as e:
            res = _error("clean" if _LOCATED.match(str(e)) else "crash", e)
        except Exception as e:  # noqa: BLE001 - a crash is what this looks for
            res = _error("crash", e)
        res["mode"] = f"{'lenient' if lenient else 'strict'} {stage}"
        if _RANK[res["class"]] > _RANK[worst["class"]]:
            worst = res
    return worst


def _child(conn, memory_gb: float) -> None:
    import resource

    limit = int(memory_gb * 1024**3)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    while True:
        job = conn.recv()
        if job is None:
            return
        try:
            out = run_one(*job)
        except MemoryError as e:  # raised outside run_one's own handlers
            out = _error("crash", e)
        conn.send(out)


class _Worker:
    """One child process fed one mutant at a time; killed and replaced when it overruns."""

    def __init__(self, ctx, memory_gb: float):
        self.ctx, self.memory_gb = ctx, memory_gb
        self._start()

    def _start(self) -> None:
        self.conn, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(target=_child, args=(child, self.memory_gb), daemon=True)
        self.proc.start()
        child.close()
        self.job = None
        self.t0 = 0.0

    def submit(self, job) -> None:
        self.job = job
        self.t0 = time.monotonic()
        self.conn.send(job[1])

    def poll(self, timeout: float) -> dict | None:
        """The answer, a hang record after ``timeout`` s, or None while still within it."""
        if self.conn.poll(0):
            try:
                return self.conn.recv()
            except EOFError:
                pass
        elif self.proc.is_alive() and time.monotonic() - self.t0 < timeout:
            return None
        alive = self.proc.is_alive()
        self.proc.kill()
        self.proc.join()
        code = self.proc.exitcode
        self._start()
        if alive:
            return {"class": "hang", "type": "timeout", "frame": "", "mode": "",
                    "last": f"no answer in {timeout:g} s"}
        return {"class": "crash", "type": "died", "frame": "", "mode": "",
                "last": f"child exited with code {code}"}

    def close(self) -> None:
        try:
            self.conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        self.proc.join(2)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()


def fuzz(n_mutants: int, seed: int, timeout: float, jobs: int, n_lines: int,
         memory_gb: float, n_examples: int) -> dict:
    """Run the fuzzer; the report as a dict."""
    import zmap.sim.gcode  # noqa: F401 - imported before forking, so children start warm
    import zmap.sim.path  # noqa: F401

    programs = load_programs(n_lines)
    names = sorted(programs)
    rng = np.random.default_rng(seed)
    todo = []
    for k in range(n_mutants):
        name = names[k % len(names)]
        lines, done, at = mutate(programs[name], rng)
        line = lines[at - 1] if 0 < at <= len(lines) else ""
        todo.append((k, (("\n".join(lines) + "\n"), name), name, done, line))
    todo.reverse()

    ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    workers = [_Worker(ctx, memory_gb) for _ in range(max(1, jobs))]
    counts: Counter = Counter()
    per_program: dict[str, Counter] = {n: Counter() for n in names}
    kinds: dict[str, Counter] = {c: Counter() for c in BAD}
    examples: dict[str, list] = {c: [] for c in BAD}
    t0 = time.perf_counter()
    busy: dict[int, tuple] = {}
    try:
        while todo or busy:
            for w_i, w in enumerate(workers):
                if w_i not in busy and todo:
                    item = todo.pop()
                    busy[w_i] = item
                    w.submit((item[0], item[1]))
            time.sleep(0.001)
            for w_i in list(busy):
                res = workers[w_i].poll(timeout)
                if res is None:
                    continue
                k, _job, name, done, line = busy.pop(w_i)
                cls = res["class"]
                counts[cls] += 1
                per_program[name][cls] += 1
                if cls in BAD:
                    if res.get("type") in ("timeout", "died"):  # named by what was done
                        kind = f"{res['type']} after " + "; ".join(
                            re.sub(r"^lines? [\d, ]+: ", "", m) for m in done)
                    else:
                        kind = " ".join(x for x in (res.get("type"), res.get("frame")) if x) \
                            or re.sub(r"move \d+ \(line \d+\): ", "", res["last"]).split(";")[0]
                    kinds[cls][kind] += 1
                    if len(examples[cls]) < n_examples or \
                            (kinds[cls][kind] == 1 and len(examples[cls]) < 4 * n_examples):
                        examples[cls].append({
                            "mutant": k, "program": name, "mutations": done,
                            "mutated_line": short(line), "mode": res.get("mode", ""),
                            "kind": kind, "last": res["last"]})
    finally:
        for w in workers:
            w.close()
    return {
        "mutants": n_mutants,
        "seed": seed,
        "timeout_s": timeout,
        "jobs": jobs,
        "lines_per_program": n_lines,
        "memory_gb": memory_gb,
        "programs": names,
        "seconds": round(time.perf_counter() - t0, 1),
        "counts": {c: counts.get(c, 0) for c in CLASSES},
        "per_program": {n: {c: per_program[n].get(c, 0) for c in CLASSES} for n in names},
        "kinds": {c: dict(kinds[c].most_common()) for c in BAD},
        "examples": examples,
        "targets": {
            "crash==0": counts.get("crash", 0) == 0,
            "hang==0": counts.get("hang", 0) == 0,
            "nonfinite==0": counts.get("nonfinite", 0) == 0,
            "wrong==0": counts.get("wrong", 0) == 0,
            "mutants>=2000": n_mutants >= 2000,
            "programs>=4": len(names) >= 4,
        },
    }


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mutants", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=10.0, help="seconds per mutant")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--lines", type=int, default=300, help="lines kept of each program")
    ap.add_argument("--memory-gb", type=float, default=4.0, help="RLIMIT_AS of each child")
    ap.add_argument("--examples", type=int, default=3, help="examples kept per bad class")
    a = ap.parse_args(argv)
    out = fuzz(a.mutants, a.seed, a.timeout, a.jobs, a.lines, a.memory_gb, a.examples)
    json.dump(out, sys.stdout, indent=1)
    print()
    return out


if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    main()
