"""Error messages print plain numbers, never numpy reprs such as ``np.float64(100.0)``."""

from __future__ import annotations

import numpy as np
import pytest

from zmap import ZMap
from zmap.errors import OutOfDomainError, ToolError
from zmap.interpolate import bezier, bilinear
from zmap.model import PrecisionModel


@pytest.fixture
def zm():
    return ZMap.from_function(lambda x, y: x + y, (0, 0, 10, 10), 1.0)


@pytest.mark.parametrize("f", [bezier, bilinear])
def test_out_of_domain_message_has_plain_numbers(f, zm):
    with pytest.raises(OutOfDomainError) as err:
        f(zm, np.array([1.0, 100.0]), np.array([2.5, 2.5]), strict=True)
    msg = str(err.value)
    assert msg.startswith("no height at point 1 (x=100.0, y=2.5): outside the map; 1 of 2 points have none")
    assert "np." not in msg


def test_precision_model_out_of_domain_message(zm):
    with pytest.raises(OutOfDomainError, match=r"no height at point 0 \(x=-3\.5, y=2\.0\)") as err:
        PrecisionModel(zm).height(np.float64(-3.5), np.float64(2.0), strict=True)
    assert "np." not in str(err.value)


def _message(fn):
    with pytest.raises((ValueError, ToolError)) as err:
        fn()
    assert "np." not in str(err.value), str(err.value)
    return str(err.value)


def test_numpy_scalars_given_by_the_caller_print_plainly():
    from zmap.accuracy import accuracy_rows
    from zmap.sim import simulate
    from zmap.sim.dexel import DexelWorkpiece
    from zmap.sim.tools import Cutter

    f64, i64 = np.float64, np.int64
    assert "got -1.0" in _message(lambda: DexelWorkpiece.from_box((0, 0, -1, 1, 1, 0), pitch=f64(-1)))
    assert "got (0.0, 0.0, 1.0)" in _message(lambda: DexelWorkpiece.from_box(np.array([0.0, 0.0, 1.0])))
    assert "got -3.0" in _message(lambda: Cutter("flat", f64(-3)))
    assert "got nan" in _message(lambda: Cutter("flat", f64("nan")))
    assert "got 9.0" in _message(lambda: Cutter("bull", 6, corner_radius=f64(9)))
    assert "got 0.5" in _message(lambda: Cutter("ball", 6, length=f64(0.5)))
    assert "got -0.25" in _message(lambda: simulate(np.zeros((1, 3)), (0, 0, -1, 1, 1, 0), tool="ball:1",
                                                    pitch=f64(-0.25)))
    assert "got [1.0, 2.0, 3.0]" in _message(lambda: ZMap(0, 0, 1, 1, np.zeros((2, 2)), origin=np.array([1.0, 2, 3])))
    assert "got 0" in _message(lambda: accuracy_rows(["plane"], [1.0], n_points=i64(0)))


def test_sampler_bounds_message():
    pytest.importorskip("OCP")
    from pathlib import Path

    import cad_io

    part = cad_io.read_step(Path(__file__).resolve().parents[2] / "data" / "boss.step")
    msg = _message(lambda: cad_io.sample(part, 1.0, bounds=(np.float64(0), np.float64(1))))
    assert "got [0.0, 1.0]" in msg
    msg = _message(lambda: cad_io.sample(part, (np.float64(1), np.float64(2), np.float64(3))))
    assert "got [1.0, 2.0, 3.0]" in msg
