"""A robot opening and closing a drawer or a door, simulated in Newton (Featherstone), and what it records.

The part hangs on one joint (prismatic or revolute) to a fixed base. The robot
holds the handle and drives the joint along a smooth multi-sine reference
with a computed-torque feedback controller that knows the part's true
physics. The wrench it applies at the handle is the controller's joint effort
turned into a handle force, plus a slowly varying push against the joint's
constraint directions (which the joint absorbs, as a real hand's does). The
handle frame is the tracked frame. The joint friction (Coulomb, holding the
part under a smaller force, see `pipelines.sim.joint`) and any concealed passive
force (damping, spring, Stribeck breakaway) go in through `joint_f`
(`apply_joint_effort_and_passive_forces`): Featherstone does not apply
`joint_friction`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import warp as wp
from scipy.spatial.transform import Rotation

from assets import Inertial, Pose
from assets.conventions import GRAVITY_M_S2
from assets.recording import JointTrack, PoseTrack, Recording, WrenchTrack

from pipelines.sim.joint import (
    FRICTION_SMOOTHING,
    JOINT_EFFECT_SIZE,
    add_jointed_part,
    apply_joint_effort_and_passive_forces,
    joint_dynamics,
    joint_turns,
)

from .held import HeldMotion, SensorNoise, measure
from .recording import write_recording


@dataclass(frozen=True)
class JointedObject:
    """A moving part on one joint, truth in the world frame at q = 0.

    The object frame has its origin at the part's COM and world axes at q = 0
    (the frame `twin build` chooses for a scanned part).
    """

    name: str
    joint_type: str
    """"prismatic" or "revolute"."""
    size_m: tuple[float, float, float]
    """Box edges of the part along world x, y, z at q = 0 [m]."""
    mass_kg: float
    position_m: tuple[float, float, float]
    """The part's COM in world at q = 0 [m]."""
    axis: tuple[float, float, float]
    """Joint axis, world, unit; +q along it (right-hand rule for revolute)."""
    origin_m: tuple[float, float, float]
    """A point on the joint axis, world [m]."""
    handle_m: tuple[float, float, float]
    """Handle (tracked frame origin) in the object frame [m]."""
    friction: float
    """Coulomb joint friction [N] or [N m]."""
    travel: tuple[float, float]
    """Range the reference stays in [m] or [rad]."""

    def mesh(self):
        import trimesh

        return trimesh.creation.box(self.size_m)

    def inertial(self) -> Inertial:
        """Uniform density, object frame."""
        mesh = self.mesh()
        mesh.density = self.mass_kg / mesh.volume
        return Inertial(self.mass_kg, (0.0, 0.0, 0.0), mesh.moment_inertia)

    def placement(self) -> Pose:
        return Pose(self.position_m)

    def handle(self) -> Pose:
        """Tracked frame in the object frame: gripper z pointing into the handle face."""
        return Pose(self.handle_m, (1.0, 0.0, 0.0, 0.0))


