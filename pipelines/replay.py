"""The exported MJCF replaying a held-out recording in MuJoCo, beside Newton's replay of the fit.

A build's numbers are only as good as what another simulator does with the files: the same windows
the identification scores itself on (back-to-back, each started from the measured state, the
measured wrench applied) are run in MuJoCo from the written MJCF, and the tracked frame's position
error is reported next to Newton's. MuJoCo integrates with its own step here, so a gap between the
two is the files' (or the simulators') doing, not the identification's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from assets import Asset, Pose
from exporters.names import mjcf_name

from .identify.windows import make_windows


def replay_held_mujoco(mjcf_path: Path, asset: Asset, recording, X_tracked_body: Pose, window_s: float,
                       substeps: int = 4) -> dict:
    """RMSE of the tracked frame's position [m] and rotation [rad] over `recording` replayed in windows.

    Each window starts from the measured pose and the velocity estimated from the poses (unsmoothed, as
    the build's own replay); at each step the measured force [N, world] acts at the body and the
    measured torque about the tracked origin is moved to the COM, where MuJoCo's `xfrc_applied` acts.
    """
    import mujoco

    pose, wrench = recording.pose, recording.wrench
    w = make_windows(pose.t_s, pose.position, pose.quat_xyzw, wrench.t_s, wrench.force, wrench.torque,
                     window_s=window_s, substeps=substeps)
    model = mujoco.MjModel.from_xml_path(str(mjcf_path))
    model.opt.timestep = w.dt_s
    data = mujoco.MjData(model)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, mjcf_name(asset.name))
    if body < 0 or model.body_jntnum[body] != 1 or model.jnt_type[model.body_jntadr[body]] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"{mjcf_path}: no free body {mjcf_name(asset.name)!r} to replay")
    qadr, vadr = model.jnt_qposadr[model.body_jntadr[body]], model.jnt_dofadr[model.body_jntadr[body]]
    p_tb, R_tb = np.asarray(X_tracked_body.position), X_tracked_body.rotation_matrix()
    position_error, rotation_error = [], []
    for k in range(w.window_count):
        mujoco.mj_resetData(model, data)
        R_t = Rotation.from_quat(w.measured_quat_xyzw[0, k]).as_matrix()
        p_t = w.measured_position[0, k]
        R_b, p_b = R_t @ R_tb, p_t + R_t @ p_tb
        v_t, omega = w.start_twist[k, :3], w.start_twist[k, 3:]
        data.qpos[qadr:qadr + 3] = p_b
        data.qpos[qadr + 3:qadr + 7] = np.roll(Rotation.from_matrix(R_b).as_quat(), 1)  # MuJoCo: w x y z
        data.qvel[vadr:vadr + 3] = v_t + np.cross(omega, p_b - p_t)  # free joint: world linear velocity
        data.qvel[vadr + 3:vadr + 6] = R_b.T @ omega  # and body-axes angular velocity
        mujoco.mj_forward(model, data)
        for step in range(w.step_count):
            R = data.xmat[body].reshape(3, 3)
            p_track = data.xpos[body] + R @ _tracked_in_body(p_tb, R_tb)
            force, torque = w.wrench[step, k, :3], w.wrench[step, k, 3:]
            data.xfrc_applied[body, :3] = force
            data.xfrc_applied[body, 3:] = torque + np.cross(p_track - data.xipos[body], force)
            mujoco.mj_step(model, data)
            if (step + 1) % w.substeps == 0:
                s = (step + 1) // w.substeps
                R = data.xmat[body].reshape(3, 3)
                p_track = data.xpos[body] + R @ _tracked_in_body(p_tb, R_tb)
                position_error.append(p_track - w.measured_position[s, k])
                R_meas = Rotation.from_quat(w.measured_quat_xyzw[s, k]).as_matrix()
                rotation_error.append(Rotation.from_matrix((R @ R_tb.T).T @ R_meas).magnitude())
    e = np.asarray(position_error)
    return {"rmse_position_m": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
            "rmse_rotation_rad": float(np.sqrt(np.mean(np.square(rotation_error)))),
            "windows": int(w.window_count), "window_s": float(w.window_s)}


def _tracked_in_body(p_tb: np.ndarray, R_tb: np.ndarray) -> np.ndarray:
    """The tracked origin in body coordinates, from the body frame's pose in the tracked frame."""
    return -R_tb.T @ p_tb
