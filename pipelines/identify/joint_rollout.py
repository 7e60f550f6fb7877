"""Shooting windows of a part on one joint and their Newton rollout: the measured effort over each
Featherstone step, every window one articulation, every parameter variant one more copy of the windows."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from assets import Inertial, Pose
from assets.conventions import GRAVITY_M_S2

from pipelines.sim.joint import (
    JOINT_EFFECT_SIZE,
    add_jointed_part,
    apply_joint_effort_and_passive_forces,
    joint_dynamics,
    joint_turns,
)

from .kind import JointFit, joint_coordinates
from .windows import lowpass

if TYPE_CHECKING:
    from .jointed import JointedConfig


def joint_effort(recording, joint: JointFit) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, tau): the applied wrench projected on the joint [N or N m], at the wrench stamps.

    Prismatic: F.a. Revolute: a.(r x F + T) with r from the axis point to the
    tracked frame (where `Recording.wrench` takes its torque).
    """
    w = recording.wrench
    if joint.type == "prismatic":
        return w.t_s, w.force @ joint.axis
    p, _ = recording.pose.interpolate(w.t_s)
    return w.t_s, (np.cross(p - joint.origin, w.force) + w.torque) @ joint.axis


@dataclass(frozen=True)
class JointWindows:
    """Back-to-back shooting windows of one or more recordings (`joint_windows`)."""

    dt_s: float
    substeps: int
    q: np.ndarray          # [S+1, W] measured q at samples
    q_smoothed: np.ndarray  # [S+1, W] zero-phase low-passed q at samples
    t_s: np.ndarray        # [S, W] times of samples 1..S
    q_start: np.ndarray    # [W] smoothed
    qd_start: np.ndarray   # [W]
    effort: np.ndarray     # [steps, W] at each step's centre


def joint_windows(recording, joint: JointFit, config: JointedConfig) -> JointWindows:
    """Back-to-back windows of motion: measured q at the pose rate on a uniform grid, smoothed start
    states, and the joint effort over each Featherstone step.

    A reading is the wrench at its stamp (DESIGN.md: stamped t, it acted at t), a sensor's mean over its period
    stamped at the mean time of what it averages; each step takes the readings interpolated at its start. Featherstone's step is
    semi-implicit Euler, which moves q with the velocity after the step's kick, so a force taken at the step's start
    lands where exact integration puts it (leapfrog; the half-step start velocity this asks for is fitted per
    window). Taken at the step's centre it came half a step early, and held from its stamp half a period late: a
    gravity moment that changes with q turns either into a torque along or against the motion (a 2.5 kg oven
    door's friction came back -3 % or +7 %)."""
    t = recording.pose.t_s
    q = joint_coordinates(joint, recording.pose)
    period = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1], period)
    qg = np.interp(grid, t, q)
    qs = lowpass(qg, config.smoothing_hz, 1.0 / period)
    qds = np.gradient(qs, period)
    samples = int(round(config.window_s / period))
    moving = np.flatnonzero(np.abs(qds) > config.hold_speed)
    if len(moving) == 0:
        raise ValueError(f"{recording.path}: the joint never moves (|dq/dt| below {config.hold_speed})")
    t_wrench, tau = joint_effort(recording, joint)
    first = max(moving[0], int(np.searchsorted(grid, t_wrench[0])) + 1, 10)
    last = min(len(grid) - 10, int(np.searchsorted(grid, t_wrench[-1])) - 1)
    starts = np.arange(first, last - samples, samples)
    if len(starts) == 0:
        raise ValueError(f"{recording.path}: too short for one {config.window_s} s window of motion")
    dt = period / config.substeps
    steps = samples * config.substeps
    t_step = grid[starts][None, :] + dt * np.arange(steps)[:, None]
    sample_idx = starts[None, :] + np.arange(samples + 1)[:, None]
    return JointWindows(dt, config.substeps, qg[sample_idx], qs[sample_idx], grid[sample_idx[1:]], qs[starts],
                        qds[starts], np.interp(t_step, t_wrench, tau))


