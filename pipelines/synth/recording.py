"""Write synthetic interaction recordings as ROS 2 MCAP files.

`write_recording` is the inverse of `pipelines.logs.read_recording` for the
data it writes: CDR-encoded ROS 2 messages with their full message definitions,
zstd-compressed chunks, header stamps AND log times taken from the track times
(seconds → sec/nanosec). It writes what it is given: the wrench goes out in the
frame named by `WrenchTrack.frame_id` (the caller decides the frame and the
point the torque is taken about, per DESIGN.md "Logs: MCAP").

Topics (a track's own `topic`, when not empty, replaces the default):

| data | type | default topic |
| --- | --- | --- |
| tracked pose | geometry_msgs/msg/TransformStamped | /tracker/pose |
| wrench | geometry_msgs/msg/WrenchStamped | /ft_sensor/wrench |
| contact point | geometry_msgs/msg/PointStamped | /contact/point |
| joints | sensor_msgs/msg/JointState | /joint_states |
| fixed frames | tf2_msgs/msg/TFMessage | /tf_static |
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from assets.recording import JointTrack, PointTrack, PoseTrack, WrenchTrack

__all__ = ["write_recording", "MSGDEFS"]

_SEP = "=" * 80

_TIME = "int32 sec\nuint32 nanosec"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id"
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z"
_QUATERNION = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w"
_TRANSFORM = "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation"
_TRANSFORM_STAMPED = "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform"


def _msgdef(top: str, deps: Sequence[tuple[str, str]]) -> str:
    """A ROS 2 message definition with its dependencies, as rosbag2 stores it."""
    parts = [top]
    for name, text in deps:
        parts.append(f"{_SEP}\nMSG: {name}\n{text}")
    return "\n".join(parts) + "\n"


_HEADER_DEPS = [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME)]
_TRANSFORM_DEPS = _HEADER_DEPS + [
    ("geometry_msgs/Transform", _TRANSFORM),
    ("geometry_msgs/Vector3", _VECTOR3),
    ("geometry_msgs/Quaternion", _QUATERNION),
]

MSGDEFS: dict[str, str] = {
    "geometry_msgs/msg/TransformStamped": _msgdef(_TRANSFORM_STAMPED, _TRANSFORM_DEPS),
    "geometry_msgs/msg/WrenchStamped": _msgdef(
        "std_msgs/Header header\ngeometry_msgs/Wrench wrench",
        _HEADER_DEPS
        + [
            ("geometry_msgs/Wrench", "geometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque"),
            ("geometry_msgs/Vector3", _VECTOR3),
        ],
    ),
    "geometry_msgs/msg/PointStamped": _msgdef(
        "std_msgs/Header header\ngeometry_msgs/Point point",
        _HEADER_DEPS + [("geometry_msgs/Point", _VECTOR3)],
    ),
    "sensor_msgs/msg/JointState": _msgdef(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort",
        _HEADER_DEPS,
    ),
    "tf2_msgs/msg/TFMessage": _msgdef(
        "geometry_msgs/TransformStamped[] transforms",
        [("geometry_msgs/TransformStamped", _TRANSFORM_STAMPED)] + _TRANSFORM_DEPS,
    ),
}
"""ROS 2 (Humble+) message definitions written as the schemas, keyed by type."""


def _split_stamp(t_s: float, what: str) -> tuple[int, int]:
    """Seconds → (sec, nanosec), rounded to the nearest nanosecond."""
    total_ns = int(round(float(t_s) * 1e9)) if abs(t_s) < 2**31 else None
    if total_ns is None or total_ns < 0:
        raise ValueError(f"{what}: stamp {t_s!r} s is outside [0, 2^31) s (MCAP log times are unsigned)")
    sec, nanosec = divmod(total_ns, 1_000_000_000)
    return sec, nanosec


def _header(t_s: float, frame_id: str, what: str) -> tuple[dict, int]:
    sec, nanosec = _split_stamp(t_s, what)
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}, sec * 1_000_000_000 + nanosec


def _vec(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quat(q) -> dict:
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


def _pose_parts(pose: Any, what: str) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,), quaternion xyzw (4,)) from a Pose-like object or a (position, quat) pair."""
    if hasattr(pose, "position") and hasattr(pose, "quaternion_xyzw"):
        p, q = pose.position, pose.quaternion_xyzw
    elif hasattr(pose, "position") and hasattr(pose, "quat_xyzw"):
        p, q = pose.position, pose.quat_xyzw
    else:
        try:
            p, q = pose
        except (TypeError, ValueError):
            raise ValueError(f"{what}: expected a Pose (position, quaternion_xyzw) or a (position, quat) pair") from None
    p = np.asarray(p, dtype=float).reshape(-1)
    q = np.asarray(q, dtype=float).reshape(-1)
    if p.shape != (3,) or q.shape != (4,) or not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        raise ValueError(f"{what}: expected a finite position (3,) and quaternion xyzw (4,)")
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > 1e-6:
        raise ValueError(f"{what}: quaternion norm {n:.6g}, expected a unit quaternion")
    return p, q


