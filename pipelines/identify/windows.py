"""Multiple-shooting windows cut from a recording, each started from the measured state."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


@dataclass(frozen=True)
class ShootingWindows:
    """Simulation inputs and targets for W windows of `sample_count` pose samples each.

    dt_s: simulation step [s]; substeps: steps per pose sample; t_start_s [W];
    wrench [steps, W, 6]: force [N] and torque about the tracked origin [N m], world
    axes, linearly interpolated between the sensor samples; measured_position [S+1, W, 3] [m]
    and measured_quat_xyzw [S+1, W, 4]: the tracked frame, sample 0 the start;
    start_twist [W, 6]: tracked-origin velocity [m/s] and angular velocity [rad/s]
    at the start, estimated from the poses.
    """

    dt_s: float
    substeps: int
    t_start_s: np.ndarray
    wrench: np.ndarray
    measured_position: np.ndarray
    measured_quat_xyzw: np.ndarray
    start_twist: np.ndarray

    @property
    def window_count(self) -> int:
        return len(self.t_start_s)

    @property
    def sample_count(self) -> int:
        return self.measured_position.shape[0] - 1

    @property
    def step_count(self) -> int:
        return self.wrench.shape[0]

    @property
    def window_s(self) -> float:
        return self.step_count * self.dt_s


MAX_GRID_SAMPLES = 10**7
"""More pose samples than a day at 100 Hz: the span holds a stray stamp, not a recording."""


def uniform_pose_grid(t_s, position, quat_xyzw) -> tuple[np.ndarray, np.ndarray, Rotation]:
    """Poses resampled onto a uniform grid at the median sampling period.

    Raises ValueError rather than allocate more than `MAX_GRID_SAMPLES` samples.
    """
    t_s = np.asarray(t_s, dtype=float)
    period = float(np.median(np.diff(t_s)))
    span = float(t_s[-1] - t_s[0])
    count = span / period + 1 if period > 0 else np.inf
    if not count <= MAX_GRID_SAMPLES:
        raise ValueError(f"uniform_pose_grid: {t_s[0]:.3f}..{t_s[-1]:.3f} s ({span:.3g} s) at a {period:.3g} s "
                         f"period would take {count:.3g} samples, more than {MAX_GRID_SAMPLES:g}")
    grid = t_s[0] + period * np.arange(int(np.floor(span / period + 1e-6)) + 1)
    grid = np.minimum(grid, t_s[-1])  # rounding may put the last point a hair past the data
    pos = np.stack([np.interp(grid, t_s, position[:, k]) for k in range(3)], axis=1)
    rot = Slerp(t_s, Rotation.from_quat(quat_xyzw))(grid)
    return grid, pos, rot


def lowpass(x: np.ndarray, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Zero-phase 4th-order Butterworth low-pass along axis 0 (no delay)."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, cutoff_hz / (0.5 * rate_hz), output="sos")
    return sosfiltfilt(sos, x, axis=0)


def lowpass_edge_samples(cutoff_hz: float, rate_hz: float) -> int:
    """Samples at each end of a `lowpass`ed record that still ring where it was cut mid-motion: 2.5 periods of
    the cutoff. On jointed recordings cut at 3 rad/s (8 Hz, 200 Hz), an equation of motion's residual in q'' and
    the effort stood 2-12x its typical size 0.10-0.15 s from the end, up to 3x at 0.25 s, and settled by 0.3 s."""
    return int(np.ceil(2.5 * rate_hz / cutoff_hz))


def smoothed_pose_grid(t_s, position, quat_xyzw, cutoff_hz: float) -> tuple[np.ndarray, np.ndarray, Rotation]:
    """Uniform pose grid, low-passed: positions directly, rotations as sign-continuous quaternions."""
    t, pos, rot = uniform_pose_grid(t_s, position, quat_xyzw)
    rate = 1.0 / (t[1] - t[0])
    q = rot.as_quat()
    for i in range(1, len(q)):  # one hemisphere, so the components can be filtered
        if q[i] @ q[i - 1] < 0:
            q[i] = -q[i]
    return t, lowpass(pos, cutoff_hz, rate), Rotation.from_quat(lowpass(q, cutoff_hz, rate))


def central_derivative(x: np.ndarray, dt_s: float) -> np.ndarray:
    """d/dt along axis 0 by the five-point central stencil (np.gradient's 2nd order at the two ends).

    The three-point stencil reads a 5 Hz sine 0.4 % low at 200 Hz, and twice that
    for a second derivative: a bias in the inertia as large as the noise allows.
    """
    d = np.gradient(x, dt_s, axis=0)
    d[2:-2] = (8 * (x[3:-1] - x[1:-3]) - (x[4:] - x[:-4])) / (12 * dt_s)
    return d


def angular_velocity(rot: Rotation, dt_s: float) -> np.ndarray:
    """World-axes angular velocity [rad/s] of a uniformly sampled rotation, by the five-point stencil
    on rotation vectors between samples symmetric about each one (three-point at the ends)."""
    def span(j: int) -> np.ndarray:
        return (rot[2 * j:] * rot[: len(rot) - 2 * j].inv()).as_rotvec()

    omega = np.empty((len(rot), 3))
    omega[1:-1] = span(1) / (2 * dt_s)
    omega[0], omega[-1] = omega[1], omega[-2]
    omega[2:-2] = (8 * span(1)[1:-1] - span(2)) / (12 * dt_s)
    return omega


def local_twist(grid_t, pos, rot: Rotation, index: int, half_width: int) -> np.ndarray:
    """Velocity [m/s] and angular velocity [rad/s, world] at `index` from a local quadratic fit."""
    lo, hi = max(0, index - half_width), min(len(grid_t), index + half_width + 1)
    tau = grid_t[lo:hi] - grid_t[index]
    A = np.stack([np.ones_like(tau), tau, tau * tau], axis=1)
    rotvec = (rot[lo:hi] * rot[index].inv()).as_rotvec()  # world-axes increments
    coef_p, *_ = np.linalg.lstsq(A, pos[lo:hi], rcond=None)
    coef_r, *_ = np.linalg.lstsq(A, rotvec, rcond=None)
    return np.concatenate([coef_p[1], coef_r[1]])


def make_windows(
    pose_t_s,
    pose_position,
    pose_quat_xyzw,
    wrench_t_s,
    wrench_force,
    wrench_torque,
    *,
    window_s: float,
    substeps: int,
    t_begin_s: float | None = None,
    t_end_s: float | None = None,
    twist_half_width: int = 5,
    smoothing_hz: float | None = None,
) -> ShootingWindows:
    """Cut back-to-back windows of `window_s` over [t_begin_s, t_end_s] (default: all of it).

    With `smoothing_hz`, poses and wrench are both low-passed (zero phase) at that cutoff
    first: start states and targets come from the smoothed motion.
    """
    if smoothing_hz:
        grid, pos, rot = smoothed_pose_grid(pose_t_s, np.asarray(pose_position), np.asarray(pose_quat_xyzw), smoothing_hz)
        w_rate = 1.0 / np.median(np.diff(wrench_t_s))
        wrench_force = lowpass(np.asarray(wrench_force), smoothing_hz, w_rate)
        wrench_torque = lowpass(np.asarray(wrench_torque), smoothing_hz, w_rate)
    else:
        grid, pos, rot = uniform_pose_grid(pose_t_s, np.asarray(pose_position), np.asarray(pose_quat_xyzw))
    period = grid[1] - grid[0]
    samples = max(1, int(round(window_s / period)))
    t_begin = max(grid[0], wrench_t_s[0]) if t_begin_s is None else t_begin_s
    t_end = min(grid[-1], wrench_t_s[-1]) if t_end_s is None else t_end_s
    first = int(np.searchsorted(grid, t_begin - 1e-9))
    starts = np.arange(first, len(grid) - samples, samples)
    starts = starts[grid[starts + samples] <= t_end + 1e-9]
    if len(starts) == 0:
        raise ValueError(f"recording too short for one {window_s} s window between {t_begin:.3f} and {t_end:.3f} s")

    dt = period / substeps
    steps = samples * substeps
    t_step = grid[starts][None, :] + dt * np.arange(steps)[:, None]  # [steps, W]
    # a sensor point-samples a continuous wrench: linear interpolation between samples at each step
    samples_w = np.concatenate([np.asarray(wrench_force), np.asarray(wrench_torque)], axis=-1)
    wrench = np.stack([np.interp(t_step, wrench_t_s, samples_w[:, c]) for c in range(6)], axis=-1)

    sample_idx = starts[None, :] + np.arange(samples + 1)[:, None]  # [S+1, W]
    twist = np.stack([local_twist(grid, pos, rot, i, twist_half_width) for i in starts])
    return ShootingWindows(
        dt_s=dt,
        substeps=substeps,
        t_start_s=grid[starts],
        wrench=wrench,
        measured_position=pos[sample_idx],
        measured_quat_xyzw=rot[sample_idx.reshape(-1)].as_quat().reshape(samples + 1, len(starts), 4),
        start_twist=twist,
    )


def concat_windows(parts: list[ShootingWindows]) -> ShootingWindows:
    """Windows of several recordings as one batch; they must share step, substeps and length."""
    first = parts[0]
    for p in parts[1:]:
        if (p.dt_s, p.substeps, p.step_count) != (first.dt_s, first.substeps, first.step_count):
            raise ValueError("recordings differ in pose rate; their windows cannot share one batch")
    return ShootingWindows(
        dt_s=first.dt_s,
        substeps=first.substeps,
        t_start_s=np.concatenate([p.t_start_s for p in parts]),
        wrench=np.concatenate([p.wrench for p in parts], axis=1),
        measured_position=np.concatenate([p.measured_position for p in parts], axis=1),
        measured_quat_xyzw=np.concatenate([p.measured_quat_xyzw for p in parts], axis=1),
        start_twist=np.concatenate([p.start_twist for p in parts], axis=0),
    )


def cluster_meat(scores: np.ndarray, fitted: int = 1) -> np.ndarray:
    """The sandwich's meat from per-cluster scores [G, P] (each cluster's J^T r) of a least-squares fit whose
    residuals are correlated within a cluster (a shooting window, a block of low-passed rows) and independent
    between clusters, with the small-sample factor G / (G - fitted).

    sigma^2 (J^T J)^-1 treats every residual as independent: on a jointed part's rows low-passed at 8 Hz on a
    200 Hz grid it reported a third of the spread over noise draws.
    """
    G = len(scores)
    return scores.T @ scores * (G / max(G - fitted, 1))


def clustered_covariance(bread: np.ndarray, scores: np.ndarray, fitted: int = 1) -> np.ndarray:
    """Sandwich covariance bread M bread: bread [P, P] the inverse Gauss-Newton matrix, M `cluster_meat`."""
    return bread @ cluster_meat(scores, fitted) @ bread


def predicts_better(mse: np.ndarray, reference: np.ndarray) -> bool:
    """Whether per-window errors `mse` beat `reference`'s by more than twice the standard error of the paired
    difference (windows are nearly independent): the rule by which a jointed identification replaces its Newton fit
    and the diagnosis keeps a candidate. The difference is of log errors: one window that diverges must not
    outweigh all the others."""
    d = np.log(np.maximum(mse, 1e-300)) - np.log(np.maximum(reference, 1e-300))
    return bool(d.mean() + 2 * d.std(ddof=1) / np.sqrt(len(d)) < 0)