def jointed_paper_objects() -> dict[str, JointedObject]:
    """Analogues of RigPI's drawer, cabinet door and oven door (notes/anchors.md).

    Each is a uniform box whose principal moments at the paper's mass match the
    paper's: drawer 1.11 kg, 33.2 x 1.6 x 11.5 cm (1.25e-3, 1.14e-2, 1.02e-2 kg m^2),
    sliding along its long edge; cabinet door 0.872 kg, a 33.2 cm square plate
    (8.0e-3, 8.0e-3, 1.6e-2 kg m^2) standing on a vertical hinge at one edge; oven
    door 64.2 g, 26.6 x 14.5 cm plate (1.12e-4, 3.62e-4, 4.74e-4 kg m^2) standing
    upright on a horizontal hinge along its bottom edge and opening downwards.
    """
    drawer_size = (0.3317, 0.0164, 0.1151)
    door_size = (0.3322, 0.004, 0.3322)
    oven_size = (0.2657, 0.002, 0.1447)
    return {
        "drawer": JointedObject(
            name="drawer", joint_type="prismatic", size_m=drawer_size, mass_kg=1.11,
            position_m=(0.6, 0.0, 0.3), axis=(-1.0, 0.0, 0.0), origin_m=(0.6, 0.0, 0.3),
            handle_m=(-drawer_size[0] / 2, 0.0, 0.0), friction=1.5, travel=(0.0, 0.25),
        ),
        "cabinet_door": JointedObject(
            name="cabinet_door", joint_type="revolute", size_m=door_size, mass_kg=0.872,
            position_m=(0.7, 0.2, 0.6), axis=(0.0, 0.0, 1.0), origin_m=(0.7 - door_size[0] / 2, 0.2 - 0.002, 0.6),
            handle_m=(door_size[0] / 2 - 0.03, -door_size[1] / 2, 0.0), friction=0.05, travel=(0.0, 1.3),
        ),
        "oven_door": JointedObject(
            name="oven_door", joint_type="revolute", size_m=oven_size, mass_kg=0.0642,
            position_m=(0.55, -0.1, 0.3), axis=(1.0, 0.0, 0.0), origin_m=(0.55, -0.1 - 0.001, 0.3 - oven_size[2] / 2),
            handle_m=(0.0, -oven_size[1] / 2, oven_size[2] / 2 - 0.015), friction=0.004, travel=(-1.3, 0.0),
        ),
    }


@dataclass(frozen=True)
class JointedMotionConfig:
    """How the robot works the joint."""

    duration_s: float = 8.0
    hold_s: float = 0.4
    """Still hold at q = 0 before the motion starts [s]."""
    control_rate_hz: float = 500.0
    """Controller and F/T sensor rate [Hz]; the wrench is held between updates, each reading stamped at the mean
    time of the steps it was applied at: half a step before its period's centre, since a semi-implicit step's
    kick lands a force read at the step's start where exact integration would (as MuJoCo's readings are)."""
    substeps: int = 4
    """Featherstone steps per control period."""
    band_hz: tuple[float, float] = (0.3, 1.2)
    """Band of the reference multi-sine [Hz]."""
    sines: int = 3
    stiffness_1_s2: float = 400.0
    """Controller proportional gain (per unit of the joint's mass or inertia) [1/s^2]."""
    damping_1_s: float = 40.0
    """Controller derivative gain [1/s]."""
    compensation_smoothing: float = 0.01
    """eps [m/s or rad/s] of the controller's friction feedforward f_c tanh(qd / eps)."""
    constraint_force_n: float = 2.0
    """Peak push against the joint's constraint directions (no joint effort) [N]."""
    constraint_torque_nm: float = 0.1
    """Peak torque about the constraint directions [N m]."""


@dataclass(frozen=True)
class JointedMotion:
    """What happened, noise-free: the handle motion and wrench (as `HeldMotion`) and q [m or rad] at `held.t_s`."""

    held: HeldMotion
    q: np.ndarray
    qd: np.ndarray


def joint_effect_vector(effect, friction: float) -> np.ndarray:
    """The [JOINT_EFFECT_SIZE] passive-force vector of a ConcealedEffect (None: zeros) on a joint whose
    Coulomb friction is `friction`."""
    out = np.zeros(JOINT_EFFECT_SIZE)
    out[4] = 1.0
    if effect is None:
        return out
    p = effect.params
    if effect.name == "viscous_damping":
        out[0] = p["b"]
    elif effect.name == "spring":
        out[1], out[2] = p["k"], p["k"] * p["q0"]
    elif effect.name == "stribeck_friction":
        if abs(p["f_c"] - friction) > 1e-12:
            raise ValueError(f"stribeck_friction f_c {p['f_c']} must be the joint's Coulomb friction {friction}")
        out[3], out[4] = p["f_s"] - p["f_c"], p["v_s"]
    else:
        raise ValueError(f"{effect.name}: not an effect of a joint (viscous_damping, spring, stribeck_friction)")
    return out