def write_recording(
    path: Path,
    *,
    pose: PoseTrack,
    wrench: WrenchTrack,
    tf_static: Iterable[tuple[str, str, Any]] = (),
    joints: JointTrack | None = None,
    contact: PointTrack | None = None,
) -> Path:
    """Write one trial as a ROS 2 MCAP file; returns the path.

    Args:
        path: the .mcap file to create (replaced if it exists). Written to a
            temporary file beside it and renamed, so a failure leaves no half file.
        pose: the tracked frame: TransformStamped, header.frame_id = `pose.frame_id`
            (normally "world"), child_frame_id = `pose.child_frame_id` [m].
        wrench: WrenchStamped with header.frame_id = `wrench.frame_id`, force [N]
            and torque [N m] written as given.
        tf_static: fixed transforms (parent, child, pose of child in parent) where
            pose is Pose-like (`position` [m], `quaternion_xyzw`) or a
            (position, quat_xyzw) pair; one TFMessage on /tf_static stamped at the
            first pose time.
        joints: JointState messages (position, velocity if given; effort empty).
        contact: PointStamped messages (the contact point, normally in world).

    Raises:
        ValueError: an argument of the wrong type, a malformed static transform,
            or a stamp outside [0, 2^31) s.
    """
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer

    path = Path(path)
    for name, value, kind in (("pose", pose, PoseTrack), ("wrench", wrench, WrenchTrack)):
        if not isinstance(value, kind):
            raise ValueError(f"write_recording: {name} must be a {kind.__name__}, got {type(value).__name__}")
    if joints is not None and not isinstance(joints, JointTrack):
        raise ValueError(f"write_recording: joints must be a JointTrack or None, got {type(joints).__name__}")
    if contact is not None and not isinstance(contact, PointTrack):
        raise ValueError(f"write_recording: contact must be a PointTrack or None, got {type(contact).__name__}")
    statics = []
    for i, item in enumerate(tf_static):
        try:
            parent, child, rel = item
        except (TypeError, ValueError):
            raise ValueError(f"write_recording: tf_static[{i}]: expected (parent, child, pose)") from None
        p, q = _pose_parts(rel, f"write_recording: tf_static[{i}] ({parent} -> {child})")
        statics.append((str(parent), str(child), p, q))

    # (log_ns, topic, type, message): written in time order across topics
    records: list[tuple[int, int, str, str, dict]] = []

    def add(log_ns: int, topic: str, type_: str, msg: dict) -> None:
        records.append((log_ns, len(records), topic, type_, msg))

    pose_topic = pose.topic or "/tracker/pose"
    for t, p, q in zip(pose.t_s, pose.position, pose.quat_xyzw):
        header, ns = _header(t, pose.frame_id, "pose.t_s")
        msg = {
            "header": header,
            "child_frame_id": pose.child_frame_id,
            "transform": {"translation": _vec(p), "rotation": _quat(q)},
        }
        add(ns, pose_topic, "geometry_msgs/msg/TransformStamped", msg)

    wrench_topic = wrench.topic or "/ft_sensor/wrench"
    for t, f, tau in zip(wrench.t_s, wrench.force, wrench.torque):
        header, ns = _header(t, wrench.frame_id, "wrench.t_s")
        add(ns, wrench_topic, "geometry_msgs/msg/WrenchStamped", {"header": header, "wrench": {"force": _vec(f), "torque": _vec(tau)}})

    if contact is not None:
        for t, p in zip(contact.t_s, contact.position):
            header, ns = _header(t, contact.frame_id, "contact.t_s")
            add(ns, contact.topic or "/contact/point", "geometry_msgs/msg/PointStamped", {"header": header, "point": _vec(p)})

    if joints is not None:
        for k, t in enumerate(joints.t_s):
            header, ns = _header(t, "", "joints.t_s")
            msg = {
                "header": header,
                "name": list(joints.names),
                "position": [float(x) for x in joints.position[k]],
                "velocity": [] if joints.velocity is None else [float(x) for x in joints.velocity[k]],
                "effort": [],
            }
            add(ns, joints.topic or "/joint_states", "sensor_msgs/msg/JointState", msg)

    if statics:
        transforms = []
        for parent, child, p, q in statics:
            header, ns = _header(pose.t_s[0], parent, "pose.t_s")
            transforms.append(
                {"header": header, "child_frame_id": child, "transform": {"translation": _vec(p), "rotation": _quat(q)}}
            )
        add(ns, "/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": transforms})

    records.sort(key=lambda r: (r[0], r[1]))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            writer = Writer(f, compression=CompressionType.ZSTD)
            schemas = {}
            for log_ns, _, topic, type_, msg in records:
                schema = schemas.get(type_)
                if schema is None:
                    schema = schemas[type_] = writer.register_msgdef(type_, MSGDEFS[type_])
                writer.write_message(topic, schema, msg, log_time=log_ns, publish_time=log_ns)
            writer.finish()
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
