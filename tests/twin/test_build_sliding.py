"""End to end: `twin build --kind sliding` on a synthetic push, and the recording options' errors."""

from __future__ import annotations

import json

import numpy as np
import pytest


def test_build_sliding_measures_friction_and_marks_the_mass_prior(tmp_path, run_twin):
    """A steel plate pushed and turned: mu measured within 5 %, mass from the prior and marked so."""
    import trimesh

    from pipelines.synth.push import PushConfig, write_push

    half = (0.05, 0.05, 0.005)
    mass = 7850.0 * 8 * half[0] * half[1] * half[2]  # the library's steel: the prior is right
    config = PushConfig(half_extents_m=half, mass_kg=mass, mu=0.3, offset_m=-0.015, push_s=1.2, seed=7,
                        force_bias_n=(-0.2, 0.3, 0.5))
    truth = write_push(tmp_path / "push.mcap", config)
    box = trimesh.creation.box([2 * h for h in half])
    box.apply_translation([0.0, 0.0, half[2]])  # resting on the table at the world origin
    box.export(tmp_path / "plate.obj")
    out = tmp_path / "out"
    # the diagnosis runs once, from `twin diagnose` below, which reads what the build chose
    proc = run_twin("build", str(tmp_path / "plate.obj"), "--logs", str(tmp_path / "push.mcap"), "--kind", "sliding",
                    "--material", "steel", "--no-diagnose", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    asset = json.loads((out / "asset.json").read_text())
    assert asset["kind"] == "sliding"
    theta = asset["theta"]
    assert theta["friction"]["source"] == "measured"
    assert theta["friction"]["value"] == pytest.approx(truth.mu, rel=0.05)
    assert theta["mass"]["source"] == "prior" and theta["com"]["source"] == "prior"
    assert asset["fit"]["final"]["rmse_position_m"] < asset["fit"]["baseline"]["rmse_position_m"]
    assert all(check["ok"] for check in asset["provenance"]["validation"]["checks"])
    assert asset["provenance"]["identify"]["kind"] == "sliding"
    assert asset["provenance"]["identify"]["friction_from"] == "sliding fit"  # a push that slides in the simulation
    # the support model the pushes chose (an evenly loaded face: each half of the push predicts the other
    # better with it), used by the diagnosis and reproduced by the export as 16 support points
    support = asset["provenance"]["identify"]["support"]
    assert support["model"] == "uniform" and support["chosen_by"] == "trial halves" and support["why"]
    assert asset["provenance"]["identify"]["config"]["support"] == "uniform"
    assert (out / asset["files"]["mjcf"]).read_text().count("_support_point_") == 16
    assert "diagnose" not in asset["provenance"]
    # the exported scene's replay beside the tracker's noise alone (sigma per axis: sqrt(2) sigma in the plane)
    replay = asset["provenance"]["heldout_replay"]
    assert replay["noise_floor_m"] == pytest.approx(2 ** 0.5 * config.position_noise_m, rel=0.15)
    assert replay["mujoco_over_noise_floor"] > 1.0

    # `twin diagnose` on the built asset reads the recording with the build's options and support, rewrites
    # asset.json, and (each half of the push fitted on the other) finds nothing in a clean push
    proc = run_twin("diagnose", str(out), "--logs", str(tmp_path / "push.mcap"), "--diagnosis.bootstraps", "5")
    assert proc.returncode == 0, proc.stderr
    diagnosed = json.loads((out / "asset.json").read_text())
    assert diagnosed["provenance"]["diagnose"]["run"]["logs"] == [str(tmp_path / "push.mcap")]
    assert diagnosed["provenance"]["diagnose"]["evaluation"] == "time-blocked cross-validation"
    assert diagnosed["effects"] == [] and diagnosed["theta"] == asset["theta"]


def test_malformed_topic_option_is_one_error_line(tmp_path, run_twin):
    """--topic without ROLE=/name names the option and exits 1."""
    proc = run_twin("build", str(tmp_path / "x.obj"), "--logs", str(tmp_path / "y.mcap"), "--topic", "/netft_data")
    assert proc.returncode == 1
    assert "twin: error: --topic '/netft_data': expected ROLE=VALUE" in proc.stderr


def test_friction_of_a_fit_that_only_bounds_mu():
    """Where the sliding fit only bounds mu (its simulation stuck throughout), the build reports the wrench
    balance as measured; without a steady window, the prior raised to the bound, marked prior."""
    from types import SimpleNamespace

    from pipelines.identify import SlidingFit
    from pipelines.identify.sliding.balance import WrenchBalance
    from twin.pushed import sliding_friction

    bound = SlidingFit(np.array([0.38, 0.84, 1e-3]), np.zeros(3), (False, False, False), 1e-4, 1e-3, 6, 10)
    prior = SimpleNamespace(friction_kinetic=(0.32, 0.2, 0.45))
    balance = WrenchBalance(0.31, 0.01, np.full(3, 0.31), 0.2)
    friction, source = sliding_friction(bound, balance, prior)
    assert source == "wrench balance" and friction.source == "measured"
    assert friction.value == 0.31 and friction.interval95 == pytest.approx((0.2904, 0.3296))
    friction, source = sliding_friction(bound, None, prior)
    assert friction.source == "prior" and friction.value == 0.38 and friction.interval95 == (0.38, 0.45)
    measured = SlidingFit(np.array([0.3, 0.84, 1e-3]), np.array([0.01, 0, 0]), (True, False, False), 1e-4, 1e-3, 6,
                          10, sliding_windows=5)
    assert sliding_friction(measured, balance, prior)[1] == "sliding fit"
