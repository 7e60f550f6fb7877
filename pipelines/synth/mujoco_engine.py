"""A robot holding an object or working a drawer or door, simulated in MuJoCo, and what it records.

A second simulator for the synthetic benches, so that truth is not built with
the same Newton code the identification fits. What differs on purpose:

- the robot is a mechanism, not a prescribed wrench: a servo body of three
  slide and three hinge joints (intrinsic x-y-z), each driven by a MuJoCo
  position actuator (kp, kv) whose set-point, updated at the sensor rate and
  held in between (zero-order hold), is q_ref + (kv / kp) qd_ref + the
  gravity load at the start pose / kp, so it acts as kp (q_ref - q) +
  kv (qd_ref - qd) with a constant gravity feed-forward;
- the wrench is what MuJoCo's `force` and `torque` sensors report on a site
  of a welded child body: the interaction between that body and its parent,
  in the site's axes, about the site's origin. MuJoCo reports it as the force
  the parent exerts ON the child (a static hold of mass m reads +m g upward in
  world), which is the wrench applied TO the object when the object (held) or
  a massless gripper (jointed) is the child. Each reading is the mean over
  its sensor period as the integrator applies it, evaluated at the
  acceleration the step realized (`_run`);
- a jointed part hangs on a MuJoCo slide or hinge with `frictionloss` (a soft
  constraint with stiction), `damping` and `stiffness`/`springref`; the robot
  holds its handle through a soft `weld` equality, so the wrench it measures
  passes through MuJoCo's constraint solver;
- integration by MuJoCo (`implicitfast` by default, or `RK4`, `implicit`,
  `Euler`) at a step of at most 1 ms.

World frame: z up, gravity -z (`GRAVITY_M_S2`). The tracked frame is the grasp
(held) or the handle (jointed), as in the Newton engine, so the recordings
differ only in the simulator that made them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from assets import Inertial, Pose
from assets.conventions import GRAVITY_M_S2
from assets.recording import JointTrack, PoseTrack, WrenchTrack

from .held import ConcealedEffect, HeldMotion, HeldMotionConfig, SensorNoise, measure, \
    multisine_reference
from .recording import write_recording

if TYPE_CHECKING:
    from .jointed import JointedMotion, JointedMotionConfig, JointedObject

INTEGRATORS = ("implicitfast", "implicit", "RK4", "Euler")
WRENCH_FRAMES = ("gripper", "world")
SERVO_AXES = ("tx", "ty", "tz", "rx", "ry", "rz")
"""The servo body's joints in kinematic order: slides along world x, y, z, then hinges about the body's
x, y, z axes as turned by the hinges before them (intrinsic x-y-z Euler angles)."""


@dataclass(frozen=True)
class MujocoSettings:
    """How MuJoCo simulates and how stiff the robot's servos are."""

    integrator: str = "implicitfast"
    """One of INTEGRATORS."""
    substeps: int = 4
    """MuJoCo steps per sensor period; the time step is 1 / (sensor rate * substeps), at most 1 ms."""
    servo_bandwidth_hz: float = 12.0
    """Natural frequency of each servo joint on the inertia it carries [Hz]; critically damped."""
    wrist_mass_kg: float = 0.5
    """Mass of the robot's moving wrist or hand body (its principal moments: `wrist_inertia_kg_m2`)."""
    wrist_inertia_kg_m2: float = 1e-3
    weld_time_constant_s: float = 0.004
    """solref time constant of the hand-handle weld of a jointed part [s] (at least two time steps)."""

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"MujocoSettings.integrator: expected one of {INTEGRATORS}, got {self.integrator!r}")


def mjcf_vec(x) -> str:
    """Numbers as an MJCF attribute: space-separated, at full precision."""
    return " ".join(repr(float(v)) for v in np.ravel(x))


def mjcf_quat(quat_xyzw) -> str:
    """A quaternion (x, y, z, w) as MJCF's w x y z."""
    x, y, z, w = quat_xyzw
    return mjcf_vec([w, x, y, z])