def joint_reference(obj: JointedObject, config: JointedMotionConfig, rng: np.random.Generator):
    """q_ref(t) and its two derivatives: faded in from q = 0 to the middle of the travel plus a multi-sine."""
    lo, hi = obj.travel
    mid = 0.5 * (lo + hi)
    freqs = rng.uniform(*config.band_hz, size=config.sines)
    phases = rng.uniform(0, 2 * np.pi, size=config.sines)
    amp = 0.45 * (hi - lo) / config.sines
    ramp_s = 1.0

    def reference(t: float):
        tau = t - config.hold_s
        if tau <= 0:
            return 0.0, 0.0, 0.0
        w = 2 * np.pi * freqs
        y = mid + amp * np.sum(np.sin(w * tau + phases) - np.sin(phases))
        dy = amp * np.sum(w * np.cos(w * tau + phases))
        ddy = -amp * np.sum(w * w * np.sin(w * tau + phases))
        x = min(tau / ramp_s, 1.0)
        g = x**3 * (10 - 15 * x + 6 * x * x)
        dg = (30 * x**2 - 60 * x**3 + 30 * x**4) / ramp_s if x < 1 else 0.0
        ddg = (60 * x - 180 * x**2 + 120 * x**3) / ramp_s**2 if x < 1 else 0.0
        return g * y, dg * y + g * dy, ddg * y + 2 * dg * dy + g * ddy

    return reference


def smooth_noise(rng: np.random.Generator, dims: int, duration_s: float):
    """Slowly varying signals in [-1, 1] per dimension (sums of 0.1-0.8 Hz sines)."""
    freqs = rng.uniform(0.1, 0.8, size=(dims, 3))
    phases = rng.uniform(0, 2 * np.pi, size=(dims, 3))
    return lambda t: np.sin(2 * np.pi * freqs * t + phases).sum(1) / 3


