"""Tests of pipelines.scan: reading the nerfstudio layout and rejecting malformed scans."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipelines.scan import ScanError, read_scan

W, H = 8, 6


def _write_scan(root: Path, frame_count: int = 2, masks: bool = True, **overrides) -> Path:
    """A tiny valid scan: 8x6 images, depth 500 mm with a 300 mm patch, cameras looking down."""
    root.mkdir(parents=True, exist_ok=True)
    for sub in ("images", "depth", "masks"):
        (root / sub).mkdir(exist_ok=True)
    frames = []
    for i in range(frame_count):
        Image.fromarray(np.full((H, W, 3), 128, np.uint8)).save(root / f"images/{i}.png")
        depth = np.full((H, W), 500, np.uint16)
        depth[2:4, 3:5] = 300
        depth[0, 0] = 0
        Image.fromarray(depth).save(root / f"depth/{i}.png")
        mask = np.zeros((H, W), np.uint8)
        mask[2:4, 3:5] = 255
        Image.fromarray(mask).save(root / f"masks/{i}.png")
        T = np.eye(4)  # OpenGL camera at (x, 0, 1) looking along world -z
        T[:3, 3] = (0.1 * i, 0.0, 1.0)
        frame = {"file_path": f"images/{i}.png", "depth_file_path": f"depth/{i}.png", "transform_matrix": T.tolist()}
        if masks:
            frame["mask_path"] = f"masks/{i}.png"
        frames.append(frame)
    meta = {"fl_x": 10.0, "fl_y": 11.0, "cx": 4.0, "cy": 3.0, "w": W, "h": H, "k1": 0.01, "frames": frames}
    meta.update(overrides)
    (root / "transforms.json").write_text(json.dumps(meta))
    (root / "object.json").write_text(json.dumps({"name": "block", "material": "oak", "notes": "test"}))
    return root


def _edit(root: Path, fn) -> None:
    path = root / "transforms.json"
    meta = json.loads(path.read_text())
    fn(meta)
    path.write_text(json.dumps(meta))


def test_reads_intrinsics_depth_masks_and_object_info(tmp_path):
    """A valid scan reads with depth in metres, boolean masks and object.json's fields."""
    scan = read_scan(_write_scan(tmp_path / "s"))
    assert scan.name == "block" and scan.material_hint == "oak" and scan.notes == "test"
    intr = scan.intrinsics
    assert (intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height, intr.k1) == (10, 11, 4, 3, W, H, 0.01)
    assert len(scan.frames) == 2
    f = scan.frames[0]
    assert f.depth_m.dtype == np.float32 and f.depth_m.shape == (H, W)
    assert f.depth_m[0, 0] == 0.0 and f.depth_m[2, 3] == pytest.approx(0.3) and f.depth_m[5, 7] == pytest.approx(0.5)
    assert f.mask.dtype == bool and f.mask.sum() == 4 and f.mask[2, 3]
    assert f.color_path.name == "0.png" and f.intrinsics == intr


def test_converts_opengl_pose_to_opencv(tmp_path):
    """An OpenGL camera looking down -z becomes an OpenCV camera whose +z looks down and +y points to -y."""
    scan = read_scan(_write_scan(tmp_path / "s"))
    T = scan.frames[1].T_world_camera
    np.testing.assert_allclose(T[:3, 0], [1, 0, 0])
    np.testing.assert_allclose(T[:3, 1], [0, -1, 0])
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1])
    np.testing.assert_allclose(T[:3, 3], [0.1, 0, 1])
    # the principal point's ray at 0.5 m z-depth lands 0.5 m below the camera
    np.testing.assert_allclose(T @ [0, 0, 0.5, 1], [0.1, 0, 0.5, 1])


def test_defaults_without_object_json_masks_or_scale(tmp_path):
    """Without object.json, masks or depth_unit_scale_factor: the folder's name, no masks, millimetres."""
    root = _write_scan(tmp_path / "plain", masks=False)
    (root / "object.json").unlink()
    scan = read_scan(root / "transforms.json")
    assert scan.name == "plain" and scan.material_hint is None and scan.notes is None
    assert scan.frames[0].mask is None
    assert scan.frames[0].depth_m[5, 7] == pytest.approx(0.5)


