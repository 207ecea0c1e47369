import subprocess
import sys

import numpy as np
import pytest

from zmap import ZMap
from zmap.cli import main


def run(*args):
    p = subprocess.run([sys.executable, "-m", "zmap.cli", *args], capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr


def test_accuracy_csv(capsys):
    assert main(["accuracy", "--points", "20000", "--format", "csv", "--surface", "plane", "--grid", "0.5"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "surface,grid,scheme,min_dev,max_dev"
    assert [line.split(",")[2] for line in out[1:]] == ["bilinear", "bezier", "bezier-central", "bezier-quartic"]
    assert all(abs(float(v)) < 1e-12 for line in out[1:] for v in line.split(",")[3:])


def test_accuracy_default_is_table1(capsys):
    assert main(["accuracy", "--points", "10000", "--scheme", "bilinear"]) == 0
    out = capsys.readouterr().out
    assert "x^2+y^2+z^2=100^2, z>70" in out and "z=100*sin" in out and "z=1000*sin" in out


@pytest.mark.slow
def test_errors_are_one_line_and_non_zero(tmp_path):
    code, out, err = run("accuracy", "--surface", "cone")
    assert code != 0 and err.strip().count("\n") == 0 and "cone" in err
    bad = tmp_path / "x.npz"
    bad.write_text("garbage")
    code, out, err = run("info", str(bad))
    assert code == 1 and err.startswith("zmap: error:") and str(bad) in err and err.strip().count("\n") == 0


def test_info(tmp_path, capsys):
    zm = ZMap(0, 0, 0.5, 0.5, np.array([[1.0, np.nan], [2.0, 3.0]]), meta={"source": "t"})
    p = zm.save(tmp_path / "m.zmap.npz")
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "2 x 2 points" in out and "3 with surface, 1 empty" in out and '"source": "t"' in out


def test_command_modules_hold_commands_and_no_library_code():
    # a command module parses, calls the library and prints: its public names are commands
    import importlib
    import inspect

    import click

    for name in ("zmap.cli.maps", "zmap.cli.sim", "zmap.cli.view", "zmap.cli.verify", "zmap.cli.cam",
                 "cad_io.commands", "cad_io.access_commands"):
        module = importlib.import_module(name)
        commands = [v for v in vars(module).values() if isinstance(v, click.Command)
                    and getattr(v.callback, "__module__", None) == name]
        helpers = [k for k, v in vars(module).items() if not k.startswith("_") and (inspect.isfunction(v)
                   or inspect.isclass(v)) and v.__module__ == name]
        assert commands and not helpers, (name, helpers)