def simulate_jointed(obj: JointedObject, config: JointedMotionConfig, rng: np.random.Generator,
                     device: str = "cpu", effect=None) -> JointedMotion:
    """Simulate the part on its joint in Newton (Featherstone, no damping) under the controller.

    effect: a ConcealedEffect on the joint (viscous_damping, spring, stribeck_friction) the controller
    does not know of, added to the joint's passive forces.
    """
    import newton

    inertial = obj.inertial()
    placement = obj.placement()
    axis = np.asarray(obj.axis, dtype=float)
    origin = np.asarray(obj.origin_m, dtype=float)
    builder = newton.ModelBuilder(gravity=tuple(GRAVITY_M_S2))
    body = add_jointed_part(builder, obj.joint_type, axis, origin, placement, inertial)
    model = builder.finalize(device=device)
    solver = newton.solvers.SolverFeatherstone(model, angular_damping=0.0)
    state_a, state_b = model.state(), model.state()
    control = model.control()
    effort = wp.zeros((1, 1), dtype=float, device=device)
    friction = wp.array([obj.friction], dtype=float, device=device)
    passive = wp.array(joint_effect_vector(effect, obj.friction)[None].astype(np.float32), dtype=float,
                       device=device)
    dynamics = wp.array([joint_dynamics(obj.joint_type, axis, origin, placement, inertial)], dtype=wp.vec3,
                        device=device)

    reference = joint_reference(obj, config, rng)
    constraint = smooth_noise(rng, 6, config.duration_s)
    m = inertial.mass
    I_body = inertial.inertia_matrix()
    handle = obj.handle()
    revolute = obj.joint_type == "revolute"

    control_dt = 1.0 / config.control_rate_hz
    sim_dt = control_dt / config.substeps
    steps = int(round(config.duration_s * config.control_rate_hz))
    force = np.zeros((steps, 3))
    torque = np.zeros((steps, 3))
    n_sim = steps * config.substeps + 1
    body_q = np.zeros((n_sim, 7))
    q_log = np.zeros(n_sim)
    qd_log = np.zeros(n_sim)
    kp, kd, eps = config.stiffness_1_s2, config.damping_1_s, config.compensation_smoothing

    for k in range(steps):
        X = state_a.body_q.numpy()[body].astype(float)
        q = float(state_a.joint_q.numpy()[0])
        qd = float(state_a.joint_qd.numpy()[0])
        R = Rotation.from_quat(X[3:7]).as_matrix()
        p_com = X[:3] + R @ inertial.com
        p_handle = X[:3] + R @ np.asarray(handle.position)
        if revolute:
            r = p_com - origin
            m_eff = axis @ (R @ I_body @ R.T) @ axis + m * np.sum(np.cross(axis, r) ** 2)
            gravity_q = axis @ np.cross(r, m * GRAVITY_M_S2)
        else:
            m_eff = m
            gravity_q = m * GRAVITY_M_S2 @ axis
        q_ref, qd_ref, qdd_ref = reference(k * control_dt)
        tau = m_eff * (qdd_ref + kp * (q_ref - q) + kd * (qd_ref - qd)) - gravity_q + obj.friction * np.tanh(qd / eps)

        # The effort becomes a handle force along the handle's direction of motion; the push
        # against the constraint (and torques about axes the joint holds) adds no effort.
        c = constraint(k * control_dt)
        if revolute:
            lever = np.cross(axis, p_handle - origin)
            radial = np.cross(lever, axis)
            f = tau * lever / (lever @ lever)
            f += config.constraint_force_n * (c[0] * radial / np.linalg.norm(radial) + c[1] * axis)
            perp = np.linalg.svd(axis[None, :])[2][1:]
            t_h = config.constraint_torque_nm * (c[3] * perp[0] + c[4] * perp[1])
        else:
            perp = np.linalg.svd(axis[None, :])[2][1:]
            f = tau * axis + config.constraint_force_n * (c[0] * perp[0] + c[1] * perp[1])
            t_h = config.constraint_torque_nm * c[3:6]
        force[k], torque[k] = f, t_h
        for j in range(config.substeps):
            i = k * config.substeps + j
            body_q[i] = state_a.body_q.numpy()[body]
            # what reaches the joint: the projection a real joint transmits, about where the handle is now (the
            # held world force's moment turns with the door within the period, as the sensor's mean has it)
            p_now = body_q[i, :3] + Rotation.from_quat(body_q[i, 3:7]).apply(handle.position)
            effort.assign(np.array([[axis @ (np.cross(p_now - origin, f) + t_h) if revolute else axis @ f]]))
            q_log[i] = state_a.joint_q.numpy()[0]
            qd_log[i] = state_a.joint_qd.numpy()[0]
            wp.launch(apply_joint_effort_and_passive_forces, dim=1,
                      inputs=[effort, 0, 1, friction, passive, dynamics, joint_turns(obj.joint_type), sim_dt,
                              FRICTION_SMOOTHING, state_a.joint_q, state_a.joint_qd],
                      outputs=[control.joint_f], device=device)
            solver.step(state_a, state_b, control, None, sim_dt)
            state_a, state_b = state_b, state_a
    body_q[-1] = state_a.body_q.numpy()[body]
    q_log[-1] = state_a.joint_q.numpy()[0]
    qd_log[-1] = state_a.joint_qd.numpy()[0]

    R_obj = Rotation.from_quat(body_q[:, 3:7])
    T_h = handle.matrix()
    held = HeldMotion(
        t_wrench_s=(np.arange(steps) + 0.5) * control_dt - sim_dt / 2,
        force_n=force,
        torque_nm=torque,
        t_s=np.arange(n_sim) * sim_dt,
        grasp_position_m=body_q[:, :3] + R_obj.apply(T_h[:3, 3]),
        grasp_quat_xyzw=(R_obj * Rotation.from_matrix(T_h[:3, :3])).as_quat(),
    )
    return JointedMotion(held, q_log, qd_log)


