"""The dense drop-cutter reference (tests.reference.cam.drop_cutter_reference_dense) against
analytic contacts where a lattice alone misses them: a sliver of wall at the rim, a wiggly
crest; and drop_cutter against it."""

from __future__ import annotations

import numpy as np
import pytest

from zmap.cam import drop_cutter
from tests.reference.cam import drop_cutter_reference, drop_cutter_reference_dense
from zmap.sim.tools import parse_tool_spec

# one xdist worker compiles this family's numba kernels once (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("cam")


def _nearest_on_curve(qx, qy, e, y0, y1, n=2_000_001):
    """min distance from (qx, qy) to the curve x = e(y), y in [y0, y1], and the point."""
    y = np.linspace(y0, y1, n)
    d = np.hypot(e(y) - qx, y - qy)
    k = int(np.argmin(d))
    # polish with a finer scan about the best sample
    yy = np.linspace(y[max(k - 1, 0)], y[min(k + 1, n - 1)], 20_001)
    dd = np.hypot(e(yy) - qx, yy - qy)
    return float(dd.min())


@pytest.mark.parametrize("spec", ["ball:6", "bull:6:1"])
def test_sliver_at_the_rim(spec):
    """A wall whose top reaches 0.002 mm into the disk: narrower than the lattice (0.02 mm);
    the contact is the top's point nearest the axis, (R - 0.002, 0)."""
    c = parse_tool_spec(spec)
    R = c.radius
    xw = R - 0.002
    f = lambda x, y: np.where(x > xw, 3.0, 0.0)
    want = 3.0 - float(c.lower_envelope(np.array([xw]))[0])
    got = drop_cutter_reference_dense(f, c, [0.0], [0.0], h=0.02)[0]
    assert abs(got - want) < 1e-6
    # the plain lattice reference (its rim points and finer lattices about its best point)
    # stops above the exact contact's error budget here; the dense one does not
    old = drop_cutter_reference(f, c, [0.0], [0.0], h=0.02, levels=3)[0]
    assert old <= got + 1e-12
    ours = float(drop_cutter(f, c, 0.0, 0.0, pitch=0.1))
    assert ours >= want - 1e-9  # sampled, the sliver bounded on its safe side: never below


def test_wiggly_crest():
    """A wall whose edge wiggles by 3 um every 0.06 mm: local maxima of the contact along the
    crest; the true CL is 3 - envelope(distance from the axis to the nearest edge point)."""
    c = parse_tool_spec("ball:6")
    e = lambda y: 1.2 + 0.003 * np.sin(y / 0.01)
    f = lambda x, y: np.where(x > e(y), 3.0, 0.0)
    qx, qy = np.array([-0.5, 0.1, -1.3]), np.array([0.0, 0.37, -0.81])
    got = drop_cutter_reference_dense(f, c, qx, qy, h=0.01)
    for k in range(qx.size):
        d = _nearest_on_curve(qx[k], qy[k], e, qy[k] - 3.0, qy[k] + 3.0)
        want = 3.0 - float(c.lower_envelope(np.array([d]))[0])
        # a lower bound (exact contacts) at the top of the curved crease
        assert -1e-7 < got[k] - want <= 1e-12, (k, got[k], want)


def test_dense_reference_on_a_smooth_bump_is_the_analytic_offset():
    """A sphere cap of radius 40: the ball's CL is the offset sphere's height."""
    Rs = 40.0
    f = lambda x, y: np.sqrt(np.clip(Rs ** 2 - x * x - y * y, 0, None))
    c = parse_tool_spec("ball:6")
    x, y = np.array([0.0, 5.0, -9.0]), np.array([0.0, 3.0, 2.0])
    got = drop_cutter_reference_dense(f, c, x, y, h=0.05)
    want = np.sqrt((Rs + 3) ** 2 - x * x - y * y) - 3
    assert np.abs(got - want).max() < 1e-8
