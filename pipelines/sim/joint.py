"""A part on one joint (drawer, door) in Newton: the body on its joint and the joint's passive forces.

Identification, diagnosis and synthesis simulate the same joint, so its physics lives here once. Frames:
world, z up; q [m] along a prismatic axis or [rad] about a revolute one, the axis a world direction at q = 0.

The joint friction is Coulomb friction with an optional Stribeck breakaway, F(v) = f_c + (f_s - f_c)
exp(-(v / v_s)^2), opposing the motion as F(v) tanh(v / eps). It is solved implicitly over each step
(`joint_friction`): explicit, eps would have to exceed dt F / M to stay stable and a part would creep at up to
eps under any force below F. Solved implicitly, eps is a thousandth of the speeds a part moves at and a force
below F holds the part, as real joints do and as MuJoCo's frictionloss (a soft constraint) does.

The friction grips with a lag tau_f: within its bound F it brings q' to rest as q'' = -q' / (tau_f + dt), not
within one step. tau_f = 0 is a rigid grip; MuJoCo's frictionloss at its default solref grips with about
9.5 ms (q'' = -105 q'), and a real joint's pre-sliding compliance lets it give a little before it holds.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from assets import Inertial, Pose
from assets.conventions import GRAVITY_M_S2


FRICTION_SMOOTHING = 1e-3
"""eps of the friction law F(v) tanh(v / eps) [m/s or rad/s]: a part under a force P below F creeps at
eps atanh(P / F), at most a few millimetres per second."""

JOINT_EFFECT_SIZE = 6
"""Passive joint forces beyond the Coulomb friction, per world: damping b [N s/m or N m s/rad], stiffness k
[N/m or N m/rad], spring force k q0 [N or N m], Stribeck excess f_s - f_c [N or N m], Stribeck speed v_s
[m/s or rad/s] (1 where there is no excess), the friction's grip lag tau_f [s] (0: rigid)."""


@wp.func
def joint_friction(free_qd: float, grip_qd: float, compliance: float, friction: float, excess: float, speed: float,
                   smoothing: float) -> float:
    """Joint friction [N or N m] over one step, -F(v) tanh((v - grip_qd) / eps) at the speed v the step ends at:
    v = free_qd - compliance F(v) tanh((v - grip_qd) / eps).

    free_qd: q' at the step's end without friction [m/s or rad/s]; grip_qd: the speed the friction holds the
    step's end to while it grips (0 for a rigid grip, `passive_joint_force`); compliance: dt / M, the change of
    q' per unit force over the step. The left side less the right rises through zero once between
    free_qd -/+ compliance (f_c + |f_s - f_c|); 40 halvings find it to float precision."""
    reach = compliance * (friction + wp.abs(excess))
    lo = free_qd - reach
    hi = free_qd + reach
    for _ in range(40):
        v = 0.5 * (lo + hi)
        x = v / speed
        if v - free_qd + compliance * (friction + excess * wp.exp(-x * x)) * wp.tanh((v - grip_qd) / smoothing) > 0.0:
            hi = v
        else:
            lo = v
    v = 0.5 * (lo + hi)
    x = v / speed
    return -(friction + excess * wp.exp(-x * x)) * wp.tanh((v - grip_qd) / smoothing)


@wp.func
def passive_joint_force(q: float, qd: float, effort: float, friction: float, effect: wp.array2d[float], w: int,
                        dynamics: wp.vec3, turns: float, dt: float, smoothing: float) -> float:
    """Damping, spring and joint friction [N or N m] of world w under the effort [N or N m] over a step of dt [s]:
    -b q' - k q + k q0 + the friction that, with the effort and gravity, the step realizes (`joint_friction`),
    gripping towards q' tau_f / (tau_f + dt) (q'' = -q' / (tau_f + dt); a rigid grip at tau_f = 0).

    dynamics: M [kg or kg m^2] and the gravity load L1 cos(turns q) + L2 sin(turns q) [N or N m] of
    `joint_dynamics` (turns 1 on a revolute joint, 0 on a prismatic one)."""
    elastic = -effect[w, 0] * qd - effect[w, 1] * q + effect[w, 2]
    load = dynamics[1] * wp.cos(turns * q) + dynamics[2] * wp.sin(turns * q)
    free_qd = qd + dt * (effort + elastic + load) / dynamics[0]
    grip_qd = qd * effect[w, 5] / (effect[w, 5] + dt)
    return elastic + joint_friction(free_qd, grip_qd, dt / dynamics[0], friction, effect[w, 3], effect[w, 4],
                                    smoothing)