def write_jointed_recording(path, obj: JointedObject, motion: JointedMotion, noise, rng: np.random.Generator,
                            encoder_resolution: float = 1e-5):
    """Write one trial as MCAP: handle pose and wrench as `measure` makes them, and the joint's
    encoder (sensor_msgs/JointState, quantised at `encoder_resolution` [m] or [rad]) at the tracker's stamps."""
    t_pose, position, quat, t_wrench, force, torque = measure(motion.held, noise, rng)
    idx = np.rint(t_pose / (motion.held.t_s[1] - motion.held.t_s[0])).astype(int)
    q = np.round(motion.q[idx] / encoder_resolution) * encoder_resolution
    return write_recording(
        path,
        pose=PoseTrack(t_pose, position, quat, "world", "gripper", "/tracker/pose"),
        wrench=WrenchTrack(t_wrench, force, torque, "/ft_sensor/wrench", "gripper"),
        joints=JointTrack(t_pose, (f"{obj.name}_joint",), q[:, None], motion.qd[idx][:, None]),
    )


def noisy_pose_recording(t_s, position, rotation: Rotation, rng: np.random.Generator, noise=None):
    """A Recording of a tracked frame's poses [m] with the tracker's noise, and a wrench of sensor noise only:
    for what reads the motion alone (kind detection)."""
    noise = noise or SensorNoise()
    position = position + rng.normal(0, noise.position_sigma_m, position.shape)
    rotation = rotation * Rotation.from_rotvec(rng.normal(0, noise.rotation_sigma_rad, (len(t_s), 3)))
    pose = PoseTrack(t_s, position, rotation.as_quat(), "world", "gripper", "/tracker/pose")
    t_w = np.arange(0, t_s[-1], 1.0 / 500.0)
    wrench = WrenchTrack(t_w, rng.normal(0, noise.force_sigma_n, (len(t_w), 3)),
                         rng.normal(0, noise.torque_sigma_nm, (len(t_w), 3)), "/ft_sensor/wrench", "world")
    return Recording(Path("synthetic.mcap"), pose, wrench, wrench, None, None, float(t_s[-1]))


def smooth_signals(rng: np.random.Generator, t_s: np.ndarray, amplitude: float, dims: int) -> np.ndarray:
    """[len(t_s), dims] smooth signals from 0 at t = 0: sums of three sines in 0.2-1.5 Hz."""
    f = rng.uniform(0.2, 1.5, (dims, 3))
    ph = rng.uniform(0, 2 * np.pi, (dims, 3))
    return amplitude * (np.sin(2 * np.pi * f[None] * t_s[:, None, None] + ph) - np.sin(ph)).sum(-1) / 3


def random_joint_recording(rng: np.random.Generator, joint_type: str, duration_s: float = 4.0):
    """A random drawer or door seen by the tracker: any axis direction, a revolute axis 5-40 cm from the
    handle, a random handle orientation and travel (up to 25 cm or 1.2 rad). Returns (Recording, axis,
    point on the axis or None)."""
    t = np.arange(0, duration_s, 0.005)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    p0 = rng.uniform(-0.5, 0.5, 3) + [0.5, 0, 0.5]
    R0 = Rotation.random(random_state=rng.integers(1 << 31))
    if joint_type == "revolute":
        lever = np.cross(axis, rng.normal(size=3))
        point = p0 - rng.uniform(0.05, 0.4) * lever / np.linalg.norm(lever)
        q = np.abs(smooth_signals(rng, t, 1.2, 1)[:, 0])
        R_q = Rotation.from_rotvec(np.outer(q, axis))
        return noisy_pose_recording(t, point + R_q.apply(p0 - point), R_q * R0, rng), axis, point
    q = np.abs(smooth_signals(rng, t, 0.25, 1)[:, 0])
    return noisy_pose_recording(t, p0 + np.outer(q, axis), Rotation.concatenate([R0] * len(t)), rng), axis, None
