"""Robot interaction logs (MCAP) into time-stamped tracks in the world frame.

`read_recording` reads one MCAP file (ROS 2 CDR messages, or JSON-encoded
Foxglove poses), finds its topics by message type (see DESIGN.md, "Logs:
MCAP") and returns a `Recording`:

- `pose`: the tracked frame (object, gripper or mocap markers) in world [m];
- `wrench`: the wrench the robot applies TO the object, converted to WORLD
  axes with its torque taken about the TRACKED FRAME's origin, so downstream
  code needs no frames;
- `wrench_raw`: the same samples as in the messages (message frame, torque
  about that frame's origin, or the contact point for world wrenches);
- `contact` and `joints` when the file has them.

World is the tracked pose's parent frame (`PoseTrack.frame_id`, e.g. "world";
the name "world" always means it too). A wrench in world acts at the contact
point when a contact topic exists, else at the tracked frame's origin. A wrench
in any other frame is resolved through the tracked pose itself and the
`/tf_static` + `/tf` tree (transforms interpolated at the wrench stamp: linear
in translation, slerp in rotation; held at the ends outside their range), and
acts at that frame's origin: τ_track = τ + (p_frame − p_track) × F.

Times are header stamps in seconds (as recorded, e.g. UNIX time); a zero stamp
falls back to the message's log time. Frame ids are compared without a leading
"/" (as tf2 does). Undecodable topics (e.g. the `robot_comm/*` schemas of the
MIT pushing bags) are skipped with a warning; a damaged file raises `LogError`.

What a file holds is checked before anything downstream sees it: samples with
non-finite values and stamps far outside the rest of their stream (one message
stamped at 2^31 s among stamps near 0) are dropped with a warning naming the file
and topic; a pose or wrench stream mostly non-finite, a force beyond 1e5 N, a
torque beyond 1e4 N m, a position beyond 1000 km, and pose and wrench streams
whose stamps do not overlap raise `LogError`.
"""

from __future__ import annotations

import json
import warnings
from collections import Counter, deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

__all__ = [
    "JointTrack",
    "LogError",
    "PointTrack",
    "PoseTrack",
    "Recording",
    "TopicSummary",
    "WrenchTrack",
    "inspect_recording",
    "read_recording",
    "POSE_TYPES",
    "WRENCH_TYPE",
    "POINT_TYPE",
    "JOINT_TYPE",
    "TF_TYPE",
    "ROLES",
]

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
_TF_TOPICS = ("/tf", "/tf_static")
_ROLE_TYPES = {
    "pose": POSE_TYPES,
    "wrench": (WRENCH_TYPE,),
    "contact": (POINT_TYPE, *POSE_TYPES),  # a pose's origin serves as the point (e.g. a pusher tip)
    "joint": (JOINT_TYPE,),
}
_QUAT_NORM_TOL = 1e-6
_FAR_STAMP_SPREADS = 1000.0
"""A stamp farther from its stream's median stamp than this many spreads (the stamps' median absolute
deviation, at least the median gap) is a glitch, not a pause: one message stamped at 2^31 s among stamps
near 0 would stretch the recording over 68 years, and a pose grid over it would need terabytes."""
MAX_FORCE_N = 1e5
MAX_TORQUE_NM = 1e4
MAX_POSITION_M = 1e6
"""Beyond these a value is no measurement of a robot pushing an object (a unit or encoding error): it
would only surface later as a singular fit."""
_MALFORMED = (TypeError, ValueError, OverflowError)
"""What reading a decoded message's fields raises when a JSON message holds the wrong types."""


class LogError(ValueError):
    """A recording that cannot be read; the message starts with the file path."""


# --------------------------------------------------------------------------
# validation of the track fields


def _stamps(values, name: str) -> np.ndarray:
    t = np.array(values, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"{name}: expected shape (N,), got {t.shape}")
    if t.size == 0:
        raise ValueError(f"{name}: empty, expected at least one sample")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: {int(np.sum(~np.isfinite(t)))} non-finite stamps")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{name}: stamps must strictly increase, got {t[i]!r} then {t[i + 1]!r} "
            f"at index {i + 1} (sort and deduplicate first)"
        )
    t.setflags(write=False)
    return t


