"""The message types the reader knows, and decoded messages (ROS 2 objects or JSON dicts) into tracks
and transform edges, their stamps and frame ids as recorded."""

from __future__ import annotations

import warnings
from collections import Counter
from pathlib import Path
from typing import Any, Callable

import numpy as np

from assets.recording import JointTrack, PointTrack, PoseTrack

from .checks import MAX_POSITION_M, LogError, bounded, clean_stream
from .frames import Edge
from .mcap_file import DecodedTopic

__all__ = ["JOINT_TYPE", "POINT_TYPE", "POSE_TYPES", "ROLES", "ROLE_TYPES", "TF_TOPICS", "TF_TYPE", "WRENCH_TYPE",
           "dominant", "joint_track", "message_fields", "point_track", "pose_track", "tf_edges", "wrench_samples"]

POSE_TYPES: tuple[str, ...] = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/TransformStamped",
    "foxglove.PoseInFrame",
    "foxglove_msgs/msg/PoseInFrame",
)
WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
POINT_TYPE = "geometry_msgs/msg/PointStamped"
JOINT_TYPE = "sensor_msgs/msg/JointState"
TF_TYPE = "tf2_msgs/msg/TFMessage"
ROLES: tuple[str, ...] = ("pose", "wrench", "contact", "joint")
TF_TOPICS = ("/tf", "/tf_static")
ROLE_TYPES = {
    "pose": POSE_TYPES,
    "wrench": (WRENCH_TYPE,),
    "contact": (POINT_TYPE, *POSE_TYPES),  # a pose's origin serves as the point (e.g. a pusher tip)
    "joint": (JOINT_TYPE,),
}
_MALFORMED = (TypeError, ValueError, OverflowError)
"""What reading a decoded message's fields raises when a JSON message holds the wrong types."""


def _get(msg: Any, name: str, default: Any = None) -> Any:
    """A field of a decoded message (ROS 2 object or JSON dict)."""
    if isinstance(msg, dict):
        return msg.get(name, default)
    return getattr(msg, name, default)


def _xyz(v: Any) -> tuple[float, float, float]:
    return (float(_get(v, "x", 0.0)), float(_get(v, "y", 0.0)), float(_get(v, "z", 0.0)))


def _xyzw(q: Any) -> tuple[float, float, float, float]:
    return (*_xyz(q), float(_get(q, "w", 1.0)))


def _stamp_s(stamp: Any, log_ns: int) -> float:
    """Seconds from a Time {sec, nanosec|nsec}; the log time if the stamp is zero or absent.

    Raises one of `_MALFORMED` for fields that are no integers (JSON messages).
    """
    if stamp is None:
        return log_ns * 1e-9
    sec = int(_get(stamp, "sec", 0) or 0)
    nsec = _get(stamp, "nanosec", None)
    if nsec is None:
        nsec = _get(stamp, "nsec", 0)
    nsec = int(nsec or 0)
    if sec == 0 and nsec == 0:
        return log_ns * 1e-9
    return sec + nsec * 1e-9


def _frame(name: Any) -> str:
    return str(name or "").lstrip("/")


def message_fields(path: Path, d: DecodedTopic, extract: Callable[[int, Any], Any]) -> list:
    """extract(log_ns, message) of each message, skipping (with a warning) those whose fields have wrong types.

    Decoded ROS 2 messages always have the schema's types; JSON messages may hold anything.
    """
    rows, malformed = [], 0
    for log_ns, m in d.items:
        try:
            rows.append(extract(log_ns, m))
        except _MALFORMED:
            malformed += 1
    if malformed:
        warnings.warn(f"{path}: {d.topic}: skipped {malformed} messages with fields of the wrong type", stacklevel=3)
    return rows


