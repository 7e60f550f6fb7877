"""Least-squares inertial identification (Atkeson, An & Hollerbach 1986): the Newton-Euler regressor.

The wrench at the tracked frame is linear in pi = (m, m c, I_o) once the
frame's velocity and acceleration are known:

    f = m (a - g) + alpha x (m c) + omega x (omega x (m c))
    tau = I_o alpha + omega x (I_o omega) + (m c) x (a - g)

all in tracked-frame axes, c the COM and I_o the inertia about the tracked
origin. Both sides pass through the same zero-phase low-pass filter
(`newton_euler_rows`). The wrench noise stays on the measured side of the
regression, which is why this estimator is not biased by it. The tracker's
noise is not: it enters the regressor through the differentiated poses
(errors in variables: -0.1 % mass, +0.17 mm COM along the grasp on the
paper's cube), so its share of the normal equations is measured by adding
noise of the recording's own level to the poses and removed (corrected
score: Nakamura 1990, Buonaccorsi 2010).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Slerp

from assets import Inertial, Pose
from assets.conventions import GRAVITY_M_S2

from .noise import NoiseLevels, estimate_noise_levels
from .windows import angular_velocity, central_derivative, cluster_meat, lowpass, smoothed_pose_grid


@dataclass(frozen=True)
class LeastSquaresResult:
    """The estimate in the object frame and its covariance over (mass, com xyz, Ixx Iyy Izz Ixy Ixz Iyz).

    pi [10]: the estimate as fitted (tracked frame, about its origin; may be unphysical); normal [10, 10]:
    the weighted normal matrix H corrected for the tracker's noise; meat [10, 10]: the block sandwich's
    meat, so that the covariance of pi is H^-1 M H^-1 (`pipelines.identify.posterior` reads the likelihood
    from these).
    """

    inertial: Inertial
    covariance: np.ndarray
    cutoff_hz: float
    sample_count: int
    pi: np.ndarray | None = None
    normal: np.ndarray | None = None
    meat: np.ndarray | None = None


def _skew(v: np.ndarray) -> np.ndarray:
    """Batched cross-product matrices, [N, 3] -> [N, 3, 3]."""
    z = np.zeros(len(v))
    return np.stack(
        [np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1),
         np.stack([-v[:, 1], v[:, 0], z], -1)], 1
    )


def _inertia_operator(v: np.ndarray) -> np.ndarray:
    """L(v) with I v = L(v) (Ixx, Iyy, Izz, Ixy, Ixz, Iyz), batched [N, 3, 6]."""
    z = np.zeros(len(v))
    x, y, w = v[:, 0], v[:, 1], v[:, 2]
    return np.stack(
        [np.stack([x, z, z, y, w, z], -1), np.stack([z, y, z, x, z, w], -1), np.stack([z, z, w, z, x, y], -1)], 1
    )


def newton_euler_regressor(accel_minus_gravity, omega, alpha) -> np.ndarray:
    """Regressor [N, 6, 10] with wrench = A pi, pi = (m, m c, Ixx Iyy Izz Ixy Ixz Iyz about the origin).

    Inputs are the frame origin's acceleration minus gravity [m/s^2], angular
    velocity [rad/s] and angular acceleration [rad/s^2], all [N, 3] in the frame's axes.
    """
    A = np.zeros((len(omega), 6, 10))
    A[:, :3, 0] = accel_minus_gravity
    Sw = _skew(omega)
    A[:, :3, 1:4] = _skew(alpha) + Sw @ Sw
    A[:, 3:, 1:4] = -_skew(accel_minus_gravity)
    A[:, 3:, 4:] = _inertia_operator(alpha) + Sw @ _inertia_operator(omega)
    return A


@dataclass(frozen=True)
class NewtonEulerRows:
    """The regression of one recording on the smoothed grid, tracked-frame axes.

    A [N, 6, 10] and measured wrench b [N, 6] (force [N], torque about the tracked origin [N m]);
    scale [6]: 1/noise per row; t_s [N]; position [N, 3] of the tracked origin in world [m];
    velocity [N, 3] of the tracked origin [m/s],
    omega [N, 3] [rad/s], gravity [N, 3] (gravity direction times 9.81 [m/s^2]), all in
    tracked axes; rate_hz of the grid; cutoff_hz of the low-pass.
    """

    t_s: np.ndarray
    A: np.ndarray
    b: np.ndarray
    scale: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    gravity: np.ndarray
    rate_hz: float
    cutoff_hz: float


def newton_euler_rows(
    pose_t_s, pose_position, pose_quat_xyzw, wrench_t_s, wrench_force, wrench_torque, *,
    cutoff_hz: float = 12.0, t_begin_s: float | None = None, noise: NoiseLevels | None = None,
) -> NewtonEulerRows:
    """Regressor and measured wrench of a recording; wrench in world axes about the tracked origin.

    Both sides are low-passed at `cutoff_hz` in tracked-frame axes (parallel
    filtering, as in robot identification practice): the equation holds at every instant and the filter
    is linear, so the filtered rows obey it exactly, where a regressor built from
    filtered poses would miss the filter's effect on its products (omega x omega,
    the turning gravity: up to 10 Hz for wrist turns of 5 Hz). The kinematics
    come from poses smoothed at 2.5 x `cutoff_hz`, above those products and below
    the tracker's noise band. Rows within 0.1 s of either stream's ends are
    dropped (filter edge effects). `noise` weights the rows; estimated from the recording when not given.
    """
    if noise is None:
        noise = estimate_noise_levels(pose_t_s, pose_position, pose_quat_xyzw, wrench_t_s, wrench_force,
                                      wrench_torque)
    t, pos, rot = smoothed_pose_grid(pose_t_s, np.asarray(pose_position), np.asarray(pose_quat_xyzw),
                                     2.5 * cutoff_hz)
    dt = t[1] - t[0]
    vel = central_derivative(pos, dt)
    acc = central_derivative(vel, dt)
    omega = angular_velocity(rot, dt)
    alpha = central_derivative(omega, dt)
    R_inv = rot.inv()
    A = newton_euler_regressor(R_inv.apply(acc - GRAVITY_M_S2), R_inv.apply(omega), R_inv.apply(alpha))
    A = lowpass(A.reshape(len(t), -1), cutoff_hz, 1.0 / dt).reshape(A.shape)

    wt = np.asarray(wrench_t_s)
    R_inv_w = Slerp(t, rot)(np.clip(wt, t[0], t[-1])).inv()  # tracked frame at the wrench's samples
    wrench = np.concatenate([R_inv_w.apply(np.array(wrench_force)), R_inv_w.apply(np.array(wrench_torque))], axis=1)
    wrench = lowpass(wrench, cutoff_hz, 1.0 / np.median(np.diff(wt)))
    b = np.stack([np.interp(t, wt, wrench[:, k]) for k in range(6)], 1)

    def tracked_axes(v: np.ndarray) -> np.ndarray:
        return lowpass(R_inv.apply(v), cutoff_hz, 1.0 / dt)

    keep = (t >= max(t[0], wt[0]) + 0.1) & (t <= min(t[-1], wt[-1]) - 0.1)
    if t_begin_s is not None:
        keep &= t >= t_begin_s
    return NewtonEulerRows(
        t_s=t[keep], A=A[keep], b=b[keep],
        scale=np.array([1 / noise.force_n] * 3 + [1 / noise.torque_nm] * 3),
        position=lowpass(pos, cutoff_hz, 1.0 / dt)[keep], velocity=tracked_axes(vel)[keep],
        omega=tracked_axes(omega)[keep], gravity=tracked_axes(np.tile(GRAVITY_M_S2, (len(t), 1)))[keep],
        rate_hz=1.0 / dt, cutoff_hz=cutoff_hz,
    )


def identify_least_squares(
    pose_t_s, pose_position, pose_quat_xyzw, wrench_t_s, wrench_force, wrench_torque,
    X_tracked_body: Pose, *, cutoff_hz: float = 12.0, t_begin_s: float | None = None, block_s: float = 0.1,
    noise_draws: int = 8, seed: int = 0,
) -> LeastSquaresResult:
    """Fit pi by weighted least squares, corrected for the tracker's noise; wrench in world axes about
    the tracked origin.

    Force and torque rows are weighted by their noise levels, estimated from
    the recording. The tracker-noise share of A^T A and A^T b is averaged over
    `noise_draws` re-noised copies of the poses (`seed`) and subtracted. The
    covariance is a sandwich over blocks of `block_s` (filtered noise is
    correlated within a block, nearly independent across).
    """
    from scipy.spatial.transform import Rotation

    noise = estimate_noise_levels(pose_t_s, pose_position, pose_quat_xyzw, wrench_t_s, wrench_force, wrench_torque)
    rows = newton_euler_rows(pose_t_s, pose_position, pose_quat_xyzw, wrench_t_s, wrench_force, wrench_torque,
                             cutoff_hz=cutoff_hz, t_begin_s=t_begin_s, noise=noise)
    n = len(rows.t_s)
    As = (rows.A * rows.scale[None, :, None]).reshape(-1, 10)
    bs = (rows.b * rows.scale).reshape(-1)

    rng = np.random.default_rng(seed)
    noise_AA, noise_Ab = np.zeros((10, 10)), np.zeros(10)
    for _ in range(noise_draws):
        position = np.asarray(pose_position) + rng.normal(0, noise.position_m, np.shape(pose_position))
        jitter = Rotation.from_rotvec(rng.normal(0, noise.rotation_rad, (len(position), 3)))
        quat = (Rotation.from_quat(pose_quat_xyzw) * jitter).as_quat()
        renoised = newton_euler_rows(pose_t_s, position, quat, wrench_t_s, wrench_force, wrench_torque,
                                     cutoff_hz=cutoff_hz, t_begin_s=t_begin_s, noise=noise)
        dA = ((renoised.A - rows.A) * rows.scale[None, :, None]).reshape(-1, 10)
        db = ((renoised.b - rows.b) * rows.scale).reshape(-1)
        noise_AA += dA.T @ dA / noise_draws
        noise_Ab += dA.T @ db / noise_draws

    H = As.T @ As - noise_AA
    try:
        pi = np.linalg.solve(H, As.T @ bs - noise_Ab)
    except np.linalg.LinAlgError:  # a motion that excites fewer than ten directions: the minimum-norm fit
        pi = np.linalg.pinv(H) @ (As.T @ bs - noise_Ab)
    rows_per_block = 6 * max(1, int(round(block_s * rows.rate_hz)))
    scores = (As * (bs - As @ pi)[:, None])
    blocks = np.add.reduceat(scores, np.arange(0, len(bs), rows_per_block), axis=0)
    H_inv = np.linalg.pinv(H)
    meat = cluster_meat(blocks, 10)
    cov_pi = H_inv @ meat @ H_inv

    inertial, J = object_frame_from_pi(pi, X_tracked_body)
    return LeastSquaresResult(inertial, J @ cov_pi @ J.T, cutoff_hz, n, pi=pi, normal=H, meat=meat)


def object_frame_from_pi(pi: np.ndarray, X_tracked_body: Pose) -> tuple[Inertial, np.ndarray]:
    """Convert pi (tracked frame, about its origin) to an object-frame Inertial, with the Jacobian."""

    def convert(p):
        m = p[0]
        c = p[1:4] / m
        Ixx, Iyy, Izz, Ixy, Ixz, Iyz = p[4:]
        I_o = np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]])
        I_c = I_o - m * (c @ c * np.eye(3) - np.outer(c, c))
        T_bt = np.linalg.inv(X_tracked_body.matrix())  # tracked frame in body frame
        c_obj = T_bt[:3, :3] @ c + T_bt[:3, 3]
        I_obj = T_bt[:3, :3] @ I_c @ T_bt[:3, :3].T
        return m, c_obj, I_obj

    def flat(p):
        m, c, I = convert(p)
        return np.array([m, *c, I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])

    J = np.zeros((10, 10))
    for k in range(10):
        e = np.zeros(10)
        e[k] = 1e-6 * max(abs(pi[k]), 1e-9)
        J[:, k] = (flat(pi + e) - flat(pi - e)) / (2 * e[k])
    m, c, I = convert(pi)
    return Inertial(max(m, 1e-12), c, I), J
