"""Pushed objects: surface friction (with mass and yaw inertia where the data determine them).

An object pushed across a support surface is simulated in Newton with
SemiImplicit and its collision pipeline, gradients from a Warp tape: one world
per shooting window, each started from the measured planar state (x, y, yaw and
their rates), driven by the measured pusher force applied at the measured
contact point, compared with the measured motion.

The support face is sampled by a grid of point contacts (small spheres, uniform
pressure). A box's own collision shape touches a plane at its four corners,
which puts all the friction at the largest radius and roughly doubles the
friction torque that resists turning; a 4 x 4 grid gets the mean lever arm of a
uniformly loaded square within 2 %.

Penalty friction in Newton is viscous below a slip speed (kf |v_t| < mu f_n)
and Coulomb above; its gradient w.r.t. mu is zero in the viscous branch, so
only windows in which the object slides are fitted (newton.md, "sticking").
A slow, quasi-static push balances on a knife edge when driven by the measured
force (a little below mu m g the object sticks, a little above it runs away):
a fit whose simulation sticks in every window has only bounded mu
(`sliding_windows`), and the wrench balance of the windows in which the object
slides throughout measures it without a simulation (`wrench_balance_friction`).
A window whose turn its pushing moment cannot give (friction would have to drive
it: `turn_check`) is a mismatch no coefficient explains, and the I_zz a fit needs
to follow it is not the body's.

Parameters are theta = (mu, m [kg], I_zz [kg m^2]). Pushes that are nearly
quasi-static determine mu * m (force balance) better than either alone; a
log-normal prior on m and I_zz closes the problem, and each parameter whose
curvature from the data is below the prior's is reported as taken from the prior.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from itertools import pairwise

import numpy as np
import warp as wp
from scipy.spatial.transform import Rotation

from assets.conventions import GRAVITY_MAGNITUDE_M_S2 as GRAVITY_M_S2

from .windows import local_twist, lowpass

__all__ = [
    "ForceBias",
    "PlanarBody",
    "PushWindows",
    "SlidingConfig",
    "SlidingFit",
    "SlidingRollout",
    "SupportChoice",
    "choose_support",
    "PushedIdentification",
    "concat_push_windows",
    "estimate_force_bias",
    "identify_pushed",
    "identify_sliding",
    "measured_friction",
    "replay_errors",
    "push_windows",
    "sliding_windows",
    "quasi_static_friction",
    "steady_windows",
    "turn_check",
    "TurnCheck",
    "wrench_balance_error",
    "wrench_balance_friction",
    "WrenchBalance",
]

_GRID = 4  # contacts per side of the support face
SUPPORTS = ("uniform", "corners")
"""Support-face load models of `SlidingConfig.support`."""


@dataclass(frozen=True)
class PlanarBody:
    """The pushed object as the simulation sees it (object frame at the COM, z up).

    half_extents_m: half sizes of its bounding box (x, y, z) [m]; the support
        face is the box's bottom face.
    mass_kg, izz_kgm2: prior values (inertia about the vertical axis through the COM).
    mass_rel_std, izz_rel_std: prior spread, as the std of the log.
    """

    half_extents_m: tuple[float, float, float]
    mass_kg: float
    izz_kgm2: float
    mass_rel_std: float = 0.3
    izz_rel_std: float = 0.3

    def __post_init__(self):
        h = np.asarray(self.half_extents_m, dtype=float)
        if h.shape != (3,) or not np.all(h > 0):
            raise ValueError(f"PlanarBody.half_extents_m: expected three positive sizes [m], got {self.half_extents_m}")
        for name in ("mass_kg", "izz_kgm2", "mass_rel_std", "izz_rel_std"):
            if not getattr(self, name) > 0:
                raise ValueError(f"PlanarBody.{name}: expected > 0, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class SlidingConfig:
    """Settings of the sliding identification (recorded in asset.json provenance).

    window_s: shooting-window length [s]. dt_s: simulation step [s].
    moving_speed_m_s: a window is fitted only if the object's median speed in it
        exceeds this (sliding, not sticking) [m/s].
    contact_margin_m: the pusher counts as touching when the contact point lies
        within the support face's circumradius plus this [m].
    yaw_length_m: heading errors are weighted as arc lengths at this radius
        (default: the face's half diagonal) [m].
    mu_bounds: admissible friction coefficients.
    smoothing_hz: zero-phase low-pass of the poses when finding the first and last motion (bias).
    twist_half_width: samples each side of a window's start in the quadratic fit
        of its start velocity.
    max_iterations: L-BFGS-B iterations.
    """

    window_s: float = 0.3
    dt_s: float = 2e-3
    moving_speed_m_s: float = 0.01
    contact_margin_m: float = 0.02
    yaw_length_m: float | None = None
    mu_bounds: tuple[float, float] = (0.02, 2.0)
    smoothing_hz: float = 10.0
    sample_period_s: float = 0.01
    """Pose samples are resampled to this period [s], so windows of any recording share one batch."""
    pusher_clear_m: float = 0.003
    """The pusher is away from the object (a zero of the force offset) once its contact point is this
    much farther from the object's origin, horizontally, than when the object first moved [m] ..."""
    lift_m: float = 0.01
    """... or this far above its height while pushing [m] (a pusher lifted off may stay above the object)."""
    preload_fraction: float = 0.05
    """A pusher resting on the object before the push preloads it when the force then exceeds the
    pusher-away zero after the push, along the push, by this fraction of the median pushing force."""
    jump_m: float = 0.005
    """Tracker samples further than this from a running median are dropped [m]."""
    twist_half_width: int = 3
    max_iterations: int = 30
    contact_sink_m: float = 3e-4
    """Static sink of the face under the object's weight [m]: sets the normal stiffness m g / sink,
    so the contact's frequency sqrt(g / sink) is the same for any mass."""
    contact_damping_ratio: float = 0.7
    max_delay_s: float = 0.05
    """The force is kept this far beyond each window's ends: the range a time delay is fitted over [s]."""
    support: str = "uniform"
    """Where the support face carries the weight: "uniform" (a grid over the face: a flat face on a flat
    table, the default) or "corners" (its four corners, as MuJoCo's box-plane and mesh-plane contacts put
    them: about twice the friction moment against turning; docs/pushes.md)."""
    fit_mass: bool = False
    """Fit the mass too. Pushes determine mu m through the force balance; the split rests on the
    accelerations, which 5 ms of force-to-pose timing error moves by about 10 % (twin bench push),
    so by default the mass keeps its prior (marked so) and mu is measured given it."""

    def __post_init__(self):
        if self.support not in SUPPORTS:
            raise ValueError(f"SlidingConfig.support: expected one of {SUPPORTS}, got {self.support!r}")


@dataclass(frozen=True)
class PushWindows:
    """W planar windows of S pose samples each, sample 0 the start.

    dt_s, substeps: simulation step [s] and steps per pose sample.
    t_start_s [W]; start [W, 6]: x, y [m], yaw [rad], vx, vy [m/s], yaw rate [rad/s];
    force [margin + steps + margin, W, 2]: pusher force on the object, world x, y [N] (bias removed),
    from `force_margin` steps before each window to as many after it (the room a time delay is fitted in);
    contact [steps, W, 2]: its point of application, world x, y [m];
    measured [S+1, W, 3]: x, y [m], yaw [rad] (continuous, not wrapped).
    """

    dt_s: float
    substeps: int
    t_start_s: np.ndarray
    start: np.ndarray
    force: np.ndarray
    contact: np.ndarray
    measured: np.ndarray
    force_margin: int = 0

    @property
    def window_count(self) -> int:
        return len(self.t_start_s)

    @property
    def step_count(self) -> int:
        return self.contact.shape[0]

    @property
    def window_force(self) -> np.ndarray:
        """The force at the window's own steps [steps, W, 2]."""
        return self.force[self.force_margin:self.force_margin + self.step_count]

    @property
    def sample_count(self) -> int:
        return self.measured.shape[0] - 1

    @property
    def sample_period_s(self) -> float:
        return self.dt_s * self.substeps

    @property
    def span_s(self) -> float:
        """A window's length [s]."""
        return self.sample_count * self.sample_period_s


def _planar_grid(recording, config: "SlidingConfig", smooth: bool):
    """Pose track on a uniform grid of config.sample_period_s: t [s], xy [m], yaw [rad, unwrapped].

    Tracker jumps (samples off a running median by more than config.jump_m, or
    config.jump_m / 0.05 m in heading) are dropped first; with `smooth`, the
    result is low-passed at config.smoothing_hz.
    """
    from scipy.signal import medfilt

    pose = recording.pose
    t = pose.t_s
    xy_raw = pose.position[:, :2]
    yaw_raw = np.unwrap(_yaw(pose.quat_xyzw))
    if len(t) > 9:
        off_xy = np.linalg.norm(xy_raw - np.stack([medfilt(xy_raw[:, k], 9) for k in range(2)], axis=1), axis=1)
        wrapped = np.angle(np.exp(1j * (yaw_raw - medfilt(yaw_raw, 9))))
        keep = (off_xy < config.jump_m) & (np.abs(wrapped) < config.jump_m / 0.05)
        t, xy_raw = t[keep], xy_raw[keep]
        yaw_raw = np.unwrap(yaw_raw[keep])
    period = config.sample_period_s
    grid = t[0] + period * np.arange(int(np.floor((t[-1] - t[0]) / period)) + 1)
    xy = np.stack([np.interp(grid, t, xy_raw[:, k]) for k in range(2)], axis=1)
    yaw = np.interp(grid, t, yaw_raw)
    if smooth:
        xy = lowpass(xy, config.smoothing_hz, 1 / period)
        yaw = lowpass(yaw[:, None], config.smoothing_hz, 1 / period)[:, 0]
    return grid, xy, yaw


def _support_points(body: PlanarBody, config: "SlidingConfig | None" = None) -> np.ndarray:
    """The support face's point contacts, object frame x, y [m]: the cell centres of a _GRID x _GRID grid
    (support "uniform"), or the face's four corners ("corners")."""
    hx, hy, _ = body.half_extents_m
    if config is not None and config.support == "corners":
        return np.array([(sx * hx, sy * hy) for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)])
    cells = (np.arange(_GRID) + 0.5) / _GRID * 2.0 - 1.0
    return np.array([(gx * hx, gy * hy) for gx in cells for gy in cells])