def dominant(path: Path, topic: str, keys: list) -> tuple[Any, np.ndarray]:
    """The most common key and a mask of the messages that have it (warns if mixed)."""
    counts = Counter(keys)
    key, _ = counts.most_common(1)[0]
    mask = np.array([k == key for k in keys], dtype=bool)
    if len(counts) > 1:
        warnings.warn(
            f"{path}: {topic}: messages carry several frames {sorted(counts)}; keeping the "
            f"{int(mask.sum())} with {key}",
            stacklevel=3,
        )
    return key, mask


def _pose_row(type_: str) -> Callable[[int, Any], tuple]:
    """(stamp, position, quaternion, (frame, child)) of one message of a pose type."""
    def transform(log_ns, m):
        header, tr = _get(m, "header"), _get(m, "transform")
        return (_stamp_s(_get(header, "stamp"), log_ns), _xyz(_get(tr, "translation")),
                _xyzw(_get(tr, "rotation")), (_frame(_get(header, "frame_id")), _frame(_get(m, "child_frame_id"))))

    def pose(log_ns, m):
        header, p = _get(m, "header"), _get(m, "pose")
        return (_stamp_s(_get(header, "stamp"), log_ns), _xyz(_get(p, "position")), _xyzw(_get(p, "orientation")),
                (_frame(_get(header, "frame_id")), ""))

    def in_frame(log_ns, m):  # foxglove PoseInFrame: timestamp, frame_id, pose
        p = _get(m, "pose")
        return (_stamp_s(_get(m, "timestamp"), log_ns), _xyz(_get(p, "position")), _xyzw(_get(p, "orientation")),
                (_frame(_get(m, "frame_id")), ""))

    if type_.endswith("TransformStamped"):
        return transform
    return pose if type_.endswith("PoseStamped") else in_frame


def pose_track(path: Path, d: DecodedTopic, required: bool = True) -> tuple[PoseTrack, str]:
    """The topic's poses, and its parent frame as recorded ("" if none; the track says "world").

    `required`: read as the tracked pose, not a contact point (see `clean_stream`).
    """
    rows = message_fields(path, d, _pose_row(d.type))
    if not rows:
        raise LogError(f"{path}: pose topic {d.topic} has no readable messages")
    (frame_id, child), mask = dominant(path, d.topic, [r[3] for r in rows])
    rows = [r for r, keep in zip(rows, mask) if keep]
    t = np.array([r[0] for r in rows], dtype=float)
    pos = np.array([r[1] for r in rows], dtype=float)
    quat = np.array([r[2] for r in rows], dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):  # huge components give an infinite norm, refused below
        norm = np.linalg.norm(quat, axis=1)
    ok = np.isfinite(norm) & (np.abs(norm - 1.0) < 0.1)  # zero quaternions: occluded markers
    t, (pos, quat) = clean_stream(path, d.topic, t, [pos, quat], ok, required)
    bounded(path, d.topic, "position", t, pos, MAX_POSITION_M, "m")
    quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    default_child = d.topic.lstrip("/")
    return PoseTrack(t, pos, quat, frame_id or "world", child or default_child, d.topic), frame_id


def wrench_samples(path: Path, d: DecodedTopic) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    def row(log_ns, m):
        header, w = _get(m, "header"), _get(m, "wrench")
        return (_stamp_s(_get(header, "stamp"), log_ns), _xyz(_get(w, "force")), _xyz(_get(w, "torque")),
                _frame(_get(header, "frame_id")))

    rows = message_fields(path, d, row)
    if not rows:
        raise LogError(f"{path}: wrench topic {d.topic} has no readable messages")
    t, f, tau, frames = zip(*rows)
    return np.array(t, dtype=float), np.array(f, dtype=float), np.array(tau, dtype=float), list(frames)


