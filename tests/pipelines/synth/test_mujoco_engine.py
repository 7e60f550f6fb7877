"""The MuJoCo engine: its sensor's sign and frames, Newton-Euler against the truth, and jointed recordings."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from assets import Inertial, Pose
from pipelines.identify.least_squares import identify_least_squares
from pipelines.logs import read_recording
from pipelines.synth.held import HeldMotionConfig, SensorNoise
from pipelines.synth.jointed import JointedMotionConfig, jointed_paper_objects
from pipelines.synth.mujoco_engine import (
    MujocoSettings,
    simulate_held_mujoco,
    simulate_jointed_mujoco,
    write_motion_recording,
)

MASS = 0.35
COM = (0.004, -0.003, 0.002)
INERTIA = np.array([[6e-4, 5e-5, -2e-5], [5e-5, 9e-4, 3e-5], [-2e-5, 3e-5, 1.1e-3]])
PLACEMENT = Pose((0.5, 0.05, 0.1), tuple(Rotation.from_euler("z", 0.35).as_quat()))
GRASP = Pose((0.0, 0.0, 0.04), (1.0, 0.0, 0.0, 0.0))
NOISE_FREE = SensorNoise(force_sigma_n=0.0, force_resolution_n=0.0, torque_sigma_nm=0.0, torque_resolution_nm=0.0,
                         position_sigma_m=0.0, rotation_sigma_rad=0.0)


@pytest.fixture(scope="module")
def held():
    truth = Inertial(MASS, COM, INERTIA)
    motion = simulate_held_mujoco(truth, PLACEMENT, GRASP, HeldMotionConfig(duration_s=4.0), np.random.default_rng(1))
    return truth, motion


def test_static_hold_measures_the_weight_upward_on_the_object():
    """Held still, the sensor gives +m g upward applied TO the object (MuJoCo's parent-on-child force), and the
    torque that holds the COM's lever about the grasp, for each integrator."""
    truth = Inertial(MASS, COM, INERTIA)
    still = HeldMotionConfig(duration_s=0.3, translation_amplitude_m=0.0, rotation_amplitude_rad=0.0)
    r_com = PLACEMENT.rotation_matrix() @ np.asarray(COM) + PLACEMENT.position - (PLACEMENT @ GRASP).position
    weight = np.array([0.0, 0.0, -9.81 * MASS])
    for integrator in ("implicitfast", "RK4"):
        motion = simulate_held_mujoco(truth, PLACEMENT, GRASP, still, np.random.default_rng(0),
                                      MujocoSettings(integrator=integrator))
        np.testing.assert_allclose(motion.force_n[-1], -weight, rtol=0, atol=1e-3 * MASS * 9.81)
        np.testing.assert_allclose(motion.torque_nm[-1], -np.cross(r_com, weight), rtol=0, atol=1e-6)


def test_least_squares_recovers_the_truth_from_a_noise_free_recording(held, tmp_path):
    """The recorded wrench obeys Newton-Euler for the true body: Atkeson's regression on the recording as read
    back gets the mass within 1 % and the COM within 1 mm."""
    truth, motion = held
    path = write_motion_recording(tmp_path / "clean.mcap", motion, NOISE_FREE, np.random.default_rng(2))
    rec = read_recording(path)
    result = identify_least_squares(rec.pose.t_s, rec.pose.position, rec.pose.quat_xyzw, rec.wrench.t_s,
                                    rec.wrench.force, rec.wrench.torque, GRASP.inverse(), t_begin_s=0.5)
    assert result.inertial.mass == pytest.approx(MASS, rel=0.01)
    np.testing.assert_allclose(result.inertial.com, COM, atol=1e-3)


def test_world_and_sensor_frame_recordings_read_to_the_same_world_wrench(held, tmp_path):
    """The same readings written in the gripper's axes and in world's read back as one world wrench about the
    tracked origin (the gripper one turned through the tracked pose)."""
    _, motion = held
    tracker_only = SensorNoise(force_sigma_n=0.0, force_resolution_n=0.0, torque_sigma_nm=0.0,
                               torque_resolution_nm=0.0)
    reads = {}
    for frame in ("gripper", "world"):
        path = write_motion_recording(tmp_path / f"{frame}.mcap", motion, tracker_only, np.random.default_rng(3),
                                      wrench_frame=frame)
        reads[frame] = read_recording(path)
    assert reads["gripper"].wrench_raw.frame_id == "gripper" and reads["world"].wrench_raw.frame_id == "world"
    assert reads["gripper"].wrench_turns_with_pose and not reads["world"].wrench_turns_with_pose
    w_g, w_w = reads["gripper"].wrench, reads["world"].wrench
    np.testing.assert_array_equal(w_g.t_s, w_w.t_s)
    scale = np.abs(w_w.force).max()
    # the gripper wrench is turned through the tracker's noisy, interpolated pose: 2 mrad of rotation noise
    assert np.sqrt(np.mean((w_g.force - w_w.force) ** 2)) < 5e-3 * scale
    np.testing.assert_allclose(w_g.force.mean(0), w_w.force.mean(0), atol=2e-3 * scale)
    np.testing.assert_allclose(w_w.force, motion.force_n, atol=1e-9)


def test_drawer_recording_reads_back_and_its_effort_balances_inertia_and_friction(tmp_path):
    """The drawer's recording carries its joint state; the force the robot puts along the joint is m qdd plus
    MuJoCo's friction loss f_c sign(qd) while it slides (qdd as each sensor period's velocity change)."""
    obj = jointed_paper_objects()["drawer"]
    config = JointedMotionConfig(duration_s=3.0)
    substeps = MujocoSettings().substeps
    motion = simulate_jointed_mujoco(obj, config, np.random.default_rng(4))
    path = write_motion_recording(tmp_path / "drawer.mcap", motion.held, SensorNoise(), np.random.default_rng(5),
                                  joint=(f"{obj.name}_joint", motion))
    rec = read_recording(path)
    assert rec.joints is not None and rec.joints.names == (f"{obj.name}_joint",)
    idx = np.rint(rec.joints.t_s / (motion.held.t_s[1] - motion.held.t_s[0])).astype(int)
    np.testing.assert_allclose(rec.joints.position[:, 0], motion.q[idx], atol=1e-5)
    assert motion.q.max() > 0.15  # it opened

    k = np.arange(len(motion.held.t_wrench_s))
    period = 1.0 / config.control_rate_hz
    qdd = (motion.qd[substeps * (k + 1)] - motion.qd[substeps * k]) / period
    qd = motion.qd[substeps * k + substeps // 2]
    along = motion.held.force_n @ np.asarray(obj.axis)
    sliding = np.abs(qd) > 0.05
    assert sliding.mean() > 0.3
    balance = along - obj.mass_kg * qdd - obj.friction * np.sign(qd)
    assert np.median(np.abs(balance[sliding])) < 0.01
    assert np.percentile(np.abs(balance[sliding]), 95) < 0.05
    # and as recorded: the noisy world wrench along the joint, averaged over the slides, is the same balance
    recorded = rec.wrench.force @ np.asarray(obj.axis)
    assert np.abs(np.mean(recorded[sliding] - along[sliding])) < 0.01