def test_depth_unit_scale_factor_is_applied(tmp_path):
    """depth_unit_scale_factor 1e-4 reads 5000 units as 0.5 m."""
    root = _write_scan(tmp_path / "s", depth_unit_scale_factor=1e-4)
    Image.fromarray(np.full((H, W), 5000, np.uint16)).save(root / "depth/0.png")
    assert read_scan(root).frames[0].depth_m[1, 1] == pytest.approx(0.5)


def _drop_key(key):
    return lambda m: m.pop(key)


def _set(key, value):
    return lambda m: m.__setitem__(key, value)


def _set_frame(key, value, i=0):
    return lambda m: m["frames"][i].__setitem__(key, value)


def _drop_frame_key(key, i=0):
    return lambda m: m["frames"][i].pop(key)


def _scaled_pose(m):
    T = np.eye(4)
    T[:3, :3] *= 1.1
    m["frames"][0]["transform_matrix"] = T.tolist()


_META_ERRORS = [
    ("missing fl_x", _drop_key("fl_x"), "fl_x"),
    ("negative focal", _set("fl_y", -3.0), "focal"),
    ("non-integer w", _set("w", 7.5), "w and h"),
    ("principal point outside", _set("cx", 40.0), "principal point"),
    ("no frames", _set("frames", []), "no frames"),
    ("frame without depth", _drop_frame_key("depth_file_path"), "depth is missing"),
    ("non-finite pose", _set_frame("transform_matrix", [[float("nan")] * 4] * 4), "non-finite"),
    ("scaled pose", _scaled_pose, "not rigid"),
    ("3x4 pose", _set_frame("transform_matrix", np.eye(4)[:3].tolist()), "4x4"),
    ("negative depth scale", _set("depth_unit_scale_factor", -0.001), "depth_unit_scale_factor"),
    ("string depth scale", _set("depth_unit_scale_factor", "mm"), "depth_unit_scale_factor"),
    ("huge depth scale", _set("depth_unit_scale_factor", 1.0), "depth_unit_scale_factor"),
    ("implausible depth", _set("depth_unit_scale_factor", 1e-6), "median depth"),
    ("fisheye", _set("camera_model", "OPENCV_FISHEYE"), "camera_model"),
]


@pytest.mark.parametrize("case,edit,words", _META_ERRORS, ids=[c[0] for c in _META_ERRORS])
def test_malformed_transforms_raise_scan_error_naming_it(tmp_path, case, edit, words):
    """Each malformed transforms.json raises ScanError that starts with its path and says what is wrong."""
    root = _write_scan(tmp_path / "s")
    _edit(root, edit)
    with pytest.raises(ScanError) as info:
        read_scan(root)
    message = str(info.value)
    assert message.startswith(str((root / "transforms.json").resolve())), message
    assert words in message


def test_missing_transforms_json_raises(tmp_path):
    """A directory without transforms.json raises ScanError naming the missing file."""
    (tmp_path / "empty").mkdir()
    with pytest.raises(ScanError, match="missing transforms.json") as info:
        read_scan(tmp_path / "empty")
    assert str(info.value).startswith(str((tmp_path / "empty" / "transforms.json").resolve()))


def test_invalid_json_raises(tmp_path):
    """A transforms.json that is not JSON raises ScanError naming it."""
    root = _write_scan(tmp_path / "s")
    (root / "transforms.json").write_text("{not json")
    with pytest.raises(ScanError, match="not valid JSON"):
        read_scan(root)


def _eight_bit_depth(root):
    Image.fromarray(np.full((H, W), 50, np.uint8)).save(root / "depth/1.png")
    return root / "depth/1.png", "16-bit"


def _small_depth(root):
    Image.fromarray(np.full((H - 1, W), 500, np.uint16)).save(root / "depth/1.png")
    return root / "depth/1.png", "w x h"


def _small_color(root):
    Image.fromarray(np.zeros((H, W + 2, 3), np.uint8)).save(root / "images/1.png")
    return root / "images/1.png", "w x h"


def _small_mask(root):
    Image.fromarray(np.zeros((2, 2), np.uint8)).save(root / "masks/1.png")
    return root / "masks/1.png", "w x h"