def point_track(path: Path, d: DecodedTopic, frame_if_empty: str = "") -> PointTrack | None:
    """Points of a PointStamped topic, or the origins of a pose topic's poses."""
    if d.type != POINT_TYPE:
        track, recorded = pose_track(path, d, required=False)
        return PointTrack(track.t_s, track.position, recorded or frame_if_empty, d.topic)

    def row(log_ns, m):
        header = _get(m, "header")
        return (_stamp_s(_get(header, "stamp"), log_ns), _xyz(_get(m, "point")),
                _frame(_get(header, "frame_id")) or frame_if_empty)

    rows = message_fields(path, d, row)
    if not rows:
        return None
    t, p, frames = zip(*rows)
    frame, mask = dominant(path, d.topic, list(frames))
    t, (p,) = clean_stream(path, d.topic, np.array(t, dtype=float)[mask], [np.array(p, dtype=float)[mask]])
    bounded(path, d.topic, "contact point", t, p, MAX_POSITION_M, "m")
    return PointTrack(t, p, frame, d.topic)


def joint_track(path: Path, d: DecodedTopic) -> JointTrack | None:
    def row(log_ns, m):
        return (_stamp_s(_get(_get(m, "header"), "stamp"), log_ns), tuple(str(x) for x in (_get(m, "name") or ())),
                [float(x) for x in (_get(m, "position") or ())], [float(x) for x in (_get(m, "velocity") or ())])

    names: tuple[str, ...] | None = None
    t, q, v, skipped = [], [], [], 0
    for stamp, n, pos, vel in message_fields(path, d, row):
        if names is None:
            if not n or len(set(n)) != len(n) or len(pos) != len(n):
                skipped += 1
                continue
            names = n
        if set(n) != set(names) or len(n) != len(names) or len(pos) != len(n):
            skipped += 1
            continue
        order = [n.index(name) for name in names]
        t.append(stamp)
        q.append([pos[i] for i in order])
        v.append([vel[i] for i in order] if len(vel) == len(n) else None)
    if skipped:
        warnings.warn(f"{path}: {d.topic}: skipped {skipped} messages with other or missing joints", stacklevel=3)
    if names is None or not t:
        return None
    has_v = all(x is not None for x in v)
    arrays = [np.asarray(q, dtype=float)] + ([np.asarray(v, dtype=float)] if has_v else [])
    t, arrays = clean_stream(path, d.topic, np.asarray(t, dtype=float), arrays)
    return JointTrack(t, names, arrays[0], arrays[1] if has_v else None, d.topic)


def tf_edges(path: Path, decoded: list[DecodedTopic]) -> list[Edge]:
    """Edges from TFMessage topics; /tf_static ones are static (last value wins)."""
    def rows(log_ns, m):
        out = []
        for tr in _get(m, "transforms") or ():
            header, x = _get(tr, "header"), _get(tr, "transform")
            out.append(((_frame(_get(header, "frame_id")), _frame(_get(tr, "child_frame_id"))),
                        (_stamp_s(_get(header, "stamp"), log_ns), *_xyz(_get(x, "translation")),
                         *_xyzw(_get(x, "rotation")))))
        return out

    samples: dict[tuple[str, str], list] = {}
    static: set[tuple[str, str]] = set()
    for d in decoded:
        is_static = d.topic.rstrip("/").endswith("tf_static")
        for message in message_fields(path, d, rows):
            for key, row in message:
                samples.setdefault(key, []).append(row)
                if is_static:
                    static.add(key)
    edges = []
    for (parent, child), rows in samples.items():
        a = np.asarray(rows, dtype=float)
        key_static = (parent, child) in static
        if key_static:
            a = a[-1:]
        with np.errstate(over="ignore", invalid="ignore"):
            norm = np.linalg.norm(a[:, 4:8], axis=1)
            ok = (np.abs(norm - 1.0) < 0.1) & (np.linalg.norm(a[:, 1:4], axis=1) <= MAX_POSITION_M)
        try:
            t, (p, q) = clean_stream(path, f"/tf {parent}->{child}", a[:, 0], [a[:, 1:4], a[:, 4:8]], ok)
        except LogError:
            continue
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        edges.append(Edge(parent, child, t, p, q, "/tf_static" if key_static else "/tf"))
    return edges
