"""Fixtures the test tree shares: the public data beside the checkout, real Kinect frames from it, the command line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = (REPO / ".." / "shared" / "data").resolve()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data, the recordings and meshes nobody here made; the test is skipped where it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is absent")
    return SHARED_DATA


@pytest.fixture(scope="session")
def run_twin():
    """`twin ARGS...` as a user runs it, in a process of its own from the checkout; returns the completed process."""
    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True, text=True, cwd=REPO)

    return run


@pytest.fixture
def synth_and_build(tmp_path, run_twin):
    """`twin synth -o SAMPLE ARGS...`, then `twin build` of it with its held-out recording, as the README runs
    them; returns the OUT folder and its asset.json."""
    def make(*synth_args: str) -> tuple[Path, dict]:
        import json

        sample, out = tmp_path / "sample", tmp_path / "out"
        proc = run_twin("synth", "-o", str(sample), *synth_args)
        assert proc.returncode == 0, proc.stderr
        proc = run_twin("build", str(sample / "scan"), "--logs", str(sample / "trial.mcap"),
                        "--holdout", str(sample / "heldout.mcap"), "-o", str(out))
        assert proc.returncode == 0, proc.stderr
        return out, json.loads((out / "asset.json").read_text())

    return make


@pytest.fixture
def kinect_frames(shared_data, tmp_path):
    """Links the real 7-Scenes Kinect frames of the ids given, from ../shared/data, into a scan folder in
    7-Scenes' own layout, and returns the folder."""
    def link(frames) -> Path:
        source = shared_data / "rgbd" / "7scenes_tsdf_demo_subset"
        root = tmp_path / "kinect"
        root.mkdir()
        (root / "camera-intrinsics.txt").symlink_to(source / "camera-intrinsics.txt")
        for n in frames:
            for suffix in ("color.jpg", "depth.png", "pose.txt"):
                (root / f"frame-{n:06d}.{suffix}").symlink_to(source / f"frame-{n:06d}.{suffix}")
        return root

    return link
