"""Kind of motion by BIC, and the joint's axis and point, on pose tracks with the tracker's noise."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipelines.identify.kind import detect_kind
from pipelines.logs import PoseTrack, Recording, WrenchTrack
from pipelines.synth.held import SensorNoise

RATE_HZ = 200.0


def _recording(t, position, rotation: Rotation, rng) -> Recording:
    noise = SensorNoise()
    position = position + rng.normal(0, noise.position_sigma_m, position.shape)
    rotation = rotation * Rotation.from_rotvec(rng.normal(0, noise.rotation_sigma_rad, (len(t), 3)))
    pose = PoseTrack(t, position, rotation.as_quat(), "world", "gripper", "/tracker/pose")
    t_w = np.arange(0, t[-1], 0.002)
    wrench = WrenchTrack(t_w, rng.normal(0, noise.force_sigma_n, (len(t_w), 3)),
                         rng.normal(0, noise.torque_sigma_nm, (len(t_w), 3)), "/ft", "world")
    return Recording(Path("synthetic.mcap"), pose, wrench, wrench, None, None, float(t[-1]))


def _smooth(rng, t, amplitude, dims):
    """Smooth signals from 0 at t = 0: sums of three sines in 0.2-1.5 Hz."""
    f = rng.uniform(0.2, 1.5, (dims, 3))
    ph = rng.uniform(0, 2 * np.pi, (dims, 3))
    return amplitude * (np.sin(2 * np.pi * f[None] * t[:, None, None] + ph) - np.sin(ph)).sum(-1) / 3


def _jointed_case(rng, joint_type):
    """A random joint (any axis direction, a point 5-40 cm from the handle) worked through a random travel."""
    t = np.arange(0, 4.0, 1 / RATE_HZ)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    p0 = rng.uniform(-0.5, 0.5, 3) + [0.5, 0, 0.5]
    R0 = Rotation.random(random_state=rng.integers(1 << 31))
    if joint_type == "revolute":
        lever = np.cross(axis, rng.normal(size=3))
        point = p0 - rng.uniform(0.05, 0.4) * lever / np.linalg.norm(lever)
        q = np.abs(_smooth(rng, t, 1.2, 1)[:, 0])
        R_q = Rotation.from_rotvec(np.outer(q, axis))
        return _recording(t, point + R_q.apply(p0 - point), R_q * R0, rng), axis, point
    q = np.abs(_smooth(rng, t, 0.25, 1)[:, 0])
    return _recording(t, p0 + np.outer(q, axis), Rotation.concatenate([R0] * len(t)), rng), axis, None


def test_kind_axis_and_point_on_20_random_jointed_cases():
    """Twenty random drawers and doors: the right joint, the axis within 1 degree, a revolute axis within 5 mm."""
    rng = np.random.default_rng(7)
    for case in range(20):
        joint_type = ("prismatic", "revolute")[case % 2]
        recording, axis, point = _jointed_case(rng, joint_type)
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
    t = np.arange(0, 4.0, 1 / RATE_HZ)
    p = [0.5, 0.0, 0.3] + _smooth(rng, t, 0.1, 3)
    R = Rotation.from_rotvec(_smooth(rng, t, 0.6, 3))
    assert detect_kind(_recording(t, p, R, rng)).kind == "free"
    xy = _smooth(rng, t, 0.1, 2)
    p = np.column_stack([0.5 + xy[:, 0], xy[:, 1], np.full(len(t), 0.02)])
    R = Rotation.from_rotvec(np.outer(_smooth(rng, t, 1.0, 1)[:, 0], [0, 0, 1]))
    assert detect_kind(_recording(t, p, R, rng)).kind == "sliding"


def test_kind_override_keeps_every_bic():
    """--kind forces the choice; the BIC of every candidate is still reported."""
    recording, _, _ = _jointed_case(np.random.default_rng(1), "prismatic")
    found = detect_kind(recording, "revolute")
    assert found.kind == "revolute" and found.forced and found.joint.type == "revolute"
    assert min(found.bic, key=found.bic.get) == "prismatic"
    with pytest.raises(ValueError, match="--kind"):
        detect_kind(recording, "hinge")
