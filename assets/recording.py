"""The recorded data of one interaction trial: time-stamped tracks of the tracked frame, the wrench, the
contact point and the joints, validated on construction.

Everything is SI (metres, seconds, newtons, radians) with stamps in seconds; quaternions are scalar-last
(x, y, z, w). `pipelines.logs` reads these from MCAP files and `pipelines.synth.recording` writes them.
Depends on nothing else of ours.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

__all__ = ["JointTrack", "PointTrack", "PoseTrack", "Recording", "WrenchTrack", "interp_linear", "interp_rotation"]

_QUAT_NORM_TOL = 1e-6


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


def interp_linear(t: np.ndarray, values: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Linear interpolation per column, held constant outside [t[0], t[-1]]."""
    return np.stack([np.interp(t_query, t, values[:, k]) for k in range(values.shape[1])], axis=1)


def interp_rotation(t: np.ndarray, quat_xyzw: np.ndarray, t_query: np.ndarray) -> Rotation:
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
            interp_linear(self.t_s, self.position, tq),
            interp_rotation(self.t_s, self.quat_xyzw, tq).as_quat(),
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
