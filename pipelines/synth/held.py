"""A robot moving a held rigid object, simulated in Newton, and the sensors that record it.

The robot grasps the object at its scanned placement and drives the grasp frame
along a smooth multi-sine reference in all six axes with a computed-wrench
feedback controller. The wrench it applies is what an F/T sensor between wrist
and gripper would measure; the grasp frame's pose is what a tracker would see.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from assets import Inertial, Pose
from assets.conventions import GRAVITY_M_S2


@dataclass(frozen=True)
class HeldMotionConfig:
    """How the robot moves the object."""

    duration_s: float = 8.0
    """Length of the recording [s], still hold included."""
    hold_s: float = 0.4
    """Still hold at the scanned placement before the motion starts [s]."""
    control_rate_hz: float = 500.0
    """F/T sensor rate [Hz]: it point-samples the wrench, which the controller updates every Newton step."""
    substeps: int = 8
    """Newton steps per sensor period."""
    translation_amplitude_m: float = 0.05
    """Peak reference displacement per axis [m]."""
    translation_band_hz: tuple[float, float] = (0.5, 2.5)
    """Band of the translation multi-sine [Hz]."""
    rotation_amplitude_rad: float = 0.3
    """Peak reference rotation per axis [rad]."""
    rotation_band_hz: tuple[float, float] = (2.0, 5.0)
    """Band of the rotation multi-sine [Hz]: small fast wrist turns give the angular
    acceleration that makes the inertia observable above the torque sensor's noise."""
    sines_per_axis: int = 3
    stiffness_1_s2: float = 900.0
    """Controller proportional gain (per unit mass or inertia) [1/s^2]."""
    damping_1_s: float = 60.0
    """Controller derivative gain [1/s]."""


@dataclass(frozen=True)
class SensorNoise:
    """Sensor noise of an ATI Axia80-class F/T sensor and an optical tracker."""

    force_sigma_n: float = 1.0 / 80.0
    force_resolution_n: float = 1.0 / 80.0
    torque_sigma_nm: float = 1.0 / 2000.0
    torque_resolution_nm: float = 1.0 / 2000.0
    position_sigma_m: float = 2e-4
    rotation_sigma_rad: float = 2e-3
    pose_rate_hz: float = 200.0
    pose_time_offset_s: float = 0.00125
    """The tracker's clock phase against the F/T sensor's [s]: the streams are not aligned."""


