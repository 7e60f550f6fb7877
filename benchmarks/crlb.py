"""`twin bench crlb`: the spread of our estimates (least squares and the Newton fit) against the
Cramer-Rao bound, per parameter.

Two bounds, both from the Fisher information of white Gaussian sensor noise
(the sensor's variance plus quantisation, q^2 / 12):

- exact motion: only the wrench is noisy and the motion is known exactly (the
  simulation's own kinematics). No estimator knows that much, so this bound is
  below the true one.
- unknown motion (errors in variables): the motion is unknown too, a smooth
  perturbation of the true one (a cubic B-spline per pose axis, knots every
  `knot_s`), and the tracker's poses measure it. The regressor then carries the
  tracker's noise as any estimator's does; the bound on the inertial parameters
  is the Schur complement of the joint Fisher information. It assumes the
  motion smooth at the knot scale, which is knowledge a low-pass filter
  also assumes.

With a few dozen draws an observed variance is itself uncertain (+-22 % at
40). The "reference" estimator, weighted least squares on the true
kinematics, attains the exact-motion bound; its variance over the same draws
checks the bound, and the paired efficiency, unknown-motion bound over an
estimator's variance with the reference's variance on the same draws
standing in for the exact-motion bound, removes most of that sampling noise.
"""

from __future__ import annotations

import numpy as np


def _exact_kinematics(motion):
    """At the wrench samples of the simulated (noise-free) motion of the tracked frame: sample times [s],
    rotation to world, and in tracked-frame axes the acceleration minus gravity [m/s^2], angular velocity
    [rad/s] and angular acceleration [rad/s^2]; also the angular velocity in world axes."""
    from scipy.spatial.transform import Rotation

    from assets.conventions import GRAVITY_M_S2

    dt = motion.t_s[1] - motion.t_s[0]
    rot = Rotation.from_quat(motion.grasp_quat_xyzw)
    acc = np.gradient(np.gradient(motion.grasp_position_m, dt, axis=0), dt, axis=0)
    omega = (rot[2:] * rot[:-2].inv()).as_rotvec() / (2 * dt)
    omega = np.vstack([omega[:1], omega, omega[-1:]])
    alpha = np.gradient(omega, dt, axis=0)
    k = np.rint(motion.t_wrench_s / dt).astype(int)
    k = k[(k > 2) & (k < len(motion.t_s) - 3)]
    inv = rot[k].inv()
    return (motion.t_s[k], rot[k], inv.apply(acc[k] - GRAVITY_M_S2), inv.apply(omega[k]), inv.apply(alpha[k]),
            omega[k])


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices [N, 3, 3] of vectors [N, 3]."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    return out - np.swapaxes(out, -1, -2)


