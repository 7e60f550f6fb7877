"""`twin build` on the bundled drawer: kind from the motion, Featherstone fit, articulated exports, replay."""

import json
from pathlib import Path

import pytest

from twin.cli import main

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "drawer"


@pytest.mark.skipif(not (SAMPLE / "trial.mcap").is_file(), reason="samples/drawer not present")
def test_build_drawer_sample(tmp_path: Path):
    """The drawer's mass and joint friction are measured, its COM and inertia marked prior with intervals that
    hold the truth, the joint's range covers the travel, MuJoCo replays the held-out trial, and the clean
    drawer's diagnosis reports no effect."""
    truth = json.loads((SAMPLE / "truth.json").read_text())
    out = tmp_path / "out"
    base = tmp_path / "cabinet.obj"
    import trimesh

    trimesh.creation.box((0.5, 0.4, 0.3), transform=trimesh.transformations.translation_matrix((0.9, 0, 0.3))).export(base)
    assert main(["build", str(SAMPLE / "part.obj"), "--logs", str(SAMPLE / "trial.mcap"), "--holdout",
                 str(SAMPLE / "heldout.mcap"), "--base-mesh", str(base), "-o", str(out)]) == 0
    doc = json.loads((out / "asset.json").read_text())
    assert doc["kind"] == "prismatic" and doc["provenance"]["kind"]["forced_by_user"] is False
    theta = doc["theta"]
    assert theta["mass"]["source"] == "measured"
    assert theta["mass"]["value"] == pytest.approx(truth["mass"], rel=0.03)
    assert theta["friction"]["source"] == "measured"
    assert theta["friction"]["value"] == pytest.approx(truth["joint"]["friction"], rel=0.05)
    assert theta["com"]["source"] == "prior" and theta["inertia"]["source"] == "prior"
    lo, hi = theta["inertia"]["interval95"]
    for k in range(3):
        assert lo[k][k] <= truth["inertia"][k][k] <= hi[k][k]
    joint = doc["joint"]
    assert joint["type"] == "prismatic"
    assert 0 < joint["axis_std_rad"] < 0.01
    travel = doc["provenance"]["kind"]["joint"]["observed_travel"]  # of the trial; the held-out one counts too
    assert joint["lower"] < travel[0] and joint["upper"] > travel[1]
    assert len(doc["provenance"]["validation"]) == 5
    replay = doc["provenance"]["heldout_replay"]
    assert replay["mujoco"]["rmse_position_m"] < 0.005 and replay["newton"]["rmse_position_m"] < 0.005
    assert doc["effects"] == [] and "screening" in doc["provenance"]["diagnose"]
    for key in ("urdf", "mjcf", "usd", "report"):
        assert (out / doc["files"][key]).is_file()
    assert (out / "meshes" / "base.obj").is_file()


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
