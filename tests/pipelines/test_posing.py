"""Tests of pipelines.posing: poses for frames given without them, and pose errors."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from pipelines.posing import PosingConfig, PosingError, estimate_poses, pose_errors
from pipelines.rgbd import ScanError
from pipelines.scan import read_scan
from pipelines.synth.render import RenderConfig, render_scan


# a hand-held sweep: 8 views over 80 degrees of one ring, so consecutive views overlap
SWEEP = RenderConfig(
    width=160, height=120, fx=150.0, fy=150.0, view_count=8, elevations_deg=(40.0,), azimuth_span_deg=80.0,
    distance_range_m=(0.4, 0.45),
)


def _blocks():
    """Three boxes of different sizes on a table: enough 3-D structure for depth-only ICP."""
    parts = []
    for extents, centre in [((0.08, 0.05, 0.06), (0, 0, 0.03)), ((0.04, 0.04, 0.1), (0.07, 0.04, 0.05)),
                            ((0.05, 0.03, 0.03), (-0.05, 0.06, 0.015))]:
        box = trimesh.creation.box(extents)
        box.apply_translation(centre)
        parts.append(box)
    return trimesh.util.concatenate(parts)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    return render_scan(_blocks(), tmp_path_factory.mktemp("sweep"), SWEEP, np.random.default_rng(0), "blocks")


def _poses(scan) -> np.ndarray:
    return np.array([f.T_world_camera for f in scan.frames])


def test_estimated_poses_match_the_rendered_ones(sweep):
    """Re-posing a rendered sweep recovers each motion within 0.3 deg and 3 mm, the trajectory within 2 mm."""
    scan = read_scan(sweep, poses="estimate")
    assert scan.pose_source == "estimated" and scan.given_T_world_camera is not None
    np.testing.assert_allclose(scan.frames[0].T_world_camera, np.eye(4), atol=1e-9)  # world = first camera
    errors = pose_errors(_poses(scan), scan.given_T_world_camera)
    assert errors.relative_rotation_deg.max() < 0.3 and errors.relative_translation_m.max() < 0.003
    assert errors.absolute_rotation_deg.max() < 0.5 and errors.absolute_translation_m.max() < 0.002
    summary = errors.summary()
    json.dumps(summary)
    assert set(summary["relative_rotation_deg"]) == {"median", "max", "rms"}


def test_nerfstudio_scan_without_poses_is_posed(sweep, tmp_path):
    """A transforms.json whose frames have no transform_matrix is posed on reading."""
    root = tmp_path / "posefree"
    shutil.copytree(sweep, root)
    meta = json.loads((root / "transforms.json").read_text())
    for frame in meta["frames"]:
        del frame["transform_matrix"]
    (root / "transforms.json").write_text(json.dumps(meta))
    config = PosingConfig(neighbour_count=1, model_rounds=1, initial_guesses=("identity",))
    scan = read_scan(root, posing=config)
    assert scan.pose_source == "estimated" and scan.given_T_world_camera is None
    assert all(np.isfinite(f.T_world_camera).all() for f in scan.frames)
    assert scan.pose_stats["odometry"]["fitness_min"] > 0.5
    with pytest.raises(ScanError, match="gives no camera poses"):
        read_scan(root, poses="given")


def test_pose_errors_ignore_the_world_frame_and_find_a_perturbation():
    """Errors are zero for a rigidly moved copy of a trajectory and find one frame turned by 2 degrees."""
    rng = np.random.default_rng(1)
    given = np.tile(np.eye(4), (6, 1, 1))
    given[:, :3, :3] = Rotation.from_rotvec(rng.normal(0, 0.3, (6, 3))).as_matrix()
    given[:, :3, 3] = rng.normal(0, 0.5, (6, 3))
    move = np.eye(4)
    move[:3, :3] = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    move[:3, 3] = (1.0, -2.0, 0.5)
    estimated = move @ given
    errors = pose_errors(estimated, given)
    for name in ("relative_rotation_deg", "absolute_rotation_deg"):
        assert getattr(errors, name).max() < 1e-5
    for name in ("relative_translation_m", "absolute_translation_m"):
        assert getattr(errors, name).max() < 1e-9
    turned = estimated.copy()
    turned[3, :3, :3] = turned[3, :3, :3] @ Rotation.from_euler("z", 2, degrees=True).as_matrix()
    errors = pose_errors(turned, given)
    assert 1.5 < errors.absolute_rotation_deg[3] <= 2.0  # the alignment takes a sixth of it on the others
    assert np.delete(errors.absolute_rotation_deg, 3).max() < 0.4
    np.testing.assert_allclose(errors.relative_rotation_deg[2:4], 2.0, atol=1e-6)
    with pytest.raises(ValueError, match="one shape"):
        pose_errors(given[:3], given)


def test_frames_that_do_not_overlap_raise(sweep):
    """Two frames whose depth lies in disjoint places raise PosingError naming both."""
    scan = read_scan(sweep)
    a, b = scan.frames[0], scan.frames[1]
    far = np.where(b.depth_m > 0, b.depth_m + 2.0, 0).astype(np.float32)
    b = dataclasses.replace(b, depth_m=far)
    with pytest.raises(PosingError, match="do not overlap"):
        estimate_poses([a, b], PosingConfig(initial_guesses=("identity",), model_rounds=0))
    with pytest.raises(PosingError, match="at least two"):
        estimate_poses([a])


def test_real_kinect_frames_are_posed(kinect_frames):
    """Six real 7-Scenes frames (1/3 s apart) are posed within 1 deg and 3 cm of KinectFusion's motions."""
    config = PosingConfig(initial_guesses=("identity", "constant_velocity"), model_rounds=1)
    scan = read_scan(kinect_frames(range(0, 60, 10)), poses="estimate", posing=config)
    errors = pose_errors(_poses(scan), scan.given_T_world_camera)
    assert errors.relative_rotation_deg.max() < 1.0 and errors.relative_translation_m.max() < 0.03


def test_pose_free_frame_with_damaged_colour_is_posed_from_depth(sweep, tmp_path):
    """A colour image whose header reads but whose data is broken (Pillow: SyntaxError) costs only the
    RGB-D odometry start of its frame; the frames are still posed."""
    from PIL import Image

    root = tmp_path / "posefree"
    shutil.copytree(sweep, root)
    meta = json.loads((root / "transforms.json").read_text())
    for frame in meta["frames"]:
        del frame["transform_matrix"]
    (root / "transforms.json").write_text(json.dumps(meta))
    colour = root / meta["frames"][1]["file_path"]
    with Image.open(colour) as im:
        im.save(colour, format="PNG")  # keeps the name: Pillow reads the content
    data = bytearray(colour.read_bytes())
    data[36] = 0  # the length of the chunk after IHDR
    colour.write_bytes(bytes(data))
    config = PosingConfig(neighbour_count=0, model_rounds=0, initial_guesses=("identity", "rgbd_odometry"))
    scan = read_scan(root, posing=config)
    assert scan.pose_source == "estimated"
    assert all(np.isfinite(f.T_world_camera).all() for f in scan.frames)
