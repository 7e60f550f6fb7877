"""`read_recording`: one trial from an MCAP file, in named steps (see the package docstring)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from assets.recording import JointTrack, PointTrack, PoseTrack, Recording, WrenchTrack, interp_linear

from .checks import MAX_FORCE_N, MAX_TORQUE_NM, LogError, bounded, clean_stream, require_overlap
from .frames import FrameTree
from .mcap_file import DecodedTopic, RawChannel, decode_topic, resolve_file, scan_file
from .messages import (
    JOINT_TYPE,
    POINT_TYPE,
    POSE_TYPES,
    ROLE_TYPES,
    ROLES,
    TF_TOPICS,
    TF_TYPE,
    WRENCH_TYPE,
    dominant,
    joint_track,
    point_track,
    pose_track,
    tf_edges,
    wrench_samples,
)

__all__ = ["read_recording"]


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
    topics, frames = _roles(topics, frames)
    fixed_rotation = _fixed_rotation(wrench_rotation_xyzw)
    path = resolve_file(Path(path))
    decoded = _decode_topics(path, topics)
    wrench_raw = _read_wrench(path, decoded, topics, frames)
    pose = _read_pose(path, decoded, topics, wrench_raw.frame_id)
    require_overlap(path, f"pose topic {pose.topic}", pose.t_s, f"wrench topic {wrench_raw.topic}", wrench_raw.t_s)
    contact = _read_contact(path, decoded, topics, frames)
    joints = _read_joints(path, decoded, topics)

    tree = FrameTree(path, pose, tf_edges(path, [d for d in decoded.values() if d.type == TF_TYPE]))
    if contact is not None:
        contact = _contact_in_world(tree, contact)
    wrench = _wrench_in_world(tree, pose, wrench_raw, contact, fixed_rotation, wrench_reaction)
    turns_with_pose = fixed_rotation is None and wrench_raw.frame_id in tree.rigid_with_tracked()

    t0 = min(pose.t_s[0], wrench.t_s[0])
    t1 = max(pose.t_s[-1], wrench.t_s[-1])
    return Recording(path, pose, wrench, wrench_raw, contact, joints, float(t1 - t0),
                     wrench_turns_with_pose=turns_with_pose)


# --------------------------------------------------------------------------
# the options


def _roles(topics: dict[str, str] | None, frames: dict[str, str] | None) -> tuple[dict[str, str], dict[str, str]]:
    """The role overrides, checked: ValueError for a role the reader does not know."""
    topics = dict(topics or {})
    frames = dict(frames or {})
    for role in topics:
        if role not in ROLES:
            raise ValueError(f"topics: unknown role {role!r}, expected one of {ROLES}")
    for role in frames:
        if role not in ("wrench", "contact"):
            raise ValueError(f"frames: unknown role {role!r}, expected 'wrench' or 'contact'")
    return topics, frames


def _fixed_rotation(wrench_rotation_xyzw) -> Rotation | None:
    """The fixed sensor-to-world rotation, or None; ValueError unless a unit quaternion."""
    if wrench_rotation_xyzw is None:
        return None
    q = np.asarray(wrench_rotation_xyzw, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-6:
        raise ValueError(f"wrench_rotation_xyzw: expected a unit quaternion (x, y, z, w), got {wrench_rotation_xyzw!r}")
    return Rotation.from_quat(q)


# --------------------------------------------------------------------------
# topic choice


def _decode_topics(path: Path, topics: dict[str, str]) -> dict[str, DecodedTopic]:
    """Every topic of a known type (or overridden) decoded, by name; LogError for an override naming an
    absent topic, a topic of a type wrong for its role, or one that cannot be decoded."""
    from mcap_ros2.decoder import DecoderFactory

    overridden = set(topics.values())
    accepted = set(POSE_TYPES) | {WRENCH_TYPE, POINT_TYPE, JOINT_TYPE, TF_TYPE}
    channels, _ = scan_file(path, lambda topic, type_: type_ in accepted or topic in overridden)

    by_topic: dict[str, RawChannel] = {}
    for raw in channels.values():
        by_topic.setdefault(raw.topic, raw)
    for role, topic in topics.items():
        raw = by_topic.get(topic)
        if raw is None:
            raise LogError(f"{path}: {role} topic {topic} not in file (topics: {sorted(by_topic)})")
        if raw.type not in ROLE_TYPES[role]:
            raise LogError(
                f"{path}: {role} topic {topic} has type {raw.type!r}, expected one of {list(ROLE_TYPES[role])}"
            )

    factory = DecoderFactory()
    decoded: dict[str, DecodedTopic] = {}
    for topic, raw in sorted(by_topic.items()):
        if raw.type in accepted:
            d = decode_topic(path, raw, factory)
            if d is not None:
                decoded[topic] = d
            elif topic in overridden:
                raise LogError(f"{path}: topic {topic} ({raw.type}) cannot be decoded")
    return decoded


def _of_type(decoded: dict[str, DecodedTopic], types, exclude=()) -> list[DecodedTopic]:
    """The decoded topics of `types` that hold messages, less those named in `exclude`."""
    return [d for t, d in decoded.items() if d.type in types and t not in exclude and d.items]


def _choose(path: Path, role: str, candidates: list[DecodedTopic], rank: Callable[[DecodedTopic], tuple]
            ) -> DecodedTopic:
    """The best-ranked candidate for a role (ties by name), with a warning naming the others."""
    ranked = sorted(sorted(candidates, key=lambda d: d.topic), key=rank, reverse=True)  # ties: by name
    best = ranked[0]
    if len(ranked) > 1:
        ties = [d.topic for d in ranked if rank(d) == rank(best)]
        warnings.warn(
            f"{path}: several {role} topics {[d.topic for d in ranked]}; using {best.topic}"
            + (f" (tied with {ties[1:]})" if len(ties) > 1 else "")
            + f"; override with topics={{'{role}': '/name'}}",
            stacklevel=4,
        )
    return best


def _most_messages(d: DecodedTopic) -> tuple:
    return (len(d.items),)


# --------------------------------------------------------------------------
# the tracks as recorded


def _read_wrench(path: Path, decoded: dict[str, DecodedTopic], topics: dict[str, str],
                 frames: dict[str, str]) -> WrenchTrack:
    """The wrench as in the messages: the samples in the topic's dominant frame, cleaned and bounded."""
    if "wrench" in topics:
        wrench_d = decoded[topics["wrench"]]
    else:
        cands = _of_type(decoded, (WRENCH_TYPE,))
        if not cands:
            raise LogError(f"{path}: no wrench topic ({WRENCH_TYPE})")
        wrench_d = _choose(path, "wrench", cands, _most_messages)
    t_w, f_w, tau_w, frames_w = wrench_samples(path, wrench_d)
    frames_w = [f or frames.get("wrench", "") for f in frames_w]
    wrench_frame, mask = dominant(path, wrench_d.topic, frames_w)
    t_w, (f_w, tau_w) = clean_stream(path, wrench_d.topic, t_w[mask], [f_w[mask], tau_w[mask]], required=True)
    bounded(path, wrench_d.topic, "force", t_w, f_w, MAX_FORCE_N, "N")
    bounded(path, wrench_d.topic, "torque", t_w, tau_w, MAX_TORQUE_NM, "N m")
    return WrenchTrack(t_w, f_w, tau_w, wrench_d.topic, wrench_frame)


