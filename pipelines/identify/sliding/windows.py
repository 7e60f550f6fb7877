"""Push windows: the planar pose track, the force sensor's offset and the shooting windows cut from a push."""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from scipy.spatial.transform import Rotation

from ..windows import local_twist, lowpass
from .body import PlanarBody, SlidingConfig


@dataclass(frozen=True)
class PushWindows:
    """W planar windows of S pose samples each, sample 0 the start.

    dt_s, substeps: simulation step [s] and steps per pose sample.
    t_start_s [W]; start [W, 6]: x, y [m], yaw [rad], vx, vy [m/s], yaw rate [rad/s];
    force [margin + steps + margin, W, 2]: pusher force on the object, world x, y [N] (bias removed),
    from `force_margin` steps before each window to as many after it (the room a time delay is fitted in);
    contact [steps, W, 2]: its point of application, world x, y [m];
    measured [S+1, W, 3]: x, y [m], yaw [rad] (continuous, not wrapped).
    """

    dt_s: float
    substeps: int
    t_start_s: np.ndarray
    start: np.ndarray
    force: np.ndarray
    contact: np.ndarray
    measured: np.ndarray
    force_margin: int = 0

    @property
    def window_count(self) -> int:
        return len(self.t_start_s)

    @property
    def step_count(self) -> int:
        return self.contact.shape[0]

    @property
    def window_force(self) -> np.ndarray:
        """The force at the window's own steps [steps, W, 2]."""
        return self.force[self.force_margin:self.force_margin + self.step_count]

    @property
    def sample_count(self) -> int:
        return self.measured.shape[0] - 1

    @property
    def sample_period_s(self) -> float:
        return self.dt_s * self.substeps

    @property
    def span_s(self) -> float:
        """A window's length [s]."""
        return self.sample_count * self.sample_period_s


def _planar_grid(recording, config: SlidingConfig, smooth: bool):
    """Pose track on a uniform grid of config.sample_period_s: t [s], xy [m], yaw [rad, unwrapped].

    Tracker jumps (samples off a running median by more than config.jump_m, or
    config.jump_m / 0.05 m in heading) are dropped first; with `smooth`, the
    result is low-passed at config.smoothing_hz.
    """
    from scipy.signal import medfilt

    pose = recording.pose
    t = pose.t_s
    xy_raw = pose.position[:, :2]
    yaw_raw = np.unwrap(_yaw(pose.quat_xyzw))
    if len(t) > 9:
        off_xy = np.linalg.norm(xy_raw - np.stack([medfilt(xy_raw[:, k], 9) for k in range(2)], axis=1), axis=1)
        wrapped = np.angle(np.exp(1j * (yaw_raw - medfilt(yaw_raw, 9))))
        keep = (off_xy < config.jump_m) & (np.abs(wrapped) < config.jump_m / 0.05)
        t, xy_raw = t[keep], xy_raw[keep]
        yaw_raw = np.unwrap(yaw_raw[keep])
    period = config.sample_period_s
    grid = t[0] + period * np.arange(int(np.floor((t[-1] - t[0]) / period)) + 1)
    xy = np.stack([np.interp(grid, t, xy_raw[:, k]) for k in range(2)], axis=1)
    yaw = np.interp(grid, t, yaw_raw)
    if smooth:
        xy = lowpass(xy, config.smoothing_hz, 1 / period)
        yaw = lowpass(yaw[:, None], config.smoothing_hz, 1 / period)[:, 0]
    return grid, xy, yaw


def scatter_about_quadratic(track: np.ndarray) -> np.ndarray:
    """RMS of a window track [S+1, W, ...] about a quadratic in time fitted per window and channel, per
    window: the tracker's scatter, the motion taken out."""
    flat = track.reshape(track.shape[0], -1)
    samples = np.arange(track.shape[0])
    fit = np.polynomial.polynomial.polyval(samples, np.polynomial.polynomial.polyfit(samples, flat, 2)).T
    return np.sqrt(np.mean(((flat - fit) ** 2).reshape(track.shape[0], track.shape[1], -1), axis=(0, 2)))


def window_thirds(samples: int) -> list[tuple[int, int]]:
    """First and last sample of each third of a window of `samples` samples."""
    return list(pairwise(np.linspace(0, samples - 1, 4).round().astype(int)))


def planar_travel(step: np.ndarray, arc_m: float) -> np.ndarray:
    """Size of planar steps (..., 3: x, y [m], yaw [rad]), the heading counted as an arc of arc_m [m]."""
    return np.hypot(np.hypot(step[..., 0], step[..., 1]), step[..., 2] * arc_m)


