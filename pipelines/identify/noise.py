"""Sensor noise levels estimated from the recording itself."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .windows import lowpass, smoothed_pose_grid, uniform_pose_grid


@dataclass(frozen=True)
class NoiseLevels:
    """Standard deviations per sample: tracker position [m] and rotation [rad], wrench force [N] and torque [N m]."""

    position_m: float
    rotation_rad: float
    force_n: float
    torque_nm: float


def estimate_noise_levels(pose_t_s, pose_position, pose_quat_xyzw, wrench_t_s, wrench_force, wrench_torque,
                          cutoff_hz: float = 20.0) -> NoiseLevels:
    """Noise per sample from what a zero-phase low-pass removes, rescaled for the share of the band it keeps.

    The motion lies well below `cutoff_hz` and the noise is white up to Nyquist,
    so what the filter removes is noise over (1 - cutoff / Nyquist) of the band.
    """
    t, pos, rot = uniform_pose_grid(pose_t_s, np.asarray(pose_position), np.asarray(pose_quat_xyzw))
    _, pos_smooth, rot_smooth = smoothed_pose_grid(pose_t_s, pose_position, pose_quat_xyzw, cutoff_hz)
    keep = 1.0 - min(0.9, cutoff_hz / (0.5 / (t[1] - t[0])))
    w_rate = 1.0 / float(np.median(np.diff(wrench_t_s)))
    w_keep = 1.0 - min(0.9, cutoff_hz / (0.5 * w_rate))
    force, torque = np.asarray(wrench_force), np.asarray(wrench_torque)
    trim = slice(10, -10)  # filter edges

    def rms(x, share):
        return float(np.sqrt(np.mean(x[trim] ** 2) / share))

    return NoiseLevels(
        position_m=rms(pos - pos_smooth, keep),
        rotation_rad=rms((rot * rot_smooth.inv()).as_rotvec(), keep),
        force_n=rms(force - lowpass(force, cutoff_hz, w_rate), w_keep),
        torque_nm=rms(torque - lowpass(torque, cutoff_hz, w_rate), w_keep),
    )


def recording_noise_levels(recording) -> NoiseLevels:
    """`estimate_noise_levels` of a `assets.recording.Recording`'s tracked poses and world-frame wrench."""
    pose, wrench = recording.pose, recording.wrench
    return estimate_noise_levels(pose.t_s, pose.position, pose.quat_xyzw, wrench.t_s, wrench.force, wrench.torque)


def renoised(recording, levels: NoiseLevels, rng: np.random.Generator):
    """`recording` (a `assets.recording.Recording`) with independent white noise of `levels` added once more to its
    tracked poses (position per axis [m], rotation per axis [rad]) and its world-frame wrench (per axis [N],
    [N m]): the same recording as a second, equally noisy set of sensors would have given. `wrench_raw` is left
    as read."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    pose, wrench = recording.pose, recording.wrench
    turn = Rotation.from_rotvec(levels.rotation_rad * rng.standard_normal((len(pose.t_s), 3)))
    pose = replace(pose, position=pose.position + levels.position_m * rng.standard_normal(pose.position.shape),
                   quat_xyzw=(turn * Rotation.from_quat(pose.quat_xyzw)).as_quat())
    wrench = replace(wrench, force=wrench.force + levels.force_n * rng.standard_normal(wrench.force.shape),
                     torque=wrench.torque + levels.torque_nm * rng.standard_normal(wrench.torque.shape))
    return replace(recording, pose=pose, wrench=wrench)
