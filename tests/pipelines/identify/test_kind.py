"""Kind of motion by BIC, and the joint's axis and point, on pose tracks with the tracker's noise."""


import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipelines.identify.kind import detect_kind
from pipelines.synth.jointed import noisy_pose_recording, random_joint_recording, smooth_signals

def test_kind_axis_and_point_on_20_random_jointed_cases():
    """Twenty random drawers and doors: the right joint, the axis within 1 degree, a revolute axis within 5 mm."""
    rng = np.random.default_rng(7)
    for case in range(20):
        joint_type = ("prismatic", "revolute")[case % 2]
        recording, axis, point = random_joint_recording(rng, joint_type)
        found = detect_kind(recording)
        assert found.kind == joint_type, (case, found.bic)
        angle = np.degrees(np.arccos(min(1.0, abs(found.joint.axis @ axis))))
        assert angle < 1.0, (case, angle)
        assert found.joint.axis_std_rad < np.radians(1.0)
        if point is not None:
            d = found.joint.origin - point
            assert np.linalg.norm(d - axis * (axis @ d)) < 0.005, case
        # +q opens: the observed travel is mostly positive
        assert np.mean(found.joint.q) > 0


def test_free_and_planar_motions_are_not_joints():
    """A held object turned in all six axes is free; one pushed in x, y and yaw on a table is sliding."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 4.0, 0.005)
    p = [0.5, 0.0, 0.3] + smooth_signals(rng, t, 0.1, 3)
    R = Rotation.from_rotvec(smooth_signals(rng, t, 0.6, 3))
    assert detect_kind(noisy_pose_recording(t, p, R, rng)).kind == "free"
    xy = smooth_signals(rng, t, 0.1, 2)
    p = np.column_stack([0.5 + xy[:, 0], xy[:, 1], np.full(len(t), 0.02)])
    R = Rotation.from_rotvec(np.outer(smooth_signals(rng, t, 1.0, 1)[:, 0], [0, 0, 1]))
    assert detect_kind(noisy_pose_recording(t, p, R, rng)).kind == "sliding"


def test_kind_override_keeps_every_bic():
    """--kind forces the choice; the BIC of every candidate is still reported."""
    recording, _, _ = random_joint_recording(np.random.default_rng(1), "prismatic")
    found = detect_kind(recording, "revolute")
    assert found.kind == "revolute" and found.forced and found.joint.type == "revolute"
    assert min(found.bic, key=found.bic.get) == "prismatic"
    with pytest.raises(ValueError, match="--kind"):
        detect_kind(recording, "hinge")
