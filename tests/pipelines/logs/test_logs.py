"""Tests for pipelines.logs (MCAP reading) and pipelines.synth.recording (writing)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from assets.recording import JointTrack, PointTrack, PoseTrack, WrenchTrack
from pipelines.logs import LogError, inspect_recording, read_recording
from pipelines.synth import recording as synth_recording
from pipelines.synth.recording import write_recording

DATA = (Path(__file__).parents[3] / ".." / "shared" / "data").resolve()
ST_1 = DATA / "mit-push" / "ros2_mcap" / "St_block" / "Test_st_1" / "Test_st_1.mcap"


def _pose(t, angle=None, position=None, child="gripper", topic="/tracker/pose") -> PoseTrack:
    t = np.asarray(t, dtype=float)
    angle = np.zeros_like(t) if angle is None else np.asarray(angle, dtype=float)
    if position is None:
        position = np.c_[0.1 * t, 0.2 + 0.0 * t, 0.05 + 0.01 * t]
    quat = Rotation.from_rotvec(np.c_[0 * angle, 0 * angle, angle]).as_quat()
    return PoseTrack(t, position, quat, "world", child, topic)


def _wrench(t, force, torque, frame_id, topic="/ft_sensor/wrench") -> WrenchTrack:
    n = len(t)
    return WrenchTrack(np.asarray(t, float), np.tile(force, (n, 1)), np.tile(torque, (n, 1)), topic, frame_id)


def _merge(dst: Path, sources: list[Path], keep=lambda topic: True, extra=()) -> Path:
    """Copy the messages of `sources` (filtered by topic) into one MCAP, plus raw extra channels.

    `extra` holds (topic, schema_name, schema_text, message_bytes) entries, written as
    ros2msg/cdr exactly as given (the bytes need not decode).
    """
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(dst, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        schema_ids, channel_ids = {}, {}
        for src in sources:
            with open(src, "rb") as g:
                for schema, channel, message in make_reader(g).iter_messages():
                    if not keep(channel.topic):
                        continue
                    if schema.name not in schema_ids:
                        schema_ids[schema.name] = w.register_schema(schema.name, schema.encoding, schema.data)
                    if channel.topic not in channel_ids:
                        channel_ids[channel.topic] = w.register_channel(
                            channel.topic, channel.message_encoding, schema_ids[schema.name]
                        )
                    w.add_message(channel_ids[channel.topic], message.log_time, message.data, message.publish_time)
        for k, (topic, name, text, data) in enumerate(extra):
            sid = w.register_schema(name, "ros2msg", text.encode())
            cid = w.register_channel(topic, "cdr", sid)
            w.add_message(cid, 10**9 + k, data, 10**9 + k)
        w.finish()
    return dst


def test_round_trip_is_exact(tmp_path):
    """Write poses, a world wrench, contact and joints; read them back unchanged."""
    rng = np.random.default_rng(0)
    t = np.arange(20) * 0.01 + 3.0
    quat = Rotation.from_rotvec(rng.normal(size=(20, 3))).as_quat()
    pose = PoseTrack(t, rng.normal(size=(20, 3)), quat, "world", "gripper", "/tracker/pose")
    tw = np.arange(15) * 0.013 + 3.001
    wrench = WrenchTrack(tw, rng.normal(size=(15, 3)), rng.normal(size=(15, 3)), "/ft_sensor/wrench", "world")
    joints = JointTrack(t, ("j1", "j2"), rng.normal(size=(20, 2)), rng.normal(size=(20, 2)))
    contact = PointTrack(tw, pose.interpolate(tw)[0], "world", "/contact/point")
    path = write_recording(tmp_path / "trial.mcap", pose=pose, wrench=wrench, joints=joints, contact=contact)

    rec = read_recording(path)
    np.testing.assert_allclose(rec.pose.t_s, t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rec.pose.position, pose.position, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rec.pose.quat_xyzw, quat, rtol=0, atol=1e-15)
    assert (rec.pose.frame_id, rec.pose.child_frame_id, rec.pose.topic) == ("world", "gripper", "/tracker/pose")
    np.testing.assert_allclose(rec.wrench_raw.t_s, tw, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(rec.wrench_raw.force, wrench.force)
    np.testing.assert_array_equal(rec.wrench_raw.torque, wrench.torque)
    assert (rec.wrench_raw.frame_id, rec.wrench.frame_id) == ("world", "world")
    # the contact is the tracked origin here, so the world wrench needs no torque shift
    np.testing.assert_allclose(rec.wrench.force, wrench.force, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rec.wrench.torque, wrench.torque, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.contact.position, contact.position, rtol=0, atol=1e-15)
    assert rec.joints.names == ("j1", "j2")
    np.testing.assert_array_equal(rec.joints.position, joints.position)
    np.testing.assert_array_equal(rec.joints.velocity, joints.velocity)
    assert rec.duration_s == pytest.approx(max(t[-1], tw[-1]) - min(t[0], tw[0]), abs=1e-9)

    summary = {s.topic: s for s in inspect_recording(path)}
    assert summary["/tracker/pose"].type == "geometry_msgs/msg/TransformStamped"
    assert summary["/tracker/pose"].count == 20
    assert summary["/tracker/pose"].rate_hz == pytest.approx(100.0, rel=1e-6)
    assert summary["/ft_sensor/wrench"].t_start_s == pytest.approx(tw[0], abs=1e-9)
    assert summary["/joint_states"].count == 20


def test_wrench_in_rotating_tracked_frame_comes_out_in_world_axes(tmp_path):
    """A wrench in the tracked frame is rotated by the slerped pose at each wrench stamp."""
    t = np.linspace(0.0, 2.0, 9)
    omega = 0.7  # rad/s about world z
    pose = _pose(t, angle=omega * t)
    tw = np.linspace(0.05, 1.95, 7)  # between pose samples: exercises slerp
    f, tau = np.array([1.0, 0.0, 0.5]), np.array([0.0, 0.2, 0.1])
    path = write_recording(tmp_path / "rot.mcap", pose=pose, wrench=_wrench(tw, f, tau, "gripper"))

    rec = read_recording(path)
    tr = rec.wrench.t_s  # the stamps as read (nanosecond resolution)
    rz = Rotation.from_rotvec(np.c_[0 * tr, 0 * tr, omega * tr])
    np.testing.assert_allclose(rec.wrench.force, rz.apply(f), rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.wrench.torque, rz.apply(tau), rtol=0, atol=1e-12)
    assert rec.wrench.frame_id == "world"
    assert rec.wrench_raw.frame_id == "gripper"
    np.testing.assert_array_equal(rec.wrench_raw.force, np.tile(f, (7, 1)))


def test_wrench_acted_turns_a_late_wrist_sample_back_with_the_pose(tmp_path):
    """A wrist sensor that stamps late was resolved through the pose at the late stamp: the wrench as it
    acted undoes that turn as well as the stamp; a world wrench only moves in time."""
    t = np.linspace(0.0, 2.0, 201)
    omega, delay = 1.0, 0.011  # rad/s about world z; s
    pose = _pose(t, angle=omega * t)
    f_world, tau_world = np.array([0.3, -0.2, 0.5]), np.array([0.01, 0.02, -0.03])
    tw = np.linspace(0.1, 1.8, 35)  # when the samples acted
    acting = Rotation.from_rotvec(np.c_[0 * tw, 0 * tw, omega * tw])
    wrist = WrenchTrack(tw + delay, acting.inv().apply(f_world), acting.inv().apply(tau_world), "/ft", "gripper")
    rec = read_recording(write_recording(tmp_path / "late.mcap", pose=pose, wrench=wrist))

    assert rec.wrench_turns_with_pose
    acted = rec.wrench_acted(delay)
    np.testing.assert_allclose(acted.t_s, tw, atol=1e-9)
    np.testing.assert_allclose(acted.force, np.tile(f_world, (len(tw), 1)), atol=1e-9)
    np.testing.assert_allclose(acted.torque, np.tile(tau_world, (len(tw), 1)), atol=1e-9)
    # shifting the stamps alone leaves each sample turned by omega * delay
    assert np.abs(rec.wrench.force - f_world).max() > 0.5 * omega * delay * np.linalg.norm(f_world[:2])

    world = read_recording(write_recording(tmp_path / "world.mcap", pose=pose,
                                           wrench=_wrench(tw + delay, f_world, tau_world, "world")))
    assert not world.wrench_turns_with_pose
    moved = world.wrench_acted(delay)
    np.testing.assert_allclose(moved.t_s, tw, atol=1e-9)
    np.testing.assert_array_equal(moved.force, world.wrench.force)


def test_wrench_in_static_sensor_frame_shifts_torque_to_tracked_origin(tmp_path):
    """A sensor frame offset through /tf_static: hand-computed force and shifted torque."""
    t = np.array([0.0, 0.5, 1.0])
    position = np.tile([1.0, 2.0, 0.0], (3, 1))
    pose = _pose(t, angle=np.full(3, np.pi / 2), position=position)  # Rz(90°): x→y, y→−x
    # the sensor sits at (0.1, 0, 0.05) in the gripper frame, flipped by Rx(180°)
    tf_static = [("gripper", "ft_sensor", ([0.1, 0.0, 0.05], [1.0, 0.0, 0.0, 0.0]))]
    wrench = _wrench([0.25, 0.75], [1.0, 0.0, 2.0], [0.1, 0.0, 0.0], "ft_sensor")
    path = write_recording(tmp_path / "static.mcap", pose=pose, wrench=wrench, tf_static=tf_static)

    rec = read_recording(path)
    # F_gripper = Rx180 (1, 0, 2) = (1, 0, −2); F_world = Rz90 (1, 0, −2) = (0, 1, −2)
    # τ_world = Rz90 Rx180 (0.1, 0, 0) = (0, 0.1, 0)
    # sensor origin − tracked origin = Rz90 (0.1, 0, 0.05) = (0, 0.1, 0.05)
    # (0, 0.1, 0.05) × (0, 1, −2) = (−0.25, 0, 0)  ⇒  τ_track = (−0.25, 0.1, 0)
    np.testing.assert_allclose(rec.wrench.force, [[0.0, 1.0, -2.0]] * 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.wrench.torque, [[-0.25, 0.1, 0.0]] * 2, rtol=0, atol=1e-12)
    assert rec.wrench_turns_with_pose  # held to the gripper by /tf_static: a wrist sensor


def test_world_wrench_acts_at_the_contact_point(tmp_path):
    """With a contact topic, a world wrench's torque is shifted from the contact to the tracked origin."""
    t = np.array([0.0, 1.0])
    pose = _pose(t, position=np.zeros((2, 3)))
    contact = PointTrack(t, [[0.0, 0.1, 0.0], [0.0, 0.1, 0.0]], "world", "/contact/point")
    wrench = _wrench(t, [2.0, 0.0, 0.0], [0.0, 0.0, 0.0], "world")
    rec = read_recording(write_recording(tmp_path / "c.mcap", pose=pose, wrench=wrench, contact=contact))
    # (0, 0.1, 0) × (2, 0, 0) = (0, 0, −0.2)
    np.testing.assert_allclose(rec.wrench.torque, [[0.0, 0.0, -0.2]] * 2, rtol=0, atol=1e-12)


