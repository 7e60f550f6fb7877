"""The joint model that identification, diagnosis and synthesis share, stepped in Newton's Featherstone."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from assets import Inertial, Pose
from pipelines.sim.joint import (
    FRICTION_SMOOTHING,
    JOINT_EFFECT_SIZE,
    add_jointed_part,
    apply_joint_effort_and_passive_forces,
    joint_dynamics,
    joint_turns,
)


def _simulate(joint_type: str, axis, origin, body: Inertial, effort: np.ndarray, friction: float,
              effect: np.ndarray, dt: float, steps: int, qd0: float = 0.0) -> np.ndarray:
    """q [steps + 1, worlds] of one part per world under a constant effort per world, started at q' = qd0."""
    import newton

    worlds = len(effort)
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    for _ in range(worlds):
        add_jointed_part(builder, joint_type, axis, origin, Pose((0.0, 0.0, 0.0)), body)
    model = builder.finalize(device="cpu")
    solver = newton.solvers.SolverFeatherstone(model, angular_damping=0.0)
    s0, s1, control = model.state(), model.state(), model.control()
    s0.joint_qd.fill_(qd0)
    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    arrays = [wp.array(effort[None], dtype=float), 0, worlds, wp.array(np.full(worlds, friction), dtype=float),
              wp.array(np.tile(effect, (worlds, 1)).astype(np.float32), dtype=float),
              wp.array(np.tile(joint_dynamics(joint_type, axis, origin, Pose((0.0, 0.0, 0.0)), body), (worlds, 1)),
                       dtype=wp.vec3)]
    q = [s0.joint_q.numpy().copy()]
    for _ in range(steps):
        wp.launch(apply_joint_effort_and_passive_forces, dim=worlds,
                  inputs=[*arrays, joint_turns(joint_type), dt, FRICTION_SMOOTHING, s0.joint_q, s0.joint_qd],
                  outputs=[control.joint_f])
        solver.step(s0, s1, control, None, dt)
        s0, s1 = s1, s0
        q.append(s0.joint_q.numpy().copy())
    return np.array(q)


def test_friction_holds_a_drawer_below_breakaway_and_yields_above():
    """A drawer at rest pushed with half its Coulomb friction holds (creeping no faster than eps atanh(1/2));
    pushed with twice it, it accelerates at (F - f_c) / m, at any step the controller rates use."""
    m, f_c = 1.1, 1.5
    body = Inertial(m, (0.0, 0.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    effect = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0])
    assert effect.shape == (JOINT_EFFECT_SIZE,)
    for dt, steps in ((1e-3, 200), (5e-3, 40)):
        q = _simulate("prismatic", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), body, np.array([0.5 * f_c, 2.0 * f_c]), f_c,
                      effect, dt, steps)
        t = dt * steps
        assert np.max(np.abs(q[:, 0])) < 1.01 * FRICTION_SMOOTHING * np.arctanh(0.5) * t
        assert q[-1, 1] == pytest.approx(0.5 * (2.0 * f_c - f_c) / m * t * t, rel=0.05)


def test_door_held_by_friction_against_gravity_and_spring():
    """A door on a tilted hinge, its gravity moment and a closer spring together below the friction: it holds.
    With the friction halved below them, it turns."""
    body = Inertial(2.0, (0.2, 0.0, 0.0), np.diag([0.02, 0.05, 0.05]))
    axis = np.array([0.0, np.sin(0.2), np.cos(0.2)])
    dynamics = joint_dynamics("revolute", axis, (0.0, 0.0, 0.0), Pose((0.0, 0.0, 0.0)), body)
    spring = np.array([0.0, 3.0, 0.6, 0.0, 1.0, 0.0])  # k 3 N m/rad, rest at 0.2 rad: 0.6 N m at q = 0
    load = abs(dynamics[1] + spring[2])
    held = _simulate("revolute", axis, (0.0, 0.0, 0.0), body, np.zeros(1), 1.5 * load, spring, 2e-3, 250)
    assert np.max(np.abs(held)) < 1e-3
    turned = _simulate("revolute", axis, (0.0, 0.0, 0.0), body, np.zeros(1), 0.5 * load, spring, 2e-3, 250)
    assert np.max(np.abs(turned)) > 0.05


def test_damping_and_stribeck_excess_act_at_speed():
    """A drawer pushed hard reaches the speed where effort = f_c + b v (Stribeck excess gone at v >> v_s)."""
    m, f_c, b, push = 1.0, 1.0, 4.0, 5.0
    body = Inertial(m, (0.0, 0.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    effect = np.array([b, 0.0, 0.0, 2.0, 0.01, 0.0])
    q = _simulate("prismatic", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), body, np.array([push]), f_c, effect, 1e-3, 3000)
    v_end = (q[-1, 0] - q[-101, 0]) / 0.1
    assert v_end == pytest.approx((push - f_c) / b, rel=0.01)


@pytest.mark.parametrize("lag", [0.0, 0.01])
def test_friction_grips_with_its_lag(lag):
    """A sliding drawer whose friction far exceeds any load comes to rest as q'' = -q' / (lag + dt): it travels
    v0 lag, and a rigid grip (lag 0) stops it within its first step (both less the creep of the smoothed law)."""
    m, v0, dt = 1.0, 0.05, 1e-3
    body = Inertial(m, (0.0, 0.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    effect = np.array([0.0, 0.0, 0.0, 0.0, 1.0, lag])
    q = _simulate("prismatic", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), body, np.zeros(1), 100.0, effect, dt, 200, qd0=v0)
    assert q[-1, 0] == pytest.approx(v0 * lag, rel=0.02, abs=0.02 * v0 * dt)
    assert q[-1, 0] == pytest.approx(q[-2, 0], abs=1e-9)