def _unknown_motion_bound(motion, pi: np.ndarray, A: np.ndarray, w: np.ndarray, noise, knot_s: float) -> np.ndarray:
    """Bound [10, 10] on pi with the motion unknown (see the module docstring).

    A [K, 6, 10]: the exact regressor; w [6]: inverse wrench variances. The wrench's
    sensitivity to a pose perturbation is linearised at the truth: a world rotation
    delta(t) of the tracked frame changes (a - g) in its axes by R^T [a - g]x delta, its
    angular velocity by R^T delta', its angular acceleration by R^T (delta'' - omega x delta');
    a translation changes the acceleration by its second derivative.
    """
    from scipy import sparse
    from scipy.interpolate import BSpline
    from scipy.sparse.linalg import splu

    t_w, rot, u, omega_b, alpha_b, omega_world = _exact_kinematics(motion)
    m, h = pi[0], pi[1:4]
    Ixx, Iyy, Izz, Ixy, Ixz, Iyz = pi[4:]
    I_o = np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]])
    K = len(t_w)
    H, Wx = _skew(np.broadcast_to(h, (K, 3))), _skew(omega_b)
    # d wrench / d (u, omega_b, alpha_b), each [K, 6, 3]
    D_u = np.concatenate([np.broadcast_to(m * np.eye(3), (K, 3, 3)), H], axis=1)
    D_omega = np.concatenate([-Wx @ H - _skew(np.cross(omega_b, h)), Wx @ I_o - _skew(omega_b @ I_o)], axis=1)
    D_alpha = np.concatenate([-H, np.broadcast_to(I_o, (K, 3, 3))], axis=1)
    RT = rot.inv().as_matrix()  # [K, 3, 3]
    world_u = rot.apply(u)  # a - g in world axes

    t0, t1 = motion.t_s[0], motion.t_s[-1]
    knots = np.arange(t0 - 3 * knot_s, t1 + 4 * knot_s, knot_s)

    def design(t, order):
        basis = BSpline.design_matrix(np.clip(t, knots[3], knots[-4]), knots, 3).tocsc()
        if order == 0:
            return basis
        n = basis.shape[1]
        cols = [BSpline(knots, np.eye(n)[j], 3).derivative(order)(t) for j in range(n)]
        return sparse.csc_matrix(np.stack(cols, axis=1))

    Phi = [design(t_w, order) for order in range(3)]
    blocks = []  # columns per pose axis: x y z translation, then x y z rotation (world)
    for axis in range(6):
        e = np.eye(3)[axis % 3]
        if axis < 3:
            M = [np.zeros((K, 6)), np.zeros((K, 6)), (D_u @ (RT @ e)[..., None])[..., 0]]
        else:
            M = [(D_u @ (RT @ np.cross(world_u, e)[..., None]))[..., 0],
                 (D_omega @ (RT @ e)[..., None] - D_alpha @ (RT @ np.cross(omega_world, e)[..., None]))[..., 0],
                 (D_alpha @ (RT @ e)[..., None])[..., 0]]
        rows = [sum(sparse.diags(M[o][:, c]) @ Phi[o] for o in range(3)) for c in range(6)]
        blocks.append(sparse.vstack([r.multiply(np.sqrt(w[c])) for c, r in enumerate(rows)]).tocsc())
    G = sparse.hstack(blocks).tocsc()  # [6K, 6 n_basis], rows component-major, weighted
    Aw = np.concatenate([A[:, c, :] * np.sqrt(w[c]) for c in range(6)], axis=0)

    t_pose = np.arange(noise.pose_time_offset_s, t1, 1.0 / noise.pose_rate_hz)
    P = design(t_pose, 0)
    pose_w = [1 / noise.position_sigma_m**2] * 3 + [1 / noise.rotation_sigma_rad**2] * 3
    F_cc = (G.T @ G + sparse.block_diag([pose_w[a] * (P.T @ P) for a in range(6)])).tocsc()
    F_cp = G.T @ Aw
    F_pp = Aw.T @ Aw
    return np.linalg.inv(F_pp - F_cp.T @ splu(F_cc).solve(np.asarray(F_cp)))


def _true_pi(truth, grasp) -> np.ndarray:
    """(m, m c, I about the tracked origin) in tracked-frame axes."""
    X = grasp.inverse()  # object frame in the tracked frame
    R, c = X.rotation_matrix(), np.asarray(X.position) + X.rotation_matrix() @ np.asarray(truth.com)
    I_o = R @ truth.inertia_matrix() @ R.T + truth.mass * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array([truth.mass, *(truth.mass * c), I_o[0, 0], I_o[1, 1], I_o[2, 2], I_o[0, 1], I_o[0, 2], I_o[1, 2]])