@dataclass(frozen=True)
class ConcealedEffect:
    """Physics the recording carries and the model does not (DESIGN.md names; params in SI).

    viscous_damping {b, b_angular} and quadratic_drag {c} act on the body in the simulation;
    sensor_bias {force, torque} (grasp-frame axes) and time_delay {seconds} act on the
    sensor; nonuniform_density {com_shift} moves the true COM off the uniform-density one.
    On a joint (`pipelines.synth.jointed`): viscous_damping {b}, spring {k, q0} and
    stribeck_friction {f_s, f_c, v_s} are passive joint forces.
    """

    name: str
    params: dict

    def __post_init__(self):
        if self.name not in EFFECT_PARAMS:
            raise ValueError(f"ConcealedEffect.name: expected one of {tuple(EFFECT_PARAMS)}, got {self.name!r}")
        missing = set(EFFECT_PARAMS[self.name]) - set(self.params)
        if missing:
            raise ValueError(f"ConcealedEffect {self.name}: missing params {sorted(missing)}")

    def body_wrench(self, v_com: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """Force [N] and torque [N m] about the COM, world axes, that the effect puts on the body."""
        if self.name == "viscous_damping":
            return np.concatenate([-self.params["b"] * v_com, -self.params.get("b_angular", 0.0) * omega])
        if self.name == "quadratic_drag":
            return np.concatenate([-self.params["c"] * np.linalg.norm(v_com) * v_com, np.zeros(3)])
        return np.zeros(6)


EFFECT_PARAMS = {
    "viscous_damping": ("b",),
    "spring": ("k", "q0"),
    "stribeck_friction": ("f_s", "f_c", "v_s"),
    "quadratic_drag": ("c",),
    "sensor_bias": ("force", "torque"),
    "time_delay": ("seconds",),
    "nonuniform_density": ("com_shift",),
}


@dataclass(frozen=True)
class HeldMotion:
    """What happened, noise-free. World frame; the grasp frame is the tracked frame.

    t_wrench_s [K]: sensor sample times; force_n [K,3] and torque_nm [K,3]: the
    wrench applied to the object at the grasp frame origin, world axes, at those
    times (it varies continuously between them). t_pose_s [N]; grasp_position_m [N,3];
    grasp_quat_xyzw [N,4]: the grasp frame in world.
    """

    t_wrench_s: np.ndarray
    force_n: np.ndarray
    torque_nm: np.ndarray
    t_s: np.ndarray
    grasp_position_m: np.ndarray
    grasp_quat_xyzw: np.ndarray


def multisine_reference(config: HeldMotionConfig, rng: np.random.Generator):
    """Reference offsets of the grasp frame from its start: a function of time returning
    (displacement [m], rotation vector [rad]) and their first two derivatives, six axes,
    faded in after the hold so velocity and acceleration start at zero."""
    freqs = np.concatenate(
        [
            rng.uniform(*config.translation_band_hz, size=(3, config.sines_per_axis)),
            rng.uniform(*config.rotation_band_hz, size=(3, config.sines_per_axis)),
        ]
    )
    phases = rng.uniform(0, 2 * np.pi, size=(6, config.sines_per_axis))
    amps = np.concatenate(
        [np.full(3, config.translation_amplitude_m), np.full(3, config.rotation_amplitude_rad)]
    )[:, None] / config.sines_per_axis
    ramp_s = 1.0

    def reference(t: float):
        tau = t - config.hold_s
        if tau <= 0:
            return np.zeros(6), np.zeros(6), np.zeros(6)
        w = 2 * np.pi * freqs
        s = np.sin(w * tau + phases) - np.sin(phases)
        ds = w * np.cos(w * tau + phases)
        dds = -w * w * np.sin(w * tau + phases)
        # smoothstep fade-in: C2 at the start so the controller sees no jump
        x = min(tau / ramp_s, 1.0)
        g = x**3 * (10 - 15 * x + 6 * x * x)
        dg = (30 * x**2 - 60 * x**3 + 30 * x**4) / ramp_s if x < 1 else 0.0
        ddg = (60 * x - 180 * x**2 + 120 * x**3) / ramp_s**2 if x < 1 else 0.0
        y = (amps * s).sum(1)
        dy = (amps * ds).sum(1)
        ddy = (amps * dds).sum(1)
        return g * y, dg * y + g * dy, ddg * y + 2 * dg * dy + g * ddy

    return reference


def simulate_held(
    inertial: Inertial,
    placement: Pose,
    grasp: Pose,
    config: HeldMotionConfig,
    rng: np.random.Generator,
    device: str = "cpu",
    effect: ConcealedEffect | None = None,
) -> HeldMotion:
    """Simulate the held object in Newton (SemiImplicit, no damping) under the controller.

    inertial: true parameters in the object frame; placement: object frame in world
    at t = 0; grasp: grasp (tracked) frame in the object frame. effect: a body effect
    (damping, drag) the controller does not know of, added to the applied wrench.
    """
    import newton
    import warp as wp

    reference = multisine_reference(config, rng)
    builder = newton.ModelBuilder(gravity=tuple(GRAVITY_M_S2))
    body = builder.add_body(
        xform=wp.transform(wp.vec3(*placement.position), wp.quat(*placement.quaternion_xyzw)),
        mass=inertial.mass,
        com=wp.vec3(*inertial.com),
        inertia=wp.mat33(*np.asarray(inertial.inertia).reshape(-1)),
        lock_inertia=True,
    )
    model = builder.finalize(device=device)
    solver = newton.solvers.SolverSemiImplicit(model, angular_damping=0.0)
    state_a, state_b = model.state(), model.state()
    control = model.control()

    m = inertial.mass
    I_body = inertial.inertia_matrix()
    com_obj = np.asarray(inertial.com)
    T_grasp = grasp.matrix()
    R0 = placement.rotation_matrix()
    p_com0 = np.asarray(placement.position) + R0 @ com_obj

    control_dt = 1.0 / config.control_rate_hz
    sim_dt = control_dt / config.substeps
    steps = int(round(config.duration_s * config.control_rate_hz))
    t_wrench = np.arange(steps) * control_dt
    force = np.zeros((steps, 3))
    torque_grasp = np.zeros((steps, 3))
    body_q_substeps = np.zeros((steps * config.substeps + 1, 7))
    kp, kd = config.stiffness_1_s2, config.damping_1_s
    body_f = np.zeros((model.body_count, 6), dtype=np.float32)

    # The controller acts continuously (evaluated every Newton step, so the applied wrench has no
    # zero-order hold at the sensor's period); the F/T sensor point-samples it at the control rate.
    for i in range(steps * config.substeps):
        q = state_a.body_q.numpy()[body].astype(float)
        qd = state_a.body_qd.numpy()[body].astype(float)
        body_q_substeps[i] = q
        R = Rotation.from_quat(q[3:7]).as_matrix()
        p_com = q[:3] + R @ com_obj
        v_com, omega = qd[:3], qd[3:6]

        # The reference moves the COM and turns the body about it; the grasp follows rigidly.
        d, dd, ddd = reference(i * sim_dt)
        R_ref = Rotation.from_rotvec(d[3:]).as_matrix() @ R0
        rot_err = Rotation.from_matrix(R_ref @ R.T).as_rotvec()
        alpha = ddd[3:] + kp * rot_err + kd * (dd[3:] - omega)
        acc = ddd[:3] + kp * (p_com0 + d[:3] - p_com) + kd * (dd[:3] - v_com)
        f = m * (acc - GRAVITY_M_S2)
        I_world = R @ I_body @ R.T
        tau_com = I_world @ alpha + np.cross(omega, I_world @ omega)
        p_grasp = q[:3] + R @ T_grasp[:3, 3]
        t_grasp = tau_com - np.cross(p_grasp - p_com, f)
        if i % config.substeps == 0:
            force[i // config.substeps], torque_grasp[i // config.substeps] = f, t_grasp

        # the robot's wrench acts at the grasp; body_f takes it about the COM
        body_f[body] = np.concatenate([f, t_grasp + np.cross(p_grasp - p_com, f)])
        if effect is not None:
            body_f[body] += effect.body_wrench(v_com, omega)
        state_a.body_f.assign(body_f)
        solver.step(state_a, state_b, control, None, sim_dt)
        state_a, state_b = state_b, state_a
    body_q_substeps[-1] = state_a.body_q.numpy()[body]

    R_obj = Rotation.from_quat(body_q_substeps[:, 3:7])
    return HeldMotion(
        t_wrench_s=t_wrench,
        force_n=force,
        torque_nm=torque_grasp,
        t_s=np.arange(len(body_q_substeps)) * sim_dt,
        grasp_position_m=body_q_substeps[:, :3] + R_obj.apply(T_grasp[:3, 3]),
        grasp_quat_xyzw=(R_obj * Rotation.from_matrix(T_grasp[:3, :3])).as_quat(),
    )


def measure(motion: HeldMotion, noise: SensorNoise, rng: np.random.Generator,
            effect: ConcealedEffect | None = None):
    """Sensor readings of a motion: (t_pose_s, position, quat_xyzw, t_wrench_s, force, torque).

    Poses at the tracker's rate and phase with Gaussian position noise and a
    random small rotation; force and torque in the grasp frame's axes, as a
    wrist sensor reports them, with Gaussian noise and quantisation at the
    sensor's resolution. effect: a sensor effect; sensor_bias adds to the
    reading, time_delay stamps the wrench late (stamp t acted at t - seconds).
    """
    sim_dt = motion.t_s[1] - motion.t_s[0]
    t_pose = np.arange(noise.pose_time_offset_s, motion.t_s[-1], 1.0 / noise.pose_rate_hz)
    idx = np.rint(t_pose / sim_dt).astype(int)  # the tracker's phase falls on the simulation grid
    position = motion.grasp_position_m[idx] + rng.normal(0, noise.position_sigma_m, (len(idx), 3))
    jitter = Rotation.from_rotvec(rng.normal(0, noise.rotation_sigma_rad, (len(idx), 3)))
    quat = (Rotation.from_quat(motion.grasp_quat_xyzw[idx]) * jitter).as_quat()

    widx = np.rint(motion.t_wrench_s / sim_dt).astype(int)
    R_grasp = Rotation.from_quat(motion.grasp_quat_xyzw[widx])
    force = R_grasp.inv().apply(motion.force_n)
    torque = R_grasp.inv().apply(motion.torque_nm)
    t_wrench = motion.t_wrench_s
    if effect is not None and effect.name == "sensor_bias":
        force = force + np.asarray(effect.params["force"])
        torque = torque + np.asarray(effect.params["torque"])
    if effect is not None and effect.name == "time_delay":
        t_wrench = t_wrench + effect.params["seconds"]
        late = t_wrench >= 0  # a leading stream starts early: stamps before 0 are not recorded
        t_wrench, force, torque = t_wrench[late], force[late], torque[late]
    force = _quantise(force + rng.normal(0, noise.force_sigma_n, force.shape), noise.force_resolution_n)
    torque = _quantise(torque + rng.normal(0, noise.torque_sigma_nm, torque.shape), noise.torque_resolution_nm)
    return idx * sim_dt, position, quat, t_wrench, force, torque


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    return np.round(x / step) * step if step > 0 else x