def _full_inertia(I: np.ndarray) -> str:
    return mjcf_vec([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def _servo_body_xml(name: str, position, settings: MujocoSettings, children: str) -> str:
    """A body with world axes at `position` [m] on the six SERVO_AXES joints, with `children` inside."""
    joints = "".join(
        f'<joint name="{name}_{a}" type="{"slide" if a[0] == "t" else "hinge"}" axis="{mjcf_vec(np.eye(3)[i % 3])}"/>'
        for i, a in enumerate(SERVO_AXES)
    )
    inertia = settings.wrist_inertia_kg_m2
    return (f'<body name="{name}" pos="{mjcf_vec(position)}">{joints}'
            f'<inertial pos="0 0 0" mass="{settings.wrist_mass_kg!r}" diaginertia="{mjcf_vec([inertia] * 3)}"/>'
            f'{children}</body>')


def _servo_actuators_xml(name: str) -> str:
    # gains are set on the compiled model (`_tune_servo`): they depend on the inertia each joint carries
    return "".join(f'<position name="{name}_{a}" joint="{name}_{a}" kp="1"/>' for a in SERVO_AXES)


def _model_xml(settings: MujocoSettings, control_rate_hz: float, worldbody: str, extra: str = "") -> str:
    timestep = 1.0 / (control_rate_hz * settings.substeps)
    if timestep > 1e-3 + 1e-12:
        raise ValueError(f"MuJoCo time step {timestep:.3g} s exceeds 1 ms: raise MujocoSettings.substeps")
    return (f'<mujoco><compiler angle="radian" autolimits="true"/>'
            f'<option timestep="{timestep!r}" gravity="{mjcf_vec(GRAVITY_M_S2)}" integrator="{settings.integrator}"/>'
            f'<worldbody>{worldbody}</worldbody>{extra}</mujoco>')


@dataclass
class _Servo:
    """The six servo joints of one body: qpos/qvel addresses, actuator ids, gains and gravity feed-forward."""

    qpos: np.ndarray
    dof: np.ndarray
    actuators: np.ndarray
    kp: np.ndarray
    kv: np.ndarray
    feedforward: np.ndarray

    def command(self, q_ref: np.ndarray, qd_ref: np.ndarray) -> np.ndarray:
        """Position set-points that make kp (q_ref - q) + kv (qd_ref - qd) + the start pose's gravity load."""
        return q_ref + self.kv / self.kp * qd_ref + self.feedforward / self.kp


def _tune_servo(model, data, name: str, settings: MujocoSettings, carried_mass_kg: float = 0.0) -> _Servo:
    """Set the servo's actuator gains for `settings.servo_bandwidth_hz` on each joint's own inertia (plus
    `carried_mass_kg` on the slides: a part held through an equality is not in the joint's tree), and
    measure the gravity load at the start pose for the feed-forward."""
    import mujoco

    joints = [model.joint(f"{name}_{a}").id for a in SERVO_AXES]
    servo = _Servo(
        qpos=np.array([model.jnt_qposadr[j] for j in joints]),
        dof=np.array([model.jnt_dofadr[j] for j in joints]),
        actuators=np.array([model.actuator(f"{name}_{a}").id for a in SERVO_AXES]),
        kp=np.zeros(6), kv=np.zeros(6), feedforward=np.zeros(6),
    )
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    inertia = M[servo.dof, servo.dof] + np.array([carried_mass_kg] * 3 + [0.0] * 3)
    w = 2 * np.pi * settings.servo_bandwidth_hz
    servo.kp, servo.kv = inertia * w * w, 2.0 * inertia * w
    for k, a in enumerate(servo.actuators):
        model.actuator_gainprm[a, 0] = servo.kp[k]
        model.actuator_biasprm[a, :3] = (0.0, -servo.kp[k], -servo.kv[k])
    servo.feedforward = data.qfrc_bias[servo.dof].copy()  # at rest: gravity only
    return servo


def servo_coordinates(displacement: np.ndarray, rotation: Rotation) -> np.ndarray:
    """SERVO_AXES coordinates [m, rad] of a servo body moved by `displacement` [m] and turned by `rotation`
    (world axes) from its start, where its axes are the world's."""
    return np.concatenate([displacement, rotation.as_euler("XYZ")])


def _servo_reference(target, h: float = 1e-4):
    """(q_ref, qd_ref) of a function t -> servo coordinates; the velocity by central difference over h [s]."""
    def reference(t: float):
        return target(t), (target(t + h) - target(t - h)) / (2 * h)

    return reference


def _site_pose(data, site: int) -> tuple[np.ndarray, np.ndarray]:
    """(position [m], quaternion xyzw) of a site in world."""
    return data.site_xpos[site].copy(), Rotation.from_matrix(data.site_xmat[site].reshape(3, 3)).as_quat()


def _sensor_wrench(model, data, force_sensor: int, torque_sensor: int, site: int) -> tuple[np.ndarray, np.ndarray]:
    """The wrench the sensor's parent body applies to its child: force [N] and torque about the site's
    origin [N m], both turned from the site's axes into world axes."""
    R = data.site_xmat[site].reshape(3, 3)
    f = data.sensordata[model.sensor_adr[force_sensor]:model.sensor_adr[force_sensor] + 3]
    tau = data.sensordata[model.sensor_adr[torque_sensor]:model.sensor_adr[torque_sensor] + 3]
    return R @ f, R @ tau


def _run(model, data, servo: _Servo, reference, control_rate_hz: float, steps: int, substeps: int, wrench,
         record, passive=None) -> tuple[np.ndarray, np.ndarray]:
    """Step the model for `steps` sensor periods of `substeps` MuJoCo steps; the sensor's readings [steps, 6]
    are force [N] and torque [N m], as `wrench()` gives them.

    The servo set-points follow `reference(t)` -> (q_ref, qd_ref), updated at the start of each period and
    held. The reading of a period is the mean of the wrench over the period's steps, as each step applies
    it: F/T sensors oversample and average, and the servo's hold makes the wrench a sawtooth at the
    sensor rate (the hold's set-point falls behind a moving hand by v / rate), which a point sample taken
    at a fixed phase of it would turn into a velocity-proportional bias. Returns (stamps [s], readings):
    each reading is stamped at the mean time of what it averages, for an Euler-family step half a step
    before the period's centre (below). `record(i)` stores the state of step i (0 .. steps * substeps);
    `passive()`, when given, sets state-dependent forces (MuJoCo model or data fields) from the current
    forward pass.
    """
    import mujoco

    rk4 = model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    h = model.opt.timestep

    def forward():
        # mj_step leaves the kinematics of the state it started from (RK4: of a later stage), so every
        # sample comes from a forward pass at the instant itself
        mujoco.mj_forward(model, data)
        if passive is not None:
            passive()
            mujoco.mj_forward(model, data)

    def step_realized() -> np.ndarray:
        """Step, and return the wrench of the step's start at the acceleration the step realized.

        MuJoCo's force and torque sensors take the forward pass's explicit acceleration, but the Euler,
        implicit and implicitfast steps advance the velocity by h (M + h D)^-1 f, with D the damping they
        treat implicitly (the servo's kv): against the motion, the raw sensor overstates the inertia by
        h kv / M (7 % in inertia, 1 % in mass for a 12 Hz servo at h = 0.5 ms). The sensors are evaluated
        again at the step's start with the realized acceleration (qvel_next - qvel) / h."""
        v0 = data.qvel.copy()
        mujoco.mj_step(model, data)
        v1 = data.qvel.copy()
        data.qacc[:] = (v1 - v0) / h
        data.qvel[:] = v0
        mujoco.mj_rnePostConstraint(model, data)
        mujoco.mj_sensorAcc(model, data)
        realized = np.concatenate(wrench())
        data.qvel[:] = v1
        return realized

    readings = np.zeros((steps, 6))
    for k in range(steps):
        q_ref, qd_ref = reference(k / control_rate_hz)
        data.ctrl[servo.actuators] = servo.command(q_ref, qd_ref)
        for j in range(substeps):
            forward()
            record(k * substeps + j)
            if rk4:  # RK4 integrates the wrench's slope within a step: the trapezoid over the step ends
                readings[k] += (0.5 if j == 0 else 1.0) / substeps * np.concatenate(wrench())
                mujoco.mj_step(model, data)
            else:  # an Euler-family step applies the wrench at its start: a left sum. Its kick lands a force
                # read at the step's start where exact integration would (x_{n+1} - 2 x_n + x_{n-1} = h^2 a_n),
                # so the sum stands for the continuous wrench half a step before the period's centre
                readings[k] += step_realized() / substeps
        if rk4:  # the period's end, still under its set-point
            forward()
            readings[k] += 0.5 / substeps * np.concatenate(wrench())
    forward()
    record(steps * substeps)
    stamps = (np.arange(steps) + 0.5) / control_rate_hz - (0.0 if rk4 else h / 2)
    return stamps, readings


def simulate_held_mujoco(
    truth: Inertial,
    placement: Pose,
    grasp: Pose,
    config: HeldMotionConfig,
    rng: np.random.Generator,
    settings: MujocoSettings = MujocoSettings(),
    effect: ConcealedEffect | None = None,
) -> HeldMotion:
    """Simulate a robot wrist holding the object in MuJoCo; returns what happened, noise-free.

    truth: the object's inertial parameters in the object frame; placement: object frame in world at t = 0;
    grasp: grasp (tracked, sensor) frame in the object frame. The wrist servo's joints pivot about the grasp
    origin and track `multisine_reference` (grasp displacement and rotation from the start) sampled at
    `config.control_rate_hz`. effect: a body effect (viscous_damping, quadratic_drag) acting on the object
    at its COM through `xfrc_applied`, not through the sensor. Returns a HeldMotion: the grasp frame in
    world at every MuJoCo step, and at every sensor sample the wrench applied TO the object at the grasp
    origin in world axes.
    """
    import mujoco

    X_grasp = placement @ grasp
    p_grasp0 = np.asarray(X_grasp.position)
    # the object body hangs from the wrist, whose frame has world axes at the grasp origin
    obj_pos = np.asarray(placement.position) - p_grasp0
    I = truth.inertia_matrix()
    obj = (f'<body name="object" pos="{mjcf_vec(obj_pos)}" quat="{mjcf_quat(placement.quaternion_xyzw)}">'
           f'<inertial pos="{mjcf_vec(truth.com)}" mass="{truth.mass!r}" fullinertia="{_full_inertia(I)}"/>'
           f'<site name="grasp" pos="{mjcf_vec(grasp.position)}" quat="{mjcf_quat(grasp.quaternion_xyzw)}"/></body>')
    xml = _model_xml(settings, config.control_rate_hz, _servo_body_xml("wrist", p_grasp0, settings, obj),
                     f'<actuator>{_servo_actuators_xml("wrist")}</actuator>'
                     '<sensor><force name="ft_force" site="grasp"/><torque name="ft_torque" site="grasp"/></sensor>')
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    servo = _tune_servo(model, data, "wrist", settings)
    body = model.body("object").id
    site = model.site("grasp").id
    f_sensor, t_sensor = model.sensor("ft_force").id, model.sensor("ft_torque").id

    offsets = multisine_reference(config, rng)

    def target(t: float) -> np.ndarray:
        d = offsets(t)[0]
        return servo_coordinates(d[:3], Rotation.from_rotvec(d[3:]))

    reference = _servo_reference(target)
    steps = int(round(config.duration_s * config.control_rate_hz))
    n_sim = steps * settings.substeps + 1
    position = np.zeros((n_sim, 3))
    quat = np.zeros((n_sim, 4))
    velocity = np.zeros(6)

    def record(i: int):
        position[i], quat[i] = _site_pose(data, site)

    def drag():
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
        data.xfrc_applied[body] = effect.body_wrench(velocity[3:], velocity[:3])

    t_wrench, wrench = _run(model, data, servo, reference, config.control_rate_hz, steps, settings.substeps,
                            lambda: _sensor_wrench(model, data, f_sensor, t_sensor, site), record,
                            drag if effect is not None else None)
    return HeldMotion(t_wrench_s=t_wrench, force_n=wrench[:, :3],
                      torque_nm=wrench[:, 3:], t_s=np.arange(n_sim) * model.opt.timestep,
                      grasp_position_m=position, grasp_quat_xyzw=quat)


@dataclass(frozen=True)
class JointFrictionProfile:
    """A joint friction the effect vocabulary has no name for, applied through MuJoCo's `frictionloss`
    each step (its friction constraint then holds the part up to the force at rest, as real stiction does).

    binding_friction {"q_range": [a, b], "extra": f}: the Coulomb friction rises by f [N or N m] while q is
    in [a, b] (a stiff stretch of a drawer's runners); directional_friction {"sign": +1 or -1, "extra": f}:
    it rises by f while the part moves along `sign` (q' sign > 0), a runner that catches one way.
    """

    name: str
    params: dict

    NAMES = ("binding_friction", "directional_friction")

    def __post_init__(self):
        if self.name not in self.NAMES:
            raise ValueError(f"JointFrictionProfile.name: expected one of {self.NAMES}, got {self.name!r}")

    def frictionloss(self, friction: float, q: float, qd: float, speed_scale: float) -> float:
        """The joint's Coulomb friction [N or N m] at q, qd; `speed_scale` [m/s or rad/s] smooths the
        direction change (a few thousandths of the travel per second)."""
        p = self.params
        if self.name == "binding_friction":
            a, b = p["q_range"]
            return friction + p["extra"] * float(a <= q <= b)
        return friction + p["extra"] * 0.5 * (1.0 + np.tanh(p["sign"] * qd / speed_scale))


def _joint_passive_xml(obj: JointedObject, effect: ConcealedEffect | None) -> str:
    """The part joint's MuJoCo attributes: Coulomb friction as `frictionloss`, and the effect's damping
    or spring (q = 0 at the scan, so `springref` is q0). Stribeck breakaway is set per step
    (`_stribeck_frictionloss`)."""
    attrs = f'frictionloss="{obj.friction!r}"'
    if isinstance(effect, JointFrictionProfile):
        return attrs
    if effect is None or effect.name == "stribeck_friction":
        if effect is not None and abs(effect.params["f_c"] - obj.friction) > 1e-12:
            raise ValueError(f"stribeck_friction f_c {effect.params['f_c']} must be the joint's Coulomb friction "
                             f"{obj.friction}")
        return attrs
    if effect.name == "viscous_damping":
        return attrs + f' damping="{float(effect.params["b"])!r}"'
    if effect.name == "spring":
        return attrs + f' stiffness="{float(effect.params["k"])!r}" springref="{float(effect.params["q0"])!r}"'
    raise ValueError(f"{effect.name}: not an effect of a joint (viscous_damping, spring, stribeck_friction)")


def _stribeck_frictionloss(effect: ConcealedEffect, qd: float) -> float:
    """f_c + (f_s - f_c) exp(-(qd / v_s)^2) [N or N m]: MuJoCo's friction constraint then holds the part
    up to the breakaway force at rest, as real stiction does, instead of a smoothed force."""
    p = effect.params
    return p["f_c"] + (p["f_s"] - p["f_c"]) * np.exp(-((qd / p["v_s"]) ** 2))


def simulate_jointed_mujoco(
    obj: JointedObject,
    config: JointedMotionConfig,
    rng: np.random.Generator,
    settings: MujocoSettings = MujocoSettings(),
    effect: ConcealedEffect | JointFrictionProfile | None = None,
) -> JointedMotion:
    """Simulate a robot hand working a drawer or door in MuJoCo; returns what happened, noise-free.

    The part hangs on its MuJoCo joint (q = 0 at `obj.placement()`) with `frictionloss` = `obj.friction`;
    effect (viscous_damping, spring, stribeck_friction) adds the joint's passive force in MuJoCo terms;
    a JointFrictionProfile (outside the vocabulary) sets the friction from q and qd each step.
    The hand, a servo body at the handle, carries a massless gripper welded (soft `weld` equality) to the
    handle; the F/T sensor sits on the gripper. The hand tracks the handle's pose along jointed.py's
    q reference, displaced off the joint's free direction by slowly varying offsets (the servo's spring
    then pushes up to `config.constraint_force_n` and turns up to `config.constraint_torque_nm` against
    the joint, which absorbs it). Returns the handle frame in world and q [m or rad], qd at every MuJoCo
    step, and at every sensor sample the wrench applied TO the part at the handle origin, world axes.
    """
    import mujoco

    # jointed.py imports warp when loaded; the held engine and the recording writer need none of it
    from .jointed import JointedMotion, joint_reference, smooth_noise

    inertial = obj.inertial()
    placement = obj.placement()
    handle = obj.handle()
    axis = np.asarray(obj.axis, dtype=float)
    origin = np.asarray(obj.origin_m, dtype=float)
    revolute = obj.joint_type == "revolute"
    X_handle0 = placement @ handle
    p_handle0 = np.asarray(X_handle0.position)
    I = inertial.inertia_matrix()

    part = (f'<body name="part" pos="{mjcf_vec(placement.position)}" quat="{mjcf_quat(placement.quaternion_xyzw)}">'
            f'<joint name="part_joint" type="{"hinge" if revolute else "slide"}" '
            f'pos="{mjcf_vec(placement.inverse().matrix()[:3] @ np.append(origin, 1.0))}" '
            f'axis="{mjcf_vec(placement.rotation_matrix().T @ axis)}" {_joint_passive_xml(obj, effect)}/>'
            f'<inertial pos="{mjcf_vec(inertial.com)}" mass="{inertial.mass!r}" fullinertia="{_full_inertia(I)}"/>'
            f'<site name="handle" pos="{mjcf_vec(handle.position)}" quat="{mjcf_quat(handle.quaternion_xyzw)}"/></body>')
    gripper = (f'<body name="gripper" quat="{mjcf_quat(X_handle0.quaternion_xyzw)}">'
               f'<site name="ft" pos="0 0 0"/></body>')
    weld = (f'<equality><weld body1="gripper" body2="part" anchor="{mjcf_vec(handle.position)}" '
            f'solref="{settings.weld_time_constant_s!r} 1"/></equality>')
    xml = _model_xml(settings, config.control_rate_hz, part + _servo_body_xml("hand", p_handle0, settings, gripper),
                     weld + f'<actuator>{_servo_actuators_xml("hand")}</actuator>'
                     '<sensor><force name="ft_force" site="ft"/><torque name="ft_torque" site="ft"/></sensor>')
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    servo = _tune_servo(model, data, "hand", settings, carried_mass_kg=inertial.mass)
    joint = model.joint("part_joint")
    q_adr, dof = int(joint.qposadr[0]), int(joint.dofadr[0])
    handle_site, ft_site = model.site("handle").id, model.site("ft").id
    f_sensor, t_sensor = model.sensor("ft_force").id, model.sensor("ft_torque").id

    q_reference = joint_reference(obj, config, rng)
    push = smooth_noise(rng, 6, config.duration_s)
    perp = np.linalg.svd(axis[None, :])[2][1:]
    k_lin, k_rot = servo.kp[0], servo.kp[3]

    def target(t: float) -> np.ndarray:
        """Servo coordinates that carry the handle to q_ref(t), pushed off the joint's free direction."""
        q = q_reference(t)[0]
        c = push(t)
        if revolute:
            turn = Rotation.from_rotvec(q * axis)
            p = origin + turn.apply(p_handle0 - origin)
            radial = p - origin - axis * (axis @ (p - origin))
            off = config.constraint_force_n * (c[0] * radial / np.linalg.norm(radial) + c[1] * axis)
            twist = config.constraint_torque_nm * (c[3] * perp[0] + c[4] * perp[1])
            return servo_coordinates(p - p_handle0 + off / k_lin, Rotation.from_rotvec(twist / k_rot) * turn)
        off = config.constraint_force_n * (c[0] * perp[0] + c[1] * perp[1])
        twist = config.constraint_torque_nm * c[3:6]
        return servo_coordinates(q * axis + off / k_lin, Rotation.from_rotvec(twist / k_rot))

    reference = _servo_reference(target)
    steps = int(round(config.duration_s * config.control_rate_hz))
    n_sim = steps * settings.substeps + 1
    position = np.zeros((n_sim, 3))
    quat = np.zeros((n_sim, 4))
    q_log = np.zeros(n_sim)
    qd_log = np.zeros(n_sim)

    def record(i: int):
        position[i], quat[i] = _site_pose(data, handle_site)
        q_log[i], qd_log[i] = data.qpos[q_adr], data.qvel[dof]

    def at_handle() -> tuple[np.ndarray, np.ndarray]:
        f, tau = _sensor_wrench(model, data, f_sensor, t_sensor, ft_site)
        # the soft weld lets the gripper sit a fraction of a millimetre off the handle: the torque is
        # moved to the handle, the tracked origin the wrench is reported about
        return f, tau + np.cross(data.site_xpos[ft_site] - data.site_xpos[handle_site], f)

    def stribeck():
        model.dof_frictionloss[dof] = _stribeck_frictionloss(effect, data.qvel[dof])

    speed_scale = 2e-3 * (obj.travel[1] - obj.travel[0])

    def profile():
        model.dof_frictionloss[dof] = effect.frictionloss(obj.friction, data.qpos[q_adr], data.qvel[dof],
                                                          speed_scale)

    passive = (profile if isinstance(effect, JointFrictionProfile) else
               stribeck if effect is not None and effect.name == "stribeck_friction" else None)
    t_wrench, wrench = _run(model, data, servo, reference, config.control_rate_hz, steps, settings.substeps,
                            at_handle, record, passive)
    held = HeldMotion(t_wrench_s=t_wrench, force_n=wrench[:, :3],
                      torque_nm=wrench[:, 3:], t_s=np.arange(n_sim) * model.opt.timestep,
                      grasp_position_m=position, grasp_quat_xyzw=quat)
    return JointedMotion(held, q_log, qd_log)


def write_motion_recording(
    path: Path,
    motion: HeldMotion,
    noise: SensorNoise,
    rng: np.random.Generator,
    wrench_frame: str = "gripper",
    effect: ConcealedEffect | None = None,
    joint: tuple[str, JointedMotion] | None = None,
    encoder_resolution: float = 1e-5,
) -> Path:
    """Write one trial as MCAP with `measure`'s sensor noise; returns the path.

    The tracked frame (grasp or handle) goes out as "world" -> "gripper". wrench_frame "gripper": force
    and torque in the tracked frame's axes about its origin, as a wrist sensor reports them (the reader
    turns them to world through the tracked pose); "world": the same readings turned to world axes
    through the true sensor orientation at the instant each sample acted, as a robot driver that knows
    its kinematics publishes them (the reader takes them about the tracked origin). A sensor_bias effect
    is constant in the message's frame (DESIGN.md), so for "world" it is added in world axes.
    joint: (joint name, the JointedMotion) adds its encoder (quantised at `encoder_resolution`) as
    sensor_msgs/JointState at the tracker's stamps.
    """
    if wrench_frame not in WRENCH_FRAMES:
        raise ValueError(f"wrench_frame: expected one of {WRENCH_FRAMES}, got {wrench_frame!r}")
    bias = effect is not None and effect.name == "sensor_bias"
    sensor_effect = None if wrench_frame == "world" and bias else effect
    t_pose, position, quat, t_wrench, force, torque = measure(motion, noise, rng, effect=sensor_effect)
    if wrench_frame == "world":
        delay = effect.params["seconds"] if effect is not None and effect.name == "time_delay" else 0.0
        sim_dt = motion.t_s[1] - motion.t_s[0]
        acted = np.rint((t_wrench - delay) / sim_dt).astype(int)
        R_sensor = Rotation.from_quat(motion.grasp_quat_xyzw[acted])
        force, torque = R_sensor.apply(force), R_sensor.apply(torque)
        if bias:
            force = force + np.asarray(effect.params["force"])
            torque = torque + np.asarray(effect.params["torque"])
    joints = None
    if joint is not None:
        name, jointed = joint
        idx = np.rint(t_pose / (motion.t_s[1] - motion.t_s[0])).astype(int)
        q = np.round(jointed.q[idx] / encoder_resolution) * encoder_resolution
        joints = JointTrack(t_pose, (name,), q[:, None], jointed.qd[idx][:, None])
    return write_recording(
        path,
        pose=PoseTrack(t_pose, position, quat, "world", "gripper", "/tracker/pose"),
        wrench=WrenchTrack(t_wrench, force, torque, "/ft_sensor/wrench", wrench_frame),
        joints=joints,
    )
