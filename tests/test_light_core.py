"""The light core runs without its extras, and a command that needs one names it.

A child process refuses every module of the ``cad``, ``view`` and ``tiled`` extras (as if
``pip install zmap`` alone had run), then simulates a real program, compares the stock with
a z-map design and writes a finishing program over it; the commands that need an extra fail
with one line naming it.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from tests.conftest import DATA
from zmap import ZMap
from zmap.extras import EXTRAS

ROOT = DATA.parent

CHILD = textwrap.dedent("""
    import importlib.abc, json, sys
    BLOCKED = set(json.loads(sys.argv[1]))

    class NoExtras(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)

    sys.meta_path.insert(0, NoExtras())
    from zmap.cli import main

    codes = {}
    for args in json.loads(sys.argv[2]):
        codes[args[0] + " " + args[1].rsplit("/", 1)[-1]] = main(args)
    print(json.dumps(codes))
""")


@pytest.mark.slow
def test_the_core_runs_without_extras_and_a_command_that_needs_one_names_it(tmp_path):
    from zmap.tiled import TiledZMap

    design = tmp_path / "die.zmap.npz"
    ZMap.from_function(lambda x, y: -5.0 + 0.0 * x, (-30, -30, 30, 30), 0.5).save(design)
    TiledZMap.from_zmap(ZMap.load(design), tmp_path / "die.zarr", tile=64)
    run = str(tmp_path / "pocket.zsim")
    commands = [
        ["simulate", str(DATA / "demo_pocket.nc"), "--tool", "ball:6", "--stock", "box:60x60x20", "--pitch", "1",
         "-o", run],
        ["compare", run, str(design)],
        ["toolpath", str(design), "--tool", "ball:6", "--stepover", "2", "-o", str(tmp_path / "finish.nc")],
        ["convert", str(DATA / "boss.step"), "--grid", "2", "-o", str(tmp_path / "boss.zmap.npz")],
        ["info", str(tmp_path / "die.zarr")],
        ["view", run],
    ]
    blocked = sorted(m for modules in EXTRAS.values() for m in modules)
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(blocked), json.dumps(commands)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    codes = json.loads(out.stdout.strip().splitlines()[-1])
    assert codes == {"simulate demo_pocket.nc": 0, "compare pocket.zsim": 0, "toolpath die.zmap.npz": 0,
                     "convert boss.step": 1, "info die.zarr": 1, "view pocket.zsim": 1}, out.stderr
    for command, extra in (("convert", "cad"), ("info", "tiled"), ("view", "view")):
        assert f"zmap: error: zmap {command} needs " in out.stderr
        assert f"which the '{extra}' extra installs: pip install 'zmap[{extra}]'" in out.stderr, out.stderr
    assert (tmp_path / "finish.nc").stat().st_size > 0
    assert not (tmp_path / "boss.zmap.npz").exists()


def test_the_extras_named_in_code_are_those_pyproject_declares():
    import tomllib

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert set(EXTRAS) | {"all", "dev", "bench"} == set(declared)
    assert declared["all"] == [f"zmap[{','.join(EXTRAS)}]"]
