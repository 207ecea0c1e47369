"""Sizes and counts as people read them (zmap.fmt)."""

import math

import pytest

from zmap.fmt import count, size


@pytest.mark.parametrize("nbytes, text", [
    (0, "0 B"), (1023, "1023 B"), (1024, "1 KB"), (299_008, "292 KB"), (3_494_988, "3.33 MB"),
    (2_080_000.47e9, "1,892 TB"), (1.5 * 1024**3, "1.5 GB"),
    (10**40, "9.09e+27 TB"), (-2048, "-2 KB"),
])
def test_size(nbytes, text):
    assert size(nbytes) == text


@pytest.mark.parametrize("n, text", [
    (0, "0"), (32_361, "32,361"), (999_999_999, "999,999,999"), (1_930_000_000, "1.93e+09"),
    (10**100, "1e+100"), (math.inf, "inf"), (-12_345, "-12,345"), (3.6, "4"),
])
def test_count(n, text):
    assert count(n) == text


def test_no_long_digit_runs_in_a_refusal():
    from cad_io.sampler import check_grid_memory
    from zmap.errors import GridTooLargeError

    with pytest.raises(GridTooLargeError) as info:
        check_grid_memory(10**50, 10**50)
    msg = str(info.value)
    assert "1e+50 x 1e+50 = 1e+100 points" in msg and " TB" in msg
    assert max(len(w) for w in msg.replace(",", " ").split()) < 12, msg
