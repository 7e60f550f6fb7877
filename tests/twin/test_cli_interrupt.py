"""Ctrl-C and SIGTERM during a build: one line, exit 130, the previous OUT as it was, no temporary folder."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "cube"


def _start_build(out: Path) -> subprocess.Popen:
    command = [sys.executable, "-m", "twin.cli", "build",
               str(SAMPLE / "scan"), "--logs", str(SAMPLE / "trial.mcap"), "-o", str(out), "--max-iterations", "2"]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_an_interrupted_build_says_one_line_and_leaves_out_alone(tmp_path, signum):
    out = tmp_path / "out"
    out.mkdir()
    (out / "asset.json").write_text(json.dumps({"schema": "twin.asset/1", "files": {}}))
    (out / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    process = _start_build(out)
    for line in process.stdout:  # interrupt once the build is into its stages
        if "reconstruct ..." in line:
            break
    time.sleep(0.5)
    process.send_signal(signum)
    _, err = process.communicate(timeout=120)
    lines = [line for line in err.splitlines() if line.strip()]
    assert process.returncode == 130, err
    assert lines == ["twin: interrupted; outputs left as they were"], err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_version():
    from twin.cli import main

    assert main(["--version"]) == 0


def test_an_interrupt_python_only_printed_still_ends_the_run_as_interrupted(monkeypatch, capsys):
    """A Ctrl-C raised inside a callback (an import lock's, a weak reference's) is printed by Python and the work
    goes on; main still exits 130 with its one line, and the printed traceback is kept quiet."""
    import twin.cli as cli

    def swallowed(command):
        try:
            cli._interrupt(signal.SIGINT, None)
        except KeyboardInterrupt as exc:  # what Python does with it inside a callback
            sys.unraisablehook(type("Unraisable", (), {"exc_type": KeyboardInterrupt, "exc_value": exc,
                                                       "exc_traceback": exc.__traceback__, "err_msg": None,
                                                       "object": None})())

    monkeypatch.setattr(cli, "_dispatch", swallowed)
    assert cli.main(["inspect", str(SAMPLE / "trial.mcap")]) == 130
    assert capsys.readouterr().err.splitlines() == ["twin: interrupted; outputs left as they were"]
