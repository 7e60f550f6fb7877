"""A robot pushing a block across a table, simulated in MuJoCo, and what its sensors record.

The MuJoCo counterpart of pipelines/synth/push.py: the same block, push
(`PushConfig`) and recording, made by MuJoCo's own models instead of twin's
Newton code, so that a fit is not judged on data made by the model it fits.
What differs on purpose:

- contact is MuJoCo's: the block is a `box` geom (or the same box as a `mesh`
  geom) on a `plane`, soft constraints with `solref`/`solimp`, an elliptic
  friction cone (`cone="elliptic"`, `impratio`) and `condim` 3 (sliding
  friction), 4 (plus torsional) or 6 (plus rolling) (`PushContact`). MuJoCo
  puts a flat box's support contacts at its bottom corners, where the Newton
  engine spreads the weight over a grid of points;
- the pusher is a mechanism: a carriage on two horizontal slide joints, each
  driven by a MuJoCo position actuator (kp, kv critically damped at
  `MujocoSettings.servo_bandwidth_hz` on the carriage's mass) whose set-point,
  updated at the sensor rate and held in between (zero-order hold), is
  x_ref + (kv / kp) v_ref: it acts as kp (x_ref - x) + kv (v_ref - v), and the
  pusher lags its reference by what the push costs it. Its tip, a vertical
  capsule of radius `tip_radius_m`, touches the block without friction (the
  force acts along the contact normal, through the tip's axis);
- the force is what MuJoCo's `force` sensor reports on a site of the tip, a
  massless body welded to the carriage: the force the carriage exerts on the
  tip, which is the force the tip applies TO the block. Each reading is the
  mean of the per-step readings over one sensor period centred on its stamp
  (an F/T sensor's anti-alias filter, as the Newton engine's);
- integration by MuJoCo (`MujocoSettings.integrator`, `implicitfast` by
  default, or `RK4`) at 1 / (rate * substeps) s, at most 1 ms.

The recording is what `write_push` writes: the block's pose from a tracker
(/tracker/block), the pusher force (/pusher/wrench) and the pusher tip's
centre as the contact point (/pusher/tip, the measured tip, not its
reference). The force goes out in world axes, or in the sensor's own axes
(`wrench_frame="sensor"`: a frame "pusher_ft" turned `sensor_yaw_rad` about
z and flipped to look down, as a wrist sensor on a downward tool is; the
pusher only translates, so /tf_static carries its rotation and the reader
turns the force to world through it). The concealed effects of `PushConfig`
(viscous drag, turning drag, a time delay, a sensor bias) act as there: the
drags through `xfrc_applied`, the delay and bias on the written messages.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from assets.conventions import GRAVITY_MAGNITUDE_M_S2 as GRAVITY_M_S2

from .mujoco_engine import INTEGRATORS, MujocoSettings, mjcf_vec, mjcf_quat
from .push import PushConfig, PushTruth

__all__ = ["PUSH_WRENCH_FRAMES", "PushContact", "make_pushed_sample", "push_settings", "pusher_reference",
           "pushed_block_xml", "simulate_pushed_mujoco", "write_pushed_mujoco"]

PUSH_WRENCH_FRAMES = ("world", "sensor")
"""Frames the pusher force is written in: world axes, or the sensor's ("pusher_ft", fixed to the pusher)."""

SENSOR_FRAME = "pusher_ft"


def push_settings(**overrides) -> MujocoSettings:
    """MujocoSettings for a push: 10 steps per 100 Hz sensor period (a 1 ms step), the carriage 0.5 kg."""
    return MujocoSettings(**({"substeps": 10, "wrist_mass_kg": 0.5} | overrides))


