"""One memory rule: the sampler's grid, a tiled window and a program's positions are refused
above the same share of the memory available, each naming what it would have needed."""

from __future__ import annotations

import math

import numpy as np
import pytest

import zmap.memory
from zmap import ZMap
from zmap.errors import GridTooLargeError, PathTooLargeError
from zmap.memory import MEMORY_SHARE, check_room, memory_limit


@pytest.fixture
def little_memory(monkeypatch):
    """As if 100 KB were available: 80 KB of room for one piece of work."""
    monkeypatch.setattr(zmap.memory, "available_bytes", lambda: 102_400)
    return 102_400


def test_room_is_the_share_of_what_is_available(little_memory):
    assert memory_limit() == (MEMORY_SHARE * little_memory, little_memory)
    assert check_room(MEMORY_SHARE * little_memory, "exactly the room", "") == MEMORY_SHARE * little_memory
    with pytest.raises(GridTooLargeError, match=r"^a block needs about 80 KB, more than 80% of the 100 KB "
                                                r"of memory available; do less$"):
        check_room(MEMORY_SHARE * little_memory + 1, "a block", "do less")
    with pytest.raises(KeyError):
        check_room(math.inf, "a block", "do less", error=KeyError)


def test_the_sampler_grid_follows_the_rule(little_memory):
    from cad_io.sampler import check_grid_memory, estimate_bytes

    small = check_grid_memory(10, 10)
    assert small == estimate_bytes(10, 10) <= MEMORY_SHARE * little_memory
    with pytest.raises(GridTooLargeError, match=r"grid of 1,000 x 1,000 = 1,000,000 points needs about .* "
                                                r"use a coarser grid or smaller bounds"):
        check_grid_memory(1000, 1000)


def test_a_tiled_window_follows_the_rule(little_memory, tmp_path):
    from zmap.tiled import TiledZMap

    zm = ZMap.from_function(lambda x, y: x * y, (0, 0, 40, 40), 0.25)  # 161 x 161 nodes, 207 kB
    store = TiledZMap.from_zmap(zm, tmp_path / "m.zarr", tile=64)
    assert np.array_equal(store.to_zmap((0, 0, 5, 5)).z, zm.z[:21, :21])
    with pytest.raises(GridTooLargeError, match=r"window of 161 x 161 = 25,921 nodes needs about .* "
                                                r"read a smaller window or work tile by tile"):
        store.to_zmap()


def test_a_programs_positions_follow_the_rule(little_memory):
    from zmap.sim.gcode import parse
    from zmap.sim.path import positions

    # 1e8 positions (gigabytes), under the default cap: only the memory refuses them
    prog = parse("G21 G90 G17\nG0 X0 Y0 Z1\nG1 X999999 F100\n", filename="long.nc")
    with pytest.raises(PathTooLargeError, match=r"^long\.nc:3: .* more than the .* that fit in 80% of the "
                                                r"100 KB of memory available"):
        positions(prog, pitch=0.01)
