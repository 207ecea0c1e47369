"""Ctrl-C in the first second of ``zmap convert``: the imports of OCP and numba."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DIE = ROOT / "data" / "freeform_die.step"


@pytest.mark.parametrize("traceback", [False, True])
def test_an_import_error_raised_from_an_interrupt_reads_interrupted(tmp_path, monkeypatch, capsys, traceback):
    """pybind11 turns a KeyboardInterrupt during a module's initialisation into
    ``ImportError: initialization failed`` raised from it; the CLI said "internal error"."""
    import cad_io.step
    from zmap.cli import main

    def interrupted_import(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    monkeypatch.setattr(cad_io.step, "read_step", interrupted_import)
    if traceback:
        monkeypatch.setenv("ZMAP_TRACEBACK", "1")  # an interrupt is not an unexpected error
    rc = main(["convert", str(DIE), "--grid", "1", "-o", str(tmp_path / "d.npz"), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 130 and err.strip() == "zmap: interrupted", err
    assert not (tmp_path / "d.npz").exists()


@pytest.mark.slow
def test_ctrl_c_during_the_first_second_of_convert(tmp_path):
    """SIGINT 0.05-1.0 s after ``zmap.cli`` is imported, while the command imports OCP and
    numba and reads the file: every run says "zmap: interrupted" and exits 130 (before:
    "internal error ... ImportError: initialization failed" from 0.8 s on)."""
    code = ("import sys, zmap.cli; sys.stderr.write('ready\\n'); sys.stderr.flush(); "
            f"sys.exit(zmap.cli.main(['convert', {str(DIE)!r}, '--grid', '0.05', '-o', sys.argv[1], "
            "'--no-progress']))")
    for k, delay in enumerate((0.05, 0.3, 0.6, 1.0)):
        out = tmp_path / f"d{k}.npz"
        p = subprocess.Popen([sys.executable, "-c", code, str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": str(ROOT)},
                             # a runner started in the background ignores SIGINT, and the child would inherit that
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # noqa: PLW1509
        assert p.stderr.readline() == "ready\n"
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
        assert p.returncode == 130 and err.strip().endswith("zmap: interrupted"), (delay, p.returncode, err)
        assert "internal error" not in err
        assert not out.exists()
