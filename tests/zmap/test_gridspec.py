"""One covering rule for every map made over a domain (zmap.gridspec)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zmap import ZMap
from zmap.gridspec import GridSpec, lines_covering, lines_within



@settings(max_examples=200, deadline=None)
@given(lo=st.floats(-1e3, 1e3), span=st.floats(0, 500), step=st.floats(0.01, 10))
def test_lines_within_stay_inside_and_are_one_short_of_covering_at_most(lo, span, step):
    hi = lo + span
    n = lines_within(lo, hi, step)
    assert n >= 1
    assert lo + (n - 1) * step <= hi + 1e-9 * step + 1e-9 * abs(hi)  # inside
    assert lo + n * step > hi  # the next line would fall beyond
    assert lines_covering(lo, hi, step, at_least=1) in (n, n + 1)

@settings(max_examples=200, deadline=None)
@given(lo=st.floats(-1e3, 1e3), span=st.floats(0, 500), step=st.floats(0.01, 10))
def test_lines_cover_the_domain_and_no_line_is_needless(lo, span, step):
    hi = lo + span
    n = lines_covering(lo, hi, step)
    assert n >= 2
    assert lo + (n - 1) * step >= hi - 1e-9 * step - 1e-9 * abs(hi)  # covers
    if n > 2:
        assert lo + (n - 2) * step < hi  # the line before the last falls short


def test_whole_intervals_end_on_the_domain_and_centred_lines_overhang_equally():
    assert GridSpec.covering((0, 0, 10, 5), 1.0).bounds == (0.0, 0.0, 10.0, 5.0)
    assert GridSpec.covering((0, 0, 10 + 1e-12, 5), 1.0).shape == (11, 6)
    g = GridSpec.covering((0, 0, 10.2, 5.0), 1.0, centred=True)
    x0, y0, x1, y1 = g.bounds
    assert g.shape == (12, 6) and math.isclose(-x0, x1 - 10.2) and (y0, y1) == (0.0, 5.0)
    assert g.window == (x0 - 1.0, y0 - 1.0, x1 + 1.0, y1 + 1.0)


def test_from_function_and_the_sampler_take_the_same_lines():
    from cad_io.sampler import grid_shape

    for bounds in [(0, 0, 10, 5), (0, 0, 10.2, 5.01), (-3.3, 1.1, 4.05, 2.2)]:
        zm = ZMap.from_function(lambda x, y: x + y, bounds, 0.5)
        assert zm.shape == grid_shape(bounds, 0.5, 0.5) == GridSpec.covering(bounds, 0.5).shape
        assert zm.spec == GridSpec.covering(bounds, 0.5)
        np.testing.assert_array_equal(zm.x, zm.spec.x)


@pytest.mark.parametrize("bounds, dx, match", [((0, 0, -1, 1), 1.0, "x1 >= x0"), ((0, 0, 1, float("nan")), 1.0, "finite"),
                                               ((0, 0, 1, 1), 0.0, "positive")])
def test_bad_domains_and_intervals_are_refused(bounds, dx, match):
    with pytest.raises(ValueError, match=match):
        GridSpec.covering(bounds, dx)
