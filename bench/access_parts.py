"""``zmap access`` on every real part of data/step and on an open die face.

Each part runs as a user would run it, ``zmap access PART --voxel 0.5 --q 4 --tool ball:6``
(no pictures), in a child process with a time limit; the open die face is the cornetta relief
of ``data/step/bug27693_cornetta-step.stp`` less its block's bottom and outer walls
(:func:`cad_io.access.top_faces`: a quilt of faces with free boundary edges and no solid),
written to a temporary STEP file first. Per part: the exit status ``rc``, the wall time of
the command ``seconds`` (reading the STEP file included; the first run also compiles the
kernels where numba's cache is cold), the material rule used, the share of the surface area
reachable from +z (``three_axis``), the uncertain share (walls or gaps thinner than the
voxel), and the command's last line where it failed.

Usage: ``python bench/access_parts.py [--voxel 0.5] [--timeout 900] [--parts NAME ...]
[--markdown]``; prints one JSON object (``--markdown``: the table instead).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DIE_FACE = "bug27693_cornetta-step.stp"


def run_one(path: Path, voxel: float, timeout: float, work: Path, extra=()) -> dict:
    import numpy as np

    out = work / (path.stem + ".access.npz")
    cmd = [sys.executable, "-m", "zmap.cli", "access", str(path), "--voxel", str(voxel), "--q", "4",
           "--tool", "ball:6", "-o", str(out), "--no-png", *extra]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
        rc, text = p.returncode, p.stdout + p.stderr
    except subprocess.TimeoutExpired as exc:
        rc, text = "timeout", f"stopped after {timeout:g} s " + str(exc.stderr or "")[-300:]
    sec = time.perf_counter() - t0
    row = {"part": path.name, "rc": rc, "seconds": round(sec, 1)}
    if rc == 0 and out.exists():
        with np.load(out) as z:
            head = json.loads(bytes(z["header"]).decode())
        v = head["verdict"]
        row.update(solid=head.get("solid"), solid_note=head.get("solid_note"),
                   three_axis_share=round(v["share"], 4), uncertain_share=round(v.get("uncertain_share", 0.0), 4),
                   pipeline_seconds=round(head["seconds"]["total"], 1))
        out.unlink()
    else:
        lines = [ln for ln in text.strip().splitlines() if ln.strip() and "Warning" not in ln]
        row["message"] = lines[-1][:400] if lines else ""
    return row


def markdown(rows: list[dict], voxel: float) -> str:
    out = [f"| part | rc | time (s) | material | 3-axis share | uncertain share | note |",
           "| --- | ---: | ---: | --- | ---: | ---: | --- |"]
    for r in rows:
        if r["rc"] == 0:
            out.append(f"| {r['part']} | 0 | {r['seconds']:.1f} | {r['solid']} | {100 * r['three_axis_share']:.1f} % "
                       f"| {100 * r['uncertain_share']:.2f} % | {r['solid_note']} |")
        else:
            out.append(f"| {r['part']} | {r['rc']} | {r['seconds']:.1f} | | | | {r.get('message', '')} |")
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--voxel", type=float, default=0.5)
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--parts", nargs="*", default=None, help="file names in data/step (default: all), "
                    "'die-face' for the open die face")
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args()
    parts = sorted((ROOT / "data" / "step").iterdir())
    want = a.parts
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for path in parts:
            if want is None or path.name in want:
                rows.append(run_one(path, a.voxel, a.timeout, work))
                print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
        if want is None or "die-face" in want:
            from cad_io.access import top_faces

            die = work / "cornetta_die_face.step"
            _, kept, left = top_faces(ROOT / "data" / "step" / DIE_FACE, die)
            row = run_one(die, a.voxel, a.timeout, work)
            row["part"] = f"open die face ({DIE_FACE}: {kept} faces, bottom and outer walls left out)"
            rows.append(row)
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    if a.markdown:
        print(markdown(rows, a.voxel))
    else:
        print(json.dumps({"voxel": a.voxel, "q": 4, "tool": "ball:6", "cpus": os.cpu_count(), "parts": rows,
                          "table": markdown(rows, a.voxel)}))


if __name__ == "__main__":
    main()