@dataclass(frozen=True)
class PushContact:
    """MuJoCo's contact between the block and the table, and between the pusher and the block."""

    shape: Literal["box", "mesh", "grid"] = "box"
    """The block's collision geom: a primitive box, or the same box as a convex mesh (MuJoCo's mesh-plane
    collision then finds the support contacts: both put them at the bottom face's corners), or "grid": the
    box touches only the pusher and `grid` x `grid` small spheres under its bottom face carry it, a
    uniformly loaded face as the Newton engine models it."""
    grid: int = 8
    """Support points per side of the bottom face ("grid")."""
    condim: Literal[3, 4, 6] = 3
    """3: normal and isotropic sliding friction; 4: plus torsional friction; 6: plus rolling friction."""
    torsional_friction: float = 0.005
    """Torsional coefficient [m] (condim 4 and 6); MuJoCo's default."""
    rolling_friction: float = 0.0001
    """Rolling coefficient [m] (condim 6); MuJoCo's default."""
    solref: tuple[float, float] = (0.02, 1.0)
    """Block-table time constant [s] and damping ratio (MuJoCo's default; at least two steps)."""
    solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    impratio: float = 10.0
    """Frictional to normal impedance ratio (MuJoCo's advice for elliptic cones: creep under tangential
    load falls with it)."""
    cone: Literal["elliptic", "pyramidal"] = "elliptic"
    tip_solref: tuple[float, float] = (0.004, 1.0)
    """Pusher-block time constant [s] and damping ratio: a stiff tip (at least two steps)."""
    tip_half_length_m: float = 0.02
    """Half length of the tip capsule's straight part [m]; it does not collide with the table."""

    def __post_init__(self):
        if self.shape not in ("box", "mesh", "grid"):
            raise ValueError(f"PushContact.shape: expected 'box', 'mesh' or 'grid', got {self.shape!r}")
        if self.condim not in (3, 4, 6):
            raise ValueError(f"PushContact.condim: expected 3, 4 or 6, got {self.condim!r}")
        if self.cone not in ("elliptic", "pyramidal"):
            raise ValueError(f"PushContact.cone: expected 'elliptic' or 'pyramidal', got {self.cone!r}")


def _sensor_rotation(sensor_yaw_rad: float) -> Rotation:
    """The F/T sensor's axes in world: turned about z, then flipped about x (its z looks down the tool)."""
    return Rotation.from_euler("z", sensor_yaw_rad) * Rotation.from_euler("x", np.pi)


def pusher_reference(config: PushConfig, t: np.ndarray) -> np.ndarray:
    """The pusher tip centre's reference (x, y) [m] at times t [s]: still and clear of the block for
    `idle_s`, then strokes along +y on the line x = `offset_m` (ramp up, hold, sharp stop, pause; the
    reference of pipelines/synth/push.py)."""
    hy = config.half_extents_m[1]
    y0 = -(hy + config.tip_radius_m + 0.01)
    fine = np.arange(0.0, config.push_s + 2e-4, 1e-4)
    tau = fine[:-1] + 5e-5
    phase = np.mod(tau, config.stroke_s) / config.stroke_s
    speed = config.speed_m_s * np.minimum(np.clip(phase / 0.2, 0.0, 1.0), np.clip((0.6 - phase) / 0.04, 0.0, 1.0))
    travelled = np.concatenate([[0.0], np.cumsum(speed) * 1e-4])
    distance = np.interp(np.asarray(t, dtype=float) - config.idle_s, fine, travelled)
    return np.stack([np.full_like(distance, config.offset_m), y0 + distance], axis=-1)


def _box_mesh_xml(half_extents_m) -> str:
    hx, hy, hz = half_extents_m
    corners = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return f'<mesh name="block" vertex="{mjcf_vec(corners)}"/>'