def _read_pose(path: Path, decoded: dict[str, DecodedTopic], topics: dict[str, str], wrench_frame: str) -> PoseTrack:
    """The tracked pose: the override, else the readable pose topic that best matches the wrench frame."""
    if "pose" in topics:
        return pose_track(path, decoded[topics["pose"]])[0]
    cands = _of_type(decoded, POSE_TYPES, exclude=(*TF_TOPICS, topics.get("contact")))
    if not cands:
        raise LogError(f"{path}: no pose topic ({', '.join(POSE_TYPES)})")
    tracks, broken = {}, []
    for d in cands:
        try:
            tracks[d.topic] = pose_track(path, d)
        except LogError as exc:  # a broken topic beside a good one is not the tracked pose
            broken.append(exc)
    if not tracks:
        raise broken[0]
    for exc in broken:
        warnings.warn(f"{exc}; not taken as the pose", stacklevel=3)
    cands = [d for d in cands if d.topic in tracks]

    def pose_rank(d: DecodedTopic) -> tuple:
        track, recorded_frame = tracks[d.topic]
        return (
            track.child_frame_id == wrench_frame,  # the tracked frame is the wrench frame
            recorded_frame == "world",
            recorded_frame != "",  # a named parent beats an unnamed one
            len(track.t_s),
        )

    return tracks[_choose(path, "pose", cands, pose_rank).topic][0]