def _missing_depth(root):
    (root / "depth/1.png").unlink()
    return root / "depth/1.png", "not found"


def _missing_color(root):
    (root / "images/1.png").unlink()
    return root / "images/1.png", "not found"


def _missing_mask(root):
    (root / "masks/1.png").unlink()
    return root / "masks/1.png", "not found"


def _empty_depth(root):
    Image.fromarray(np.zeros((H, W), np.uint16)).save(root / "depth/1.png")
    return root / "depth/1.png", "no valid"


def _corrupt_depth(root):
    (root / "depth/1.png").write_bytes(b"not a png")
    return root / "depth/1.png", "cannot read"


_FILE_ERRORS = [
    _eight_bit_depth,
    _small_depth,
    _small_color,
    _small_mask,
    _missing_depth,
    _missing_color,
    _missing_mask,
    _empty_depth,
    _corrupt_depth,
]


@pytest.mark.parametrize("damage", _FILE_ERRORS, ids=[f.__name__.strip("_") for f in _FILE_ERRORS])
def test_bad_image_files_raise_scan_error_naming_them(tmp_path, damage):
    """A missing, unreadable, 8-bit or wrongly sized image raises ScanError that starts with its path."""
    _assert_damage_named(_write_scan(tmp_path / "s"), damage)


def _assert_damage_named(root, damage):
    path, words = damage(root)
    with pytest.raises(ScanError) as info:
        read_scan(root)
    message = str(info.value)
    assert message.startswith(str(path.resolve())), message
    assert words in message


def test_bad_object_json_raises(tmp_path):
    """An object.json whose name is not a string raises ScanError naming object.json."""
    root = _write_scan(tmp_path / "s")
    (root / "object.json").write_text(json.dumps({"name": 3}))
    with pytest.raises(ScanError) as info:
        read_scan(root)
    assert str(info.value).startswith(str((root / "object.json").resolve()))


def test_arrays_are_read_only(tmp_path):
    """Depth and mask arrays of the frozen Frame cannot be written."""
    frame = read_scan(_write_scan(tmp_path / "s")).frames[0]
    with pytest.raises(ValueError):
        frame.depth_m[0, 0] = 1.0
    with pytest.raises(ValueError):
        frame.mask[0, 0] = True


# ---------------------------------------------------------------------------------------------
# 7-Scenes / tsdf-fusion layout

REAL_7SCENES = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd" / "7scenes_tsdf_demo_subset"
K_TEXT = "10 0 4\n0 11 3\n0 0 1\n"


def _pose_text(T: np.ndarray) -> str:
    return "\n".join(" ".join(f"{x:.12e}" for x in row) for row in T) + "\n"