def concat_windows(parts: list[JointWindows]) -> JointWindows:
    return JointWindows(parts[0].dt_s, parts[0].substeps, np.concatenate([p.q for p in parts], 1),
                        np.concatenate([p.q_smoothed for p in parts], 1),
                        np.concatenate([p.t_s for p in parts], 1),
                        np.concatenate([p.q_start for p in parts]), np.concatenate([p.qd_start for p in parts]),
                        np.concatenate([p.effort for p in parts], 1))


class JointRollout:
    """V parameter variants x W windows, each a one-joint articulation in one Featherstone model."""

    def __init__(self, windows: JointWindows, variants: int, joint: JointFit, placement: Pose, prior: Inertial,
                 smoothing: float, device: str = "cpu"):
        import newton

        self.windows, self.V, self.device, self.smoothing = windows, variants, device, smoothing
        self.joint, self.placement = joint, placement
        W = windows.q.shape[1]
        builder = newton.ModelBuilder(gravity=tuple(GRAVITY_M_S2))
        for _ in range(variants * W):
            add_jointed_part(builder, joint.type, joint.axis, joint.origin, placement, prior)
        self.model = builder.finalize(device=device)
        self.solver = newton.solvers.SolverFeatherstone(self.model, angular_damping=0.0)
        self.states = [self.model.state(), self.model.state()]
        self.control = self.model.control()
        self.effort = wp.array(windows.effort.astype(np.float32), dtype=float, device=device)
        self.friction = wp.zeros(variants * W, dtype=float, device=device)
        self.effect = wp.zeros((variants * W, JOINT_EFFECT_SIZE), dtype=float, device=device)
        self.dynamics = wp.zeros(variants * W, dtype=wp.vec3, device=device)

    def run(self, inertials: list[Inertial], friction: np.ndarray, effect: np.ndarray, dq0: np.ndarray,
            dqd0: np.ndarray) -> np.ndarray:
        """q [S+1, V, W] of every window for each variant's body, friction [V], passive-force vector
        [V, JOINT_EFFECT_SIZE] and start offsets [V, W]."""
        import newton

        w = self.windows
        W = w.q.shape[1]
        model = self.model
        mass = np.repeat([i.mass for i in inertials], W)
        com = np.repeat([i.com for i in inertials], W, axis=0)
        inertia = np.repeat([i.inertia_matrix() for i in inertials], W, axis=0)
        model.body_mass.assign(mass.astype(np.float32))
        model.body_inv_mass.assign((1.0 / mass).astype(np.float32))
        model.body_com.assign(com.astype(np.float32))
        model.body_inertia.assign(inertia.astype(np.float32))
        model.body_inv_inertia.assign(np.linalg.inv(inertia).astype(np.float32))
        self.solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
        self.friction.assign(np.repeat(friction, W).astype(np.float32))
        self.effect.assign(np.repeat(effect, W, axis=0).astype(np.float32))
        j, placement = self.joint, self.placement
        self.dynamics.assign(np.repeat([joint_dynamics(j.type, j.axis, j.origin, placement, i) for i in inertials],
                                       W, axis=0).astype(np.float32))
        s0, s1 = self.states
        s0.joint_q.assign((w.q_start[None, :] + dq0).reshape(-1).astype(np.float32))
        s0.joint_qd.assign((w.qd_start[None, :] + dqd0).reshape(-1).astype(np.float32))
        newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
        S = w.q.shape[0] - 1
        out = np.zeros((S + 1, self.V * W))
        out[0] = s0.joint_q.numpy()
        for step in range(S * w.substeps):
            wp.launch(apply_joint_effort_and_passive_forces, dim=self.V * W,
                      inputs=[self.effort, step, W, self.friction, self.effect, self.dynamics,
                              joint_turns(self.joint.type), w.dt_s, self.smoothing, s0.joint_q, s0.joint_qd],
                      outputs=[self.control.joint_f], device=self.device)
            self.solver.step(s0, s1, self.control, None, w.dt_s)
            s0, s1 = s1, s0
            if (step + 1) % w.substeps == 0:
                out[(step + 1) // w.substeps] = s0.joint_q.numpy()
        self.states = [s0, s1]
        return out.reshape(S + 1, self.V, W)
