"""Identify a held body's mass, COM and inertia from its motion and wrench, and check the tape's gradient.

A 20 g body is held at a grasp 2 cm above its COM and waved for 5 s (`pipelines.synth.held`: Newton's
integrator, the sensors' noise); its shooting windows are fitted by Levenberg-Marquardt in Newton from a start
2.5x too heavy. First, the gradient Warp's tape gives of the pose loss is compared with central differences:
a kernel that silently breaks the tape shows here as a zero or a wrong sign.

    python examples/identify_free_body.py          # prints the check and the fit
    python examples/identify_free_body.py --test   # and asserts them (tests/test_examples.py)
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from assets import Inertial, Pose
from pipelines.identify import IdentifyConfig, InertialBounds, identify_free_body, make_windows
from pipelines.identify.inertia import theta_from_physical
from pipelines.identify.rollout import FreeBodyRollout
from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held

MASS_KG = 0.02
COM_M = (0.001, -0.002, 0.0)
INERTIA_KG_M2 = np.diag([4.0e-6, 5.3e-6, 6.1e-6])
GRASP = Pose((0.0, 0.0, 0.02), (1.0, 0.0, 0.0, 0.0))
"""The tracked (grasp) frame in the body's [m, quaternion w x y z]."""


def record(seed: int = 3):
    """Poses and the world-axes wrench about the grasp of a held, waved body (tracker and F/T noise)."""
    truth = Inertial(MASS_KG, COM_M, INERTIA_KG_M2)
    motion = simulate_held(truth, Pose((0.5, 0.0, 0.02)), GRASP, HeldMotionConfig(duration_s=5.0, substeps=4),
                           np.random.default_rng(seed))
    tp, pos, quat, tw, force, torque = measure(motion, SensorNoise(), np.random.default_rng(seed + 1))
    turn = Slerp(tp, Rotation.from_quat(quat))(np.clip(tw, tp[0], tp[-1]))
    return truth, (tp, pos, quat, tw, turn.apply(force), turn.apply(torque))


def gradient_check(data) -> float:
    """Largest relative gap between the tape's gradient and central differences over mass, a first moment
    and an inertia entry of theta, at a point 1.5x off the truth."""
    windows = make_windows(*data, window_s=0.05, substeps=5, t_begin_s=1.0, t_end_s=1.5)
    rollout = FreeBodyRollout(windows, GRASP.inverse())
    theta = theta_from_physical(1.5 * MASS_KG, COM_M, 1.3 * INERTIA_KG_M2)
    weight = np.full((windows.sample_count, 6), 1.0 / windows.sample_count)
    worst = 0.0
    for scaled in (False, True):  # the plain pose loss (RigPI's), and the momentum-scaled one the fit uses
        _, grad, _, _ = rollout.loss_and_grad(theta[None], None, None, weight, scaled)
        for k in (0, 1, 7):
            step = np.zeros(10)
            step[k] = 1e-4
            plus = rollout.loss_and_grad((theta + step)[None], None, None, weight, scaled)[0][0]
            minus = rollout.loss_and_grad((theta - step)[None], None, None, weight, scaled)[0][0]
            central = (plus - minus) / 2e-4
            gap = abs(grad[0][k] - central) / max(abs(central), 1e-3 * np.abs(grad[0]).max())
            print(f"  {'momentum-scaled' if scaled else 'plain':15s} loss, theta[{k}]: tape {grad[0][k]:+.5e}, "
                  f"central difference {central:+.5e}")
            worst = max(worst, gap)
    return worst


def fit(data) -> Inertial:
    windows = make_windows(*data, window_s=0.1, substeps=5, t_begin_s=0.4)
    start = Inertial(2.5 * MASS_KG, (0.0, 0.0, 0.0), 2.0 * INERTIA_KG_M2)
    bounds = InertialBounds((0.002, -0.02, -0.02, -0.02, 1e-7, 1e-7, 1e-7), (0.2, 0.02, 0.02, 0.02, 1e-4, 1e-4, 1e-4))
    result = identify_free_body(windows, GRASP.inverse(), [start], bounds, IdentifyConfig())
    print(f"  {len(result.loss_history) - 1} iterations, loss {result.loss_history[0]:.3g} -> {result.loss_history[-1]:.3g}")
    return result.inertial


def main(test: bool = False) -> None:
    truth, data = record()
    print("gradient of the pose loss, Warp's tape against central differences:")
    gap = gradient_check(data)
    print("Newton fit from 2.5x the mass and 2x the inertia:")
    found = fit(data)
    mass_err = found.mass / truth.mass - 1
    com_err = float(np.linalg.norm(np.subtract(found.com, truth.com)))
    moments_err = np.diag(found.inertia_matrix()) / np.diag(INERTIA_KG_M2) - 1
    print(f"  mass {found.mass * 1e3:.3f} g ({100 * mass_err:+.2f} %), COM off by {com_err * 1e3:.3f} mm, "
          f"moments {np.array2string(100 * moments_err, precision=1)} %")
    if test:
        assert gap < 0.05, f"tape and central differences differ by {100 * gap:.1f} %"
        # the Newton fit alone carries the wrench noise that drives its simulation (docs/identification.md);
        # a build combines it with least squares and the geometry prior
        assert abs(mass_err) < 0.03, f"mass {100 * mass_err:+.2f} %"
        assert com_err < 1.5e-3, f"COM {com_err * 1e3:.2f} mm"
        assert np.all(np.abs(moments_err) < 0.2), f"moments {moments_err}"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--test", action="store_true", help="assert the gradient check and the fit")
    main(parser.parse_args().test)
