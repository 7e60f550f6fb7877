"""Warp kernels of free-body identification, each beside the launcher that runs it.

One Newton world per (parameter set, shooting window), set-major: body
b = k * W + w. The windows of set k share its ten inertial parameters theta[k];
each world has its own initial-state correction. Sets batch multi-start and
finite-difference Jacobians into one rollout. All kernels run on the tape so
gradients reach theta and the corrections.
"""

from __future__ import annotations

import warp as wp

from .inertia import inertial_from_theta


@wp.kernel
def assign_inertial_params(
    theta: wp.array2d[float],
    windows_per_set: int,
    body_mass: wp.array[float],
    body_inv_mass: wp.array[float],
    body_com: wp.array[wp.vec3],
    body_inertia: wp.array[wp.mat33],
    body_inv_inertia: wp.array[wp.mat33],
):
    """Write mass [kg], COM [m, body frame] and inertia [kg m^2] from its set's theta into each world's body.

    SemiImplicit integrates with the inverses, so those must carry the gradient.
    """
    b = wp.tid()
    m, com, inertia = inertial_from_theta(theta, b // windows_per_set)
    body_mass[b] = m
    body_inv_mass[b] = 1.0 / m
    body_com[b] = com
    body_inertia[b] = inertia
    body_inv_inertia[b] = wp.inverse(inertia)


def assign_inertial_params_to_model(theta: wp.array2d, windows_per_set: int, model) -> None:
    wp.launch(
        assign_inertial_params,
        dim=model.body_count,
        inputs=[theta, windows_per_set],
        outputs=[model.body_mass, model.body_inv_mass, model.body_com, model.body_inertia, model.body_inv_inertia],
        device=model.device,
    )


@wp.kernel
def set_window_start_state(
    tracked_pose: wp.array[wp.transform],
    tracked_twist: wp.array[wp.spatial_vector],
    correction: wp.array[wp.spatial_vector],
    correction_rate: wp.array[wp.spatial_vector],
    X_tracked_body: wp.transform,
    windows_per_set: int,
    body_com: wp.array[wp.vec3],
    body_q: wp.array[wp.transform],
    body_qd: wp.array[wp.spatial_vector],
):
    """Start each window's body at the measured tracked-frame pose and twist plus a correction.

    tracked_twist: (linear velocity of the tracked origin [m/s], angular velocity [rad/s]),
    world axes. correction: (position [m], rotation vector [rad]); correction_rate:
    (velocity [m/s], angular velocity [rad/s]). Newton's body_qd holds the COM's
    velocity, which depends on the COM being estimated.
    """
    b = wp.tid()
    w = b % windows_per_set
    X = tracked_pose[w]
    dx = wp.spatial_top(correction[b])
    dr = wp.spatial_bottom(correction[b])
    # first-order exponential map: smooth at zero, where the gradient must not vanish
    dq = wp.normalize(wp.quat(0.5 * dr[0], 0.5 * dr[1], 0.5 * dr[2], 1.0))
    X = wp.transform(wp.transform_get_translation(X) + dx, dq * wp.transform_get_rotation(X))
    Xb = X * X_tracked_body
    body_q[b] = Xb
    v = wp.spatial_top(tracked_twist[w]) + wp.spatial_top(correction_rate[b])
    omega = wp.spatial_bottom(tracked_twist[w]) + wp.spatial_bottom(correction_rate[b])
    r = wp.transform_point(Xb, body_com[b]) - wp.transform_get_translation(X)
    body_qd[b] = wp.spatial_vector(v + wp.cross(omega, r), omega)


@wp.kernel
def apply_measured_wrench(
    body_q: wp.array[wp.transform],
    body_com: wp.array[wp.vec3],
    X_body_tracked: wp.transform,
    wrench: wp.array2d[wp.spatial_vector],
    step: int,
    windows_per_set: int,
    body_f: wp.array[wp.spatial_vector],
):
    """Apply the measured wrench (force [N], torque [N m] about the tracked origin, world axes).

    Newton wants torque about the COM; the moment arm uses the current COM
    estimate so the gradient reaches it.
    """
    b = wp.tid()
    X = body_q[b]
    f = wp.spatial_top(wrench[step, b % windows_per_set])
    tau = wp.spatial_bottom(wrench[step, b % windows_per_set])
    arm = wp.transform_point(X, wp.transform_get_translation(X_body_tracked)) - wp.transform_point(X, body_com[b])
    body_f[b] = wp.spatial_vector(f, tau + wp.cross(arm, f))


EFFECT_SIZE = 9
"""Effect parameters per set: sensor bias force [N] and torque [N m] (tracked-frame axes), viscous
damping b [N s/m] and b_angular [N m s/rad], quadratic drag c [N s^2/m^2]."""


@wp.kernel
def apply_effect_wrench(
    body_q: wp.array[wp.transform],
    body_qd: wp.array[wp.spatial_vector],
    body_com: wp.array[wp.vec3],
    X_body_tracked: wp.transform,
    effect: wp.array2d[float],
    windows_per_set: int,
    body_f: wp.array[wp.spatial_vector],
):
    """Add the candidate effects to the applied wrench (world axes, about the COM).

    The sensor reads applied + bias in its own (tracked) axes, so the bias is taken off
    the measured wrench at the tracked origin; damping -b v_com, -b_angular omega and
    drag -c |v_com| v_com act at the COM.
    """
    b = wp.tid()
    k = b // windows_per_set
    X = body_q[b]
    R_tracked = wp.transform_get_rotation(X * X_body_tracked)
    bias_f = wp.quat_rotate(R_tracked, wp.vec3(effect[k, 0], effect[k, 1], effect[k, 2]))
    bias_tau = wp.quat_rotate(R_tracked, wp.vec3(effect[k, 3], effect[k, 4], effect[k, 5]))
    arm = wp.transform_point(X, wp.transform_get_translation(X_body_tracked)) - wp.transform_point(X, body_com[b])
    v = wp.spatial_top(body_qd[b])
    omega = wp.spatial_bottom(body_qd[b])
    f = -bias_f - effect[k, 6] * v - effect[k, 8] * wp.length(v) * v
    tau = -bias_tau - wp.cross(arm, bias_f) - effect[k, 7] * omega
    body_f[b] = body_f[b] + wp.spatial_vector(f, tau)


@wp.kernel
def eval_tracked_pose_error(
    body_q: wp.array[wp.transform],
    body_mass: wp.array[float],
    body_inertia: wp.array[wp.mat33],
    X_body_tracked: wp.transform,
    measured: wp.array2d[wp.transform],
    sample: int,
    momentum_scaled: int,
    windows_per_set: int,
    residual: wp.array3d[float],
):
    """Tracked-frame error per world: position [m], then rotation vector [rad], world axes.

    With momentum_scaled = 1 the position error is multiplied by the mass [kg m]
    and the rotation error by the world-frame inertia [kg m^2 rad]. The measured
    wrench drives the simulation, so its noise makes the simulated pose wander
    by noise / mass (or / inertia); an unscaled loss is smallest when the mass
    and inertia are too large, a bias that grows with the noise. Scaled, the
    noise-driven part no longer depends on the parameters: in effect the loss
    compares measured and predicted impulses, where the noise sits on the side
    that does not bias a least-squares fit.
    """
    b = wp.tid()
    X = body_q[b] * X_body_tracked
    Xm = measured[sample, b % windows_per_set]
    dp = wp.transform_get_translation(X) - wp.transform_get_translation(Xm)
    dq = wp.transform_get_rotation(X) * wp.quat_inverse(wp.transform_get_rotation(Xm))
    # 2 vec(dq) is the rotation vector for small angles; the sign picks the short way round
    s = wp.where(dq[3] < 0.0, -2.0, 2.0)
    dr = wp.vec3(dq[0], dq[1], dq[2]) * s
    if momentum_scaled != 0:
        R = wp.quat_to_matrix(wp.transform_get_rotation(body_q[b]))
        dp = body_mass[b] * dp
        dr = R * body_inertia[b] * wp.transpose(R) * dr
    for k in range(3):
        residual[sample, b, k] = dp[k]
        residual[sample, b, 3 + k] = dr[k]


@wp.kernel
def eval_weighted_squares(
    residual: wp.array3d[float],
    weight: wp.array2d[float],
    loss: wp.array[float],
):
    """loss += sum of weight[j, k] * residual[j, w, k]^2 over sample j, window w, channel k."""
    j, w, k = wp.tid()
    r = residual[j, w, k]
    wp.atomic_add(loss, 0, weight[j, k] * r * r)


# columns of the Gauss-Newton blocks: theta (10) and one window's start corrections (12)
NORMAL_COLUMNS = 22
vec_columns = wp.types.vector(length=NORMAL_COLUMNS, dtype=float)
mat_columns = wp.types.matrix(shape=(NORMAL_COLUMNS, NORMAL_COLUMNS), dtype=float)


@wp.kernel
def eval_window_normal_equations(
    residual: wp.array3d[float],
    sqrt_weight: wp.array2d[float],
    step: wp.array2d[float],
    windows_per_set: int,
    sets_per_point: int,
    gram: wp.array2d[mat_columns],
    jtr: wp.array2d[vec_columns],
):
    """Per point k and window w, from a central-difference rollout: J^T J and J^T r of the weighted
    residuals, J column a = (r(+step a) - r(-step a)) / (2 step a).

    Sets of point k: k P (the point), k P + 1 + a (+step a), k P + 1 + n + a (-step a). Assembled
    here so that only 22 x 22 numbers per window leave the device, not the residuals.
    """
    k, w = wp.tid()
    n = NORMAL_COLUMNS
    base = k * sets_per_point
    point = base * windows_per_set + w
    G = mat_columns()
    g = vec_columns()
    for s in range(sqrt_weight.shape[0]):
        for c in range(6):
            j = vec_columns()
            for a in range(n):
                plus = (base + 1 + a) * windows_per_set + w
                minus = (base + 1 + n + a) * windows_per_set + w
                difference = residual[s + 1, plus, c] - residual[s + 1, minus, c]
                j[a] = difference * sqrt_weight[s, c] / (2.0 * step[k, a])
            G += wp.outer(j, j)
            g += j * (residual[s + 1, point, c] * sqrt_weight[s, c])
    gram[k, w] = G
    jtr[k, w] = g