def _scatter_about_quadratic(track: np.ndarray) -> np.ndarray:
    """RMS of a window track [S+1, W, ...] about a quadratic in time fitted per window and channel, per
    window: the tracker's scatter, the motion taken out."""
    flat = track.reshape(track.shape[0], -1)
    samples = np.arange(track.shape[0])
    fit = np.polynomial.polynomial.polyval(samples, np.polynomial.polynomial.polyfit(samples, flat, 2)).T
    return np.sqrt(np.mean(((flat - fit) ** 2).reshape(track.shape[0], track.shape[1], -1), axis=(0, 2)))


def _thirds(samples: int) -> list[tuple[int, int]]:
    """First and last sample of each third of a window of `samples` samples."""
    return list(pairwise(np.linspace(0, samples - 1, 4).round().astype(int)))


def _planar_travel(step: np.ndarray, arc_m: float) -> np.ndarray:
    """Size of planar steps (..., 3: x, y [m], yaw [rad]), the heading counted as an arc of arc_m [m]."""
    return np.hypot(np.hypot(step[..., 0], step[..., 1]), step[..., 2] * arc_m)


def _yaw(quat_xyzw: np.ndarray) -> np.ndarray:
    """Heading of the frame's x axis about world z [rad] (valid while the object stays flat)."""
    x_axis = Rotation.from_quat(quat_xyzw).apply([1.0, 0.0, 0.0])
    return np.arctan2(x_axis[:, 1], x_axis[:, 0])


