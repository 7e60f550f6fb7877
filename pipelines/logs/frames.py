"""The frame tree of a recording: transforms between named frames, static or sampled over time, and
the chain from the world to any frame connected to it."""

from __future__ import annotations

import warnings
from collections import deque
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from assets.recording import PoseTrack, interp_linear, interp_rotation

from .checks import LogError

__all__ = ["Edge", "FrameTree", "world_from_frame"]


class Edge:
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
        return interp_rotation(self.t, self.q, tq), interp_linear(self.t, self.p, tq)


def world_from_frame(
    frame: str, world: str, edges: list[Edge], tq: np.ndarray
) -> tuple[Rotation, np.ndarray] | None:
    """T_world_frame at stamps tq as (rotation, origin [m]), or None if not connected."""
    adjacency: dict[str, list[tuple[str, Edge, bool]]] = {}
    for e in edges:  # earlier edges take precedence (BFS order)
        adjacency.setdefault(e.parent, []).append((e.child, e, True))
        adjacency.setdefault(e.child, []).append((e.parent, e, False))
    previous: dict[str, tuple[str, Edge, bool] | None] = {world: None}
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


class FrameTree:
    """The frames of one recording: the tracked pose first, then the /tf_static and /tf edges.

    World is the tracked pose's parent frame; the name "world" means it too unless an edge names it.
    """

    def __init__(self, path: Path, pose: PoseTrack, tf: list[Edge]):
        self.path = path
        self.world = pose.frame_id
        tracked = Edge(self.world, pose.child_frame_id, pose.t_s, pose.position, pose.quat_xyzw, pose.topic)
        self.tf = [e for e in tf if {e.parent, e.child} != {self.world, pose.child_frame_id}]
        self.edges = [tracked] + self.tf
        self.tracked_frame = pose.child_frame_id

    def is_world(self, frame: str) -> bool:
        return frame in (self.world, "world")

    def world_from(self, frame: str, tq: np.ndarray, what: str) -> tuple[Rotation, np.ndarray]:
        """T_world_frame at stamps tq as (rotation, origin [m]); LogError if `frame` is not connected."""
        world, edges = self.world, self.edges
        if frame == world or (frame == "world" and not any("world" in (e.parent, e.child) for e in edges)):
            n = len(tq)
            return Rotation.from_quat(np.tile([0.0, 0, 0, 1], (n, 1))), np.zeros((n, 3))
        if not frame:
            raise LogError(f"{self.path}: {what} has an empty frame_id; cannot resolve it to world {world!r}")
        found = world_from_frame(frame, world, edges, tq)
        if found is None:
            known = sorted({e.parent for e in edges} | {e.child for e in edges})
            raise LogError(
                f"{self.path}: {what} frame {frame!r} cannot be resolved to world {world!r} through "
                f"the tracked pose, /tf_static or /tf (known frames: {known})"
            )
        return found

    def warn_extrapolated(self) -> None:
        """Warn (of the caller of `read_recording`) of each transform held constant outside its stamped range
        since the last call."""
        for e in self.edges:
            if e.extrapolated:
                warnings.warn(
                    f"{self.path}: transform {e.parent}->{e.child} ({e.source}) held constant for "
                    f"{e.extrapolated} wrench samples outside its stamped range",
                    stacklevel=4,
                )
                e.extrapolated = 0

    def rigid_with_tracked(self) -> set[str]:
        """The frames held to the tracked one by constant transforms (a wrist sensor's, for one)."""
        rigid = {self.tracked_frame}
        grew = True
        while grew:
            grew = False
            for e in self.tf:
                if len(e.t) == 1 and (e.parent in rigid) != (e.child in rigid):
                    rigid |= {e.parent, e.child}
                    grew = True
        return rigid