def _samples(values, n: int, width: int, name: str) -> np.ndarray:
    a = np.array(values, dtype=float)
    if a.shape != (n, width):
        raise ValueError(f"{name}: expected shape ({n}, {width}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        rows = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
        raise ValueError(f"{name}: non-finite values in {rows.size} rows (first: row {int(rows[0])})")
    a.setflags(write=False)
    return a


def _text(value, name: str) -> str:
    if not isinstance(value, str):
        raise ValueError(f"{name}: expected a string, got {type(value).__name__}")
    return value


def _interp_linear(t: np.ndarray, values: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Linear interpolation per column, held constant outside [t[0], t[-1]]."""
    return np.stack([np.interp(t_query, t, values[:, k]) for k in range(values.shape[1])], axis=1)


def _interp_rotation(t: np.ndarray, quat_xyzw: np.ndarray, t_query: np.ndarray) -> Rotation:
    """Slerp between samples, held constant outside [t[0], t[-1]]."""
    if len(t) == 1:
        return Rotation.from_quat(np.repeat(quat_xyzw, len(t_query), axis=0))
    return Slerp(t, Rotation.from_quat(quat_xyzw))(np.clip(t_query, t[0], t[-1]))


# --------------------------------------------------------------------------
# the tracks


@dataclass(frozen=True, eq=False)
class PoseTrack:
    """Poses of a tracked frame over time.

    Attributes:
        t_s: stamps [s], shape (N,), strictly increasing.
        position: origin of `child_frame_id` in `frame_id` (world) [m], shape (N, 3).
        quat_xyzw: orientation of `child_frame_id` in `frame_id`, unit quaternions
            (x, y, z, w), shape (N, 4).
        frame_id: the parent frame, the recording's world (e.g. "world").
        child_frame_id: the tracked frame (e.g. "gripper").
        topic: the topic it came from (or is written to).
    """

    t_s: np.ndarray
    position: np.ndarray
    quat_xyzw: np.ndarray
    frame_id: str
    child_frame_id: str
    topic: str

    def __post_init__(self):
        t = _stamps(self.t_s, "PoseTrack.t_s")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "position", _samples(self.position, len(t), 3, "PoseTrack.position"))
        q = _samples(self.quat_xyzw, len(t), 4, "PoseTrack.quat_xyzw")
        norm = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > _QUAT_NORM_TOL)
        if bad.size:
            i = int(bad[0])
            raise ValueError(
                f"PoseTrack.quat_xyzw: expected unit quaternions, row {i} has norm {norm[i]:.6g} "
                f"({bad.size} rows off by more than {_QUAT_NORM_TOL:g})"
            )
        object.__setattr__(self, "quat_xyzw", q)
        for name in ("frame_id", "child_frame_id", "topic"):
            _text(getattr(self, name), f"PoseTrack.{name}")

    def interpolate(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """Position [m] (K, 3) and quaternion xyzw (K, 4) at stamps `t_s` [s].

        Linear in position, slerp in rotation; held at the first/last sample
        outside the track's time range.
        """
        tq = np.atleast_1d(np.asarray(t_s, dtype=float))
        return (
            _interp_linear(self.t_s, self.position, tq),
            _interp_rotation(self.t_s, self.quat_xyzw, tq).as_quat(),
        )


@dataclass(frozen=True, eq=False)
class WrenchTrack:
    """A wrench over time.

    In `Recording.wrench` it is the wrench applied by the robot TO the object in
    world axes (`frame_id` is the world frame) with the torque about the tracked
    frame's origin; in `Recording.wrench_raw` and when writing, it is as in the
    messages: axes of `frame_id`, torque about that frame's origin (or, for a
    world wrench with a contact topic, about the contact point).

    Attributes:
        t_s: stamps [s], shape (M,), strictly increasing.
        force: [N], shape (M, 3).
        torque: [N m], shape (M, 3).
        topic: the topic it came from (or is written to).
        frame_id: the frame whose axes express it.
    """

    t_s: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    topic: str
    frame_id: str

    def __post_init__(self):
        t = _stamps(self.t_s, "WrenchTrack.t_s")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "force", _samples(self.force, len(t), 3, "WrenchTrack.force"))
        object.__setattr__(self, "torque", _samples(self.torque, len(t), 3, "WrenchTrack.torque"))
        for name in ("topic", "frame_id"):
            _text(getattr(self, name), f"WrenchTrack.{name}")


@dataclass(frozen=True, eq=False)
class PointTrack:
    """Contact point of the wrench over time.

    Attributes:
        t_s: stamps [s], shape (K,), strictly increasing.
        position: the point in `frame_id` [m], shape (K, 3).
        frame_id: the frame of `position` (world in a `Recording`).
        topic: the topic it came from (or is written to).
    """

    t_s: np.ndarray
    position: np.ndarray
    frame_id: str
    topic: str

    def __post_init__(self):
        t = _stamps(self.t_s, "PointTrack.t_s")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "position", _samples(self.position, len(t), 3, "PointTrack.position"))
        for name in ("frame_id", "topic"):
            _text(getattr(self, name), f"PointTrack.{name}")


@dataclass(frozen=True, eq=False)
class JointTrack:
    """Joint positions (sensor_msgs/msg/JointState) over time.

    Attributes:
        t_s: stamps [s], shape (K,), strictly increasing.
        names: joint names, J of them, unique.
        position: [rad] or [m] per joint type, shape (K, J).
        velocity: [rad/s] or [m/s], shape (K, J), or None when not recorded.
        topic: the topic it came from (or is written to).
    """

    t_s: np.ndarray
    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray | None = None
    topic: str = "/joint_states"

    def __post_init__(self):
        t = _stamps(self.t_s, "JointTrack.t_s")
        object.__setattr__(self, "t_s", t)
        if isinstance(self.names, str):
            raise ValueError("JointTrack.names: expected a sequence of names, got one string")
        names = tuple(_text(n, "JointTrack.names[]") for n in self.names)
        if not names:
            raise ValueError("JointTrack.names: empty, expected at least one joint")
        if len(set(names)) != len(names):
            raise ValueError(f"JointTrack.names: duplicate names in {names}")
        object.__setattr__(self, "names", names)
        object.__setattr__(
            self, "position", _samples(self.position, len(t), len(names), "JointTrack.position")
        )
        if self.velocity is not None:
            object.__setattr__(
                self, "velocity", _samples(self.velocity, len(t), len(names), "JointTrack.velocity")
            )
        _text(self.topic, "JointTrack.topic")


@dataclass(frozen=True, eq=False)
class Recording:
    """One interaction trial read from an MCAP file.

    Attributes:
        path: the file.
        pose: the tracked frame in world.
        wrench: applied to the object; world axes, torque about the tracked
            frame's origin [N, N m].
        wrench_raw: the same samples as in the messages (for diagnosis).
        contact: contact point in world, or None.
        joints: joint states, or None.
        duration_s: from the first to the last stamp of `pose` and `wrench` [s].
        wrench_turns_with_pose: the wrench's frame turns with the tracked frame (it is that frame, or hangs
            off it through constant transforms: a wrist sensor), so it was resolved to world through the pose.
    """

    path: Path
    pose: PoseTrack
    wrench: WrenchTrack
    wrench_raw: WrenchTrack
    contact: PointTrack | None
    joints: JointTrack | None
    duration_s: float
    wrench_turns_with_pose: bool = False

    def __post_init__(self):
        object.__setattr__(self, "path", Path(self.path))
        for name, kind in (("pose", PoseTrack), ("wrench", WrenchTrack), ("wrench_raw", WrenchTrack)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"Recording.{name}: expected a {kind.__name__}")
        if self.contact is not None and not isinstance(self.contact, PointTrack):
            raise ValueError("Recording.contact: expected a PointTrack or None")
        if self.joints is not None and not isinstance(self.joints, JointTrack):
            raise ValueError("Recording.joints: expected a JointTrack or None")
        d = float(self.duration_s)
        if not np.isfinite(d) or d < 0:
            raise ValueError(f"Recording.duration_s: expected a finite value >= 0, got {self.duration_s!r}")
        object.__setattr__(self, "duration_s", d)
        if len(self.wrench.t_s) != len(self.wrench_raw.t_s) or not np.array_equal(
            self.wrench.t_s, self.wrench_raw.t_s
        ):
            raise ValueError("Recording.wrench_raw: expected the same stamps as Recording.wrench")

    def wrench_acted(self, delay_s: float) -> WrenchTrack:
        """`wrench` as it acted if the sensor stamped each sample `delay_s` [s] late (early if negative).

        Each sample acted at its stamp less the delay, and so did the sensor's orientation: a wrist sensor
        (`wrench_turns_with_pose`) was resolved to world through the pose at the late stamp, so the sample is
        turned back through the pose's rotation over the delay, torque about the tracked origin included.
        Shifting only the stamps leaves that rotation in: on a held sphere turning at 3 rad/s RMS an 11 ms
        delay so corrected still replayed 1.74 mm off against 0.69 mm for the same motion recorded without
        it. Any other wrench only moves in time.
        """
        t_acted = self.wrench.t_s - delay_s
        if delay_s == 0.0 or not self.wrench_turns_with_pose:
            return replace(self.wrench, t_s=t_acted)
        _, q_stamp = self.pose.interpolate(self.wrench.t_s)
        _, q_acted = self.pose.interpolate(t_acted)
        turn = Rotation.from_quat(q_acted) * Rotation.from_quat(q_stamp).inv()
        return replace(self.wrench, t_s=t_acted, force=turn.apply(np.array(self.wrench.force)),
                       torque=turn.apply(np.array(self.wrench.torque)))


@dataclass(frozen=True)
class TopicSummary:
    """One topic of an MCAP file, for `twin inspect`.

    Attributes:
        topic: the topic name.
        type: the schema name (e.g. "geometry_msgs/msg/WrenchStamped"), "" if none.
        count: number of messages.
        rate_hz: mean rate (count − 1) / (t_end_s − t_start_s) [Hz], 0 if undefined.
        t_start_s, t_end_s: first and last log time [s].
    """

    topic: str
    type: str
    count: int
    rate_hz: float
    t_start_s: float
    t_end_s: float


# --------------------------------------------------------------------------
# reading the file


@dataclass
class _Raw:
    """Messages of one channel, undecoded: log times [ns] and payloads."""

    topic: str
    type: str
    message_encoding: str
    schema: Any
    log_ns: list
    data: list


def _resolve_file(path: Path) -> Path:
    path = Path(path)
    if path.is_dir():  # a rosbag2 directory: metadata.yaml + one .mcap
        found = sorted(path.glob("*.mcap"))
        if len(found) != 1:
            raise LogError(f"{path}: a directory, expected exactly one .mcap inside, found {len(found)}")
        return found[0]
    if not path.exists():
        raise LogError(f"{path}: file not found")
    return path


def _scan(path: Path, want: Callable[[str, str], bool] | None) -> tuple[dict[int, _Raw], dict[int, list]]:
    """Read every record of `path` once, in file order.

    Returns the channels (id → _Raw) and, for each channel, [count, first_ns,
    last_ns]. Payloads are kept only for channels where want(topic, type) holds.
    Raises LogError for anything but a complete, valid MCAP file.
    """
    from mcap.exceptions import InvalidMagic
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Any] = {}
    channels: dict[int, _Raw] = {}
    stats: dict[int, list] = {}
    pending: list = []  # messages seen before their channel (not expected, but harmless)
    size = path.stat().st_size
    try:
        with open(path, "rb") as f:
            reader = StreamReader(f, validate_crcs=True, record_size_limit=max(size, 1024))
            for rec in reader.records:
                if isinstance(rec, Message):
                    s = stats.setdefault(rec.channel_id, [0, rec.log_time, rec.log_time])
                    s[0] += 1
                    s[1] = min(s[1], rec.log_time)
                    s[2] = max(s[2], rec.log_time)
                    ch = channels.get(rec.channel_id)
                    if ch is None:
                        pending.append(rec)
                    elif want is not None and want(ch.topic, ch.type):
                        ch.log_ns.append(rec.log_time)
                        ch.data.append(rec.data)
                elif isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel) and rec.id not in channels:
                    schema = schemas.get(rec.schema_id)
                    channels[rec.id] = _Raw(
                        rec.topic, schema.name if schema else "", rec.message_encoding, schema, [], []
                    )
    except InvalidMagic:
        raise LogError(f"{path}: not an MCAP file (bad magic bytes)") from None
    except LogError:
        raise
    except Exception as e:  # EndOfFile, struct.error, CRC mismatch, zstd errors, ...
        detail = f"{type(e).__name__}: {e}".strip().rstrip(":")
        raise LogError(f"{path}: truncated or corrupt MCAP file ({detail})") from None
    for rec in pending:
        ch = channels.get(rec.channel_id)
        if ch is None:
            raise LogError(f"{path}: corrupt MCAP file (message on undeclared channel {rec.channel_id})")
        if want is not None and want(ch.topic, ch.type):
            ch.log_ns.append(rec.log_time)
            ch.data.append(rec.data)
    return channels, stats


def inspect_recording(path: Path) -> list[TopicSummary]:
    """Every topic of an MCAP file with its type, count, rate and log-time span.

    Times are log times (no message is decoded), so topics with undecodable
    schemas are listed too. Sorted by topic name. Raises LogError for a missing
    or damaged file.
    """
    path = _resolve_file(Path(path))
    channels, stats = _scan(path, None)
    out = []
    for cid, ch in channels.items():
        count, t0, t1 = stats.get(cid, [0, 0, 0])
        t0_s, t1_s = t0 * 1e-9, t1 * 1e-9
        rate = (count - 1) / (t1_s - t0_s) if count > 1 and t1 > t0 else 0.0
        out.append(TopicSummary(ch.topic, ch.type, int(count), float(rate), t0_s, t1_s))
    return sorted(out, key=lambda s: s.topic)


def _decoder(path: Path, raw: _Raw, ros2_factory) -> Callable[[bytes], Any] | None:
    """A payload decoder for the channel, or None (with a warning) if it has none."""
    enc = raw.message_encoding
    if enc == "json":
        return lambda data: json.loads(data)
    if enc == "cdr" and raw.schema is not None and raw.schema.encoding == "ros2msg":
        try:
            return ros2_factory.decoder_for(enc, raw.schema)
        except Exception as e:
            warnings.warn(
                f"{path}: skipping topic {raw.topic} ({raw.type}): its schema cannot be decoded "
                f"({type(e).__name__}: {e})",
                stacklevel=3,
            )
            return None
    warnings.warn(
        f"{path}: skipping topic {raw.topic} ({raw.type}): no decoder for message encoding "
        f"{enc!r} with schema encoding {getattr(raw.schema, 'encoding', None)!r}",
        stacklevel=3,
    )
    return None


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


class _Decoded:
    """Decoded messages of one topic: (log_ns, message) in file order."""

    def __init__(self, raw: _Raw, items: list):
        self.topic = raw.topic
        self.type = raw.type
        self.items = items


def _decode_all(path: Path, raw: _Raw, ros2_factory) -> _Decoded | None:
    dec = _decoder(path, raw, ros2_factory)
    if dec is None:
        return None
    items, failed = [], 0
    for log_ns, data in zip(raw.log_ns, raw.data):
        try:
            items.append((log_ns, dec(data)))
        except Exception:
            failed += 1
    if failed:
        warnings.warn(f"{path}: {raw.topic}: skipped {failed} messages that could not be decoded", stacklevel=3)
    return _Decoded(raw, items)


def _at(t: float) -> str:
    """A stamp for a message: to the millisecond (UNIX stamps need all ten digits before the point)."""
    return f"{t:.3f}" if abs(t) < 1e12 else f"{t:.3g}"


def _samples_word(n: int) -> str:
    return f"{n} sample" if n == 1 else f"{n} samples"


def _far_stamps(t: np.ndarray) -> np.ndarray:
    """Mask of the stamps of a sorted, repeat-free stream that lie far outside its bulk.

    Far is more than `_FAR_STAMP_SPREADS` spreads from the median stamp, the spread being the stamps'
    median absolute deviation or the median gap if larger (so that three samples, two close together,
    do not make the third an outlier). The median sample is never far, so something always remains.
    """
    t = np.asarray(t, dtype=float)
    if len(t) < 3:
        return np.zeros(len(t), dtype=bool)
    middle = np.median(t)
    spread = max(float(np.median(np.abs(t - middle))), float(np.median(np.diff(t))))
    return np.abs(t - middle) > _FAR_STAMP_SPREADS * spread


def _clean(path: Path, topic: str, t: np.ndarray, arrays: list[np.ndarray], ok: np.ndarray | None = None,
           required: bool = False):
    """Drop non-finite / invalid rows and stamps far from the rest, sort by stamp, keep the first of equal stamps.

    A few non-finite samples are glitches and go with a warning; a `required` stream (pose, wrench) mostly
    non-finite is broken (LogError), and so is any stream with nothing left.
    """
    n = len(t)
    finite = np.isfinite(t)
    for a in arrays:
        finite &= np.all(np.isfinite(a.reshape(n, -1)), axis=1)
    non_finite = int(np.sum(~finite))
    if required and 2 * non_finite > n:
        raise LogError(f"{path}: {topic}: {non_finite} of {n} samples hold non-finite stamps or values")
    keep = finite if ok is None else finite & ok
    dropped = int(np.sum(~keep))
    if dropped:
        warnings.warn(f"{path}: {topic}: dropped {_samples_word(dropped)} with non-finite or invalid values",
                      stacklevel=3)
    t = t[keep]
    arrays = [a[keep] for a in arrays]
    order = np.argsort(t, kind="stable")
    t = t[order]
    arrays = [a[order] for a in arrays]
    first = np.ones(len(t), dtype=bool)
    first[1:] = np.diff(t) > 0
    dup = int(np.sum(~first))
    if dup:
        warnings.warn(f"{path}: {topic}: dropped {_samples_word(dup)} with repeated stamps", stacklevel=3)
    if not np.any(first):
        raise LogError(f"{path}: topic {topic} has no usable samples")
    return drop_far_stamps(path, topic, t[first], [a[first] for a in arrays])


def drop_far_stamps(path: Path, topic: str, t: np.ndarray, arrays: list[np.ndarray]):
    """The rows of a sorted, repeat-free stream less those stamped far outside the rest, with a warning."""
    far = _far_stamps(t)
    if not far.any():
        return t, arrays
    near = t[~far]
    warnings.warn(
        f"{path}: {topic}: dropped {_samples_word(int(far.sum()))} stamped far outside the rest "
        f"({_at(near[0])}..{_at(near[-1])} s), e.g. at {_at(t[far][0])} s",
        stacklevel=4,
    )
    return near, [a[~far] for a in arrays]


def require_overlap(path: Path, first: str, t_first: np.ndarray, second: str, t_second: np.ndarray) -> None:
    """LogError unless two streams share some time: on clocks that never meet, nothing can be paired."""
    if t_first[-1] < t_second[0] or t_second[-1] < t_first[0]:
        raise LogError(
            f"{path}: {first} stamps {_at(t_first[0])}..{_at(t_first[-1])} s and {second} stamps "
            f"{_at(t_second[0])}..{_at(t_second[-1])} s do not overlap"
        )


def bounded(path: Path, topic: str, what: str, t: np.ndarray, values: np.ndarray, limit: float, unit: str) -> None:
    """LogError if a component of a row exceeds `limit` in magnitude (see `MAX_FORCE_N`)."""
    size = np.max(np.abs(values), axis=1)
    beyond = np.flatnonzero(size > limit)
    if beyond.size:
        i = int(beyond[0])
        raise LogError(
            f"{path}: {topic}: {what} of {size[i]:.3g} {unit} at {_at(t[i])} s is beyond {limit:g} {unit} "
            f"({beyond.size} of {len(t)} samples)"
        )


def _fields(path: Path, d: _Decoded, extract: Callable[[int, Any], Any]) -> list:
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


def _dominant(path: Path, topic: str, keys: list) -> tuple[Any, np.ndarray]:
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


def _pose_track(path: Path, d: _Decoded, required: bool = True) -> tuple[PoseTrack, str]:
    """The topic's poses, and its parent frame as recorded ("" if none; the track says "world").

    `required`: read as the tracked pose, not a contact point (see `_clean`).
    """
    rows = _fields(path, d, _pose_row(d.type))
    if not rows:
        raise LogError(f"{path}: pose topic {d.topic} has no readable messages")
    (frame_id, child), mask = _dominant(path, d.topic, [r[3] for r in rows])
    rows = [r for r, keep in zip(rows, mask) if keep]
    t = np.array([r[0] for r in rows], dtype=float)
    pos = np.array([r[1] for r in rows], dtype=float)
    quat = np.array([r[2] for r in rows], dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):  # huge components give an infinite norm, refused below
        norm = np.linalg.norm(quat, axis=1)
    ok = np.isfinite(norm) & (np.abs(norm - 1.0) < 0.1)  # zero quaternions: occluded markers
    t, (pos, quat) = _clean(path, d.topic, t, [pos, quat], ok, required)
    bounded(path, d.topic, "position", t, pos, MAX_POSITION_M, "m")
    quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    default_child = d.topic.lstrip("/")
    return PoseTrack(t, pos, quat, frame_id or "world", child or default_child, d.topic), frame_id


def _wrench_samples(path: Path, d: _Decoded) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    def row(log_ns, m):
        header, w = _get(m, "header"), _get(m, "wrench")
        return (_stamp_s(_get(header, "stamp"), log_ns), _xyz(_get(w, "force")), _xyz(_get(w, "torque")),
                _frame(_get(header, "frame_id")))

    rows = _fields(path, d, row)
    if not rows:
        raise LogError(f"{path}: wrench topic {d.topic} has no readable messages")
    t, f, tau, frames = zip(*rows)
    return np.array(t, dtype=float), np.array(f, dtype=float), np.array(tau, dtype=float), list(frames)


def _point_track(path: Path, d: _Decoded, frame_if_empty: str = "") -> PointTrack | None:
    """Points of a PointStamped topic, or the origins of a pose topic's poses."""
    if d.type != POINT_TYPE:
        track, recorded = _pose_track(path, d, required=False)
        return PointTrack(track.t_s, track.position, recorded or frame_if_empty, d.topic)

    def row(log_ns, m):
        header = _get(m, "header")
        return (_stamp_s(_get(header, "stamp"), log_ns), _xyz(_get(m, "point")),
                _frame(_get(header, "frame_id")) or frame_if_empty)

    rows = _fields(path, d, row)
    if not rows:
        return None
    t, p, frames = zip(*rows)
    frame, mask = _dominant(path, d.topic, list(frames))
    t, (p,) = _clean(path, d.topic, np.array(t, dtype=float)[mask], [np.array(p, dtype=float)[mask]])
    bounded(path, d.topic, "contact point", t, p, MAX_POSITION_M, "m")
    return PointTrack(t, p, frame, d.topic)