@dataclass(frozen=True)
class ForceBias:
    """Offset of the measured force (measured = applied + offset), world x, y, z [N], over time.

    Measured at "zeros", stretches where the object is still and nothing pushes
    it; linear in time between zeros, held before the first and after the last.
    t_s [K]: each zero's median stamp [s]; force_n [K, 3]: its median force [N]
    (K = 0: no zero found, no offset); source: where the zeros were taken.
    """

    t_s: np.ndarray
    force_n: np.ndarray
    source: str

    def at(self, t_s) -> np.ndarray:
        """The offset [N] at stamps t_s [s], shape (len(t_s), 3)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        if len(self.t_s) == 0:
            return np.zeros((len(t), 3))
        return np.stack([np.interp(t, self.t_s, self.force_n[:, k]) for k in range(3)], axis=1)

    def provenance(self) -> dict:
        return {"source": self.source, "t_s": list(map(float, self.t_s)),
                "force_n": [list(map(float, f)) for f in self.force_n]}


def estimate_force_bias(recording, config: SlidingConfig, margin_s: float = 0.3) -> ForceBias:
    """The force sensor's offset from the recording's zeros (see ForceBias); real F/T sensors are
    often not zeroed (mit-push README).

    A zero is a stretch, more than `margin_s` before the object first moves or
    after it last moves, where the pusher is away: its contact point farther
    from the object, by config.pusher_clear_m, than as the object started to
    move, or config.lift_m above its height while pushing. With zeros before
    and after, the offset drifts linearly between them.

    Where the pusher rests against the object before the push (no zero before
    it), that resting stretch is the offset, taken in the pose the push is
    made in, unless it shows a preload: the pusher pressing while static
    friction holds reads higher ALONG the push than the zero after it, by more
    than config.preload_fraction of the median pushing force (the 2015
    plastic-block bags: 0.08-0.28 N of a 0.5 N push). Then the zero after the
    push is the offset. `source` says which.
    """
    grid, xy, _ = _planar_grid(recording, config, smooth=True)
    speed = np.linalg.norm(np.gradient(xy, grid, axis=0), axis=1)
    run = 10  # samples: a filter's edge or a tracker glitch is not motion
    fast = (speed > config.moving_speed_m_s).astype(float)
    moving = np.flatnonzero(np.convolve(fast, np.ones(run), "valid") == run)
    w = recording.wrench
    t_w = w.t_s
    t_first = grid[moving[0]] if len(moving) else grid[-1]
    t_last = grid[moving[-1] + run - 1] if len(moving) else grid[-1]
    before = t_w < t_first - margin_s
    after = t_w > t_last + margin_s
    away = np.zeros(len(t_w), dtype=bool)
    c = recording.contact
    if c is not None and len(moving):
        tip = np.stack([np.interp(t_w, c.t_s, c.position[:, k]) for k in range(3)], axis=1)
        obj = np.stack([np.interp(t_w, grid, xy[:, k]) for k in range(2)], axis=1)
        distance = np.linalg.norm(tip[:, :2] - obj, axis=1)
        pushing_z = np.median(tip[(t_w >= t_first) & (t_w <= t_last), 2])
        away = ((distance > np.interp(t_first, t_w, distance) + config.pusher_clear_m)
                | (tip[:, 2] > pushing_z + config.lift_m))

    def zero(mask):
        return float(np.median(t_w[mask])), np.median(w.force[mask], axis=0)

    first = zero(before & away) if (before & away).sum() >= 10 else None
    last = zero(after & away) if (after & away).sum() >= 10 else None
    if first is None and before.sum() >= 10:
        resting = zero(before)
        if last is not None:
            pushing = np.median(w.force[(t_w >= t_first) & (t_w <= t_last)] - last[1], axis=0)[:2]
            excess = float((resting[1] - last[1])[:2] @ pushing) / max(float(np.linalg.norm(pushing)), 1e-9)
            if excess > config.preload_fraction * np.linalg.norm(pushing):
                return ForceBias(np.array([last[0]]), last[1][None], "pusher away after a preload")
        return ForceBias(np.array([resting[0]]), resting[1][None], "pusher resting before the push")
    zeros = [z for z in (first, last) if z is not None]
    return ForceBias(np.array([z[0] for z in zeros]), np.array([z[1] for z in zeros]).reshape(-1, 3),
                     "pusher away" if zeros else "none")


def push_windows(recording, body: PlanarBody, config: SlidingConfig, bias: ForceBias | None = None,
                 moving_only: bool = True) -> PushWindows:
    """Back-to-back windows over the part of `recording` where the pusher touches the object.

    The force is the recording's world-axes wrench force minus `bias` at its stamps; the contact
    point is the recording's contact track (required: a push is a force at a point).
    With moving_only, windows where the object does not slide are left out. The force is kept
    config.max_delay_s beyond each window's ends, the range a time delay is fitted over.
    """
    if recording.contact is None:
        raise ValueError(
            f"{recording.path}: sliding needs the contact point of the pushing force "
            "(a PointStamped or pose topic; name it with --topic contact=/name)"
        )
    grid, xy, yaw = _planar_grid(recording, config, smooth=False)  # smoothing would blunt stops
    period = grid[1] - grid[0]
    substeps = max(1, int(round(period / config.dt_s)))
    dt = period / substeps
    samples = max(2, int(round(config.window_s / period)))
    c = recording.contact
    contact_grid = np.stack([np.interp(grid, c.t_s, c.position[:, k]) for k in range(2)], axis=1)
    reach = float(np.hypot(*body.half_extents_m[:2])) + config.contact_margin_m
    touching = np.linalg.norm(contact_grid - xy, axis=1) < reach
    speed = np.linalg.norm(np.gradient(xy, grid, axis=0), axis=1)
    starts = []
    for s in range(0, len(grid) - samples, samples):
        span = slice(s, s + samples + 1)
        if not touching[span].all():
            continue
        if moving_only and np.median(speed[span]) < config.moving_speed_m_s:
            continue
        starts.append(s)
    if not starts:
        raise ValueError(
            f"{recording.path}: no {config.window_s} s window in which the pusher touches the object"
            + (f" and it slides faster than {config.moving_speed_m_s} m/s (a slow push needs a lower "
               f"--push-min-speed, e.g. 0.001)" if moving_only else "")
        )
    starts = np.asarray(starts)
    w = recording.wrench
    force = w.force[:, :2] - (bias.at(w.t_s)[:, :2] if bias is not None else 0.0)  # unfiltered: noise averages out
    margin = int(np.ceil(config.max_delay_s / dt)) + 1
    t_step = grid[starts][None, :] + dt * np.arange(samples * substeps)[:, None]
    t_force = grid[starts][None, :] + dt * np.arange(-margin, samples * substeps + margin)[:, None]
    f = np.stack([np.interp(t_force, w.t_s, force[:, k]) for k in range(2)], axis=-1)
    p = np.stack([np.interp(t_step, c.t_s, c.position[:, k]) for k in range(2)], axis=-1)
    rot = Rotation.from_rotvec(np.c_[np.zeros((len(yaw), 2)), yaw])
    pos3 = np.c_[xy, np.zeros(len(grid))]
    start = []
    for s in starts:
        twist = local_twist(grid, pos3, rot, s, config.twist_half_width)
        start.append([xy[s, 0], xy[s, 1], yaw[s], twist[0], twist[1], twist[5]])
    idx = starts[None, :] + np.arange(samples + 1)[:, None]
    measured = np.stack([xy[idx, 0], xy[idx, 1], yaw[idx]], axis=-1)
    return PushWindows(dt, substeps, grid[starts], np.asarray(start), f, p, measured, margin)


def concat_push_windows(parts: list[PushWindows]) -> PushWindows:
    """Windows of several recordings as one batch (same step, substeps and length)."""
    first = parts[0]
    for p in parts[1:]:
        if ((p.substeps, p.step_count, p.force_margin) != (first.substeps, first.step_count, first.force_margin)
                or abs(p.dt_s - first.dt_s) > 1e-6):
            raise ValueError("recordings differ in pose rate; their windows cannot share one batch")
    return PushWindows(
        first.dt_s, first.substeps,
        np.concatenate([p.t_start_s for p in parts]),
        np.concatenate([p.start for p in parts]),
        np.concatenate([p.force for p in parts], axis=1),
        np.concatenate([p.contact for p in parts], axis=1),
        np.concatenate([p.measured for p in parts], axis=1),
        first.force_margin,
    )


# --------------------------------------------------------------------------
# kernels, beside their launches in SlidingRollout


@wp.kernel
def assign_sliding_params(
    theta: wp.array[float],
    inertia_xy: wp.vec2,
    shape_body: wp.array[int],
    body_mass: wp.array[float],
    body_inv_mass: wp.array[float],
    body_inertia: wp.array[wp.mat33],
    body_inv_inertia: wp.array[wp.mat33],
    shape_material_mu: wp.array[float],
):
    """Write mu (every shape, so the pair average is mu), mass [kg] and I_zz [kg m^2] on the tape.

    One thread per shape; the thread of a body's first contact sphere also writes
    the body. SemiImplicit integrates with the inverses (newton.md trap 1).
    """
    s = wp.tid()
    shape_material_mu[s] = theta[0]
    b = shape_body[s]
    if b >= 0 and (s == 0 or shape_body[s - 1] != b):
        m = theta[1]
        inertia = wp.mat33(inertia_xy[0], 0.0, 0.0, 0.0, inertia_xy[1], 0.0, 0.0, 0.0, theta[2])
        body_mass[b] = m
        body_inv_mass[b] = 1.0 / m
        body_inertia[b] = inertia
        body_inv_inertia[b] = wp.inverse(inertia)


@wp.kernel
def set_planar_start_state(
    start: wp.array[wp.spatial_vector],
    velocity_correction: wp.array[wp.vec3],
    rest_height_m: float,
    body_q: wp.array[wp.transform],
    body_qd: wp.array[wp.spatial_vector],
):
    """Body w at (x, y, rest height), heading yaw, velocity (vx, vy, 0) [m/s] and yaw rate [rad/s],
    each rate plus the window's correction (vx, vy, yaw rate)."""
    w = wp.tid()
    s = start[w]
    c = velocity_correction[w]
    body_q[w] = wp.transform(wp.vec3(s[0], s[1], rest_height_m), wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), s[2]))
    body_qd[w] = wp.spatial_vector(wp.vec3(s[3] + c[0], s[4] + c[1], 0.0), wp.vec3(0.0, 0.0, s[5] + c[2]))


@wp.kernel
def apply_pusher_force(
    body_q: wp.array[wp.transform],
    body_com: wp.array[wp.vec3],
    force: wp.array2d[wp.vec2],
    contact: wp.array2d[wp.vec2],
    effect: wp.array[float],
    step: int,
    margin: int,
    dt: float,
    body_f: wp.array[wp.spatial_vector],
):
    """Horizontal pusher force [N] at the contact point (x, y) [m], taken at the COM's height.

    The height at which a pusher meets the object only tilts it (SemiImplicit
    would rock the box on its contacts); the planar motion needs the in-plane moment.
    effect[4] is the wrench's delay d [s] (DESIGN.md time_delay: stamped t, it acted at t - d), so
    the force acting now was read d later: interpolated between steps, so d has a gradient.
    effect[5:7] is the contact point's offset [m], world x, y: the force acts at the measured point plus it
    (a probe or tracker calibration off by millimetres moves the pushing moment of a near-central push).
    """
    w = wp.tid()
    X = body_q[w]
    c = wp.transform_point(X, body_com[w])
    at = float(step + margin) + effect[4] / dt
    i = wp.clamp(int(wp.floor(at)), 0, force.shape[0] - 2)
    a = wp.clamp(at - float(i), 0.0, 1.0)
    f2 = force[i, w] * (1.0 - a) + force[i + 1, w] * a
    p2 = contact[step, w] + wp.vec2(effect[5], effect[6])
    f = wp.vec3(f2[0], f2[1], 0.0)
    arm = wp.vec3(p2[0] - c[0], p2[1] - c[1], 0.0)
    body_f[w] = wp.spatial_vector(f, wp.cross(arm, f))


EFFECT_SLOTS = {"sensor_bias": (0, 1), "viscous_damping": (2, 3), "time_delay": (4,), "contact_offset": (5, 6)}
"""Where each effect's parameters sit in the rollout's effect vector (apply_sliding_effects, apply_pusher_force)."""
EFFECT_SIZE = 7


@wp.kernel
def apply_sliding_effects(
    body_qd: wp.array[wp.spatial_vector],
    effect: wp.array[float],
    body_f: wp.array[wp.spatial_vector],
):
    """Add to the pusher's wrench what the base model leaves out: a force offset still in the reading
    (measured = applied + (effect[0], effect[1]) [N], world x, y; the same at every point of the push
    contact, so applied at the COM it only shifts the force) and viscous drag on the sliding body,
    -effect[2] v [N s/m] and -effect[3] omega_z [N m s] (velocity-strengthening friction)."""
    w = wp.tid()
    qd = body_qd[w]
    v = wp.spatial_top(qd)
    omega = wp.spatial_bottom(qd)
    f = wp.vec3(-effect[0] - effect[2] * v[0], -effect[1] - effect[2] * v[1], 0.0)
    tau = wp.vec3(0.0, 0.0, -effect[3] * omega[2])
    body_f[w] = body_f[w] + wp.spatial_vector(f, tau)


