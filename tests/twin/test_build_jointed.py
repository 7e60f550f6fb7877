"""`twin build`'s jointed options refused early (the drawer's build itself is examples/build_drawer.py)."""

from pathlib import Path

import pytest

from twin.cli import main

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "drawer"


def test_unknown_kind_is_a_usage_error(tmp_path: Path):
    """--kind takes only the four kinds."""
    with pytest.raises(SystemExit):
        main(["build", str(SAMPLE / "part.obj"), "--logs", str(SAMPLE / "trial.mcap"), "--kind", "hinge",
              "-o", str(tmp_path / "out")])


def test_missing_base_mesh_is_named(tmp_path: Path, capsys):
    """A --base-mesh that does not exist fails at once with its path and exit code 1."""
    missing = tmp_path / "cabinet.obj"
    assert main(["build", str(SAMPLE / "part.obj"), "--logs", str(SAMPLE / "trial.mcap"), "--base-mesh",
                 str(missing), "-o", str(tmp_path / "out")]) == 1
    assert f"twin: error: {missing}: base mesh not found" in capsys.readouterr().err
