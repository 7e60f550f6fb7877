"""`twin build SOURCE --scan SESSION`: a session that cannot be registered fails cleanly."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import trimesh

from pipelines.synth.render import RenderConfig, render_scan

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "samples" / "cube"


def test_session_of_another_object_fails_cleanly(tmp_path):
    """A second session showing a 9 cm bar, not the sample's 4 cm cube: one error line naming that session,
    exit code 1, and the previous out/ untouched."""
    bar = trimesh.creation.box((0.09, 0.02, 0.02))
    bar.apply_translation((0.4, -0.1, 0.01))
    other = render_scan(bar, tmp_path / "bar_session", RenderConfig(width=320, height=240, fx=300.0, fy=300.0,
                                                                     view_count=12), np.random.default_rng(3), "bar")
    out = tmp_path / "out"
    out.mkdir()
    (out / "asset.json").write_text('{"schema": "twin.asset/1", "files": {}}')  # an earlier build's output
    (out / "marker.txt").write_text("previous build")
    proc = subprocess.run([sys.executable, "-m", "twin.cli", "build", str(SAMPLE / "scan"), "--scan", str(other),
                           "--logs", str(SAMPLE / "trial.mcap"), "-o", str(out)],
                          capture_output=True, text=True, cwd=REPO)
    assert proc.returncode == 1
    lines = [line for line in proc.stderr.strip().splitlines() if line.startswith("twin: error:")]
    assert len(lines) == 1 and "bar_session" in lines[0] and "cannot register" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert (out / "marker.txt").read_text() == "previous build" and len(list(out.iterdir())) == 2