def test_json_foxglove_pose_in_frame_is_a_pose_topic(tmp_path):
    """A JSON-encoded foxglove.PoseInFrame topic serves as the tracked pose."""
    import json

    from mcap.writer import Writer

    t = np.array([0.0, 1.0])
    base = write_recording(tmp_path / "w.mcap", pose=_pose(t), wrench=_wrench(t, [0, 1, 0], [0, 0, 0], "world"))
    poses = tmp_path / "fox.mcap"
    with open(poses, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("foxglove.PoseInFrame", "jsonschema", b"{}")
        cid = w.register_channel("/object/pose", "json", sid)
        for k, sec in enumerate((0, 1)):
            msg = {
                "timestamp": {"sec": sec, "nsec": 0},
                "frame_id": "world",
                "pose": {"position": {"x": 1.0 + k, "y": 0, "z": 0}, "orientation": {"x": 0, "y": 0, "z": 1, "w": 0}},
            }
            w.add_message(cid, sec * 10**9, json.dumps(msg).encode(), sec * 10**9)
        w.finish()
    both = _merge(tmp_path / "both.mcap", [base, poses], keep=lambda topic: topic != "/tracker/pose")
    rec = read_recording(both)
    assert (rec.pose.topic, rec.pose.frame_id, rec.pose.child_frame_id) == ("/object/pose", "world", "object/pose")
    np.testing.assert_allclose(rec.pose.position[:, 0], [1.0, 2.0])
    np.testing.assert_allclose(rec.pose.quat_xyzw, [[0, 0, 1, 0]] * 2)


def test_role_override_picks_the_named_pose_topic(tmp_path):
    """With two pose topics the override wins; bad overrides fail clearly."""
    t = np.linspace(0, 1, 5)
    a = write_recording(tmp_path / "a.mcap", pose=_pose(t), wrench=_wrench(t, [1, 0, 0], [0, 0, 0], "world"))
    t_obj = np.linspace(0, 1, 8)
    b = write_recording(
        tmp_path / "b.mcap",
        pose=_pose(t_obj, child="object", topic="/mocap/object"),
        wrench=_wrench(t, [1, 0, 0], [0, 0, 0], "world", topic="/b/wrench"),
    )
    both = _merge(tmp_path / "both.mcap", [a, b], keep=lambda topic: topic != "/b/wrench")

    with pytest.warns(UserWarning, match="several pose topics"):
        default = read_recording(both)
    assert default.pose.topic == "/mocap/object"  # more samples, otherwise equal
    chosen = read_recording(both, {"pose": "/tracker/pose", "wrench": "/ft_sensor/wrench"})
    assert (chosen.pose.topic, chosen.pose.child_frame_id, len(chosen.pose.t_s)) == ("/tracker/pose", "gripper", 5)
    with pytest.raises(LogError, match="pose topic /nope not in file"):
        read_recording(both, {"pose": "/nope"})
    with pytest.raises(LogError, match="has type 'geometry_msgs/msg/WrenchStamped'"):
        read_recording(both, {"pose": "/ft_sensor/wrench"})
    with pytest.raises(ValueError, match="unknown role"):
        read_recording(both, {"object": "/tracker/pose"})


def test_missing_wrench_topic_is_a_log_error(tmp_path):
    """A file with poses but no WrenchStamped names what is missing."""
    t = np.linspace(0, 1, 5)
    full = write_recording(tmp_path / "full.mcap", pose=_pose(t), wrench=_wrench(t, [1, 0, 0], [0, 0, 0], "world"))
    no_wrench = _merge(tmp_path / "no_wrench.mcap", [full], keep=lambda topic: topic != "/ft_sensor/wrench")
    with pytest.raises(LogError, match=r"no wrench topic \(geometry_msgs/msg/WrenchStamped\)") as err:
        read_recording(no_wrench)
    assert str(err.value).startswith(str(no_wrench))


def test_unresolvable_wrench_frame_is_a_log_error(tmp_path):
    """A wrench frame outside the tracked pose and TF tree is reported, not guessed."""
    t = np.linspace(0, 1, 5)
    path = write_recording(tmp_path / "f.mcap", pose=_pose(t), wrench=_wrench(t, [1, 0, 0], [0, 0, 0], "elsewhere"))
    with pytest.raises(LogError, match="frame 'elsewhere' cannot be resolved"):
        read_recording(path)


def test_damaged_or_missing_files_are_clean_log_errors(tmp_path):
    """Truncated, non-MCAP and missing files raise LogError starting with the path."""
    t = np.linspace(0, 1, 50)
    path = write_recording(tmp_path / "t.mcap", pose=_pose(t), wrench=_wrench(t, [1, 0, 0], [0, 0, 0], "world"))
    data = path.read_bytes()
    truncated = tmp_path / "half.mcap"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(LogError, match="truncated or corrupt") as err:
        read_recording(truncated)
    assert str(err.value).startswith(str(truncated)) and "\n" not in str(err.value)
    with pytest.raises(LogError, match="truncated or corrupt"):
        inspect_recording(truncated)

    text = tmp_path / "notes.mcap"
    text.write_text("not a recording\n")
    with pytest.raises(LogError, match="not an MCAP file"):
        read_recording(text)
    with pytest.raises(LogError, match="file not found"):
        read_recording(tmp_path / "absent.mcap")


def test_undecodable_extra_topic_is_skipped_with_a_warning(tmp_path):
    """A topic whose ROS 2 schema breaks the decoder is skipped; the rest still reads."""
    t = np.linspace(0, 1, 5)
    good = write_recording(tmp_path / "g.mcap", pose=_pose(t), wrench=_wrench(t, [1, 0, 0], [0, 0, 0], "world"))
    bad_schema = "float64 timeStamp\nfloat64 x\n"  # upper case breaks ROS 2 field naming
    # an accepted type with a broken definition: the decoder is built, and fails
    extra = [
        ("/robot2_JointsLog", "robot_comm/msg/robot_JointsLog", bad_schema, b"\x00" * 20),
        ("/other/wrench", "geometry_msgs/msg/WrenchStamped", bad_schema, b"\x00" * 20),
    ]
    path = _merge(tmp_path / "extra.mcap", [good], extra=extra)
    with pytest.warns(UserWarning, match="skipping topic /other/wrench"):
        rec = read_recording(path)
    assert rec.wrench.topic == "/ft_sensor/wrench"
    assert {s.topic for s in inspect_recording(path)} >= {"/robot2_JointsLog", "/other/wrench"}


def test_writer_leaves_no_half_file(tmp_path, monkeypatch):
    """A failure while writing leaves neither the target nor a temporary file."""
    t = np.linspace(0, 1, 5)
    monkeypatch.setitem(synth_recording.MSGDEFS, "geometry_msgs/msg/WrenchStamped", "no_such_pkg/Thing wrench\n")
    with pytest.raises(Exception):
        write_recording(tmp_path / "x.mcap", pose=_pose(t), wrench=_wrench(t, [1, 0, 0], [0, 0, 0], "world"))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "make, field",
    [
        (lambda: PoseTrack([], np.zeros((0, 3)), np.zeros((0, 4)), "world", "g", "/p"), "PoseTrack.t_s"),
        (lambda: PoseTrack([0, 0], np.zeros((2, 3)), [[0, 0, 0, 1]] * 2, "world", "g", "/p"), "PoseTrack.t_s"),
        (lambda: PoseTrack([0, 1], np.zeros((3, 3)), [[0, 0, 0, 1]] * 2, "world", "g", "/p"), "PoseTrack.position"),
        (lambda: PoseTrack([0, 1], np.zeros((2, 3)), [[0, 0, 0, 2]] * 2, "world", "g", "/p"), "PoseTrack.quat_xyzw"),
        (lambda: WrenchTrack([0, 1], [[0, 0, np.nan], [0, 0, 0]], np.zeros((2, 3)), "/w", "world"), "WrenchTrack.force"),
        (lambda: WrenchTrack([1, 0], np.zeros((2, 3)), np.zeros((2, 3)), "/w", "world"), "WrenchTrack.t_s"),
        (lambda: JointTrack([0, 1], ("a",), np.zeros((2, 2))), "JointTrack.position"),
        (lambda: PointTrack([0.0], np.zeros((1, 2)), "world", "/c"), "PointTrack.position"),
    ],
)
def test_tracks_reject_bad_data_naming_the_field(make, field):
    """Empty data, length mismatches, repeated stamps, non-finite values name their field."""
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        make()