def _write_7scenes(root: Path, frame_count: int = 2, poses: bool = True) -> Path:
    """A tiny 7-Scenes scan: 8x6 frames, depth 500 mm with a 300 mm patch, one 0 and one 65535 pixel."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "camera-intrinsics.txt").write_text(K_TEXT)
    for i in range(frame_count):
        stem = root / f"frame-{i:06d}"
        Image.fromarray(np.full((H, W, 3), 128, np.uint8)).save(f"{stem}.color.jpg")
        depth = np.full((H, W), 500, np.uint16)
        depth[2:4, 3:5] = 300
        depth[0, 0] = 0
        depth[0, 1] = 65535
        Image.fromarray(depth).save(f"{stem}.depth.png")
        if poses:
            T = np.eye(4)  # OpenCV camera at (x, 0, 0) looking along world +z
            T[:3, 3] = (0.1 * i, 0.0, 0.0)
            Path(f"{stem}.pose.txt").write_text(_pose_text(T))
    return root


def test_reads_the_7scenes_layout(tmp_path):
    """Depth in metres with 0 and 65535 invalid, K from camera-intrinsics.txt, poses as given (OpenCV axes)."""
    scan = read_scan(_write_7scenes(tmp_path / "kitchen", frame_count=3))
    assert scan.layout == "7scenes" and scan.pose_source == "given" and scan.name == "kitchen"
    intr = scan.intrinsics
    assert (intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height) == (10, 11, 4, 3, W, H)
    assert [f.depth_path.name for f in scan.frames] == [f"frame-{i:06d}.depth.png" for i in range(3)]
    f = scan.frames[2]
    assert f.depth_m[0, 0] == 0.0 and f.depth_m[0, 1] == 0.0  # 65535 is Kinect's "invalid"
    assert f.depth_m[2, 3] == pytest.approx(0.3) and f.depth_m[5, 7] == pytest.approx(0.5)
    assert f.mask is None and f.color_path.name == "frame-000002.color.jpg"
    np.testing.assert_allclose(f.T_world_camera[:3, 3], [0.2, 0, 0])
    np.testing.assert_allclose(f.T_world_camera[:3, :3], np.eye(3))


def test_7scenes_pose_slightly_off_rotation_is_orthonormalised(tmp_path):
    """A KinectFusion pose with det R = 0.9997 is accepted and made a rotation."""
    root = _write_7scenes(tmp_path / "s")
    T = np.eye(4)
    T[:3, :3] = np.diag([0.9999, 0.9999, 0.9999])
    (root / "frame-000001.pose.txt").write_text(_pose_text(T))
    R = read_scan(root).frames[1].T_world_camera[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)


def test_7scenes_depth_unit_can_be_given(tmp_path):
    """depth_unit_m=1e-4 reads 5000 units as 0.5 m."""
    root = _write_7scenes(tmp_path / "s")
    for i in range(2):
        Image.fromarray(np.full((H, W), 5000, np.uint16)).save(root / f"frame-{i:06d}.depth.png")
    assert read_scan(root, depth_unit_m=1e-4).frames[0].depth_m[1, 1] == pytest.approx(0.5)


def _write_text(name, text):
    def damage(root):
        (root / name).write_text(text)
        return root / name, None

    return damage


def _nan_pose(root):
    T = np.eye(4)
    T[0, 3] = np.nan
    (root / "frame-000001.pose.txt").write_text(_pose_text(T))
    return root / "frame-000001.pose.txt", "non-finite"


def _scaled_7scenes_pose(root):
    (root / "frame-000001.pose.txt").write_text(_pose_text(np.diag([1.1, 1.1, 1.1, 1.0])))
    return root / "frame-000001.pose.txt", "not rigid"


def _bad_last_row(root):
    T = np.eye(4)
    T[3, 0] = 0.5
    (root / "frame-000001.pose.txt").write_text(_pose_text(T))
    return root / "frame-000001.pose.txt", "last row"


def _short_pose(root):
    (root / "frame-000001.pose.txt").write_text(_pose_text(np.eye(4)[:3]))
    return root / "frame-000001.pose.txt", "must be 4x4"


def _text_pose(root):
    (root / "frame-000001.pose.txt").write_text("identity\n")
    return root / "frame-000001.pose.txt", "numeric"


def _one_pose_missing(root):
    (root / "frame-000001.pose.txt").unlink()
    return root / "frame-000001.depth.png", "no pose"


def _no_intrinsics(root):
    (root / "camera-intrinsics.txt").unlink()
    return root / "camera-intrinsics.txt", "missing camera-intrinsics.txt"


def _skewed_k(root):
    (root / "camera-intrinsics.txt").write_text("10 0.5 4\n0 11 3\n0 0 1\n")
    return root / "camera-intrinsics.txt", "no skew"


def _negative_focal(root):
    (root / "camera-intrinsics.txt").write_text("-10 0 4\n0 11 3\n0 0 1\n")
    return root / "camera-intrinsics.txt", "focal"


def _k_outside(root):
    (root / "camera-intrinsics.txt").write_text("10 0 40\n0 11 3\n0 0 1\n")
    return root / "camera-intrinsics.txt", "principal point"


def _k_2x3(root):
    (root / "camera-intrinsics.txt").write_text("10 0 4\n0 11 3\n")
    return root / "camera-intrinsics.txt", "must be 3x3"


def _7scenes_color_missing(root):
    (root / "frame-000001.color.jpg").unlink()
    return root / "frame-000001.color.jpg", "not found"


def _7scenes_color_size(root):
    Image.fromarray(np.zeros((H + 2, W, 3), np.uint8)).save(root / "frame-000001.color.jpg")
    return root / "frame-000001.color.jpg", "w x h"


def _7scenes_depth_size(root):
    Image.fromarray(np.full((H, W + 1), 500, np.uint16)).save(root / "frame-000001.depth.png")
    return root / "frame-000001.depth.png", "w x h"


def _7scenes_depth_8bit(root):
    Image.fromarray(np.full((H, W), 50, np.uint8)).save(root / "frame-000001.depth.png")
    return root / "frame-000001.depth.png", "16-bit"


def _7scenes_depth_all_invalid(root):
    Image.fromarray(np.full((H, W), 65535, np.uint16)).save(root / "frame-000001.depth.png")
    return root / "frame-000001.depth.png", "no valid"


_7SCENES_ERRORS = [
    _nan_pose,
    _scaled_7scenes_pose,
    _bad_last_row,
    _short_pose,
    _text_pose,
    _one_pose_missing,
    _no_intrinsics,
    _skewed_k,
    _negative_focal,
    _k_outside,
    _k_2x3,
    _7scenes_color_missing,
    _7scenes_color_size,
    _7scenes_depth_size,
    _7scenes_depth_8bit,
    _7scenes_depth_all_invalid,
]


@pytest.mark.parametrize("damage", _7SCENES_ERRORS, ids=[f.__name__.strip("_") for f in _7SCENES_ERRORS])
def test_malformed_7scenes_raise_scan_error_naming_the_file(tmp_path, damage):
    """Each malformed 7-Scenes file raises ScanError that starts with its path and says what is wrong."""
    _assert_damage_named(_write_7scenes(tmp_path / "s"), damage)


def test_7scenes_implausible_depth_unit_raises(tmp_path):
    """A depth unit that puts the median depth at 0.5 mm raises ScanError naming camera-intrinsics.txt."""
    root = _write_7scenes(tmp_path / "s")
    with pytest.raises(ScanError, match="median depth") as info:
        read_scan(root, depth_unit_m=1e-6)
    assert str(info.value).startswith(str((root / "camera-intrinsics.txt").resolve()))


def test_7scenes_without_poses_refuses_given(tmp_path):
    """poses='given' on a scan with no pose files raises ScanError saying so."""
    root = _write_7scenes(tmp_path / "s", poses=False)
    with pytest.raises(ScanError, match="gives no camera poses"):
        read_scan(root, poses="given")


def test_directory_of_neither_layout_raises(tmp_path):
    """A directory with neither transforms.json nor frame-*.depth.png names both layouts."""
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "frame-000000.color.jpg").write_bytes(b"")
    with pytest.raises(ScanError, match="7-Scenes"):
        read_scan(tmp_path / "x")


@pytest.mark.skipif(not REAL_7SCENES.is_dir(), reason="../shared/data is absent")
def test_reads_real_kinect_frames(tmp_path):
    """Three real 7-Scenes Kinect frames read with K 585/320/240, 0.8-4 m depth and rigid camera-to-world poses."""
    root = tmp_path / "kinect"
    root.mkdir()
    (root / "camera-intrinsics.txt").symlink_to(REAL_7SCENES / "camera-intrinsics.txt")
    for n in (0, 10, 500):
        for suffix in ("color.jpg", "depth.png", "pose.txt"):
            name = f"frame-{n:06d}.{suffix}"
            (root / name).symlink_to(REAL_7SCENES / name)
    scan = read_scan(root)
    assert scan.layout == "7scenes" and len(scan.frames) == 3
    intr = scan.intrinsics
    assert (intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height) == (585, 585, 320, 240, 640, 480)
    for frame in scan.frames:
        valid = frame.depth_m[frame.depth_m > 0]
        assert 0.7 < valid.min() and valid.max() < 4.0  # millimetres read as metres, 65535 dropped
        assert 0.7 < valid.size / frame.depth_m.size < 0.99
        R = frame.T_world_camera[:3, :3]
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    raw = np.loadtxt(REAL_7SCENES / "frame-000500.pose.txt")
    np.testing.assert_allclose(scan.frames[2].T_world_camera[:3, 3], raw[:3, 3])
    np.testing.assert_allclose(scan.frames[2].T_world_camera[:3, :3], raw[:3, :3], atol=1e-3)