def _joint_track(path: Path, d: _Decoded) -> JointTrack | None:
    def row(log_ns, m):
        return (_stamp_s(_get(_get(m, "header"), "stamp"), log_ns), tuple(str(x) for x in (_get(m, "name") or ())),
                [float(x) for x in (_get(m, "position") or ())], [float(x) for x in (_get(m, "velocity") or ())])

    names: tuple[str, ...] | None = None
    t, q, v, skipped = [], [], [], 0
    for stamp, n, pos, vel in _fields(path, d, row):
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
    t, arrays = _clean(path, d.topic, np.asarray(t, dtype=float), arrays)
    return JointTrack(t, names, arrays[0], arrays[1] if has_v else None, d.topic)


# --------------------------------------------------------------------------
# frames


class _Edge:
    """parent → child transform: static, or sampled over time (interpolated)."""

    def __init__(self, parent: str, child: str, t: np.ndarray, p: np.ndarray, q: np.ndarray, source: str):
        self.parent, self.child, self.source = parent, child, source
        if len(t) > 1 and np.allclose(p, p[0], rtol=0, atol=1e-12) and np.allclose(q, q[0], rtol=0, atol=1e-12):
            t, p, q = t[:1], p[:1], q[:1]  # a constant transform published repeatedly
        self.t, self.p, self.q = t, p, q
        self.extrapolated = 0

    def at(self, tq: np.ndarray) -> tuple[Rotation, np.ndarray]:
        if len(self.t) == 1:
            return Rotation.from_quat(np.repeat(self.q, len(tq), axis=0)), np.repeat(self.p, len(tq), axis=0)
        tol = max(0.1, 2.0 * float(np.median(np.diff(self.t))))
        self.extrapolated += int(np.sum((tq < self.t[0] - tol) | (tq > self.t[-1] + tol)))
        return _interp_rotation(self.t, self.q, tq), _interp_linear(self.t, self.p, tq)


