"""The mujoco.sysid adapter of `twin bench mujoco` recovers a held body from a short clean recording."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco.sysid._src.optimize")


def test_sysid_recovers_held_cube_from_clean_recording(tmp_path):
    """A 20 g cube held at its top and moved for 2.5 s, without sensor noise, written to MCAP and read back:
    sysid, started from the uniform-density prior (mass 2.6 times the truth), finds mass, COM and moments."""
    import trimesh

    from assets import Inertial, Pose
    from assets.materials import material_range
    from pipelines.identify import InertialBounds, tracked_to_object
    from assets.recording import PoseTrack, WrenchTrack
    from pipelines.logs import read_recording
    from pipelines.priors import uniform_density_prior
    from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held
    from pipelines.synth.recording import write_recording
    from benchmarks.mujoco import sysid_held

    mesh = trimesh.creation.box((0.04, 0.04, 0.04))
    mesh.density = 0.02 / mesh.volume
    truth = Inertial(0.02, (0.0, 0.0, 0.0), mesh.moment_inertia)
    placement, grasp = Pose((0.5, 0.0, 0.02)), Pose((0.0, 0.0, 0.02), (1.0, 0.0, 0.0, 0.0))
    motion = simulate_held(truth, placement, grasp, HeldMotionConfig(duration_s=2.5, hold_s=0.2),
                           np.random.default_rng(3))
    t_pose, position, quat, t_wrench, force, torque = measure(motion, SensorNoise(0, 0, 0, 0, 0, 0),
                                                              np.random.default_rng(0))
    path = tmp_path / "clean.mcap"
    write_recording(path, pose=PoseTrack(t_pose, position, quat, "world", "gripper", "/tracker/pose"),
                    wrench=WrenchTrack(t_wrench, force, torque, "/ft_sensor/wrench", "gripper"))
    recording = read_recording(path)
    prior = uniform_density_prior(mesh.copy(), material_range(None))

    result = sysid_held(recording, tracked_to_object(recording, placement), prior.inertial,
                        InertialBounds(prior.lower, prior.upper))

    est = result.inertial
    assert abs(est.mass / truth.mass - 1) < 0.01
    assert np.linalg.norm(np.asarray(est.com)) < 5e-4
    moments = np.linalg.eigvalsh(est.inertia_matrix()) / np.linalg.eigvalsh(truth.inertia_matrix())
    assert np.all(np.abs(moments - 1) < 0.05), moments
    assert result.covariance.shape == (10, 10) and np.all(np.diag(result.covariance) >= 0)