def pushed_block_xml(config: PushConfig, settings: MujocoSettings, contact: PushContact, *,
                     pusher: bool = True, sensor_yaw_rad: float = 0.0) -> str:
    """The MJCF of the push: table plane, block on its free joint ("block"), and (with `pusher`) the servoed
    carriage with its tip and force sensor. Without the pusher it is the truth model a replay drives by the
    recorded force."""
    hx, hy, hz = config.half_extents_m
    m = config.mass_kg
    inertia = m / 3.0 * np.array([hy * hy + hz * hz, hx * hx + hz * hz, hx * hx + hy * hy])
    timestep = 1.0 / (config.rate_hz * settings.substeps)
    if timestep > 1e-3 + 1e-12:
        raise ValueError(f"MuJoCo time step {timestep:.3g} s exceeds 1 ms: raise MujocoSettings.substeps")
    for name, tc in (("solref", contact.solref[0]), ("tip_solref", contact.tip_solref[0])):
        if tc < 2 * timestep:
            raise ValueError(f"PushContact.{name} time constant {tc:g} s is under two steps ({timestep:g} s)")
    friction = mjcf_vec((config.mu, contact.torsional_friction, contact.rolling_friction))
    surface = (f'friction="{friction}" condim="{contact.condim}" solref="{mjcf_vec(contact.solref)}" '
               f'solimp="{mjcf_vec(contact.solimp)}"')
    # contype/conaffinity bits: table 1, block 1|2, tip 2: the tip touches the block, never the table
    assets = ""
    if contact.shape == "box":
        geom = f'<geom name="block" type="box" size="{mjcf_vec((hx, hy, hz))}" density="0" {surface} contype="3" ' \
               f'conaffinity="3"/>'
    elif contact.shape == "grid":
        radius = 5e-4
        cells = (np.arange(contact.grid) + 0.5) / contact.grid * 2.0 - 1.0
        geom = f'<geom name="block" type="box" size="{mjcf_vec((hx, hy, hz))}" density="0" contype="2" conaffinity="2"/>'
        geom += "".join(f'<geom type="sphere" size="{radius!r}" pos="{mjcf_vec((gx * hx, gy * hy, -hz + radius))}" '
                        f'density="0" {surface} contype="1" conaffinity="1"/>' for gx in cells for gy in cells)
    else:
        geom = f'<geom name="block" type="mesh" mesh="block" density="0" {surface} contype="3" conaffinity="3"/>'
        assets = f"<asset>{_box_mesh_xml(config.half_extents_m)}</asset>"
    q0 = Rotation.from_euler("z", config.yaw0_rad).as_quat()
    block = (f'<body name="block" pos="{mjcf_vec((0.0, 0.0, hz))}" quat="{mjcf_quat(q0)}"><freejoint name="block_free"/>'
             f'<inertial pos="0 0 0" mass="{m!r}" diaginertia="{mjcf_vec(inertia)}"/>{geom}</body>')
    world = f'<geom name="table" type="plane" size="0 0 0.05" {surface} contype="1" conaffinity="1"/>' + block
    extra = ""
    if pusher:
        start = pusher_reference(config, np.zeros(1))[0]
        w = 2 * np.pi * settings.servo_bandwidth_hz
        carriage = settings.wrist_mass_kg
        kp, kv = carriage * w * w, 2.0 * carriage * w
        r = config.tip_radius_m
        # priority 1: the pair takes the tip's condim 1 (no friction) and its solref
        world += (f'<body name="carriage" pos="{mjcf_vec((*start, hz))}">'
                  '<joint name="pusher_x" type="slide" axis="1 0 0"/><joint name="pusher_y" type="slide" axis="0 1 0"/>'
                  f'<inertial pos="0 0 0" mass="{carriage!r}" diaginertia="{mjcf_vec([settings.wrist_inertia_kg_m2] * 3)}"/>'
                  f'<body name="tip" quat="{mjcf_quat(_sensor_rotation(sensor_yaw_rad).as_quat())}">'
                  f'<site name="ft"/><geom name="tip" type="capsule" size="{mjcf_vec((r, contact.tip_half_length_m))}" '
                  f'density="0" condim="1" priority="1" solref="{mjcf_vec(contact.tip_solref)}" contype="2" '
                  'conaffinity="2"/></body></body>')
        extra = (f'<actuator><position name="pusher_x" joint="pusher_x" kp="{kp!r}" kv="{kv!r}"/>'
                 f'<position name="pusher_y" joint="pusher_y" kp="{kp!r}" kv="{kv!r}"/></actuator>'
                 '<sensor><force name="ft_force" site="ft"/></sensor>')
    return (f'<mujoco model="push"><compiler angle="radian" autolimits="true"/>'
            f'<option timestep="{timestep!r}" gravity="0 0 {-GRAVITY_M_S2!r}" integrator="{settings.integrator}" '
            f'cone="{contact.cone}" impratio="{contact.impratio!r}"/>{assets}'
            f'<worldbody>{world}</worldbody>{extra}</mujoco>')


