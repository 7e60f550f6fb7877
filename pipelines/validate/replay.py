"""The exported files run in MuJoCo on a held-out recording, in the windows the build scores Newton's fit on."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from assets import Asset
from exporters.names import joint_name, mjcf_name

from .loaders import REST_S, mujoco_free_body, rotation_from_wxyz, settle


def _free_body_state(model, data, body: int, qadr: int, vadr: int):
    """A free body's rotation, COM arm from its origin [m], angular velocity [rad/s] and COM velocity [m/s],
    world axes, from qpos and qvel: `mj_step` leaves xpos, xipos and xmat at the state before its integration."""
    R = rotation_from_wxyz(data.qpos[qadr + 3:qadr + 7])
    com_arm = R @ model.body_ipos[body]
    spin = R @ data.qvel[vadr + 3:vadr + 6]  # a free joint's angular velocity is in body axes
    return R, com_arm, spin, data.qvel[vadr:vadr + 3] + np.cross(spin, com_arm)


def replay_jointed_mujoco(mjcf_path: Path, asset: Asset, recording, joint_fit, config=None) -> dict:
    # joint_fit: the JointFit asset.joint was written from (same axis, so the same q)
    """Windowed replay of `recording` in MuJoCo from the exported MJCF: the measured joint effort as
    `qfrc_applied`, each window started from the measured state, the joint's friction and damping
    as MuJoCo models them (`frictionloss`, `damping`). A `stribeck_friction` in `asset.effects`, which no
    format carries, sets `frictionloss` at each step to f_c + (f_s - f_c) exp(-(qd / v_s)^2): MuJoCo's
    friction constraint then holds the part up to the breakaway force at rest. RMSE of q and of the tracked
    frame's position."""
    import mujoco

    from pipelines.identify import JointedConfig, joint_windows, q_and_position_rmse

    config = config or JointedConfig()
    w = joint_windows(recording, joint_fit, config)
    model = mujoco.MjModel.from_xml_path(str(mjcf_path))
    model.opt.timestep = w.dt_s
    data = mujoco.MjData(model)
    joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint_name(mjcf_name(asset.name)))
    qpos, dof = model.jnt_qposadr[joint], model.jnt_dofadr[joint]
    stribeck = next(((e.params["f_s"], e.params["f_c"], e.params["v_s"]) for e in asset.effects
                     if e.name == "stribeck_friction"), None)
    S, W = w.q.shape[0] - 1, w.q.shape[1]
    q = np.zeros((S, W))
    for k in range(W):
        mujoco.mj_resetData(model, data)
        data.qpos[qpos], data.qvel[dof] = w.q_start[k], w.qd_start[k]
        for step in range(S * w.substeps):
            if stribeck is not None:
                f_s, f_c, v_s = stribeck
                model.dof_frictionloss[dof] = f_c + (f_s - f_c) * np.exp(-((data.qvel[dof] / v_s) ** 2))
            data.qfrc_applied[dof] = w.effort[step, k]
            mujoco.mj_step(model, data)
            if (step + 1) % w.substeps == 0:
                q[(step + 1) // w.substeps - 1, k] = data.qpos[qpos]
    return q_and_position_rmse(joint_fit, q, w.q[1:])


def replay_held_mujoco(mjcf_path: Path, asset: Asset, recording, X_tracked_body, window_s: float,
                       substeps: int = 4) -> dict:
    """The exported MJCF replaying a held body's recording in MuJoCo, on the windows the build scores Newton on.

    Each window starts from the measured pose and the velocity estimated from the poses (unsmoothed, as
    the build's own replay); at each step the measured force [N, world] acts on the body and the
    measured torque about the tracked origin is moved to the COM, where `xfrc_applied` acts. The object's
    `viscous_damping` and `quadratic_drag` in `asset.effects` act there too (-b v_com and -b_angular omega,
    -c |v_com| v_com): a free joint's `damping` is one value for its six velocities, so the MJCF cannot
    carry them. Returns the RMSE of the tracked frame's position [m] and rotation [rad].
    X_tracked_body: the object frame in the tracked frame (`Pose`).
    """
    import mujoco
    from scipy.spatial.transform import Rotation

    from pipelines.identify import make_windows

    pose, wrench = recording.pose, recording.wrench
    w = make_windows(pose.t_s, pose.position, pose.quat_xyzw, wrench.t_s, wrench.force, wrench.torque,
                     window_s=window_s, substeps=substeps)
    model = mujoco.MjModel.from_xml_path(str(mjcf_path))
    model.opt.timestep = w.dt_s
    data = mujoco.MjData(model)
    body, qadr, vadr = mujoco_free_body(model, asset, mjcf_path)
    p_tb, R_tb = np.asarray(X_tracked_body.position), X_tracked_body.rotation_matrix()
    tracked_in_body = -R_tb.T @ p_tb
    effects = {e.name: e.params for e in asset.effects}
    b, b_angular = (effects.get("viscous_damping", {}).get(k, 0.0) for k in ("b", "b_angular"))
    c = effects.get("quadratic_drag", {}).get("c", 0.0)
    position_error, rotation_error = [], []
    for k in range(w.window_count):
        mujoco.mj_resetData(model, data)
        R_t, p_t = Rotation.from_quat(w.measured_quat_xyzw[0, k]).as_matrix(), w.measured_position[0, k]
        R_b, p_b = R_t @ R_tb, p_t + R_t @ p_tb
        v_t, omega = w.start_twist[k, :3], w.start_twist[k, 3:]
        data.qpos[qadr:qadr + 3] = p_b
        data.qpos[qadr + 3:qadr + 7] = np.roll(Rotation.from_matrix(R_b).as_quat(), 1)  # MuJoCo: w x y z
        data.qvel[vadr:vadr + 3] = v_t + np.cross(omega, p_b - p_t)  # free joint: world linear velocity
        data.qvel[vadr + 3:vadr + 6] = R_b.T @ omega  # and body-axes angular velocity
        mujoco.mj_forward(model, data)
        for step in range(w.step_count):
            R, com_arm, spin, v_com = _free_body_state(model, data, body, qadr, vadr)
            force, torque = w.wrench[step, k, :3], w.wrench[step, k, 3:]
            data.xfrc_applied[body, :3] = force - (b + c * np.linalg.norm(v_com)) * v_com
            data.xfrc_applied[body, 3:] = torque + np.cross(R @ tracked_in_body - com_arm, force) - b_angular * spin
            mujoco.mj_step(model, data)
            if (step + 1) % w.substeps == 0:
                s = (step + 1) // w.substeps
                R = rotation_from_wxyz(data.qpos[qadr + 3:qadr + 7])
                position_error.append(data.qpos[qadr:qadr + 3] + R @ tracked_in_body - w.measured_position[s, k])
                R_meas = Rotation.from_quat(w.measured_quat_xyzw[s, k]).as_matrix()
                rotation_error.append(Rotation.from_matrix((R @ R_tb.T).T @ R_meas).magnitude())
    e = np.asarray(position_error)
    return {"rmse_position_m": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
            "rmse_rotation_rad": float(np.sqrt(np.mean(np.square(rotation_error)))),
            "windows": int(w.window_count), "window_s": float(w.window_s)}


def replay_pushed_mujoco(scene_path: Path, asset: Asset, recording, window_s: float = 0.5, config=None) -> dict:
    """Windowed replay of a push in MuJoCo from the exported scene.xml (the object on its support plane).

    The windows are the identification's (`pipelines.identify.sliding.push_windows` with `config`, a
    `SlidingConfig`, at `window_s` [s] and the scene's time step): back to back where the pusher touches
    the object and it slides, the force offset of the sensor taken out as the build does
    (`estimate_force_bias`). Each starts from the measured planar state: the tracked frame's x, y and the
    heading of its x axis [rad] are the object frame's (the sliding model's convention), the height and
    tilt those the object settles to on the plane; the start velocity (vx, vy [m/s], yaw rate [rad/s]) is
    the slope of a quadratic through the poses around the start. At every step the measured horizontal
    pusher force [N, world] acts at the measured contact point, taken at the COM's height (the height a
    pusher meets the object at only tilts it, and planar recordings put it at z = 0), through
    `xfrc_applied` as that force at the COM plus its moment. The recorded force is what acted; a kinematic
    pusher would replay the pusher's path instead and need its shape and contact stiffness, which the
    recordings do not carry. The effects in `asset.effects` act as the sliding model's do (`pushed_effects`).

    Returns SI values: "rmse_position_m" and "rmse_heading_rad" over every pose sample of every window
    (as asset.json → fit), "rmse_final_position_m" and "rmse_final_heading_rad" over the windows' last
    samples, per window "t_start_s", "final_position_error_m" and "final_heading_error_rad",
    "windows", "window_s", "timestep_s", and "noise_floor_m", what the tracker's noise alone puts into
    rmse_position_m (`tracker_scatter_m`): no model's replay can go below it.
    """
    import mujoco
    import trimesh

    from pipelines.identify import PlanarBody

    scene_path = Path(scene_path)
    model = mujoco.MjModel.from_xml_path(str(scene_path))
    vertices = np.concatenate([trimesh.load(scene_path.parent / rel, force="mesh", process=False).vertices
                               for rel in asset.geometry.collision])
    inertial = asset.theta.inertial()
    planar = PlanarBody(tuple(0.5 * (vertices.max(axis=0) - vertices.min(axis=0))), inertial.mass,
                        float(inertial.inertia_matrix()[2, 2]))
    return replay_pushed_model(model, mjcf_name(asset.name), planar, recording, window_s, config, where=scene_path,
                               effects=pushed_effects(asset.effects))


def pushed_effects(effects) -> dict[str, np.ndarray]:
    """A pushed asset's effects as the sliding model's parameters (`pipelines.identify.sliding.EFFECT_SLOTS`):
    the force bias left after the zeros' in world x, y [N], damping b [N s/m] and b_angular [N m s], the
    wrench's delay [s] and the contact point's offset in world x, y [m]."""
    read = {"sensor_bias": lambda e: e.evidence["force_world_n"][:2],
            "viscous_damping": lambda e: (e.params["b"], e.params["b_angular"]),
            "time_delay": lambda e: (e.params["seconds"],),
            "contact_offset": lambda e: e.params["offset_m"][:2]}
    return {e.name: np.asarray(read[e.name](e), dtype=float) for e in effects if e.name in read}


def replay_pushed_model(model, body_name: str, planar, recording, window_s: float = 0.5, config=None,
                        where: Path | str = "model", effects: dict | None = None) -> dict:
    """`replay_pushed_mujoco` on a compiled MuJoCo model whose body `body_name` sits on a free joint above a
    support plane: the exported scene, or the model that made a synthetic recording (its truth), so both
    replay the same windows the same way. planar: the `PlanarBody` the windows are cut for (its half
    extents set how near the pusher counts as touching); the model's own time step is the replay's.
    effects: `pushed_effects`, applied as the sliding model's kernels apply them: the bias off the force, the
    force read `time_delay` later, at the contact point plus the offset, and damping at the COM."""
    from dataclasses import replace

    import mujoco
    from scipy.spatial.transform import Rotation

    from pipelines.identify import SlidingConfig, estimate_force_bias, push_windows

    data = mujoco.MjData(model)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
    joint = model.body_jntadr[body] if body >= 0 else -1
    if body < 0 or model.body_jntnum[body] != 1 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"{where}: no body {body_name!r} on a free joint")
    qadr, vadr = int(model.jnt_qposadr[joint]), int(model.jnt_dofadr[joint])
    settle(model, data, body, REST_S)
    rest_z = float(data.qpos[qadr + 2])
    R_rest = rotation_from_wxyz(data.qpos[qadr + 3:qadr + 7])
    tilt = Rotation.from_euler("z", -math.atan2(R_rest[1, 0], R_rest[0, 0])).as_matrix() @ R_rest

    config = replace(config or SlidingConfig(), window_s=window_s, dt_s=float(model.opt.timestep))
    w = push_windows(recording, planar, config, estimate_force_bias(recording, config))
    model.opt.timestep = w.dt_s
    effects = effects or {}
    bias, offset = (effects.get(name, np.zeros(2)) for name in ("sensor_bias", "contact_offset"))
    b, b_angular = effects.get("viscous_damping", np.zeros(2))
    # the force acting at a step was read the delay later (`apply_pusher_force`), between the margin's steps
    at = w.force_margin + np.arange(w.step_count) + effects.get("time_delay", np.zeros(1))[0] / w.dt_s
    i = np.clip(np.floor(at).astype(int), 0, w.force.shape[0] - 2)
    a = np.clip(at - i, 0.0, 1.0)[:, None, None]
    force = w.force[i] * (1 - a) + w.force[i + 1] * a - bias
    contact = w.contact + offset
    S, W = w.sample_count, w.window_count
    simulated = np.zeros((S, W, 3))
    for k in range(W):
        x, y, yaw, vx, vy, yaw_rate = w.start[k]
        R = Rotation.from_euler("z", yaw).as_matrix() @ tilt
        mujoco.mj_resetData(model, data)
        data.qpos[qadr:qadr + 3] = (x, y, rest_z)
        data.qpos[qadr + 3:qadr + 7] = np.roll(Rotation.from_matrix(R).as_quat(), 1)  # MuJoCo: w x y z
        data.qvel[vadr:vadr + 3] = (vx, vy, 0.0)  # free joint: the body origin's velocity, world axes
        data.qvel[vadr + 3:vadr + 6] = R.T @ np.array([0.0, 0.0, yaw_rate])  # and body-axes angular velocity
        mujoco.mj_forward(model, data)
        for step in range(w.step_count):
            _, com_arm, spin, v_com = _free_body_state(model, data, body, qadr, vadr)
            f = np.array([*(force[step, k] - b * v_com[:2]), 0.0])
            arm = np.array([*(contact[step, k] - data.qpos[qadr:qadr + 2] - com_arm[:2]), 0.0])
            data.xfrc_applied[body] = np.r_[f, np.cross(arm, f) - [0.0, 0.0, b_angular * spin[2]]]
            mujoco.mj_step(model, data)
            if (step + 1) % w.substeps == 0:
                # qpos, not xpos: mj_step leaves the kinematics at the state before its integration
                x_axis = rotation_from_wxyz(data.qpos[qadr + 3:qadr + 7])[:, 0]
                heading = math.atan2(x_axis[1], x_axis[0])
                simulated[(step + 1) // w.substeps - 1, k] = (*data.qpos[qadr:qadr + 2], heading)
    measured = w.measured[1:]
    position = np.linalg.norm(simulated[..., :2] - measured[..., :2], axis=-1)
    heading = np.angle(np.exp(1j * (simulated[..., 2] - measured[..., 2])))  # the short way round
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    return {"rmse_position_m": rms(position), "rmse_heading_rad": rms(heading),
            "rmse_final_position_m": rms(position[-1]), "rmse_final_heading_rad": rms(heading[-1]),
            "t_start_s": w.t_start_s.tolist(), "final_position_error_m": position[-1].tolist(),
            "final_heading_error_rad": np.abs(heading[-1]).tolist(),
            "windows": int(W), "window_s": float(w.span_s), "timestep_s": float(w.dt_s),
            "noise_floor_m": tracker_scatter_m(measured[..., :2])}


def tracker_scatter_m(track: np.ndarray) -> float:
    """What the tracker's own noise alone puts into a replay's position RMSE [m]: track [S, W, 2], x and y
    per window sample. Each axis's noise is read from its second differences within the windows (white noise
    of sigma gives 6 sigma^2), robustly (the median absolute deviation), so the few samples where a push
    starts or stops do not count as noise; returns sqrt(sigma_x^2 + sigma_y^2), the RMS of a 2-D error (0 for
    windows of under three samples, which cannot tell noise from motion)."""
    if len(track) < 3:
        return 0.0
    from scipy.stats import median_abs_deviation

    d2 = (track[2:] - 2 * track[1:-1] + track[:-2]).reshape(-1, track.shape[-1])
    sigma = median_abs_deviation(d2, axis=0, scale="normal") / np.sqrt(6)
    return float(np.sqrt(np.sum(sigma**2)))
