import numpy as np
import pytest

from zmap.surfaces import SURFACES, TABLE1, get


@pytest.mark.parametrize("name", list(SURFACES))
def test_gradient_matches_finite_differences(name):
    s = get(name)
    x0, y0, x1, y1 = s.domain
    rng = np.random.default_rng(0)
    x, y = rng.uniform(x0, x1, 400), rng.uniform(y0, y1, 400)
    ok = np.isfinite(s.height(x, y))
    x, y = x[ok], y[ok]
    h = 1e-5
    gx, gy = s.gradient(x, y)
    fdx = (s.height(x + h, y) - s.height(x - h, y)) / (2 * h)
    fdy = (s.height(x, y + h) - s.height(x, y - h)) / (2 * h)
    good = np.isfinite(fdx) & np.isfinite(fdy)
    np.testing.assert_allclose(gx[good], fdx[good], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(gy[good], fdy[good], rtol=1e-5, atol=1e-6)
    n = s.normal(x, y)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0)
    assert (n[:, 2] > 0).all()


def test_table1_surfaces_are_the_papers():
    assert TABLE1 == ("sphere", "sine100", "sine1000")
    sphere = get("sphere")
    assert sphere.height(0.0, 0.0) == 100.0
    assert np.isnan(sphere.height(72.0, 0.0))  # z = 69.4 < 70: not on the cap
    assert get("sine1000").height(90.0, 3.0) == pytest.approx(1000.0)
    assert get("sine100").height(-90.0, 0.0) == pytest.approx(-100.0)


def test_unknown_surface():
    with pytest.raises(ValueError, match="surface='cone' is not one of"):
        get("cone")
