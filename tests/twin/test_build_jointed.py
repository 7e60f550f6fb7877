"""`twin build` of a part on a joint: options refused early, and a build that keeps an effect (the clean drawer's
build is examples/build_drawer.py)."""

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


def test_a_part_built_with_an_effect_reports_its_replay_like_for_like(synth_and_build):
    """A drawer with concealed damping: the build keeps the refit with it, and asset.json's fit and the Newton
    replay beside MuJoCo's are that refit replayed as the identification replays (its windows, measured
    starts), not the diagnosis's own 0.6 s smoothed windows; the MJCF carries the damping."""
    _, asset = synth_and_build("--object", "drawer", "--effect", "viscous_damping", "--effect-magnitude", "6")
    assert [e["name"] for e in asset["effects"]] == ["viscous_damping"]
    replay = asset["provenance"]["heldout_replay"]
    assert asset["fit"]["final"]["rmse_position_m"] == replay["newton"]["rmse_position_m"]
    assert replay["mujoco"]["rmse_position_m"] < 1.3 * replay["newton"]["rmse_position_m"]
    assert asset["joint"]["damping"] > 0