@wp.kernel
def apply_joint_effort_and_passive_forces(
    effort: wp.array2d[float],
    step: int,
    effort_count: int,
    friction: wp.array[float],
    effect: wp.array2d[float],
    dynamics: wp.array[wp.vec3],
    turns: float,
    dt: float,
    smoothing: float,
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    joint_f: wp.array[float],
):
    """Generalized force [N or N m] of world w's one joint: the effort effort[step, w % effort_count], held over
    the step of dt [s], plus the joint's passive forces. Worlds that repeat the same windows with other
    parameters share their efforts."""
    w = wp.tid()
    tau = effort[step, w % effort_count]
    joint_f[w] = tau + passive_joint_force(joint_q[w], joint_qd[w], tau, friction[w], effect, w, dynamics[w], turns,
                                           dt, smoothing)


def joint_turns(joint_type: str) -> float:
    """1 on a revolute joint, whose gravity load turns with q, 0 on a prismatic one (see `passive_joint_force`)."""
    return 1.0 if joint_type == "revolute" else 0.0


def joint_dynamics(joint_type: str, axis, origin, placement: Pose, inertial: Inertial) -> np.ndarray:
    """(M, L1, L2) of the part on its joint: M the inertia the joint moves [kg or kg m^2], constant about a
    fixed axis, and the gravity load along it, L1 cos q + L2 sin q [N m] on a revolute joint (a.(r(q) x m g),
    r from the axis to the COM), L1 = m g.a [N] on a prismatic one."""
    a, m = np.asarray(axis, dtype=float), inertial.mass
    if joint_type == "prismatic":
        return np.array([m, m * GRAVITY_M_S2 @ a, 0.0])
    R = placement.rotation_matrix()
    r = np.asarray(placement.position) + R @ np.asarray(inertial.com) - np.asarray(origin, dtype=float)
    r_perp = r - a * (a @ r)
    M = a @ R @ inertial.inertia_matrix() @ R.T @ a + m * r_perp @ r_perp
    return np.array([M, m * GRAVITY_M_S2 @ np.cross(a, r_perp), -m * GRAVITY_M_S2 @ r_perp])


def add_jointed_part(builder, joint_type: str, axis, origin, placement: Pose, inertial: Inertial) -> int:
    """Add the part as a body on a joint to the world, q = 0 at `placement`; returns the body index.

    The joint frame sits at `origin` with world axes in the parent and the same
    place in the body, so `axis` is a world direction at q = 0.
    """
    body = builder.add_link(
        xform=wp.transform(wp.vec3(*placement.position), wp.quat(*placement.quaternion_xyzw)),
        mass=inertial.mass, com=wp.vec3(*inertial.com),
        inertia=wp.mat33(*np.asarray(inertial.inertia).reshape(-1)), lock_inertia=True,
    )
    X_joint_world = Pose(tuple(origin))
    X_body_joint = placement.inverse() @ X_joint_world
    kwargs = dict(
        parent_xform=wp.transform(wp.vec3(*origin), wp.quat_identity()),
        child_xform=wp.transform(wp.vec3(*X_body_joint.position), wp.quat(*X_body_joint.quaternion_xyzw)),
        axis=wp.vec3(*axis),
    )
    add = builder.add_joint_prismatic if joint_type == "prismatic" else builder.add_joint_revolute
    joint = add(-1, body, **kwargs)
    builder.add_articulation([joint])
    return body
