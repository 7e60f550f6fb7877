"""`twin bench crlb`: the spread of our estimates (least squares and the Newton fit) against the
Cramer-Rao bound, per parameter.

The bound here is computed with the motion known exactly (the simulation's own
kinematics) and only the wrench sensor's noise: white, Gaussian, its variance
the sensor's noise plus quantisation (q^2 / 12). Knowing the motion exactly is
more information than any estimator has, so this bound is at or below the true
one, and the efficiencies reported against it are at or below the true ones.
"""

from __future__ import annotations

import numpy as np


def _exact_regressor(motion, grasp):
    """Regressor at the wrench samples from the simulated (noise-free) motion of the tracked frame."""
    from scipy.spatial.transform import Rotation

    from pipelines.identify.least_squares import GRAVITY_M_S2, newton_euler_regressor

    dt = motion.t_s[1] - motion.t_s[0]
    rot = Rotation.from_quat(motion.grasp_quat_xyzw)
    acc = np.gradient(np.gradient(motion.grasp_position_m, dt, axis=0), dt, axis=0)
    omega = (rot[2:] * rot[:-2].inv()).as_rotvec() / (2 * dt)
    omega = np.vstack([omega[:1], omega, omega[-1:]])
    alpha = np.gradient(omega, dt, axis=0)
    k = np.rint(motion.t_wrench_s / dt).astype(int)
    k = k[(k > 2) & (k < len(motion.t_s) - 3)]
    inv = rot[k].inv()
    return newton_euler_regressor(inv.apply(acc[k] - GRAVITY_M_S2), inv.apply(omega[k]), inv.apply(alpha[k]))


def _true_pi(truth, grasp) -> np.ndarray:
    """(m, m c, I about the tracked origin) in tracked-frame axes."""
    X = grasp.inverse()  # object frame in the tracked frame
    R, c = X.rotation_matrix(), np.asarray(X.position) + X.rotation_matrix() @ np.asarray(truth.com)
    I_o = R @ truth.inertia_matrix() @ R.T + truth.mass * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array([truth.mass, *(truth.mass * c), I_o[0, 0], I_o[1, 1], I_o[2, 2], I_o[0, 1], I_o[0, 2], I_o[1, 2]])


def bench_crlb(draws: int = 20, duration_s: float = 10.0) -> list[dict]:
    from scipy.spatial.transform import Rotation, Slerp

    from assets import Inertial, Pose
    from assets.materials import material_range
    from pipelines.identify import IdentifyConfig, InertialBounds, identify_free_body, identify_least_squares, make_windows
    from pipelines.identify.held import newton_starts
    from pipelines.identify.least_squares import object_frame_from_pi
    from pipelines.priors import uniform_density_prior
    from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held
    from twin.bench.paper import paper_objects

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
        A = _exact_regressor(motion, grasp)
        w = np.array([1 / var_f] * 3 + [1 / var_tau] * 3)
        fisher = np.einsum("nik,i,nil->kl", A, w, A)
        _, J = object_frame_from_pi(_true_pi(truth, grasp), grasp.inverse())
        bound = J @ np.linalg.inv(fisher) @ J.T

        prior = uniform_density_prior(mesh.copy(), material_range(None))
        bounds = InertialBounds(prior.lower, prior.upper)
        config = IdentifyConfig()
        estimates: dict = {"least squares": [], "newton": []}
        for d in range(draws):
            tp, pos, quat, tw, f, tq = measure(motion, noise, np.random.default_rng(d))
            rot = Slerp(tp, Rotation.from_quat(quat))(np.clip(tw, tp[0], tp[-1]))
            data = (tp, pos, quat, tw, rot.apply(f), rot.apply(tq))
            ls = identify_least_squares(*data, grasp.inverse()).inertial
            windows = make_windows(*data, window_s=config.window_s, substeps=config.substeps,
                                   smoothing_hz=config.smoothing_hz)
            starts = newton_starts(ls, prior.inertial, bounds, config)
            fit = identify_free_body(windows, grasp.inverse(), starts, bounds, config).inertial
            for label, est in (("least squares", ls), ("newton", fit)):
                estimates[label].append([est.mass, *np.diag(est.inertia_matrix())])
        true = np.array([truth.mass, *np.diag(truth.inertia_matrix())])
        for label, values in estimates.items():
            values = np.asarray(values)
            for j, param in enumerate(names):
                bound_std = float(np.sqrt(bound[index[j], index[j]]))
                observed_std = float(values[:, j].std(ddof=1))
                rows.append({
                    "object": name, "estimator": label, "parameter": param,
                    "bound_std_pct": 100 * bound_std / true[j], "observed_std_pct": 100 * observed_std / true[j],
                    "bias_pct": float(100 * (values[:, j].mean() / true[j] - 1)),
                    "efficiency": bound_std**2 / observed_std**2,
                })
    print(f"{'object':7} {'estimator':13} {'param':6} {'bound std %':>11} {'observed std %':>14} {'bias %':>7} "
          f"{'efficiency':>10}")
    for r in rows:
        print(f"{r['object']:7} {r['estimator']:13} {r['parameter']:6} {r['bound_std_pct']:11.3f} "
              f"{r['observed_std_pct']:14.3f} {r['bias_pct']:+7.3f} {r['efficiency']:10.3f}")
    return rows