def jointed_effort_design(obj, motion, noise) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """The equation of motion of a one-joint motion known exactly, per F/T sample (the wrench held over each
    sensor period [t, t + dt], stamped at its centre): effort = columns @ (M, [m d along, across the true first
    moment], f_c), with M (q'(t + dt) - q'(t)) / dt, Q_g at the period's middle and f_c sign(q'). Returns (names of
    `jointed_truth`'s quantities each column measures, columns [K, P], the effort's noise variance [K] from the
    sensor's (variance plus quantisation, isotropic in its axes, through the lever arm), moving [K])."""
    from scipy.spatial.transform import Rotation

    from assets.conventions import GRAVITY_M_S2

    held = motion.held
    dt = held.t_wrench_s[1] - held.t_wrench_s[0]
    t = np.floor(held.t_wrench_s / dt) * dt  # the start of the period each reading's stamp falls in
    q = np.interp(t + dt / 2, held.t_s, motion.q)
    qd = np.interp(t, held.t_s, motion.qd)
    qdd = (np.interp(t + dt, held.t_s, motion.qd) - qd) / dt
    a = np.asarray(obj.axis, dtype=float)
    force_var = noise.force_sigma_n**2 + noise.force_resolution_n**2 / 12
    torque_var = noise.torque_sigma_nm**2 + noise.torque_resolution_nm**2 / 12
    if obj.joint_type == "prismatic":
        names, columns, var = ["mass"], [qdd - GRAVITY_M_S2 @ a], np.full(len(t), force_var)
    else:
        r = grasp_positions(held, t) - np.asarray(obj.origin_m)
        names, columns = ["axis_inertia"], [qdd]
        var = torque_var + force_var * np.sum(np.cross(a, r) ** 2, axis=1)
        if np.linalg.norm(np.cross(a, GRAVITY_M_S2)) > 1e-3 * np.linalg.norm(GRAVITY_M_S2):  # a tilted axis
            r_com = np.asarray(obj.position_m) - np.asarray(obj.origin_m)
            u = r_com - a * (a @ r_com)
            u /= np.linalg.norm(u)
            turn = Rotation.from_rotvec(np.outer(q, a))
            names += ["gravity_moment", "gravity_moment_across"]
            columns += [-(np.cross(turn.apply(e), GRAVITY_M_S2) @ a) for e in (u, np.cross(a, u))]
    names.append("friction")
    columns.append(np.sign(qd))
    return names, np.stack(columns, 1), var, np.abs(qd) > 1e-3 * np.max(np.abs(qd))


def grasp_positions(held, t_s: np.ndarray) -> np.ndarray:
    """The grasp frame's origin [K, 3] at times t_s (the simulation's samples nearest them)."""
    index = np.clip(np.rint(np.interp(t_s, held.t_s, np.arange(len(held.t_s)))).astype(int), 0, len(held.t_s) - 1)
    return np.asarray(held.grasp_position_m)[index]


def jointed_exact_motion_bound(obj, motion, noise) -> dict:
    """Exact-motion Cramer-Rao bound on what a one-joint motion determines: standard deviations of
    `jointed_truth`'s quantities in their units, from the F/T sensor's noise alone with the motion known
    exactly (`jointed_effort_design`). Every estimator's spread is at least this; one that also reads the
    motion from a tracker sits above it."""
    names, columns, var, moving = jointed_effort_design(obj, motion, noise)
    cov = np.linalg.inv(columns[moving].T @ (columns[moving] / var[moving, None]))
    return {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(names) if n != "gravity_moment_across"}


