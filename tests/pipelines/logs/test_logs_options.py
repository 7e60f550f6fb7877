"""Reading recordings as they come: contact from a pose topic, frames for empty headers,
a fixed sensor-to-world rotation, and `twin inspect`, on the real 2015 MIT pushing bags."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from assets.recording import PoseTrack, WrenchTrack
from pipelines.logs import LogError, read_recording
from pipelines.synth.recording import write_recording
from twin.cli import main

BAGS = (Path(__file__).parents[3] / ".." / "shared" / "data" / "mit-push" / "ros2_mcap").resolve()
ST_1 = BAGS / "St_block" / "Test_st_1"
AL_1 = BAGS / "Al_block" / "Test_metal_1"
needs_bags = pytest.mark.skipif(not ST_1.exists(), reason="shared data (../shared/data/mit-push) not present")
ST_TOPICS = {"pose": "/vicon/SteelBlock/SteelBlock", "wrench": "/netft_data", "contact": "/tip_pose"}


@needs_bags
def test_pusher_tip_pose_is_the_contact_point_through_tf():
    """/tip_pose (PoseStamped, empty frame_id, base_link) lands in the Vicon world via map -> viconworld."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = read_recording(ST_1, ST_TOPICS, {"contact": "base_link"})
    assert rec.contact is not None and rec.contact.frame_id == "objworld"
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(next(ST_1.glob("*.mcap")), "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        tip = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                        for *_, m in reader.iter_decoded_messages(topics=["/tip_pose"])])
    # St bags: map -> viconworld is (0.4, 0, 0.01), viconworld -> objworld identity (mit-push README)
    np.testing.assert_allclose(rec.contact.position[0], tip[0] - [0.4, 0.0, 0.01], atol=1e-9)
    # the pusher starts behind the block (-y) and the block is pushed +y
    assert rec.contact.position[0, 1] < rec.pose.position[0, 1] - 0.04


@needs_bags
def test_contact_pose_without_its_frame_is_a_log_error():
    """An empty frame_id with no --frame for it names the topic and the problem."""
    with pytest.raises(LogError, match="contact topic /tip_pose has an empty frame_id"):
        read_recording(AL_1, {**ST_TOPICS, "pose": "/vicon/MetalSquare/MetalSquare"})


@needs_bags
def test_fixed_sensor_rotation_matches_the_tf_resolution():
    """R_world_ft given as a fixed quaternion gives the force that /tf gives (tool pointing down)."""
    via_tf = read_recording(ST_1, ST_TOPICS, {"contact": "base_link"})
    q_world_ft = Rotation.from_matrix([[0, 1, 0], [1, 0, 0], [0, 0, -1]]).as_quat()
    fixed = read_recording(ST_1, ST_TOPICS, {"contact": "base_link"}, tuple(q_world_ft))
    np.testing.assert_allclose(fixed.wrench.force, via_tf.wrench.force, atol=0.02)
    # the fixed-rotation wrench acts at the contact point: torque about the block = r x F
    p_block = fixed.pose.interpolate(fixed.wrench.t_s)[0]
    p_contact = np.stack([np.interp(fixed.wrench.t_s, fixed.contact.t_s, fixed.contact.position[:, k])
                          for k in range(3)], axis=1)
    expected = fixed.wrench_raw.torque @ Rotation.from_quat(q_world_ft).as_matrix().T
    expected = expected + np.cross(p_contact - p_block, fixed.wrench.force)
    np.testing.assert_allclose(fixed.wrench.torque, expected, atol=1e-9)


def test_bad_rotation_and_frame_role_are_rejected(tmp_path):
    """A non-unit quaternion or an unknown frame role is a ValueError naming the argument."""
    t = np.linspace(0, 1, 11)
    pose = PoseTrack(t, np.zeros((11, 3)), np.tile([0, 0, 0, 1.0], (11, 1)), "world", "block", "/block")
    wrench = WrenchTrack(t, np.zeros((11, 3)), np.zeros((11, 3)), "/ft", "")
    path = write_recording(tmp_path / "r.mcap", pose=pose, wrench=wrench)
    with pytest.raises(ValueError, match="wrench_rotation_xyzw"):
        read_recording(path, wrench_rotation_xyzw=(0, 0, 0, 2.0))
    with pytest.raises(ValueError, match="frames: unknown role 'pose'"):
        read_recording(path, frames={"pose": "map"})
    rec = read_recording(path, frames={"wrench": "block"})  # the empty frame named: the tracked frame
    assert rec.wrench_raw.frame_id == "block"


@needs_bags
def test_twin_inspect_lists_every_topic_with_rates(capsys):
    """`twin inspect` prints each topic, undecodable robot_comm ones included, with count and rate."""
    assert main(["inspect", str(ST_1)]) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split() for line in out.splitlines()[2:]}
    assert rows["/robot2_CartesianLog"][1] == "robot_comm/msg/robot_CartesianLog"
    assert rows["/netft_data"][2] == "602" and abs(float(rows["/netft_data"][3]) - 100.0) < 1.0
    assert abs(float(rows["/vicon/SteelBlock/SteelBlock"][5]) - 6.02) < 0.05


def test_twin_inspect_of_a_missing_file_exits_1(tmp_path, capsys):
    """A missing file is one error line naming it and exit code 1."""
    assert main(["inspect", str(tmp_path / "none.mcap")]) == 1
    assert "none.mcap: file not found" in capsys.readouterr().err
