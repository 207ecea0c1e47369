"""LinuxCNC .tbl tool tables: reading, units, G43 length offsets, compensation radius, simulation."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import GCODE_DATA
from zmap.errors import GCodeError, ToolError
from zmap.sim.gcode import parse
from zmap.sim.tools import TableTool, load_linuxcnc_tool_table, load_tool_table


def test_reads_the_linuxcnc_test_table_in_inches():
    table = load_tool_table(GCODE_DATA / "cam-nisley_test.tbl")  # dispatches on .tbl
    assert sorted(table) == [1, 2, 3, 4, 32]
    t1 = table[1]
    assert isinstance(t1, TableTool)
    assert t1.diameter == pytest.approx(0.0625 * 25.4) and t1.length_offset == pytest.approx(12.7)
    assert t1.pocket == 1 and t1.comment == "first tool"
    assert table[32].diameter == 0.0
    mm = load_linuxcnc_tool_table(GCODE_DATA / "cam-nisley_test.tbl", units="mm")
    assert mm[4].diameter == 1.0 and mm[4].length_offset == 0.7


@pytest.mark.parametrize("text,key", [
    ("P1 D0.5\n", "needs a T word"),
    ("T1.5 D1\n", "integer"),
    ("T1 D-1\n", "negative"),
    ("T1 D1 junk\n", "cannot read"),
    ("; only a comment\n", "no tools"),
])
def test_bad_tables_name_file_and_line(tmp_path, text, key):
    path = tmp_path / "bad.tbl"
    path.write_text(text)
    with pytest.raises(ToolError, match=key) as info:
        load_linuxcnc_tool_table(path)
    assert "bad.tbl" in str(info.value)
    with pytest.raises(ToolError, match="units"):
        load_linuxcnc_tool_table(path, units="cm")


def test_g43_shifts_the_tip_by_the_tool_length_offset(tmp_path):
    tbl = tmp_path / "t.tbl"
    tbl.write_text("T1 P1 Z10 D6\nT2 P2 Z25 D3\n")
    table = load_linuxcnc_tool_table(tbl, units="mm")
    p = parse("G21 G90\nT1 M6\nG0 Z50\nG43 H1\nG0 X5\nG43 H2 X6\nG0 Z5\nG49 X0\n", tool_table=table)
    # as LinuxCNC: the controlled point stays, the tip's programmed Z drops by the offset
    np.testing.assert_allclose(p.moves["end"], [[0, 0, 50], [5, 0, 40], [6, 0, 25], [6, 0, 5],
                                                [0, 0, 30]])
    with pytest.raises(GCodeError, match="not in the tool table") as info:
        parse("G43 H7\n", tool_table=table)
    assert info.value.word == "H7"


def test_g41_takes_its_radius_from_the_table(tmp_path):
    tbl = tmp_path / "t.tbl"
    tbl.write_text("T3 D4\n")
    prog = "G21 G90 G0 X-10 Y0\nG41 D3\nG1 X0 F100\nG1 Y10\nG40\nG0 X20\n"
    p = parse(prog, tool_table=load_linuxcnc_tool_table(tbl, units="mm"))
    # entry along +x with the tool on the left (y = 2), then a turn to +y: an inside corner,
    # so the entry ends where the two offset lines meet, x = -2
    np.testing.assert_allclose(p.moves["end"][1], [-2, 2, 0], atol=1e-12)
    np.testing.assert_allclose(p.moves["end"][2], [-2, 10, 0], atol=1e-12)
    with pytest.raises(GCodeError, match="not in the tool table"):
        parse(prog.replace("D3", "D9"), tool_table=load_linuxcnc_tool_table(tbl, units="mm"))


def test_simulate_with_a_tbl_uses_flat_cutters_of_its_diameters(tmp_path):
    from zmap.sim.session import simulate

    tbl = tmp_path / "t.tbl"
    tbl.write_text("T1 D0.25\nT9 D0\n")  # inches; T9 is never used
    run = simulate("G20 G90\nT1 M6\nG0 X0 Y0 Z0.1\nG1 Z-0.1 F10\nG1 X0.5\n",
                   (-5, -5, -5, 20, 5, 0), tools=str(tbl), pitch=0.5, history="none")
    heights = run.display(run.stage("1/1"))
    assert np.nanmin(heights) == pytest.approx(-2.54, abs=1e-6)
    with pytest.raises(ToolError, match="T9 has diameter 0"):
        simulate("T9 M6\nG0 X1\nG1 Z-1 F10\n", (-5, -5, -5, 5, 5, 0), tools=str(tbl),
                 pitch=0.5, history="none")