def bench_crlb(draws: int = 20, duration_s: float = 10.0, knot_s: float = 0.025) -> list[dict]:
    from scipy.spatial.transform import Rotation, Slerp

    from assets import Inertial, Pose
    from assets.materials import material_range
    from pipelines.identify import IdentifyConfig, InertialBounds, identify_free_body, identify_least_squares, make_windows
    from pipelines.identify.held import newton_starts
    from pipelines.identify.least_squares import newton_euler_regressor, object_frame_from_pi
    from pipelines.priors import uniform_density_prior
    from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held
    from benchmarks.paper import paper_objects

    noise = SensorNoise()
    var_f = noise.force_sigma_n**2 + noise.force_resolution_n**2 / 12
    var_tau = noise.torque_sigma_nm**2 + noise.torque_resolution_nm**2 / 12
    names = ("mass", "Ixx", "Iyy", "Izz")
    index = [0, 4, 5, 6]
    rows = []
    for k, (name, (mesh, mass)) in enumerate(paper_objects().items()):
        mesh = mesh.copy()
        mesh.density = mass / mesh.volume
        truth = Inertial(mass, (0.0, 0.0, 0.0), mesh.moment_inertia)
        half_height = 0.5 * (mesh.bounds[1, 2] - mesh.bounds[0, 2])
        placement, grasp = Pose((0.5, 0.0, half_height)), Pose((0.0, 0.0, half_height), (1.0, 0.0, 0.0, 0.0))
        motion = simulate_held(truth, placement, grasp, HeldMotionConfig(duration_s=duration_s),
                               np.random.default_rng(1000 + k))
        t_exact, _, u, omega_b, alpha_b, _ = _exact_kinematics(motion)
        A = newton_euler_regressor(u, omega_b, alpha_b)
        exact_rows = np.isin(np.round(motion.t_wrench_s, 9), np.round(t_exact, 9))
        w = np.array([1 / var_f] * 3 + [1 / var_tau] * 3)
        fisher = np.einsum("nik,i,nil->kl", A, w, A)
        pi = _true_pi(truth, grasp)
        _, J = object_frame_from_pi(pi, grasp.inverse())
        exact_bound = J @ np.linalg.inv(fisher) @ J.T
        bound = J @ _unknown_motion_bound(motion, pi, A, w, noise, knot_s) @ J.T

        prior = uniform_density_prior(mesh.copy(), material_range(None))
        bounds = InertialBounds(prior.lower, prior.upper)
        config = IdentifyConfig()
        estimates: dict = {"least squares": [], "newton": [], "reference": []}
        for d in range(draws):
            # each object its own noise draws, so that its spread is independent of the others'
            tp, pos, quat, tw, f, tq = measure(motion, noise, np.random.default_rng(10_000 * k + d))
            rot = Slerp(tp, Rotation.from_quat(quat))(np.clip(tw, tp[0], tp[-1]))
            data = (tp, pos, quat, tw, rot.apply(f), rot.apply(tq))
            ls = identify_least_squares(*data, grasp.inverse()).inertial
            windows = make_windows(*data, window_s=config.window_s, substeps=config.substeps,
                                   smoothing_hz=config.smoothing_hz)
            starts = newton_starts(ls, prior.inertial, bounds, config)
            fit = identify_free_body(windows, grasp.inverse(), starts, bounds, config).inertial
            # the estimator that attains the exact-motion bound: weighted least squares on the true kinematics
            b = np.concatenate([f[exact_rows], tq[exact_rows]], axis=1) * np.sqrt(w)
            pi_ref = np.linalg.lstsq((A * np.sqrt(w)[None, :, None]).reshape(-1, 10), b.reshape(-1), rcond=None)[0]
            reference = object_frame_from_pi(pi_ref, grasp.inverse())[0]
            for label, est in (("least squares", ls), ("newton", fit), ("reference", reference)):
                estimates[label].append([est.mass, *np.diag(est.inertia_matrix())])
        true = np.array([truth.mass, *np.diag(truth.inertia_matrix())])
        reference_var = np.asarray(estimates["reference"]).var(axis=0, ddof=1)
        for label, values in estimates.items():
            values = np.asarray(values)
            for j, param in enumerate(names):
                exact_std = float(np.sqrt(exact_bound[index[j], index[j]]))
                bound_std = float(np.sqrt(bound[index[j], index[j]]))
                observed_std = float(values[:, j].std(ddof=1))
                rows.append({
                    "object": name, "estimator": label, "parameter": param,
                    "exact_motion_bound_std_pct": 100 * exact_std / true[j],
                    "bound_std_pct": 100 * bound_std / true[j], "observed_std_pct": 100 * observed_std / true[j],
                    "bias_pct": float(100 * (values[:, j].mean() / true[j] - 1)),
                    "exact_motion_efficiency": exact_std**2 / observed_std**2,
                    "efficiency": bound_std**2 / observed_std**2,
                    # the reference's variance stands in for the exact-motion bound on the same draws
                    "paired_efficiency": float(bound_std**2 / exact_std**2 * reference_var[j] / observed_std**2),
                })
    print(f"{'object':7} {'estimator':13} {'param':6} {'bound std % (exact motion)':>26} {'(unknown motion)':>16} "
          f"{'observed std %':>14} {'bias %':>7} {'efficiency (exact)':>18} {'(unknown)':>9} {'(paired, unknown)':>17}")
    for r in rows:
        print(f"{r['object']:7} {r['estimator']:13} {r['parameter']:6} {r['exact_motion_bound_std_pct']:26.3f} "
              f"{r['bound_std_pct']:16.3f} {r['observed_std_pct']:14.3f} {r['bias_pct']:+7.3f} "
              f"{r['exact_motion_efficiency']:18.3f} {r['efficiency']:9.3f} {r['paired_efficiency']:17.3f}")
    return rows