def _read_contact(path: Path, decoded: dict[str, DecodedTopic], topics: dict[str, str],
                  frames: dict[str, str]) -> PointTrack | None:
    """The contact point in its recorded frame, or None."""
    if "contact" in topics:
        return point_track(path, decoded[topics["contact"]], frames.get("contact", ""))
    if cands := _of_type(decoded, (POINT_TYPE,)):
        return point_track(path, _choose(path, "contact", cands, _most_messages), frames.get("contact", ""))
    return None


def _read_joints(path: Path, decoded: dict[str, DecodedTopic], topics: dict[str, str]) -> JointTrack | None:
    """The joint states, or None."""
    if "joint" in topics:
        return joint_track(path, decoded[topics["joint"]])
    if cands := _of_type(decoded, (JOINT_TYPE,)):
        return joint_track(path, _choose(path, "joint", cands, _most_messages))
    return None


# --------------------------------------------------------------------------
# into the world frame


def _contact_in_world(tree: FrameTree, contact: PointTrack) -> PointTrack:
    if tree.is_world(contact.frame_id):
        return PointTrack(contact.t_s, contact.position, tree.world, contact.topic)
    r_c, o_c = tree.world_from(contact.frame_id, contact.t_s, f"contact topic {contact.topic}")
    return PointTrack(contact.t_s, o_c + r_c.apply(np.array(contact.position)), tree.world, contact.topic)


def _wrench_in_world(tree: FrameTree, pose: PoseTrack, raw: WrenchTrack, contact: PointTrack | None,
                     fixed_rotation: Rotation | None, reaction: bool) -> WrenchTrack:
    """The wrench applied TO the object in world axes, its torque about the tracked frame's origin.

    A world wrench (or one turned by `fixed_rotation`) acts at the contact point when there is one, else
    at the tracked origin; any other acts at its frame's origin (module docstring).
    """
    t_w = raw.t_s
    acts_as_world = fixed_rotation is not None or tree.is_world(raw.frame_id)
    if fixed_rotation is not None:
        r_wf = Rotation.from_quat(np.tile(fixed_rotation.as_quat(), (len(t_w), 1)))
    else:
        r_wf, p_frame = tree.world_from(raw.frame_id, t_w, f"wrench topic {raw.topic}")
    if acts_as_world and contact is not None:
        p_frame = interp_linear(contact.t_s, contact.position, t_w)  # world wrench acts at the contact
    elif acts_as_world:
        p_frame = None  # acts at the tracked frame's origin
    tree.warn_extrapolated()
    sign = -1.0 if reaction else 1.0
    force = sign * r_wf.apply(np.array(raw.force))
    torque = sign * r_wf.apply(np.array(raw.torque))
    if p_frame is not None:
        p_track, _ = pose.interpolate(t_w)
        torque = torque + np.cross(p_frame - p_track, force)
    return WrenchTrack(t_w, force, torque, raw.topic, tree.world)