def simulate_pushed_mujoco(config: PushConfig, settings: MujocoSettings | None = None,
                           contact: PushContact = PushContact(), *, sensor_yaw_rad: float = 0.0
                           ) -> tuple[dict, PushTruth]:
    """Run the push in MuJoCo; returns noiseless samples at `config.rate_hz` and the truth.

    Samples (as `simulate_push`'s, plus the sensor's own axes): "t_s" [s]; "position" [m] and "quat_xyzw"
    of the block in world; "force": the force applied TO the block, world x, y [N]; "force_sensor": the
    same force in the sensor's axes (x, y, z) [N]; "tip": the measured tip centre, world x, y [m];
    "sensor_quat_xyzw": the sensor's axes in world. settings: MuJoCo's (default `push_settings()`).
    """
    import mujoco

    settings = settings or push_settings()
    if settings.integrator not in INTEGRATORS:
        raise ValueError(f"integrator: expected one of {INTEGRATORS}, got {settings.integrator!r}")
    model = mujoco.MjModel.from_xml_string(pushed_block_xml(config, settings, contact, sensor_yaw_rad=sensor_yaw_rad))
    data = mujoco.MjData(model)
    block = model.body("block").id
    site = model.site("ft").id
    sensor = model.sensor("ft_force")
    adr = int(sensor.adr[0])
    actuators = np.array([model.actuator(n).id for n in ("pusher_x", "pusher_y")])
    kv_over_kp = model.actuator_biasprm[actuators[0], 2] / model.actuator_biasprm[actuators[0], 1]
    start = pusher_reference(config, np.zeros(1))[0]
    free = model.joint("block_free")
    vadr = int(free.dofadr[0])

    period = 1.0 / config.rate_hz
    s = settings.substeps
    samples = int(round((config.idle_s + config.push_s + 0.5) / period)) + 1
    out = {k: [] for k in ("t_s", "position", "quat_xyzw", "tip")}
    step_force = np.zeros((samples * s, 3))  # sensor axes, each the force the step applied
    mujoco.mj_forward(model, data)
    R_sensor = data.site_xmat[site].reshape(3, 3).copy()
    h = 1e-4
    for j in range(samples):
        t = j * period
        out["t_s"].append(t)
        out["position"].append(data.qpos[0:3].copy())
        w, x, y, z = data.qpos[3:7]
        out["quat_xyzw"].append(np.array([x, y, z, w]) / np.linalg.norm([x, y, z, w]))
        out["tip"].append(data.site_xpos[site, :2].copy())
        ref = pusher_reference(config, np.array([t, t - h, t + h]))
        # the carriage's joints count from its start; the hold's set-point makes kp e + kv e_dot
        data.ctrl[actuators] = ref[0] - start + kv_over_kp * (ref[2] - ref[1]) / (2 * h)
        for k in range(s):
            if config.damping_n_s_m or config.turning_damping_n_m_s:
                v = data.qvel[vadr:vadr + 6]
                omega_z = (data.xmat[block].reshape(3, 3) @ v[3:])[2]  # free joint: body-axes angular velocity
                data.xfrc_applied[block, :2] = -config.damping_n_s_m * v[:2]
                data.xfrc_applied[block, 5] = -config.turning_damping_n_m_s * omega_z
            mujoco.mj_step(model, data)  # its forward pass: the contact force this step applies
            step_force[j * s + k] = data.sensordata[adr:adr + 3]
        mujoco.mj_forward(model, data)  # the kinematics of the state reached (mj_step leaves the old ones)
    if not np.all(np.isfinite(data.qpos)):
        raise RuntimeError("MuJoCo push diverged: lower the time step (MujocoSettings.substeps)")
    result = {k: np.asarray(v, dtype=float) for k, v in out.items()}
    # the mean over one period centred on each stamp: steps j s - s/2 .. j s + s/2 - 1
    padded = np.concatenate([np.zeros((s // 2, 3)), step_force, np.zeros((s - s // 2, 3))])
    cumulative = np.concatenate([np.zeros((1, 3)), np.cumsum(padded, axis=0)])
    idx = np.arange(samples) * s
    force_sensor = (cumulative[idx + s] - cumulative[idx]) / s
    result["force_sensor"] = force_sensor
    result["force"] = (force_sensor @ R_sensor.T)[:, :2]
    result["sensor_quat_xyzw"] = Rotation.from_matrix(R_sensor).as_quat()
    hx, hy, _ = config.half_extents_m
    return result, PushTruth(config.mu, config.mass_kg, config.mass_kg * ((2 * hx) ** 2 + (2 * hy) ** 2) / 12.0)


def write_pushed_mujoco(path: Path, config: PushConfig, settings: MujocoSettings | None = None,
                        contact: PushContact = PushContact(), *, wrench_frame: str = "world",
                        sensor_yaw_rad: float = 0.6) -> PushTruth:
    """Simulate one push in MuJoCo and write it as `write_push` does: a ROS 2 MCAP file with the tracker's
    noise, and the force's bias and noise (`config`), constant in the message's frame.

    wrench_frame "world": the force in world axes, acting at the contact point (/pusher/tip); "sensor": in
    the axes of "pusher_ft" (turned `sensor_yaw_rad` [rad] about z, z looking down), whose rotation
    /tf_static gives; the torque is zero about the tip's axis, which a frictionless round tip's force
    passes through (the static frame's origin, the tip's start, only stands in for the moving one).
    """
    from assets.recording import PointTrack, PoseTrack, WrenchTrack
    from .recording import write_recording

    if wrench_frame not in PUSH_WRENCH_FRAMES:
        raise ValueError(f"wrench_frame: expected one of {PUSH_WRENCH_FRAMES}, got {wrench_frame!r}")
    data, truth = simulate_pushed_mujoco(config, settings, contact, sensor_yaw_rad=sensor_yaw_rad)
    rng = np.random.default_rng(config.seed)
    t = data["t_s"] + 1.0  # stamps must be positive
    n = len(t)
    position = data["position"] + rng.normal(0, config.position_noise_m, (n, 3))
    quat = (Rotation.from_rotvec(np.c_[np.zeros((n, 2)), rng.normal(0, config.yaw_noise_rad, n)])
            * Rotation.from_quat(data["quat_xyzw"])).as_quat()
    if wrench_frame == "world":
        force, frame, statics = np.c_[data["force"], np.zeros(n)], "world", ()
    else:
        start = (*data["tip"][0], config.half_extents_m[2])
        force, frame = data["force_sensor"].copy(), SENSOR_FRAME
        statics = (("world", SENSOR_FRAME, (start, data["sensor_quat_xyzw"])),)
    force = force + np.asarray(config.force_bias_n) + rng.normal(0, config.force_noise_n, (n, 3))
    tip = np.c_[data["tip"], np.full(n, config.half_extents_m[2])]
    write_recording(
        path,
        pose=PoseTrack(t, position, quat, "world", "block", "/tracker/block"),
        wrench=WrenchTrack(t + config.delay_s, force, np.zeros((n, 3)), "/pusher/wrench", frame),
        contact=PointTrack(t, tip, "world", "/pusher/tip"),
        tf_static=statics,
    )
    return truth


@dataclass(frozen=True)
class PushedSampleConfig:
    """What `twin synth --pushed` makes: a block, resting on the table at the world origin, pushed twice."""

    push: PushConfig = field(default_factory=PushConfig)
    """The trial's push; the held-out one differs in its offset (the other side of the centre line)."""
    heldout_offset_m: float = -0.015
    contact: PushContact = field(default_factory=PushContact)
    material: str = "steel"


def make_pushed_sample(out_dir: Path, config: PushedSampleConfig = PushedSampleConfig(), *, engine: str = "newton",
                       wrench_frame: str = "world", mujoco: MujocoSettings | None = None) -> Path:
    """Write out_dir/{block.obj, trial.mcap, heldout.mcap, truth.json}.

    block.obj: the block's box in world, axis-aligned, resting on the table (z = 0) at the origin (the
    build's mesh SOURCE; its object frame is the tracked "block" frame). engine "newton" (`write_push`,
    world wrench only) or "mujoco" (`write_pushed_mujoco` under `mujoco` and `config.contact`).
    """
    import trimesh

    from .push import write_push

    if engine not in ("newton", "mujoco"):
        raise ValueError(f"engine: expected 'newton' or 'mujoco', got {engine!r}")
    if engine == "newton" and wrench_frame != "world":
        raise ValueError("the Newton push engine writes the force in world axes only: use --wrench-frame world")
    if wrench_frame not in PUSH_WRENCH_FRAMES:
        raise ValueError(f"wrench_frame: expected one of {PUSH_WRENCH_FRAMES}, got {wrench_frame!r}")
    mujoco = mujoco or push_settings()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    box = trimesh.creation.box([2 * h for h in config.push.half_extents_m])
    box.apply_translation([0.0, 0.0, config.push.half_extents_m[2]])
    box.export(out_dir / "block.obj")
    pushes = {"trial": config.push,
              "heldout": PushConfig(**{**asdict(config.push), "offset_m": config.heldout_offset_m,
                                       "seed": config.push.seed + 1000})}
    for name, push in pushes.items():
        if engine == "mujoco":
            truth = write_pushed_mujoco(out_dir / f"{name}.mcap", push, mujoco, config.contact,
                                        wrench_frame=wrench_frame)
        else:
            truth = write_push(out_dir / f"{name}.mcap", push)
    doc = {"name": "block", "kind": "sliding", "material": config.material,
           "frame": "object frame: the tracked 'block' frame, origin at the box's centre",
           "mass": truth.mass_kg, "mu": truth.mu, "izz": truth.izz_kgm2,
           "half_extents_m": list(config.push.half_extents_m),
           "recordings": {"trial": "trial.mcap", "heldout": "heldout.mcap"},
           "engine": engine, "wrench_frame": wrench_frame,
           **({"mujoco": asdict(mujoco), "contact": asdict(config.contact)} if engine == "mujoco" else {}),
           "config": json.loads(json.dumps(asdict(config)))}
    (out_dir / "truth.json").write_text(json.dumps(doc, indent=2) + "\n")
    return out_dir
