"""A robot pushing a block across a table with a round pusher, simulated in Newton, and its sensors.

The pusher (a vertical rod of radius `tip_radius_m`) moves along a straight
line in the plane at a varying speed; it touches the block through a stiff,
frictionless penalty contact, so its force acts along the contact normal and
the contact point slides along the face as the block turns. Pushing off the
face's centre line makes the block rotate. The support face rests on a fine
grid of point contacts with Coulomb friction of known mu (Newton SemiImplicit,
its collision pipeline), finer in space and time than the identification's
model, so a fit cannot simply replay the generator.

What is recorded is what the MIT pushing bags record: the block's pose from a
tracker, the force on the pusher's F/T sensor (given as the force applied TO
the block, world axes, with an optional constant bias and white noise) and the
pusher tip's centre as the contact point.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from assets.conventions import GRAVITY_MAGNITUDE_M_S2 as GRAVITY_M_S2
from assets.recording import PointTrack, PoseTrack, WrenchTrack

from .recording import write_recording

__all__ = ["PushConfig", "PushTruth", "simulate_push", "write_push"]


@dataclass(frozen=True)
class PushConfig:
    """One push of a box-shaped block; SI units.

    half_extents_m: block half sizes (x, y, z) [m]; mass_kg; mu: block-table friction.
    offset_m: lateral offset of the push line from the block's centre [m] (turns it).
    yaw0_rad: initial heading of the block.
    speed_m_s: pusher speed while a stroke holds; stroke_s: period of the strokes.
    idle_s: pusher still, clear of the block, before it moves (a quiet interval
        from which a sensor bias can be read); push_s: length of the motion.
    """

    half_extents_m: tuple[float, float, float] = (0.05, 0.05, 0.005)
    mass_kg: float = 0.75
    mu: float = 0.3
    offset_m: float = 0.01
    yaw0_rad: float = 0.0
    speed_m_s: float = 0.15
    stroke_s: float = 0.6
    idle_s: float = 0.5
    push_s: float = 2.0
    tip_radius_m: float = 0.005
    rate_hz: float = 100.0
    """Tracker, F/T sensor and tip-pose rate [Hz]."""
    dt_s: float = 2.5e-4
    grid: int = 8
    """Point contacts per side of the support face."""
    force_noise_n: float = 0.05
    force_bias_n: tuple[float, float, float] = (0.0, 0.0, 0.0)
    damping_n_s_m: float = 0.0
    """Concealed viscous drag on the block, -b v [N s/m] (velocity-strengthening friction) ..."""
    turning_damping_n_m_s: float = 0.0
    """... and -b_angular omega_z [N m s]."""
    delay_s: float = 0.0
    """Concealed time delay: the wrench stamped t acted at t - delay_s [s]."""
    position_noise_m: float = 2e-4
    yaw_noise_rad: float = 2e-3
    seed: int = 0


@dataclass(frozen=True)
class PushTruth:
    """What the generator used: mu, mass [kg], I_zz [kg m^2] about the COM."""

    mu: float
    mass_kg: float
    izz_kgm2: float


def _pusher_speed(config: PushConfig, tau: np.ndarray) -> np.ndarray:
    """Pusher speed [m/s] at times tau into the push: strokes of ramp up, hold, sharp stop, pause.

    The ramps make the block accelerate (its mass shows against the force); the
    sharp stops let it slide on alone, decelerating at mu g whatever its mass.
    """
    phase = np.mod(tau, config.stroke_s) / config.stroke_s
    up = np.clip(phase / 0.2, 0.0, 1.0)
    down = np.clip((0.6 - phase) / 0.04, 0.0, 1.0)
    v = config.speed_m_s * np.minimum(up, down)
    return np.where((tau >= 0) & (tau <= config.push_s), v, 0.0)


def _pusher_path(config: PushConfig, t: np.ndarray) -> np.ndarray:
    """Pusher centre (x, y) [m] over time: still and clear of the block, then strokes along +y."""
    hy = config.half_extents_m[1]
    y0 = -(hy + config.tip_radius_m + 0.01)
    fine = np.arange(0.0, config.push_s + 2e-4, 1e-4)
    travelled = np.concatenate([[0.0], np.cumsum(_pusher_speed(config, fine[:-1] + 5e-5)) * 1e-4])
    distance = np.interp(t - config.idle_s, fine, travelled)
    return np.stack([np.full_like(t, config.offset_m), y0 + distance], axis=-1)


def simulate_push(config: PushConfig) -> tuple[dict, PushTruth]:
    """Run the push; returns noiseless samples at rate_hz {t_s, position, quat_xyzw, force, tip} and the truth."""
    import newton
    import warp as wp

    hx, hy, hz = config.half_extents_m
    m = config.mass_kg
    izz = m * ((2 * hx) ** 2 + (2 * hy) ** 2) / 12.0
    n = config.grid * config.grid
    ke = 2.0e4 / n
    cfg = newton.ModelBuilder.ShapeConfig(ke=ke, kd=300.0 / n, kf=m / n / (4.0 * config.dt_s), mu=config.mu,
                                          density=0.0)
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, -GRAVITY_M_S2), up_axis=newton.Axis.Z)
    inertia = np.diag([m * ((2 * hy) ** 2 + (2 * hz) ** 2) / 12, m * ((2 * hx) ** 2 + (2 * hz) ** 2) / 12, izz])
    body = builder.add_body(mass=m, inertia=wp.mat33(inertia), lock_inertia=True)
    radius = 5e-4
    cells = (np.arange(config.grid) + 0.5) / config.grid * 2.0 - 1.0
    for gx in cells:
        for gy in cells:
            centre = wp.vec3(gx * hx, gy * hy, -hz + radius)
            builder.add_shape_sphere(body, xform=wp.transform(centre, wp.quat_identity()), radius=radius, cfg=cfg)
    builder.add_ground_plane(cfg=cfg)
    model = builder.finalize(device="cpu")
    solver = newton.solvers.SolverSemiImplicit(model, angular_damping=0.0)
    state, nxt = model.state(), model.state()
    q0 = Rotation.from_euler("z", config.yaw0_rad).as_quat()
    state.body_q.assign(np.array([[0.0, 0.0, hz - m * GRAVITY_M_S2 / 2.0e4, *q0]], dtype=np.float32))
    pipeline = newton.CollisionPipeline(model)
    contacts = pipeline.contacts()
    pipeline.collide(state, contacts)

    period = 1.0 / config.rate_hz
    substeps = int(round(period / config.dt_s))
    samples = int(round((config.idle_s + config.push_s + 0.5) / period)) + 1
    # pusher contact stiffness [N/m], damping near critical [N s/m]: a hard tip on a block chatters
    k_tip, c_tip = 3000.0, 2.0 * np.sqrt(3000.0 * m)
    out = {k: [] for k in ("t_s", "position", "quat_xyzw", "tip")}
    step_force = []  # the force at every simulation step, for the sensor's averaging
    for j in range(samples):
        t = j * period
        q = state.body_q.numpy()[0].astype(float)
        out["t_s"].append(t)
        out["position"].append(q[:3])
        out["quat_xyzw"].append(q[3:] / np.linalg.norm(q[3:]))
        out["tip"].append(_pusher_path(config, np.array([t]))[0])
        for k in range(substeps):
            ts = t + k * config.dt_s
            q = state.body_q.numpy()[0].astype(float)
            qd = state.body_qd.numpy()[0].astype(float)
            tip = _pusher_path(config, np.array([ts, ts + config.dt_s]))
            tip_v = (tip[1] - tip[0]) / config.dt_s
            force, point = _tip_contact(q, qd, tip[0], tip_v, config, k_tip, c_tip)
            step_force.append(force)
            arm = np.array([point[0] - q[0], point[1] - q[1], 0.0])
            f3 = np.array([force[0], force[1], 0.0])
            drag = -config.damping_n_s_m * np.array([qd[0], qd[1], 0.0])
            turning = np.array([0.0, 0.0, -config.turning_damping_n_m_s * qd[5]])
            state.body_f.assign(np.array([[*(f3 + drag), *(np.cross(arm, f3) + turning)]], dtype=np.float32))
            solver.step(state, nxt, None, contacts, config.dt_s)
            state, nxt = nxt, state
    data = {k: np.asarray(v, dtype=float) for k, v in out.items()}
    # a sensor's anti-alias filter without delay: the mean over one period centred on the stamp
    kernel = np.ones(substeps) / substeps
    smooth = np.stack([np.convolve(np.asarray(step_force)[:, k], kernel, "same") for k in range(2)], axis=1)
    data["force"] = smooth[::substeps]
    return data, PushTruth(config.mu, m, izz)


def _tip_contact(q, qd, tip, tip_v, config: PushConfig, k: float, c: float) -> tuple[np.ndarray, np.ndarray]:
    """Force [N] on the block from the round tip and its point of application (x, y) [m]."""
    hx, hy, _ = config.half_extents_m
    R = Rotation.from_quat(q[3:]).as_matrix()[:2, :2]
    p_b = R.T @ (tip - q[:2])
    closest = np.clip(p_b, [-hx, -hy], [hx, hy])
    gap = p_b - closest
    d = float(np.linalg.norm(gap))
    if d < 1e-9 or d >= config.tip_radius_m:
        return np.zeros(2), tip
    normal = R @ (gap / d)  # out of the block, towards the tip centre
    point = q[:2] + R @ closest
    v_point = qd[:2] + qd[5] * np.array([-(point[1] - q[1]), point[0] - q[0]])
    approach = -float(normal @ (tip_v - v_point))  # rate of penetration
    magnitude = max(0.0, k * (config.tip_radius_m - d) + c * approach)
    return -normal * magnitude, point


def write_push(path: Path, config: PushConfig) -> PushTruth:
    """Simulate one push and write it as a ROS 2 MCAP file with sensor noise and bias."""
    data, truth = simulate_push(config)
    rng = np.random.default_rng(config.seed)
    t = data["t_s"] + 1.0  # stamps must be positive
    n = len(t)
    position = data["position"] + rng.normal(0, config.position_noise_m, (n, 3))
    quat = (Rotation.from_rotvec(np.c_[np.zeros((n, 2)), rng.normal(0, config.yaw_noise_rad, n)])
            * Rotation.from_quat(data["quat_xyzw"])).as_quat()
    force = np.c_[data["force"], np.zeros(n)] + np.asarray(config.force_bias_n)
    force = force + rng.normal(0, config.force_noise_n, (n, 3))
    tip = np.c_[data["tip"], np.full(n, config.half_extents_m[2])]
    write_recording(
        path,
        pose=PoseTrack(t, position, quat, "world", "block", "/tracker/block"),
        wrench=WrenchTrack(t + config.delay_s, force, np.zeros((n, 3)), "/pusher/wrench", "world"),
        contact=PointTrack(t, tip, "world", "/pusher/tip"),
    )
    return truth