def _tf_edges(path: Path, decoded: list[_Decoded]) -> list[_Edge]:
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
        for message in _fields(path, d, rows):
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
            t, (p, q) = _clean(path, f"/tf {parent}->{child}", a[:, 0], [a[:, 1:4], a[:, 4:8]], ok)
        except LogError:
            continue
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        edges.append(_Edge(parent, child, t, p, q, "/tf_static" if key_static else "/tf"))
    return edges


def _world_from_frame(
    frame: str, world: str, edges: list[_Edge], tq: np.ndarray
) -> tuple[Rotation, np.ndarray] | None:
    """T_world_frame at stamps tq as (rotation, origin [m]), or None if not connected."""
    adjacency: dict[str, list[tuple[str, _Edge, bool]]] = {}
    for e in edges:  # earlier edges take precedence (BFS order)
        adjacency.setdefault(e.parent, []).append((e.child, e, True))
        adjacency.setdefault(e.child, []).append((e.parent, e, False))
    previous: dict[str, tuple[str, _Edge, bool] | None] = {world: None}
    queue = deque([world])
    while queue and frame not in previous:
        node = queue.popleft()
        for nxt, e, forward in adjacency.get(node, ()):
            if nxt not in previous:
                previous[nxt] = (node, e, forward)
                queue.append(nxt)
    if frame not in previous:
        return None
    steps = []
    node = frame
    while previous[node] is not None:
        parent_node, e, forward = previous[node]
        steps.append((e, forward))
        node = parent_node
    rot = Rotation.from_quat(np.tile([0.0, 0.0, 0.0, 1.0], (len(tq), 1)))
    origin = np.zeros((len(tq), 3))
    for e, forward in reversed(steps):  # from world towards frame
        r_e, p_e = e.at(tq)
        if not forward:  # we walk child → parent: use the inverse transform
            r_e = r_e.inv()
            p_e = -r_e.apply(p_e)
        origin = origin + rot.apply(p_e)
        rot = rot * r_e
    return rot, origin