@pytest.mark.skipif(not ST_1.exists(), reason="shared data (../shared/data) not present")
def test_real_mit_push_bag():
    """A 2015 MIT pushing bag: robot_comm topics listed, link_ft wrench resolved through /tf."""
    summary = {s.topic: s for s in inspect_recording(ST_1)}
    assert summary["/robot2_JointsLog"].type == "robot_comm/msg/robot_JointsLog"  # undecodable, still listed
    assert summary["/netft_data"].count == 602
    assert summary["/netft_data"].rate_hz == pytest.approx(100, rel=0.05)

    topics = {"pose": "/vicon/SteelBlock/SteelBlock", "wrench": "/netft_data"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the chosen topics read without complaint
        rec = read_recording(ST_1, topics)
    assert (rec.pose.frame_id, rec.pose.child_frame_id) == ("objworld", "vicon/SteelBlock/SteelBlock")
    assert len(rec.pose.t_s) == 603 and len(rec.wrench.t_s) == 602
    assert rec.wrench_raw.frame_id == "link_ft"
    assert rec.joints is not None and rec.joints.names == tuple(f"joint{i}" for i in range(1, 7))
    assert 5.9 < rec.duration_s < 6.1

    # the tool points down: R_world_ft = [[0,1,0],[1,0,0],[0,0,-1]] (mit-push README)
    raw = rec.wrench_raw
    swap = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]], dtype=float)
    np.testing.assert_allclose(rec.wrench.force, raw.force @ swap.T, rtol=0, atol=0.02)
    # torque shifted from link_ft to the block: check against /tip_pose (link_ft in base_link),
    # with map→viconworld = (0.4, 0, 0.01) and viconworld→objworld = identity in the St bags
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(ST_1, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        rows = [
            (m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, m.pose.position.x, m.pose.position.y, m.pose.position.z)
            for _, _, _, m in reader.iter_decoded_messages(topics=["/tip_pose"])
        ]
    tip = np.array(sorted(rows))
    p_ft = np.stack([np.interp(raw.t_s, tip[:, 0], tip[:, k]) for k in (1, 2, 3)], axis=1) - [0.4, 0.0, 0.01]
    p_block = rec.pose.interpolate(raw.t_s)[0]
    expected = raw.torque @ swap.T + np.cross(p_ft - p_block, raw.force @ swap.T)
    shift = np.abs(rec.wrench.torque - raw.torque @ swap.T).max()
    assert shift > 0.5  # N m: the lever arm matters
    np.testing.assert_allclose(rec.wrench.torque, expected, rtol=0, atol=0.04)

    # /tip_pose (PoseStamped, empty frame_id) as the tracked frame cannot place link_ft
    with pytest.raises(LogError, match="frame 'link_ft' cannot be resolved"):
        read_recording(ST_1, {"pose": "/tip_pose", "wrench": "/netft_data"})


def _write_messages(path: Path, pose_rows, wrench_rows, tip_rows=()) -> Path:
    """An MCAP file of TransformStamped poses and world WrenchStamped messages written as given:
    (sec, nanosec, position, quaternion) and (sec, nanosec, force, torque) rows, values unchecked;
    `tip_rows` go to a second pose topic, /tip_pose."""
    from mcap_ros2.writer import Writer

    def header(sec, nanosec, frame):
        return {"stamp": {"sec": int(sec), "nanosec": int(nanosec)}, "frame_id": frame}

    def xyz(v):
        return dict(zip("xyz", map(float, v)))

    with open(path, "wb") as f:
        w = Writer(f)
        pose_schema = w.register_msgdef("geometry_msgs/msg/TransformStamped",
                                        synth_recording.MSGDEFS["geometry_msgs/msg/TransformStamped"])
        wrench_schema = w.register_msgdef("geometry_msgs/msg/WrenchStamped",
                                          synth_recording.MSGDEFS["geometry_msgs/msg/WrenchStamped"])
        for topic, child, rows in (("/tracker/pose", "gripper", pose_rows), ("/tip_pose", "tip", tip_rows)):
            for sec, ns, p, q in rows:
                msg = {"header": header(sec, ns, "world"), "child_frame_id": child,
                       "transform": {"translation": xyz(p), "rotation": dict(zip("xyzw", map(float, q)))}}
                w.write_message(topic, pose_schema, msg, log_time=sec * 10**9 + ns, publish_time=0)
        for sec, ns, force, torque in wrench_rows:
            msg = {"header": header(sec, ns, "world"), "wrench": {"force": xyz(force), "torque": xyz(torque)}}
            w.write_message("/ft_sensor/wrench", wrench_schema, msg, log_time=sec * 10**9 + ns, publish_time=0)
        w.finish()
    return path


def _rows(seconds, first, second):
    """Rows stamped at `seconds` (after 100 s, so that no stamp is zero) holding `first` and `second`."""
    return [(100 + int(s), int(round((s % 1) * 1e9)), first, second) for s in seconds]


def test_a_stamp_far_from_the_rest_is_dropped_with_a_warning(tmp_path):
    """One pose stamped at 2^31 s among stamps near 100 s would stretch the track over 68 years: it is
    dropped, and the warning names the file, the topic and the count."""
    t = np.linspace(0.0, 1.0, 50)
    poses = _rows(t, (0.1, 0.2, 0.3), (0, 0, 0, 1))
    poses.insert(20, (2**31 - 1, 0, (0.1, 0.2, 0.3), (0, 0, 0, 1)))
    path = _write_messages(tmp_path / "far.mcap", poses, _rows(t, (1, 0, 0), (0, 0, 0)))
    with pytest.warns(UserWarning, match=r"far\.mcap: /tracker/pose: dropped 1 sample stamped far"):
        rec = read_recording(path)
    assert len(rec.pose.t_s) == 50 and rec.pose.t_s[-1] == pytest.approx(101.0)
    assert rec.duration_s == pytest.approx(1.0)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_few_non_finite_wrench_samples_are_dropped_most_are_an_error(tmp_path, bad):
    """Non-finite wrench values: a few are dropped with a warning naming file and topic; a stream
    that is mostly non-finite is a LogError."""
    t = np.linspace(0.0, 1.0, 20)
    poses = _rows(t, (0.1, 0.2, 0.3), (0, 0, 0, 1))
    wrenches = _rows(t, (1, 0, 0), (0, 0, 0))
    wrenches[3] = (wrenches[3][0], wrenches[3][1], (bad, 0, 0), (0, 0, 0))
    path = _write_messages(tmp_path / "few.mcap", poses, wrenches)
    with pytest.warns(UserWarning, match=r"few\.mcap: /ft_sensor/wrench: dropped 1 sample"):
        rec = read_recording(path)
    assert len(rec.wrench.t_s) == 19
    mostly = [(s, ns, f, (0, 0, bad) if k % 3 else tau) for k, (s, ns, f, tau) in enumerate(wrenches)]
    path = _write_messages(tmp_path / "most.mcap", poses, mostly)
    with pytest.raises(LogError, match=r"most\.mcap: /ft_sensor/wrench: 14 of 20 samples hold non-finite"):
        read_recording(path)


def test_a_broken_second_pose_topic_does_not_stop_the_read(tmp_path):
    """A pusher tip's pose topic mostly NaN is no candidate for the tracked pose (a warning says why); the
    good topic is read."""
    t = np.linspace(0.0, 1.0, 20)
    tips = _rows(t, (np.nan, 0, 0), (0, 0, 0, 1))[:15] + _rows(t[15:], (0.2, 0, 0), (0, 0, 0, 1))
    path = _write_messages(tmp_path / "tip.mcap", _rows(t, (0.1, 0.2, 0.3), (0, 0, 0, 1)),
                           _rows(t, (1, 0, 0), (0, 0, 0)), tips)
    with pytest.warns(UserWarning, match=r"tip\.mcap: /tip_pose: 15 of 20 samples hold non-finite .* not taken"):
        rec = read_recording(path)
    assert rec.pose.topic == "/tracker/pose" and len(rec.pose.t_s) == 20


@pytest.mark.parametrize("force, torque, what", [((1e300, 0, 0), (0, 0, 0), "force"),
                                                 ((0, -2e5, 0), (0, 0, 0), "force"),
                                                 ((1, 0, 0), (0, 0, 3e4), "torque")])
def test_an_absurd_wrench_is_a_log_error(tmp_path, force, torque, what):
    """A wrench beyond 1e5 N or 1e4 N m is no measurement (it would end as a singular fit): a LogError
    naming the file and the topic."""
    t = np.linspace(0.0, 1.0, 20)
    wrenches = _rows(t, (1, 0, 0), (0, 0, 0))
    wrenches[5] = (wrenches[5][0], wrenches[5][1], force, torque)
    path = _write_messages(tmp_path / "huge.mcap", _rows(t, (0.1, 0.2, 0.3), (0, 0, 0, 1)), wrenches)
    with pytest.raises(LogError, match=rf"huge\.mcap: /ft_sensor/wrench: {what} of .* beyond") as err:
        read_recording(path)
    assert "\n" not in str(err.value)


def test_pose_and_wrench_that_do_not_overlap_in_time_are_a_log_error(tmp_path):
    """Poses over 100..101 s and wrenches over 200..201 s (two clocks): a LogError naming both ranges."""
    t = np.linspace(0.0, 1.0, 20)
    path = _write_messages(tmp_path / "apart.mcap", _rows(t, (0.1, 0.2, 0.3), (0, 0, 0, 1)),
                           _rows(t + 100, (1, 0, 0), (0, 0, 0)))
    with pytest.raises(LogError, match=r"apart\.mcap: pose topic /tracker/pose stamps 100\.000\.\.101\.000 s and "
                                       r"wrench topic /ft_sensor/wrench stamps 200\.000\.\.201\.000 s do not overlap"):
        read_recording(path)


def test_uniform_pose_grid_refuses_a_span_it_cannot_hold():
    """A stray stamp at 2^31 s behind 50 samples 20 ms apart would take 10^11 grid samples (terabytes): the
    grid refuses, naming the span, instead of allocating."""
    from pipelines.identify.windows import uniform_pose_grid

    t = np.r_[np.linspace(0.0, 1.0, 50), 2.0**31]
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
    with pytest.raises(ValueError, match=r"0\.000\.\.2147483648\.000 s \(2\.15e\+09 s\)"):
        uniform_pose_grid(t, np.zeros((len(t), 3)), quat)
    grid, _, _ = uniform_pose_grid(t[:-1], np.zeros((len(t) - 1, 3)), quat[:-1])
    assert len(grid) == 50
