"""Table 1 of paper 004, reproduced (fewer points than the CLI's 10^6 to stay fast)."""

import pytest

from zmap.accuracy import accuracy_rows, format_csv, format_markdown

# Table 1: column A (Bezier) and column B (bilinear), largest deviation magnitudes.
COLUMN_A = {"sphere": 3.0e-6, "sine100": 1.2e-5, "sine1000": 2.1e-4}
COLUMN_B = {"sphere": 3.7e-3, "sine100": 3.8e-3, "sine1000": 3.8e-2}


@pytest.fixture(scope="module")
def table():
    rows = accuracy_rows(n_points=200_000, seed=7)
    return {(r.surface, r.scheme): r for r in rows}


@pytest.mark.parametrize("surface", list(COLUMN_B))
def test_bilinear_matches_column_b(table, surface):
    r = table[surface, "bilinear"]
    assert r.max_abs == pytest.approx(COLUMN_B[surface], rel=0.05)
    if surface == "sphere":
        assert r.max_dev < 0  # a cap is always under-estimated by bilinear
    else:
        assert r.min_dev == pytest.approx(-r.max_dev, rel=0.01)


@pytest.mark.parametrize("surface", ["sphere", "sine100"])
def test_circle_tangent_bezier_within_2x_of_column_a(table, surface):
    assert table[surface, "bezier"].max_abs <= 2 * COLUMN_A[surface]


def test_circle_tangent_is_not_scale_invariant(table):
    # 1000*sin: the literal circle fit loses its tangent accuracy (~2e-3, see README).
    assert 1e-3 < table["sine1000", "bezier"].max_abs < 4e-3


@pytest.mark.parametrize("surface", list(COLUMN_A))
def test_best_scheme_at_or_below_column_a(table, surface):
    assert table[surface, "bezier-quartic"].max_abs <= COLUMN_A[surface]


def test_plane_and_formats():
    rows = accuracy_rows(["plane"], [0.7, 1.3], n_points=5000)
    assert all(r.max_abs <= 1e-12 for r in rows)
    csv = format_csv(rows).splitlines()
    assert csv[0] == "surface,grid,scheme,min_dev,max_dev"
    assert len(csv) == 1 + 2 * 4
    md = format_markdown(rows)
    assert md.count("\n") == 3 and "bezier-quartic (min / max)" in md


def test_bad_arguments():
    with pytest.raises(ValueError, match="scheme='spline'"):
        accuracy_rows(["plane"], schemes=["spline"], n_points=10)
    with pytest.raises(ValueError, match="grid interval"):
        accuracy_rows(["plane"], grids=[0.0], n_points=10)
    with pytest.raises(ValueError, match="n_points"):
        accuracy_rows(["plane"], n_points=0)
    with pytest.raises(ValueError, match="surface="):
        accuracy_rows(["cone"], n_points=10)
