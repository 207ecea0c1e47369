"""The reader against LinuxCNC's own interpreter: moves of its test programs vs their .expected.

For each LinuxCNC interpreter test program in ``data/gcode`` that ships with the canonical
output of LinuxCNC's ``rs274 -g`` (``.expected``), parses the program with
:func:`zmap.sim.gcode.parse` and compares every STRAIGHT_TRAVERSE / STRAIGHT_FEED /
ARC_FEED in order: the move kind (and an arc's direction and turns), end points and arc
centres in program units. The reference prints 4 decimals, so a move matches when every
number is within 0.5e-4 of it. Prints one JSON object.

    python bench/linuxcnc_expected.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from zmap.sim.canon import expected_moves, program_moves
from zmap.sim.gcode import parse

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
#: program, tool table (None: none), as LinuxCNC's test.sh runs them
PROGRAMS = [("cam-nisley_cam", "cam-nisley_test.tbl"), ("m98m99-05-loops", None),
            ("g17-g99-g81", None)]
def compare(name: str, table: str | None) -> dict:
    want = expected_moves(DATA / f"{name}.expected")
    got = program_moves(parse(DATA / f"{name}.ngc", tool_table=DATA / table if table else None))
    worst, first_bad, matching = 0.0, None, 0
    for k, ((kw, vw), (kg, vg)) in enumerate(zip(want, got)):
        diff = float(np.max(np.abs(np.subtract(vw, vg)))) if kw == kg else float("inf")
        worst = max(worst, diff)
        if diff <= 0.5e-4 + 1e-9:
            matching += 1
        elif first_bad is None:
            first_bad = {"move": k, "expected": [kw, vw], "got": [kg, [round(v, 6) for v in vg]]}
    return {"expected_moves": len(want), "our_moves": len(got), "matching": matching,
            "max_abs_diff": worst, "first_difference": first_bad,
            "match": len(want) == len(got) == matching}


def main() -> dict:
    res = {name: compare(name, table) for name, table in PROGRAMS}
    out = {"bench": "linuxcnc_expected", "programs": res,
           "matching_programs": sum(r["match"] for r in res.values()), "of": len(res)}
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