# --------------------------------------------------------------------------
# topic choice


def _choose(path: Path, role: str, candidates: list[_Decoded], rank: Callable[[_Decoded], tuple]) -> _Decoded:
    ranked = sorted(sorted(candidates, key=lambda d: d.topic), key=rank, reverse=True)  # ties: by name
    best = ranked[0]
    if len(ranked) > 1:
        ties = [d.topic for d in ranked if rank(d) == rank(best)]
        warnings.warn(
            f"{path}: several {role} topics {[d.topic for d in ranked]}; using {best.topic}"
            + (f" (tied with {ties[1:]})" if len(ties) > 1 else "")
            + f"; override with topics={{'{role}': '/name'}}",
            stacklevel=3,
        )
    return best


def read_recording(
    path: Path,
    topics: dict[str, str] | None = None,
    frames: dict[str, str] | None = None,
    wrench_rotation_xyzw: tuple[float, float, float, float] | None = None,
    wrench_reaction: bool = False,
) -> Recording:
    """Read one trial from an MCAP file (or a rosbag2 directory holding one).

    Args:
        path: the .mcap file.
        topics: role overrides {"pose" | "wrench" | "contact" | "joint": "/topic"};
            other roles are found by message type (DESIGN.md, "Logs: MCAP").
            A contact topic may also be a pose topic (e.g. a pusher tip's
            PoseStamped): its origin is the contact point.
        frames: {"wrench" | "contact": frame id} for messages whose header has
            an empty frame_id (recorders often leave it empty); resolved
            through the tracked pose and /tf like any recorded frame.
        wrench_rotation_xyzw: a fixed rotation of the wrench messages' axes in
            world (sensor-to-world), for recordings whose sensor frame is not
            in /tf. The wrench then acts at the contact point when a contact
            topic exists, else at the tracked frame's origin, as a world
            wrench does.
        wrench_reaction: the messages give the wrench ON the sensor (the
            object's reaction, as a tool-mounted F/T sensor reports it, e.g. the
            MIT pushing bags); it is negated to the wrench applied TO the object.

    Returns:
        A Recording whose `wrench` is in world axes with its torque about the
        tracked frame's origin [N, N m] (module docstring).

    Raises:
        LogError: file missing, not MCAP, truncated or corrupt; no pose or wrench
            topic; an override naming an absent topic or a wrong type; a wrench
            frame that cannot be resolved to world; values out of reason or pose
            and wrench stamps that do not overlap (module docstring).
        ValueError: an unknown role in `topics` or `frames`, or a rotation that
            is not a unit quaternion.
    """
    from mcap_ros2.decoder import DecoderFactory

    topics = dict(topics or {})
    frames = dict(frames or {})
    for role in topics:
        if role not in ROLES:
            raise ValueError(f"topics: unknown role {role!r}, expected one of {ROLES}")
    for role in frames:
        if role not in ("wrench", "contact"):
            raise ValueError(f"frames: unknown role {role!r}, expected 'wrench' or 'contact'")
    fixed_rotation = None
    if wrench_rotation_xyzw is not None:
        q = np.asarray(wrench_rotation_xyzw, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-6:
            raise ValueError(f"wrench_rotation_xyzw: expected a unit quaternion (x, y, z, w), got {wrench_rotation_xyzw!r}")
        fixed_rotation = Rotation.from_quat(q)
    path = _resolve_file(Path(path))
    overridden = set(topics.values())
    accepted = set(POSE_TYPES) | {WRENCH_TYPE, POINT_TYPE, JOINT_TYPE, TF_TYPE}
    channels, _ = _scan(path, lambda topic, type_: type_ in accepted or topic in overridden)

    by_topic: dict[str, _Raw] = {}
    for raw in channels.values():
        by_topic.setdefault(raw.topic, raw)
    for role, topic in topics.items():
        raw = by_topic.get(topic)
        if raw is None:
            raise LogError(f"{path}: {role} topic {topic} not in file (topics: {sorted(by_topic)})")
        if raw.type not in _ROLE_TYPES[role]:
            raise LogError(
                f"{path}: {role} topic {topic} has type {raw.type!r}, expected one of {list(_ROLE_TYPES[role])}"
            )

    factory = DecoderFactory()
    decoded: dict[str, _Decoded] = {}
    for topic, raw in sorted(by_topic.items()):
        if raw.type in accepted:
            d = _decode_all(path, raw, factory)
            if d is not None:
                decoded[topic] = d
            elif topic in overridden:
                raise LogError(f"{path}: topic {topic} ({raw.type}) cannot be decoded")

    def of_type(types, exclude=()) -> list[_Decoded]:
        return [d for t, d in decoded.items() if d.type in types and t not in exclude and d.items]

    # wrench
    if "wrench" in topics:
        wrench_d = decoded[topics["wrench"]]
    else:
        cands = of_type((WRENCH_TYPE,))
        if not cands:
            raise LogError(f"{path}: no wrench topic ({WRENCH_TYPE})")
        wrench_d = _choose(path, "wrench", cands, lambda d: (len(d.items),))
    t_w, f_w, tau_w, frames_w = _wrench_samples(path, wrench_d)
    frames_w = [f or frames.get("wrench", "") for f in frames_w]
    wrench_frame, mask = _dominant(path, wrench_d.topic, frames_w)
    t_w, (f_w, tau_w) = _clean(path, wrench_d.topic, t_w[mask], [f_w[mask], tau_w[mask]], required=True)
    bounded(path, wrench_d.topic, "force", t_w, f_w, MAX_FORCE_N, "N")
    bounded(path, wrench_d.topic, "torque", t_w, tau_w, MAX_TORQUE_NM, "N m")
    wrench_raw = WrenchTrack(t_w, f_w, tau_w, wrench_d.topic, wrench_frame)

    # pose
    if "pose" in topics:
        pose, _ = _pose_track(path, decoded[topics["pose"]])
    else:
        cands = of_type(POSE_TYPES, exclude=(*_TF_TOPICS, topics.get("contact")))
        if not cands:
            raise LogError(f"{path}: no pose topic ({', '.join(POSE_TYPES)})")
        tracks, broken = {}, []
        for d in cands:
            try:
                tracks[d.topic] = _pose_track(path, d)
            except LogError as exc:  # a broken topic beside a good one is not the tracked pose
                broken.append(exc)
        if not tracks:
            raise broken[0]
        for exc in broken:
            warnings.warn(f"{exc}; not taken as the pose", stacklevel=2)
        cands = [d for d in cands if d.topic in tracks]

        def pose_rank(d: _Decoded) -> tuple:
            track, recorded_frame = tracks[d.topic]
            return (
                track.child_frame_id == wrench_frame,  # the tracked frame is the wrench frame
                recorded_frame == "world",
                recorded_frame != "",  # a named parent beats an unnamed one
                len(track.t_s),
            )

        pose = tracks[_choose(path, "pose", cands, pose_rank).topic][0]
    require_overlap(path, f"pose topic {pose.topic}", pose.t_s, f"wrench topic {wrench_d.topic}", t_w)

    # contact and joints (optional)
    contact = None
    if "contact" in topics:
        contact = _point_track(path, decoded[topics["contact"]], frames.get("contact", ""))
    elif cands := of_type((POINT_TYPE,)):
        contact = _point_track(
            path, _choose(path, "contact", cands, lambda d: (len(d.items),)), frames.get("contact", "")
        )
    joints = None
    if "joint" in topics:
        joints = _joint_track(path, decoded[topics["joint"]])
    elif cands := of_type((JOINT_TYPE,)):
        joints = _joint_track(path, _choose(path, "joint", cands, lambda d: (len(d.items),)))

    # frames: the tracked pose first, then /tf_static and /tf
    world = pose.frame_id
    tracked_edge = _Edge(world, pose.child_frame_id, pose.t_s, pose.position, pose.quat_xyzw, pose.topic)
    tf_edges = _tf_edges(path, [d for d in decoded.values() if d.type == TF_TYPE])
    tf_edges = [e for e in tf_edges if {e.parent, e.child} != {world, pose.child_frame_id}]
    edges = [tracked_edge] + tf_edges

    def world_from(frame: str, tq: np.ndarray, what: str) -> tuple[Rotation, np.ndarray]:
        if frame == world or (frame == "world" and not any("world" in (e.parent, e.child) for e in edges)):
            n = len(tq)
            return Rotation.from_quat(np.tile([0.0, 0, 0, 1], (n, 1))), np.zeros((n, 3))
        if not frame:
            raise LogError(f"{path}: {what} has an empty frame_id; cannot resolve it to world {world!r}")
        found = _world_from_frame(frame, world, edges, tq)
        if found is None:
            known = sorted({e.parent for e in edges} | {e.child for e in edges})
            raise LogError(
                f"{path}: {what} frame {frame!r} cannot be resolved to world {world!r} through "
                f"the tracked pose, /tf_static or /tf (known frames: {known})"
            )
        return found

    if contact is not None and contact.frame_id not in (world, "world"):
        r_c, o_c = world_from(contact.frame_id, contact.t_s, f"contact topic {contact.topic}")
        contact = PointTrack(contact.t_s, o_c + r_c.apply(np.array(contact.position)), world, contact.topic)
    elif contact is not None:
        contact = PointTrack(contact.t_s, contact.position, world, contact.topic)

    acts_as_world = fixed_rotation is not None or wrench_frame in (world, "world")
    if fixed_rotation is not None:
        r_wf = Rotation.from_quat(np.tile(fixed_rotation.as_quat(), (len(t_w), 1)))
    else:
        r_wf, p_frame = world_from(wrench_frame, t_w, f"wrench topic {wrench_d.topic}")
    if acts_as_world and contact is not None:
        p_frame = _interp_linear(contact.t_s, contact.position, t_w)  # world wrench acts at the contact
    elif acts_as_world:
        p_frame = None  # acts at the tracked frame's origin
    for e in edges:
        if e.extrapolated:
            warnings.warn(
                f"{path}: transform {e.parent}->{e.child} ({e.source}) held constant for "
                f"{e.extrapolated} wrench samples outside its stamped range",
                stacklevel=2,
            )
            e.extrapolated = 0
    sign = -1.0 if wrench_reaction else 1.0
    force = sign * r_wf.apply(f_w)
    torque = sign * r_wf.apply(tau_w)
    if p_frame is not None:
        p_track, _ = pose.interpolate(t_w)
        torque = torque + np.cross(p_frame - p_track, force)
    wrench = WrenchTrack(t_w, force, torque, wrench_d.topic, world)
    rigid = {pose.child_frame_id}  # the frames held to the tracked one by constant transforms
    grew = True
    while grew:
        grew = False
        for e in tf_edges:
            if len(e.t) == 1 and (e.parent in rigid) != (e.child in rigid):
                rigid |= {e.parent, e.child}
                grew = True

    t0 = min(pose.t_s[0], wrench.t_s[0])
    t1 = max(pose.t_s[-1], wrench.t_s[-1])
    return Recording(path, pose, wrench, wrench_raw, contact, joints, float(t1 - t0),
                     wrench_turns_with_pose=fixed_rotation is None and wrench_frame in rigid)