def _yaw(quat_xyzw: np.ndarray) -> np.ndarray:
    """Heading of the frame's x axis about world z [rad] (valid while the object stays flat)."""
    x_axis = Rotation.from_quat(quat_xyzw).apply([1.0, 0.0, 0.0])
    return np.arctan2(x_axis[:, 1], x_axis[:, 0])


@dataclass(frozen=True)
class ForceBias:
    """Offset of the measured force (measured = applied + offset), world x, y, z [N], over time.

    Measured at "zeros", stretches where the object is still and nothing pushes
    it; linear in time between zeros, held before the first and after the last.
    t_s [K]: each zero's median stamp [s]; force_n [K, 3]: its median force [N]
    (K = 0: no zero found, no offset); source: where the zeros were taken.
    """

    t_s: np.ndarray
    force_n: np.ndarray
    source: str

    def at(self, t_s) -> np.ndarray:
        """The offset [N] at stamps t_s [s], shape (len(t_s), 3)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        if len(self.t_s) == 0:
            return np.zeros((len(t), 3))
        return np.stack([np.interp(t, self.t_s, self.force_n[:, k]) for k in range(3)], axis=1)

    def provenance(self) -> dict:
        return {"source": self.source, "t_s": list(map(float, self.t_s)),
                "force_n": [list(map(float, f)) for f in self.force_n]}


def estimate_force_bias(recording, config: SlidingConfig, margin_s: float = 0.3) -> ForceBias:
    """The force sensor's offset from the recording's zeros (see ForceBias); real F/T sensors are
    often not zeroed (mit-push README).

    A zero is a stretch, more than `margin_s` before the object first moves or
    after it last moves, where the pusher is away: its contact point farther
    from the object, by config.pusher_clear_m, than as the object started to
    move, or config.lift_m above its height while pushing. With zeros before
    and after, the offset drifts linearly between them.

    Where the pusher rests against the object before the push (no zero before
    it), that resting stretch is the offset, taken in the pose the push is
    made in, unless it shows a preload: the pusher pressing while static
    friction holds reads higher ALONG the push than the zero after it, by more
    than config.preload_fraction of the median pushing force (the 2015
    plastic-block bags: 0.08-0.28 N of a 0.5 N push). Then the zero after the
    push is the offset. `source` says which.
    """
    grid, xy, _ = _planar_grid(recording, config, smooth=True)
    speed = np.linalg.norm(np.gradient(xy, grid, axis=0), axis=1)
    run = 10  # samples: a filter's edge or a tracker glitch is not motion
    fast = (speed > config.moving_speed_m_s).astype(float)
    moving = np.flatnonzero(np.convolve(fast, np.ones(run), "valid") == run)
    w = recording.wrench
    t_w = w.t_s
    t_first = grid[moving[0]] if len(moving) else grid[-1]
    t_last = grid[moving[-1] + run - 1] if len(moving) else grid[-1]
    before = t_w < t_first - margin_s
    after = t_w > t_last + margin_s
    away = np.zeros(len(t_w), dtype=bool)
    c = recording.contact
    if c is not None and len(moving):
        tip = np.stack([np.interp(t_w, c.t_s, c.position[:, k]) for k in range(3)], axis=1)
        obj = np.stack([np.interp(t_w, grid, xy[:, k]) for k in range(2)], axis=1)
        distance = np.linalg.norm(tip[:, :2] - obj, axis=1)
        pushing_z = np.median(tip[(t_w >= t_first) & (t_w <= t_last), 2])
        away = ((distance > np.interp(t_first, t_w, distance) + config.pusher_clear_m)
                | (tip[:, 2] > pushing_z + config.lift_m))

    def zero(mask):
        return float(np.median(t_w[mask])), np.median(w.force[mask], axis=0)

    first = zero(before & away) if (before & away).sum() >= 10 else None
    last = zero(after & away) if (after & away).sum() >= 10 else None
    if first is None and before.sum() >= 10:
        resting = zero(before)
        if last is not None:
            pushing = np.median(w.force[(t_w >= t_first) & (t_w <= t_last)] - last[1], axis=0)[:2]
            excess = float((resting[1] - last[1])[:2] @ pushing) / max(float(np.linalg.norm(pushing)), 1e-9)
            if excess > config.preload_fraction * np.linalg.norm(pushing):
                return ForceBias(np.array([last[0]]), last[1][None], "pusher away after a preload")
        return ForceBias(np.array([resting[0]]), resting[1][None], "pusher resting before the push")
    zeros = [z for z in (first, last) if z is not None]
    return ForceBias(np.array([z[0] for z in zeros]), np.array([z[1] for z in zeros]).reshape(-1, 3),
                     "pusher away" if zeros else "none")


def push_windows(recording, body: PlanarBody, config: SlidingConfig, bias: ForceBias | None = None,
                 moving_only: bool = True, phase: int = 0) -> PushWindows:
    """Back-to-back windows over the part of `recording` where the pusher touches the object, tiled from
    `phase` pose samples after its first pose.

    The force is the recording's world-axes wrench force minus `bias` at its stamps; the contact
    point is the recording's contact track (required: a push is a force at a point).
    With moving_only, windows where the object does not slide are left out. The force is kept
    config.max_delay_s beyond each window's ends, the range a time delay is fitted over.
    """
    if recording.contact is None:
        raise ValueError(
            f"{recording.path}: sliding needs the contact point of the pushing force "
            "(a PointStamped or pose topic; name it with --topic contact=/name)"
        )
    grid, xy, yaw = _planar_grid(recording, config, smooth=False)  # smoothing would blunt stops
    period = grid[1] - grid[0]
    substeps = max(1, int(round(period / config.dt_s)))
    dt = period / substeps
    samples = max(2, int(round(config.window_s / period)))
    c = recording.contact
    contact_grid = np.stack([np.interp(grid, c.t_s, c.position[:, k]) for k in range(2)], axis=1)
    reach = float(np.hypot(*body.half_extents_m[:2])) + config.contact_margin_m
    touching = np.linalg.norm(contact_grid - xy, axis=1) < reach
    speed = np.linalg.norm(np.gradient(xy, grid, axis=0), axis=1)
    starts = []
    for s in range(phase, len(grid) - samples, samples):
        span = slice(s, s + samples + 1)
        if not touching[span].all():
            continue
        if moving_only and np.median(speed[span]) < config.moving_speed_m_s:
            continue
        starts.append(s)
    if not starts:
        raise ValueError(
            f"{recording.path}: no {config.window_s} s window in which the pusher touches the object"
            + (f" and it slides faster than {config.moving_speed_m_s} m/s (a slow push needs a lower "
               f"--push-min-speed, e.g. 0.001)" if moving_only else "")
        )
    starts = np.asarray(starts)
    w = recording.wrench
    force = w.force[:, :2] - (bias.at(w.t_s)[:, :2] if bias is not None else 0.0)  # unfiltered: noise averages out
    margin = int(np.ceil(config.max_delay_s / dt)) + 1
    t_step = grid[starts][None, :] + dt * np.arange(samples * substeps)[:, None]
    t_force = grid[starts][None, :] + dt * np.arange(-margin, samples * substeps + margin)[:, None]
    f = np.stack([np.interp(t_force, w.t_s, force[:, k]) for k in range(2)], axis=-1)
    p = np.stack([np.interp(t_step, c.t_s, c.position[:, k]) for k in range(2)], axis=-1)
    rot = Rotation.from_rotvec(np.c_[np.zeros((len(yaw), 2)), yaw])
    pos3 = np.c_[xy, np.zeros(len(grid))]
    start = []
    for s in starts:
        twist = local_twist(grid, pos3, rot, s, config.twist_half_width)
        start.append([xy[s, 0], xy[s, 1], yaw[s], twist[0], twist[1], twist[5]])
    idx = starts[None, :] + np.arange(samples + 1)[:, None]
    measured = np.stack([xy[idx, 0], xy[idx, 1], yaw[idx]], axis=-1)
    return PushWindows(dt, substeps, grid[starts], np.asarray(start), f, p, measured, margin)


def concat_push_windows(parts: list[PushWindows]) -> PushWindows:
    """Windows of several recordings as one batch (same step, substeps and length)."""
    first = parts[0]
    for p in parts[1:]:
        if ((p.substeps, p.step_count, p.force_margin) != (first.substeps, first.step_count, first.force_margin)
                or abs(p.dt_s - first.dt_s) > 1e-6):
            raise ValueError("recordings differ in pose rate; their windows cannot share one batch")
    return PushWindows(
        first.dt_s, first.substeps,
        np.concatenate([p.t_start_s for p in parts]),
        np.concatenate([p.start for p in parts]),
        np.concatenate([p.force for p in parts], axis=1),
        np.concatenate([p.contact for p in parts], axis=1),
        np.concatenate([p.measured for p in parts], axis=1),
        first.force_margin,
    )
