"""zmap.verify.collisions: rapids that cut, flat plunges, shank and holder contacts."""

from __future__ import annotations

import pytest

from zmap.errors import ToolError, ZMapError
from zmap.sim import simulate
from zmap.sim.tools import Cutter
from zmap.verify import Holder, collisions, load_holders

BOX = (0, 0, -10, 20, 20, 0)


def _run(tmp_path, text, cutter, history="treap"):
    p = tmp_path / "p.ngc"
    p.write_text(text)
    return p, simulate(p, BOX, tool=cutter, pitch=0.25, history=history)


def test_rapid_into_stock_named_by_line(tmp_path):
    prog = "G21 G90\nG0 X5 Y5 Z5\nG0 Z-1\nG1 X8 F100\nG0 Z5\nG0 X15\n"
    p, run = _run(tmp_path, prog, "ball:2")
    hits = collisions(run, p, kinds=["rapid"])
    assert [h.line for h in hits] == [3]
    h = hits[0]
    assert h.kind == "rapid" and run.line[h.stage - 1] == 3
    assert h.z <= 0.0 and (h.x, h.y) == pytest.approx((5.0, 5.0))
    # the same path with a feed instead: no rapid collision
    p2, run2 = _run(tmp_path, prog.replace("G0 Z-1", "G1 Z-1 F50"), "ball:2")
    assert collisions(run2, p2, kinds=["rapid"]) == []


@pytest.mark.slow
def test_flat_plunge_but_not_ball(tmp_path):
    prog = "G21 G90\nG0 X5 Y5 Z2\nG1 Z-1 F50\nG1 X10\nG0 Z2\nG0 X15\nG1 Z0.5\n"
    p, run = _run(tmp_path, prog, "flat:4")
    hits = collisions(run, p, kinds=["plunge"])
    assert [h.line for h in hits] == [3]
    assert hits[0].depth > 0
    p, run = _run(tmp_path, prog, "ball:4")
    assert collisions(run, p, kinds=["plunge"]) == []


def test_shank_above_cutting_length(tmp_path):
    prog = "G21 G90\nG0 X5 Y5 Z2\nG1 Z-3 F50\nG1 X12\nG0 Z2\n"
    p, run = _run(tmp_path, prog, Cutter("flat", 2, length=1.0))
    hits = collisions(run, p, kinds=["shank"])
    # the plunge clears its own column flute-length by flute-length; the side move on line 4
    # leaves 2 mm of wall above the flutes, where the shank rubs (and again on the retract)
    assert hits and hits[0].line == 4
    assert max(h.depth for h in hits) == pytest.approx(2.0, abs=0.05)  # 3 deep, 1 of flute
    p, run = _run(tmp_path, prog, Cutter("flat", 2, length=5.0))
    assert collisions(run, p, kinds=["shank"]) == []


def test_missing_holder_data_names_the_ways_out(tmp_path):
    prog = "G21 G90\nG0 X10 Y10 Z2\nG1 Z-3 F50\nG1 X12\nG0 Z5\n"
    p, run = _run(tmp_path, prog, Cutter("ball", 2, length=10.0))
    with pytest.raises(ToolError, match="holder data") as info:
        collisions(run, p)
    assert "--no-holder" in str(info.value) and "--holders FILE" in str(info.value)
    with pytest.raises(ToolError, match=r"no holder data for tool T0") as info:
        collisions(run, p, holders={7: Holder(20, 10)})
    assert "[holder.0]" in str(info.value) and "--no-holder" in str(info.value)
    assert "--holders FILE" in str(info.value)


def test_holder_needs_data_and_finds_contact(tmp_path):
    prog = "G21 G90\nG0 X10 Y10 Z2\nG1 Z-3 F50\nG1 X12\nG0 Z5\n"
    p, run = _run(tmp_path, prog, Cutter("ball", 2, length=10.0))
    with pytest.raises(ToolError, match="holder data"):
        collisions(run, p)
    with pytest.raises(ToolError, match="T0"):
        collisions(run, p, holders={7: Holder(20, 10)})
    hits = collisions(run, p, holders={0: Holder(stickout=2.0, diameter=12.0)}, kinds=["holder"])
    assert hits and hits[0].kind == "holder" and hits[0].line == 3
    assert collisions(run, p, holders={0: Holder(stickout=12.0, diameter=12.0)}, kinds=["holder"]) == []
    t = tmp_path / "h.toml"
    t.write_text('[tool.0]\nkind = "ball"\ndiameter = 2\n[holder.0]\nstickout = 2\ndiameter = 12\nlength = 30\n')
    assert collisions(run, p, holders=t, kinds=["holder"])[0].line == 3
    assert load_holders(t)[0] == Holder(2.0, 12.0, 30.0)


def test_bad_holder_table_and_history(tmp_path):
    t = tmp_path / "h.toml"
    t.write_text("[holder.1]\nstickout = -2\ndiameter = 12\n")
    with pytest.raises(ToolError, match="holder.1.*stickout"):
        load_holders(t)
    t.write_text("[holder.1]\ndiameter = 12\n")
    with pytest.raises(ToolError, match="needs 'stickout'"):
        load_holders(t)
    prog = "G21 G90\nG0 X5 Y5 Z2\nG1 Z-1 F50\n"
    p, run = _run(tmp_path, prog, "flat:2", history="ztrace")
    with pytest.raises(ZMapError, match="treap"):
        collisions(run, p, kinds=["rapid"])
    p, run = _run(tmp_path, prog, "flat:2")
    other = tmp_path / "other.ngc"
    other.write_text("G21 G90\nG0 X5 Y5 Z2\nG1 Z-1 F50\nG1 X9\n")
    with pytest.raises(ZMapError, match="does not match the run"):
        collisions(run, other, kinds=["rapid"])
    with pytest.raises(ValueError, match="not one of"):
        collisions(run, p, kinds=["crash"])


def test_rapid_found_in_a_run_with_one_stage_per_move(tmp_path):
    prog = "G21 G90\nG0 X5 Y5 Z5\nG0 Z-1\nG1 X8 F100\nG0 Z5\nG0 X15\n"
    p = tmp_path / "move.nc"
    p.write_text(prog)
    run = simulate(str(p), (0, 0, -5, 20, 10, 0), tool="ball:2", pitch=0.5, history="treap", stages="move")
    assert run.n_stages == 5
    hits = collisions(run, str(p), kinds=["rapid"])
    assert [(h.line, h.stage) for h in hits] == [(3, 2)]
