"""`twin bench throughput`: time per identification iteration, one object's windows and many batched.

One object is the 4 cm cube's 8 s recording cut into 0.1 s windows (one Newton
world each). N objects are N copies of those windows in one model, which is
the work of identifying N such objects at once (they share the rollout; the
per-object parameters are a matter of indexing). A Levenberg-Marquardt
iteration is what `levenberg_marquardt` runs per step from one start: one
rollout of the central-difference Jacobian (45 parameter sets side by side)
with its per-window normal equations assembled on the device, one taped
forward/backward pass for the gradient, one trial rollout.
"""

from __future__ import annotations

import time

import numpy as np


def bench_throughput(device: str = "cpu", object_counts: tuple[int, ...] = (1, 1024), repeats: int = 3) -> list[dict]:
    import warp as wp
    from scipy.spatial.transform import Rotation, Slerp

    from assets import Inertial, Pose
    from pipelines.identify import IdentifyConfig, concat_windows, make_windows
    from pipelines.identify.free_body import JACOBIAN_SETS, window_normal_equations
    from pipelines.identify.inertia import theta_from_physical
    from pipelines.identify.rollout import FreeBodyRollout
    from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held

    rng = np.random.default_rng(0)
    config = IdentifyConfig(device=device)
    truth = Inertial(0.02, (0.0, 0.0, 0.0), np.eye(3) * 0.02 * 0.04**2 / 6)
    grasp = Pose((0.0, 0.0, 0.02), (1.0, 0.0, 0.0, 0.0))
    motion = simulate_held(truth, Pose((0.5, 0.0, 0.02)), grasp, HeldMotionConfig(), rng)
    tp, pos, quat, tw, f, tq = measure(motion, SensorNoise(), rng)
    rot = Slerp(tp, Rotation.from_quat(quat))(np.clip(tw, tp[0], tp[-1]))
    one = make_windows(tp, pos, quat, tw, rot.apply(f), rot.apply(tq), window_s=config.window_s,
                       substeps=config.substeps, smoothing_hz=config.smoothing_hz)
    theta = theta_from_physical(truth.mass, truth.com, truth.inertia_matrix())[None]
    rows = []
    for count in object_counts:
        windows = concat_windows([one] * count)
        W = windows.window_count
        rollout = FreeBodyRollout(windows, grasp.inverse(), device=device)
        jacobian = FreeBodyRollout(windows, grasp.inverse(), sets=JACOBIAN_SETS, device=device, requires_grad=False)
        weight = np.ones((windows.sample_count, 6))
        zero = np.zeros((1, W, 6))

        def timed(run):
            for _ in range(2):  # compile, then capture on a GPU
                run()
            wp.synchronize_device(device)
            t0 = time.perf_counter()
            for _ in range(repeats):
                run()
            wp.synchronize_device(device)
            return (time.perf_counter() - t0) / repeats

        jac_s = timed(lambda: window_normal_equations(jacobian, theta, zero, zero, weight))
        grad_s = timed(lambda: rollout.loss_and_grad(theta, zero, zero, weight, True))
        forward_s = timed(lambda: rollout.residuals(theta, zero, zero))
        rows.append({"device": device, "objects": count, "worlds": W, "steps": windows.step_count,
                     "jacobian_s": jac_s, "forward_backward_s": grad_s, "forward_s": forward_s,
                     "iteration_s": jac_s + grad_s + forward_s})
    print(f"{'device':8} {'objects':>7} {'worlds':>7} {'steps':>5} {'Jacobian ms':>11} {'fwd+bwd ms':>10} "
          f"{'forward ms':>10} {'iteration ms':>12} {'per object ms':>13}")
    for r in rows:
        print(f"{r['device']:8} {r['objects']:7d} {r['worlds']:7d} {r['steps']:5d} {1e3 * r['jacobian_s']:11.1f} "
              f"{1e3 * r['forward_backward_s']:10.1f} {1e3 * r['forward_s']:10.1f} {1e3 * r['iteration_s']:12.1f} "
              f"{1e3 * r['iteration_s'] / r['objects']:13.2f}")
    return rows


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--objects", type=int, nargs="+", default=[1, 1024])
    args = parser.parse_args()
    bench_throughput(args.device, tuple(args.objects))