@wp.kernel
def eval_planar_error(
    body_q: wp.array[wp.transform],
    measured: wp.array2d[wp.vec3],
    sample: int,
    yaw_length_m: float,
    residual: wp.array3d[float],
):
    """Per window: x, y error [m] and heading error [rad] times yaw_length_m [m]."""
    w = wp.tid()
    X = body_q[w]
    p = wp.transform_get_translation(X)
    ax = wp.quat_rotate(wp.transform_get_rotation(X), wp.vec3(1.0, 0.0, 0.0))
    m = measured[sample, w]
    dyaw = wp.atan2(ax[1], ax[0]) - m[2]
    dyaw = dyaw - 2.0 * wp.pi * wp.round(dyaw / (2.0 * wp.pi))  # the short way round
    residual[sample, w, 0] = p[0] - m[0]
    residual[sample, w, 1] = p[1] - m[1]
    residual[sample, w, 2] = dyaw * yaw_length_m


@wp.kernel
def eval_sum_squares(residual: wp.array3d[float], loss: wp.array[float]):
    """loss += sum of squared residuals [m^2]."""
    j, w, k = wp.tid()
    r = residual[j, w, k]
    wp.atomic_add(loss, 0, r * r)


class SlidingRollout:
    """One pushed body on a shared ground plane per window; SemiImplicit, no damping."""

    def __init__(self, windows: PushWindows, body: PlanarBody, config: SlidingConfig, device: str = "cpu"):
        import newton

        self.windows, self.body, self.config, self.device = windows, body, config, device
        hx, hy, hz = body.half_extents_m
        W = windows.window_count
        radius = 1e-3
        support = _support_points(body, config)
        n_contacts = len(support)
        ke = body.mass_kg * GRAVITY_M_S2 / config.contact_sink_m
        kd = 2.0 * config.contact_damping_ratio * np.sqrt(ke * body.mass_kg)
        cfg = newton.ModelBuilder.ShapeConfig(
            ke=ke / n_contacts, kd=kd / n_contacts,
            # slip speed mu g dt: Coulomb (mu-sensitive) at the speeds a push is fitted at,
            # while kf dt / (m / n) = 1 keeps the explicit viscous branch stable (deadbeat)
            kf=body.mass_kg / n_contacts / windows.dt_s, mu=0.5, density=0.0,
        )
        sub = newton.ModelBuilder(gravity=(0.0, 0.0, -GRAVITY_M_S2), up_axis=newton.Axis.Z)
        b = sub.add_body(mass=body.mass_kg, inertia=wp.mat33(np.eye(3) * body.izz_kgm2), lock_inertia=True)
        for px, py in support:
            sub.add_shape_sphere(b, xform=wp.transform(wp.vec3(px, py, -hz + radius), wp.quat_identity()),
                                 radius=radius, cfg=cfg)
        builder = newton.ModelBuilder(gravity=(0.0, 0.0, -GRAVITY_M_S2), up_axis=newton.Axis.Z)
        builder.replicate(sub, W)
        builder.add_ground_plane(cfg=cfg)
        self.model = builder.finalize(device=device, requires_grad=True)
        self.solver = newton.solvers.SolverSemiImplicit(self.model, angular_damping=0.0)
        self.control = self.model.control()
        self.states = [self.model.state(requires_grad=True) for _ in range(windows.step_count + 1)]
        self.rest_height_m = hz - config.contact_sink_m
        m_box = body.mass_kg
        self.inertia_xy = wp.vec2(m_box * (hy * hy + hz * hz) / 3.0, m_box * (hx * hx + hz * hz) / 3.0)
        self.yaw_length_m = config.yaw_length_m or float(np.hypot(hx, hy))

        self.start = wp.array(windows.start.astype(np.float32), dtype=wp.spatial_vector, device=device)
        self.force = wp.array(windows.force.astype(np.float32), dtype=wp.vec2, device=device)
        self.contact = wp.array(windows.contact.astype(np.float32), dtype=wp.vec2, device=device)
        self.measured = wp.array(windows.measured.astype(np.float32), dtype=wp.vec3, device=device)
        self.theta = wp.zeros(3, dtype=float, device=device, requires_grad=True)
        self.effect = wp.zeros(EFFECT_SIZE, dtype=float, device=device, requires_grad=True)
        self.correction = wp.zeros(W, dtype=wp.vec3, device=device, requires_grad=True)
        self.residual = wp.zeros((windows.sample_count + 1, W, 3), dtype=float, device=device, requires_grad=True)
        self.loss = wp.zeros(1, dtype=float, device=device, requires_grad=True)

        # Contacts against a plane depend only on the body-local sphere centres: found once.
        self.pipeline = newton.CollisionPipeline(self.model, broad_phase="explicit", requires_grad=True)
        self.contacts = self.pipeline.contacts()
        wp.launch(set_planar_start_state, dim=W, inputs=[self.start, self.correction, self.rest_height_m],
                  outputs=[self.states[0].body_q, self.states[0].body_qd], device=device)
        self.pipeline.collide(self.states[0], self.contacts)
        found = int(self.contacts.rigid_contact_count.numpy()[0])
        if found != W * n_contacts:
            raise RuntimeError(f"sliding model: expected {W * n_contacts} support contacts, the pipeline found {found}")

    def _forward(self) -> None:
        w, model = self.windows, self.model
        wp.launch(assign_sliding_params, dim=model.shape_count, inputs=[self.theta, self.inertia_xy, model.shape_body],
                  outputs=[model.body_mass, model.body_inv_mass, model.body_inertia, model.body_inv_inertia,
                           model.shape_material_mu], device=self.device)
        s0 = self.states[0]
        wp.launch(set_planar_start_state, dim=w.window_count, inputs=[self.start, self.correction, self.rest_height_m],
                  outputs=[s0.body_q, s0.body_qd], device=self.device)
        self.residual.zero_()
        for step in range(w.step_count):
            s, s_next = self.states[step], self.states[step + 1]
            wp.launch(apply_pusher_force, dim=w.window_count,
                      inputs=[s.body_q, model.body_com, self.force, self.contact, self.effect, step,
                              w.force_margin, w.dt_s],
                      outputs=[s.body_f], device=self.device)
            wp.launch(apply_sliding_effects, dim=w.window_count, inputs=[s.body_qd, self.effect], outputs=[s.body_f],
                      device=self.device)
            self.solver.step(s, s_next, self.control, self.contacts, w.dt_s)
            if (step + 1) % w.substeps == 0:
                wp.launch(eval_planar_error, dim=w.window_count,
                          inputs=[s_next.body_q, self.measured, (step + 1) // w.substeps, self.yaw_length_m],
                          outputs=[self.residual], device=self.device)

    def _load(self, theta, correction, effect) -> None:
        self.theta.assign(np.asarray(theta, dtype=np.float32))
        W = self.windows.window_count
        c = np.zeros((W, 3)) if correction is None else np.asarray(correction).reshape(W, 3)
        self.correction.assign(c.astype(np.float32))
        self.effect.assign(np.zeros(EFFECT_SIZE, np.float32) if effect is None else np.asarray(effect, np.float32))

    def residuals(self, theta, correction=None, effect=None) -> np.ndarray:
        """Errors [S, W, 3] at samples 1..S: x, y [m], heading x yaw_length_m [m].

        correction [W, 3]: start-velocity corrections (vx, vy [m/s], yaw rate [rad/s]);
        effect [EFFECT_SIZE]: see apply_sliding_effects (None: none).
        """
        self._load(theta, correction, effect)
        self._forward()
        return self.residual.numpy()[1:].astype(float)

    def trajectories(self, theta, correction=None, effect=None) -> np.ndarray:
        """Simulated x, y [m] and yaw [rad] at samples 0..S, shape [S+1, W, 3]."""
        r = self.residuals(theta, correction, effect)
        pred = self.windows.measured.copy()
        pred[1:, :, :2] += r[:, :, :2]
        pred[1:, :, 2] += r[:, :, 2] / self.yaw_length_m
        return pred

    def loss_and_grad(self, theta, correction=None, effect=None) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Sum of squared residuals [m^2] and its gradients w.r.t. theta, the corrections [W, 3] and the effect."""
        self._load(theta, correction, effect)
        tape = wp.Tape()
        with tape:
            self._forward()
            self.loss.zero_()
            wp.launch(eval_sum_squares, dim=self.residual.shape, inputs=[self.residual], outputs=[self.loss],
                      device=self.device)
        tape.backward(self.loss)
        out = (float(self.loss.numpy()[0]), self.theta.grad.numpy().astype(float).copy(),
               self.correction.grad.numpy().astype(float).copy(), self.effect.grad.numpy().astype(float).copy())
        tape.zero()
        return out


# --------------------------------------------------------------------------
# the fit


@dataclass(frozen=True)
class SlidingFit:
    """Result of `identify_sliding`.

    theta: (mu, mass [kg], I_zz [kg m^2]); std: their standard deviations from the
    curvature at the optimum, start velocities profiled out (residuals treated as
    independent, so optimistic); determined: per parameter, whether the data at
    least halve the prior's variance (else the value is essentially the prior's
    and is marked "prior"); mu is not determined when the simulation sticks in every window in which
    the object moved.
    effect [EFFECT_SIZE], effect_std: the fitted effect vector (zeros where no effect was
    fitted; see apply_sliding_effects) and the standard deviations of its fitted slots.
    rmse_position_m, rmse_heading_rad: windowed replay at theta over the fitted
    windows, each started at its fitted velocity.
    loss_history: objective per evaluation.
    """

    theta: np.ndarray
    std: np.ndarray
    determined: tuple[bool, bool, bool]
    rmse_position_m: float
    rmse_heading_rad: float
    window_count: int
    evaluations: int
    loss_history: list = field(default_factory=list)
    correction: np.ndarray | None = None
    """Fitted start-velocity corrections per window [W, 3]: vx, vy [m/s], yaw rate [rad/s]."""
    effect: np.ndarray = field(default_factory=lambda: np.zeros(EFFECT_SIZE))
    effect_std: np.ndarray = field(default_factory=lambda: np.zeros(EFFECT_SIZE))
    sliding_windows: int = 0
    """Windows in which the simulation at theta slides where the measured object moves (`sliding_windows`);
    with none while the object moved, mu is a lower bound and not determined."""

    def provenance(self) -> dict:
        names = ("friction", "mass", "izz")
        return {
            "theta": dict(zip(names, map(float, self.theta))),
            "std": dict(zip(names, map(float, self.std))),
            "determined_by_data": dict(zip(names, self.determined)),
            "windows": self.window_count,
            "sliding_windows": self.sliding_windows,
            "evaluations": self.evaluations,
            "rmse_position_m": self.rmse_position_m,
            "rmse_heading_rad": self.rmse_heading_rad,
        }


def sliding_windows(rollout: SlidingRollout, theta, correction=None, effect=None) -> tuple[np.ndarray, np.ndarray]:
    """Per window: whether the measured object still moves over the window's second half (at least
    config.moving_speed_m_s on average), and whether the simulation at theta then slides too: at least half
    the measured travel (x, y and the heading as an arc at the face's half diagonal), at a measured speed
    of at least twice the slip speed mu g dt of Newton's penalty friction, below which it moves any body.

    A force-driven Coulomb model of a slow push balances on a knife edge: below the force over m g the
    object accelerates, above it it sticks, after coasting off its start velocity. Where the real object kept
    moving, a fit that sticks in every window has found the smallest mu that holds it, a lower bound, and
    its curvature is that of sliding below the bound, not a measurement of mu.
    """
    simulated = rollout.trajectories(theta, correction, effect)
    measured = rollout.windows.measured
    half = measured.shape[0] // 2
    span_s = (measured.shape[0] - 1 - half) * rollout.windows.sample_period_s

    def travel(track):
        return _planar_travel(track[-1] - track[half], rollout.yaw_length_m)

    moving = travel(measured) >= rollout.config.moving_speed_m_s * span_s
    # below twice the penalty friction's slip speed (mu g dt) a simulated body moves in its viscous branch,
    # whatever mu: that is creep of the step, not Coulomb sliding
    coulomb = travel(measured) >= 2.0 * float(theta[0]) * GRAVITY_M_S2 * rollout.windows.dt_s * span_s
    return moving, moving & coulomb & (travel(simulated) >= 0.5 * travel(measured))


def replay_errors(rollout: SlidingRollout, theta, correction=None, effect=None) -> tuple[float, float]:
    """Position RMSE [m] and heading RMSE [rad] of the windowed replay at theta."""
    r = rollout.residuals(theta, correction, effect)
    return float(np.sqrt(np.mean(np.sum(r[..., :2] ** 2, axis=-1)))), float(
        np.sqrt(np.mean(r[..., 2] ** 2)) / rollout.yaw_length_m
    )


_EFFECT_SCALE = np.array([0.05, 0.05, 0.5, 1e-3, 0.005, 0.002, 0.002])
"""Typical sizes of the effect slots (force offset [N], drag [N s/m], turning drag [N m s], delay [s],
contact offset [m]): the optimiser's units."""


def _effect_bounds(config: SlidingConfig) -> tuple:
    """Drag is passive (it only takes energy out); a delay stays within the force kept beyond the windows; a
    contact offset within 2 cm (a calibration, not a different contact)."""
    return ((-5.0, 5.0), (-5.0, 5.0), (0.0, 50.0), (0.0, 0.5), (-config.max_delay_s, config.max_delay_s),
            (-0.02, 0.02), (-0.02, 0.02))


def friction_start(rollout: SlidingRollout, theta, mu_bounds: tuple[float, float], coarse: int = 17,
                   fine: int = 9) -> float:
    """The mu a gradient fit starts from: the best of a log scan over `mu_bounds`, refined between the best
    point's neighbours, at theta's mass and I_zz.

    Across stick and slip the loss in mu has plateaus and kinks: started from a prior above the truth, most
    windows stick, the gradient is zero or a line search fails, and L-BFGS-B returns the start (a MuJoCo
    push fitted at its prior, mu +10 %). A scan costs a forward rollout per point."""
    def loss(mu):
        return float(np.sum(rollout.residuals(np.r_[mu, theta[1:]]) ** 2))

    grid = np.geomspace(*mu_bounds, coarse)
    best = int(np.argmin([loss(mu) for mu in grid]))
    grid = np.geomspace(grid[max(best - 1, 0)], grid[min(best + 1, coarse - 1)], fine)
    return float(grid[int(np.argmin([loss(mu) for mu in grid]))])


def identify_sliding(
    windows: PushWindows,
    body: PlanarBody,
    config: SlidingConfig,
    mu_prior: float = 0.3,
    free: tuple[bool, bool, bool] = (True, True, True),
    device: str = "cpu",
    effects: tuple[str, ...] = (),
) -> SlidingFit:
    """Fit theta = (mu, m, I_zz), and the parameters of `effects` (names of EFFECT_SLOTS), to the
    windows by L-BFGS-B on the tape's gradient.

    The objective is the pose loss over sigma^2 (sigma: the fit's own residual
    RMS, refitted once) plus the log-normal prior of m and I_zz; mu and the
    effects have only their bounds. `free` freezes parameters at their prior
    (e.g. free=(True, False, False)).
    """
    from scipy.optimize import minimize

    rollout = SlidingRollout(windows, body, config, device)
    W = windows.window_count
    prior = np.log([mu_prior, body.mass_kg, body.izz_kgm2])
    prior_std = np.array([np.inf, body.mass_rel_std, body.izz_rel_std])
    prior_curv = np.where(np.isfinite(prior_std), 1.0 / prior_std**2, 0.0)
    lo = np.log([config.mu_bounds[0], body.mass_kg / 4, body.izz_kgm2 / 4])
    hi = np.log([config.mu_bounds[1], body.mass_kg * 4, body.izz_kgm2 * 4])
    free_idx = np.flatnonzero(free)
    slots = [k for name in effects for k in EFFECT_SLOTS[name]]
    k = len(free_idx)
    g = k + len(slots)  # global parameters: free theta (log) and effect slots (in _EFFECT_SCALE units)
    # corrections are optimised in units of a typical start-rate error: 1 cm/s and 0.1 rad/s
    c_scale = np.tile([0.01, 0.01, 0.1], W)
    history: list[float] = []
    n_res = windows.sample_count * W * 3

    def split(x):
        u = prior.copy()
        u[free_idx] = x[:k]
        e = np.zeros(EFFECT_SIZE)
        e[slots] = x[k:g] * _EFFECT_SCALE[slots]
        return u, e, (x[g:] * c_scale).reshape(W, 3)

    def data_gradient(x, sigma2):
        u, e, c = split(x)
        theta = np.exp(u)
        loss, g_theta, g_c, g_e = rollout.loss_and_grad(theta, c, e)
        return 0.5 * loss / sigma2, np.concatenate([(0.5 * g_theta * theta / sigma2)[free_idx],
                                                    0.5 * g_e[slots] * _EFFECT_SCALE[slots] / sigma2,
                                                    0.5 * g_c.ravel() * c_scale / sigma2])

    def objective(x, sigma2):
        value, grad = data_gradient(x, sigma2)
        u, _, _ = split(x)
        value += 0.5 * np.sum(prior_curv * (u - prior) ** 2)
        grad[:k] += (prior_curv * (u - prior))[free_idx]
        history.append(float(value))
        return value, grad

    # the data's weight against the prior is 1 / sigma^2: fitted at a typical tracker error first,
    # then again at the residual level that fit leaves
    x = np.concatenate([prior[free_idx], np.zeros(len(slots)), np.zeros(3 * W)])
    bounds = (list(zip(lo[free_idx], hi[free_idx]))
              + [(a / sc, b / sc) for a, b, sc in ((*_effect_bounds(config)[j], _EFFECT_SCALE[j]) for j in slots)]
              + [(-20.0, 20.0)] * (3 * W))
    def fit(x):
        sigma2 = (1e-3) ** 2
        for _ in range(2):
            x = minimize(objective, x, args=(sigma2,), jac=True, method="L-BFGS-B", bounds=bounds,
                         options={"maxiter": config.max_iterations, "ftol": 1e-10, "gtol": 1e-8}).x
            u, e, c = split(x)
            sigma2 = max(float(np.sum(rollout.residuals(np.exp(u), c, e) ** 2)) / n_res, 1e-12)
        return x, sigma2

    if free[0]:
        x[0] = np.log(friction_start(rollout, np.exp(prior), config.mu_bounds))
    x, sigma2 = fit(x)
    u, effect, correction = split(x)
    theta = np.exp(u)
    moving, slides = sliding_windows(rollout, theta, correction, effect)
    if free[0] and moving.any() and not slides.any():
        # stuck: on that plateau the gradient in mu is zero (newton.md), so a sliding fit below it is found by
        # a scan, and the fit restarted from the scan's best if that beats sticking
        scan = np.geomspace(config.mu_bounds[0], theta[0], 13)[:-1]
        losses = [float(np.sum(rollout.residuals(np.r_[mu, theta[1:]], correction, effect) ** 2)) for mu in scan]
        if min(losses) < sigma2 * n_res:
            x[0] = np.log(scan[int(np.argmin(losses))])
            x, sigma2 = fit(x)
            u, effect, correction = split(x)
            theta = np.exp(u)
            moving, slides = sliding_windows(rollout, theta, correction, effect)

    # curvature of the data term, Gauss-Newton: J^T J / sigma^2 from central differences of the residuals.
    # Across stick and slip the loss has kinks, where differences of the gradient gave an indefinite
    # Hessian (a MuJoCo push: mu reported undetermined while six windows slid); J^T J is never indefinite.
    # Each window's corrections touch only its own residuals, so three perturbations (one per component, all
    # windows at once) give their Jacobian blocks; the globals take one each.
    h = 1e-2
    n = g + 3 * W

    def jacobian_column(step):
        u_p, e_p, c_p = split(x + step)
        u_m, e_m, c_m = split(x - step)
        return (rollout.residuals(np.exp(u_p), c_p, e_p) - rollout.residuals(np.exp(u_m), c_m, e_m)) / (2 * h)

    J_t = np.stack([jacobian_column(np.eye(n)[j] * h) for j in range(g)], axis=-1)  # [S, W, 3, g]
    J_c = np.zeros((*J_t.shape[:3], 3))  # [S, W, 3, 3]: each window's residuals by its own corrections
    for comp in range(3):
        step = np.zeros(n)
        step[g + comp::3] = h
        J_c[..., comp] = jacobian_column(step)
    J_t = J_t.transpose(1, 0, 2, 3).reshape(W, -1, g) / np.sqrt(sigma2)
    J_c = J_c.transpose(1, 0, 2, 3).reshape(W, -1, 3) / np.sqrt(sigma2)
    # the globals' information with every window's start velocity profiled out (Schur complement)
    H = sum(J_t[w].T @ J_t[w] - (J_t[w].T @ J_c[w]) @ np.linalg.pinv(J_c[w].T @ J_c[w]) @ (J_c[w].T @ J_t[w])
            for w in range(W))
    H = 0.5 * (H + H.T)
    H_post = H + np.diag(np.r_[prior_curv[free_idx], np.zeros(len(slots))])
    cov = np.linalg.pinv(H_post)
    var = np.maximum(np.diag(cov), 0.0)
    std_log = np.array(prior_std, dtype=float)
    # a parameter the loss is flat in (e.g. mu while every window sticks) has no curvature: unknown, not exact
    std_log[free_idx] = np.where(np.diag(H_post)[:k] > 1e-12, np.sqrt(var[:k]), np.inf)
    # a simulated object that sticks in every window, where the real one moved, only bounds mu from below: the
    # curvature there is the cost of sliding at a smaller mu, not a measurement of mu
    sliding = int(np.sum(slides))
    if moving.any() and sliding == 0:
        std_log[0] = np.inf
    # determined: the data at least halve the prior's variance (mu has no prior: determined when it has curvature)
    determined = tuple(bool(free[i] and np.isfinite(std_log[i])
                            and (not np.isfinite(prior_std[i]) or std_log[i] ** 2 < 0.5 * prior_std[i] ** 2))
                       for i in range(3))
    std = theta * np.where(np.isfinite(std_log), std_log, 0.0)
    effect_std = np.zeros(EFFECT_SIZE)
    effect_std[slots] = np.sqrt(var[k:g]) * _EFFECT_SCALE[slots]
    rmse_p, rmse_h = replay_errors(rollout, theta, correction, effect)
    return SlidingFit(theta, std, determined, rmse_p, rmse_h, W, len(history), history, correction=correction,
                      effect=effect, effect_std=effect_std, sliding_windows=sliding)


def quasi_static_friction(recording, body: PlanarBody, config: SlidingConfig, bias: ForceBias,
                          mass_kg: float) -> float:
    """The lab's estimate, mu = steady pushing force / (m g).

    "Steady pushing": the object slides and the pusher presses (force above a
    quarter of its 90th percentile); the median horizontal force over those
    samples. It ignores inertia and the force that turns the object, so it
    reads high while the object accelerates and low while it turns.
    """
    windows = push_windows(recording, body, config, bias)
    f = np.linalg.norm(windows.window_force, axis=-1).ravel()
    pressing = f > 0.25 * np.percentile(f, 90)
    return float(np.median(f[pressing]) / (mass_kg * GRAVITY_M_S2))


@dataclass(frozen=True)
class WrenchBalance:
    """Result of `wrench_balance_friction`: mu and its standard deviation (least squares over the
    windows' balances), mu per window, and the RMS of the balance left [N] (moments over the face's half
    diagonal), the measure of how well Coulomb friction under uniform pressure explains the pushes."""

    mu: float
    std: float
    per_window: np.ndarray
    residual_n: float

    def provenance(self) -> dict:
        return {"mu": self.mu, "std": self.std, "per_window": self.per_window.tolist(), "residual_n": self.residual_n}


def steady_windows(windows: PushWindows, body: PlanarBody, config: SlidingConfig) -> np.ndarray:
    """Per window, whether the object slides throughout it: it travels at least config.moving_speed_m_s on
    average and ten times the tracker's scatter about a quadratic in time, at least half a third of its
    travel over each third, and at its start and end at least half its mean speed (travel: x, y and the
    heading as an arc at the face's half diagonal)."""
    m = windows.measured
    scatter = _scatter_about_quadratic(m[..., :2])
    arc = float(np.hypot(*body.half_extents_m[:2]))
    span_s = windows.span_s
    whole = _planar_travel(m[-1] - m[0], arc)
    thirds = np.all([_planar_travel(m[b] - m[a], arc) >= whole / 6 for a, b in _thirds(m.shape[0])], axis=0)
    start, end = windows.start[:, 3:6], _end_twist(windows, config)
    mean_speed = whole / span_s
    return ((whole >= np.maximum(config.moving_speed_m_s * span_s, 10.0 * scatter)) & thirds
            & (_planar_travel(start, arc) >= 0.5 * mean_speed) & (_planar_travel(end, arc) >= 0.5 * mean_speed))


def _end_twist(windows: PushWindows, config: SlidingConfig) -> np.ndarray:
    """x, y rates [m/s] and yaw rate [rad/s] at each window's end [W, 3], by the quadratic fit that gives its
    start's (`local_twist`), one-sided over as many samples as the start's centred one."""
    S = windows.sample_count
    t = np.arange(S + 1) * windows.sample_period_s
    out = []
    for m in np.moveaxis(windows.measured, 1, 0):
        rot = Rotation.from_rotvec(np.c_[np.zeros((S + 1, 2)), m[:, 2]])
        twist = local_twist(t, np.c_[m[:, :2], np.zeros(S + 1)], rot, S, 2 * config.twist_half_width)
        out.append([twist[0], twist[1], twist[5]])
    return np.asarray(out)


def wrench_balance_friction(windows: PushWindows, body: PlanarBody, config: SlidingConfig) -> WrenchBalance | None:
    """mu from each window's balance of the pushing wrench, the momentum change and Coulomb friction.

    Over a window, the mean pushing force and its moment about the COM, less the change of momentum, equal
    mu times the friction wrench that the window's mean twist (from its measured end poses) draws from the
    support grid of the simulation (uniform pressure): linear in mu, solved by least squares. It needs no
    simulation, so unlike a force-driven rollout it does not balance on the knife edge of a slow push (a
    Coulomb object under a force a little below or above mu m g sticks or accelerates), and it holds for
    pushes that turn the object, where steady force over m g (`quasi_static_friction`) does not.
    Only windows in which the object slides throughout (`steady_windows`) are used: a window's mean twist
    stands for its friction only then (a push in strokes, which stops the object, has few or none). None
    when there is no such window.
    """
    balance = _balance_rows(windows, body, config)
    if balance is None:
        return None
    X, y = balance
    mu = float(np.sum(X * y) / np.sum(X * X))
    residual = y - mu * X
    dof = max(X.size - 1, 1)
    std = float(np.sqrt(np.sum(residual**2) / dof / np.sum(X * X)))
    per_window = np.sum(X * y, axis=1) / np.sum(X * X, axis=1)
    return WrenchBalance(mu, std, per_window, float(np.sqrt(np.mean(residual**2))))


def wrench_balance_error(windows: PushWindows, body: PlanarBody, config: SlidingConfig, mu: float) -> float | None:
    """RMS [N] by which friction `mu` misses the steady windows' wrench balance (moments over the face's half
    diagonal): the pushing wrench predicted from the measured motion, where a force-driven replay of a slow
    push cannot predict the motion. None without a steady window."""
    balance = _balance_rows(windows, body, config)
    if balance is None:
        return None
    X, y = balance
    return float(np.sqrt(np.mean((y - mu * X) ** 2)))


def _pushing_moment(windows: PushWindows) -> tuple[np.ndarray, np.ndarray]:
    """Per window, the mean moment of the pushing force about the measured COM [N m], and the mean of its size."""
    com = np.repeat(windows.measured[:-1, :, :2], windows.substeps, axis=0)
    arm, f = windows.contact - com, windows.window_force
    moment = arm[..., 0] * f[..., 1] - arm[..., 1] * f[..., 0]
    return moment.mean(axis=0), np.abs(moment).mean(axis=0)


@dataclass(frozen=True)
class TurnCheck:
    """Result of `turn_check`, per window: the turn [rad], the pushing moment and the mean friction moment the
    turn requires [N m], whether friction would have to drive the turn (no mu explains the window at the
    body's I_zz), and the I_zz at which the required friction moment is zero [kg m^2] (an I_zz beyond it, the
    other way from the body's, would let friction oppose the turn; inf where none would)."""

    turn_rad: np.ndarray
    pushing_nm: np.ndarray
    friction_nm: np.ndarray
    drives_turn: np.ndarray
    izz_balance_kgm2: np.ndarray


def turn_check(windows: PushWindows, body: PlanarBody, config: SlidingConfig, margin: float = 0.1) -> TurnCheck:
    """Whether each window's turn can come from its pushing moment at any friction coefficient.

    Over a window the friction moment about the COM is the change of angular momentum less the pushing moment.
    Coulomb friction under a pressure symmetric about the COM opposes the turn at every instant (the unit-slip
    map is monotone: the friction moments of the points r and -r sum against the rotation), so in a window in
    which the object turns one way and the required friction moment has the turn's sign, by more than `margin`
    of the mean pushing moment's size, no mu explains it: the pushing moment's arm (contact point, force
    direction), the COM or the pressure's symmetry is off. "Turns one way": each third of the window turns the
    way the whole does, which turns ten times the heading's scatter about a quadratic in time (an object that
    does not turn can hold any moment below its friction's).
    """
    yaw = windows.measured[..., 2]
    turn = yaw[-1] - yaw[0]
    scatter = _scatter_about_quadratic(yaw)
    one_way = np.all([np.sign(yaw[b] - yaw[a]) == np.sign(turn) for a, b in _thirds(len(yaw))], axis=0)
    pushing, size = _pushing_moment(windows)
    spin_up = (_end_twist(windows, config)[:, 2] - windows.start[:, 5]) / windows.span_s
    friction = body.izz_kgm2 * spin_up - pushing
    drives = one_way & (np.abs(turn) >= 10 * scatter) & (friction * np.sign(turn) > margin * size)
    with np.errstate(divide="ignore", invalid="ignore"):
        balance = np.where(pushing / spin_up > 0, pushing / spin_up, np.inf)
    return TurnCheck(turn, pushing, friction, drives, balance)


def _balance_rows(windows: PushWindows, body: PlanarBody, config: SlidingConfig):
    """Per steady window, the friction wrench per unit mu (X) and the momentum change less the pushing wrench
    (y), world x, y [N] and the moment over the face's half diagonal [N]; None without a steady window."""
    hx, hy, _ = body.half_extents_m
    grid = _support_points(body, config)
    normal_n = body.mass_kg * GRAVITY_M_S2 / len(grid)
    lever_m = float(np.hypot(hx, hy))
    span_s = windows.span_s
    steady = np.flatnonzero(steady_windows(windows, body, config))
    if not len(steady):
        return None
    ends = _end_twist(windows, config)
    moments, _ = _pushing_moment(windows)
    rows, targets = [], []
    for w in steady:
        m = windows.measured[:, w]
        v, omega = (m[-1, :2] - m[0, :2]) / span_s, (m[-1, 2] - m[0, 2]) / span_s
        yaw = 0.5 * (m[0, 2] + m[-1, 2])
        c, s_ = np.cos(yaw), np.sin(yaw)
        r = grid @ np.array([[c, s_], [-s_, c]])  # support points about the COM, world axes
        slip = v[None] + omega * np.c_[-r[:, 1], r[:, 0]]
        u = slip / np.maximum(np.linalg.norm(slip, axis=1), 1e-12)[:, None]
        friction = np.r_[-normal_n * u.sum(0), -normal_n * np.sum(r[:, 0] * u[:, 1] - r[:, 1] * u[:, 0]) / lever_m]
        start, end = windows.start[w, 3:6], ends[w]
        f = windows.window_force[:, w]
        change = np.r_[body.mass_kg * (end[:2] - start[:2]), body.izz_kgm2 * (end[2] - start[2]) / lever_m] / span_s
        rows.append(friction)
        targets.append(change - np.r_[f.mean(0), moments[w] / lever_m])
    return np.asarray(rows), np.asarray(targets)


def measured_friction(fit: SlidingFit, balance: WrenchBalance | None) -> tuple[float, float, str] | None:
    """mu, its standard deviation and what measured it: the sliding fit where it determined mu, else (its
    simulation stuck throughout: a bound) the wrench balance; None when neither measured it."""
    if fit.determined[0]:
        return float(fit.theta[0]), float(fit.std[0]), "sliding fit"
    if balance is not None:
        return balance.mu, balance.std, "wrench balance"
    return None


@dataclass(frozen=True)
class SupportChoice:
    """Which support model (`SUPPORTS`) `identify_pushed` kept, and why.

    support: the model kept; evaluated_on: "held-out recording" or "trial halves" (each half of every
    trial's windows predicted by a fit on the other half); per candidate, the prediction's position RMSE
    [m], heading RMSE [rad] and loss (sum of squared x, y and arc residuals [m^2]) on those windows.
    """

    support: str
    evaluated_on: str
    rmse_position_m: dict
    rmse_heading_rad: dict
    loss_m2: dict

    @property
    def words(self) -> str:
        """The choice in a sentence (asset.json provenance, the build's log)."""
        other = [s for s in self.loss_m2 if s != self.support]
        told = ", ".join(f"{s}: {1e3 * self.rmse_position_m[s]:.2f} mm, {np.degrees(self.rmse_heading_rad[s]):.2f} deg"
                         for s in (self.support, *other))
        margin = min((self.loss_m2[s] / max(self.loss_m2[self.support], 1e-30) for s in other), default=1.0)
        return (f"support {self.support!r}: its fit predicts the {self.evaluated_on} better ({told}; the next "
                f"best's squared error is {margin:.2f}x)")

    def provenance(self) -> dict:
        return {"model": self.support, "chosen_by": self.evaluated_on, "why": self.words,
                "rmse_position_m": self.rmse_position_m, "rmse_heading_rad": self.rmse_heading_rad,
                "loss_m2": self.loss_m2}


def _take(windows: PushWindows, mask: np.ndarray) -> PushWindows:
    return PushWindows(windows.dt_s, windows.substeps, windows.t_start_s[mask], windows.start[mask],
                       windows.force[:, mask], windows.contact[:, mask], windows.measured[:, mask],
                       windows.force_margin)


def _prediction(fit_on: PushWindows, check: PushWindows, body: PlanarBody, config: SlidingConfig, mu_prior: float,
                device: str) -> tuple[SlidingFit, np.ndarray]:
    """The fit on `fit_on` and its residuals [S, W, 3] predicting `check` (windows started at their measured
    velocities), at the friction `measured_friction` reports."""
    fit = identify_sliding(fit_on, body, config, mu_prior=mu_prior, free=(True, config.fit_mass, True), device=device)
    measured = measured_friction(fit, wrench_balance_friction(fit_on, body, config))
    theta = np.r_[measured[0] if measured is not None else fit.theta[0], fit.theta[1:]]
    return fit, SlidingRollout(check, body, config, device).residuals(theta)


def choose_support(windows: PushWindows, check: PushWindows | None, body: PlanarBody, mu_prior: float,
                   config: SlidingConfig, supports: tuple[str, ...] = SUPPORTS,
                   device: str = "cpu") -> tuple[SupportChoice, dict] | None:
    """Fit each support model of `supports` and keep the one that predicts better: the held-out windows
    `check` from a fit on all of `windows`, or without them each half of `windows` (in time) from a fit on
    the other. Returns the choice and, with `check`, the fits on all windows per support (so the kept one
    is not fitted twice); None when there is nothing to predict (one window, no held-out recording)."""
    if check is None:
        W = windows.window_count
        if W < 2:
            return None
        first = np.arange(W) < W / 2
        folds = [(_take(windows, first), _take(windows, ~first)), (_take(windows, ~first), _take(windows, first))]
    else:
        folds = [(windows, check)]
    fits, residuals = {}, {}
    for support in supports:
        c = replace(config, support=support)
        runs = [_prediction(a, b, body, c, mu_prior, device) for a, b in folds]
        if check is not None:
            fits[support] = runs[0][0]
        residuals[support] = np.concatenate([r for _, r in runs], axis=1)
    length = config.yaw_length_m or float(np.hypot(*body.half_extents_m[:2]))
    loss = {s: float(np.sum(r**2)) for s, r in residuals.items()}
    chosen = min(loss, key=loss.get)
    choice = SupportChoice(
        chosen, "held-out recording" if check is not None else "trial halves",
        {s: float(np.sqrt(np.mean(np.sum(r[..., :2] ** 2, axis=-1)))) for s, r in residuals.items()},
        {s: float(np.sqrt(np.mean(r[..., 2] ** 2)) / length) for s, r in residuals.items()}, loss)
    return choice, fits


@dataclass(frozen=True)
class PushedIdentification:
    """What `identify_pushed` gives the build.

    fit: the sliding fit on the trials; biases: the force offset per trial;
    baseline and final: (position RMSE [m], heading RMSE [rad], loss [m^2]) of the
    windowed replay at the prior's and the fitted theta (mu as `measured_friction` gives it), on the
    held-out recording when there is one, else on the trials; traces: the replay for the report
    (positions and headings);
    balance: the quasi-static wrench balance on the trials (None without a steady window), the
    measurement of mu where the fit's simulation sticks throughout (a slow push); turns: `turn_check` of
    the trials' windows. Where some window turns against its pushing moment, the turning has a cause the
    model lacks, and the I_zz a fit needs to follow it is a stand-in for that cause, not the body's
    inertia (`turns_explained`).
    config: the settings the fit ran with, `support` the model kept; support: how it was chosen
    (`choose_support`; None when there was one candidate, or nothing to predict).
    """

    fit: SlidingFit
    prior_theta: np.ndarray
    biases: list
    baseline: tuple[float, float, float]
    final: tuple[float, float, float]
    traces: dict
    config: SlidingConfig
    balance: WrenchBalance | None = None
    turns: TurnCheck | None = None
    support: SupportChoice | None = None

    @property
    def turns_explained(self) -> bool:
        """Whether every window's turn is one its pushing moment can give: only then can a fit measure I_zz."""
        return self.turns is None or not bool(self.turns.drives_turn.any())

    def provenance(self) -> dict:
        from dataclasses import asdict

        turns = None if self.turns is None else {
            "windows_against": int(self.turns.drives_turn.sum()), "windows": len(self.turns.drives_turn),
            "izz_balance_kgm2": [float(v) for v in self.turns.izz_balance_kgm2[self.turns.drives_turn]],
            "izz_fitted_kgm2": float(self.fit.theta[2]), "turns_explained": self.turns_explained}
        return {"kind": "sliding", **self.fit.provenance(), "prior_theta": list(map(float, self.prior_theta)),
                "force_bias_world": [b.provenance() for b in self.biases],
                "wrench_balance": self.balance.provenance() if self.balance else None,
                "turn_check": turns, "config": asdict(self.config),
                "support": self.support.provenance() if self.support else {
                    "model": self.config.support, "chosen_by": "setting",
                    "why": f"support {self.config.support!r}: the setting (SlidingConfig.support), not chosen from the data"}}


def identify_pushed(trials, holdout, body: PlanarBody, mu_prior: float, config: SlidingConfig,
                    device: str = "cpu", supports: tuple[str, ...] = ()) -> PushedIdentification:
    """Fit mu (with m and I_zz where the pushes determine them) on all trials; replay the holdout.

    supports: support models (`SUPPORTS`) to choose among: each is fitted and the one that predicts the
    held-out pushes better is kept (`choose_support`; without a holdout, the trials' halves each other),
    `config.support` is replaced by it in the result. Empty or one: `config.support` without a choice.
    """
    biases = [estimate_force_bias(r, config) for r in trials]
    windows = concat_push_windows([push_windows(r, body, config, b) for r, b in zip(trials, biases)])
    check = windows
    if holdout is not None:
        check = push_windows(holdout, body, config, estimate_force_bias(holdout, config))
    chosen, fit = None, None
    if len(set(supports)) > 1:
        found = choose_support(windows, check if holdout is not None else None, body, mu_prior, config,
                               tuple(dict.fromkeys(supports)), device)
        if found is not None:
            chosen, fits = found
            config = replace(config, support=chosen.support)
            fit = fits.get(chosen.support)
    if fit is None:
        fit = identify_sliding(windows, body, config, mu_prior=mu_prior, free=(True, config.fit_mass, True),
                               device=device)
    balance = wrench_balance_friction(windows, body, config)
    prior_theta = np.array([mu_prior, body.mass_kg, body.izz_kgm2])
    # replayed at the friction reported: where the fit only bounds mu, the wrench balance's
    measured = measured_friction(fit, balance)
    final_theta = np.r_[measured[0] if measured is not None else fit.theta[0], fit.theta[1:]]
    rollout = SlidingRollout(check, body, config, device)
    metrics, paths = {}, {}
    for name, theta in (("baseline", prior_theta), ("final", final_theta)):
        r = rollout.residuals(theta)
        p, h = replay_errors(rollout, theta)
        metrics[name] = (p, h, float(np.sum(r**2)))
        paths[name] = rollout.trajectories(theta)
    S = check.sample_count
    t = (check.t_start_s[None, :] + config.sample_period_s * np.arange(S + 1)[:, None]).ravel()

    def xyz(a):
        return np.c_[a[..., :2].reshape(-1, 2), np.zeros(len(t))]

    traces = {"t_s": t, "window_s": S * config.sample_period_s,
              "replayed": "held-out recording" if holdout is not None else "fitted trials",
              **{f"{k}_position": xyz(a) for k, a in (("measured", check.measured), *paths.items())},
              **{f"{k}_heading_rad": a[..., 2].ravel() for k, a in (("measured", check.measured), *paths.items())}}
    return PushedIdentification(fit, prior_theta, biases, metrics["baseline"], metrics["final"], traces, config,
                                balance, turn_check(windows, body, config), chosen)
