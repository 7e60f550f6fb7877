"""Tests of pipelines.scan: reading the nerfstudio layout and rejecting malformed scans."""

from __future__ import annotations

import json
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipelines.rgbd import OPENCV_FROM_OPENGL, ScanError
from pipelines.scan import read_scan

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
    _assert_refused(root, root / "transforms.json", words)


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


def _saved(label, name, image, words):
    """A damage that saves `image` (an array) as `name`; the error must name it and say `words`."""
    def damage(root):
        Image.fromarray(image).save(root / name)
        return root / name, words

    damage.__name__ = label
    return damage


def _removed(label, name, words, shown=None):
    """A damage that deletes `name`; the error must name `shown` (default the deleted file) and say `words`."""
    def damage(root):
        (root / name).unlink()
        return root / (shown or name), words

    damage.__name__ = label
    return damage


def _corrupt_depth(root):
    (root / "depth/1.png").write_bytes(b"not a png")
    return root / "depth/1.png", "cannot read"


_FILE_ERRORS = [
    _saved("eight_bit_depth", "depth/1.png", np.full((H, W), 50, np.uint8), "16-bit"),
    _saved("small_depth", "depth/1.png", np.full((H - 1, W), 500, np.uint16), "w x h"),
    _saved("small_color", "images/1.png", np.zeros((H, W + 2, 3), np.uint8), "w x h"),
    _saved("small_mask", "masks/1.png", np.zeros((2, 2), np.uint8), "w x h"),
    _removed("missing_depth", "depth/1.png", "not found"),
    _removed("missing_color", "images/1.png", "not found"),
    _removed("missing_mask", "masks/1.png", "not found"),
    _saved("empty_depth", "depth/1.png", np.zeros((H, W), np.uint16), "no valid"),
    _corrupt_depth,
]


@pytest.mark.parametrize("damage", _FILE_ERRORS, ids=[f.__name__.strip("_") for f in _FILE_ERRORS])
def test_bad_image_files_raise_scan_error_naming_them(tmp_path, damage):
    """A missing, unreadable, 8-bit or wrongly sized image raises ScanError that starts with its path."""
    _assert_damage_named(_write_scan(tmp_path / "s"), damage)


def _assert_damage_named(root, damage):
    _assert_refused(root, *damage(root))


def _assert_refused(root, path, words):
    """read_scan refuses the scan with one line that starts with `path` and says `words`."""
    with pytest.raises(ScanError) as info:
        read_scan(root)
    message = str(info.value)
    assert message.startswith(str(path.resolve())), message
    assert words in message and "\n" not in message and len(message) < 500, message


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


def _written(label, name, text, words):
    """A damage that writes `text` into `name`; the error must name it and say `words`."""
    def damage(root):
        (root / name).write_text(text)
        return root / name, words

    damage.__name__ = label
    return damage


def _eye_with(row, col, value):
    T = np.eye(4)
    T[row, col] = value
    return T


POSE, K = "frame-000001.pose.txt", "camera-intrinsics.txt"
_7SCENES_ERRORS = [
    _written("nan_pose", POSE, _pose_text(_eye_with(0, 3, np.nan)), "non-finite"),
    _written("scaled_7scenes_pose", POSE, _pose_text(np.diag([1.1, 1.1, 1.1, 1.0])), "not rigid"),
    _written("bad_last_row", POSE, _pose_text(_eye_with(3, 0, 0.5)), "last row"),
    _written("short_pose", POSE, _pose_text(np.eye(4)[:3]), "must be 4x4"),
    _written("text_pose", POSE, "identity\n", "numeric"),
    _removed("one_pose_missing", POSE, "no pose", shown="frame-000001.depth.png"),
    _removed("no_intrinsics", K, "missing camera-intrinsics.txt"),
    _written("skewed_k", K, "10 0.5 4\n0 11 3\n0 0 1\n", "no skew"),
    _written("negative_focal", K, "-10 0 4\n0 11 3\n0 0 1\n", "focal"),
    _written("k_outside", K, "10 0 40\n0 11 3\n0 0 1\n", "principal point"),
    _written("k_2x3", K, "10 0 4\n0 11 3\n", "must be 3x3"),
    _removed("7scenes_color_missing", "frame-000001.color.jpg", "not found"),
    _saved("7scenes_color_size", "frame-000001.color.jpg", np.zeros((H + 2, W, 3), np.uint8), "w x h"),
    _saved("7scenes_depth_size", "frame-000001.depth.png", np.full((H, W + 1), 500, np.uint16), "w x h"),
    _saved("7scenes_depth_8bit", "frame-000001.depth.png", np.full((H, W), 50, np.uint8), "16-bit"),
    _saved("7scenes_depth_all_invalid", "frame-000001.depth.png", np.full((H, W), 65535, np.uint16), "no valid"),
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


def test_reads_real_kinect_frames(kinect_frames):
    """Three real 7-Scenes Kinect frames read with K 585/320/240, 0.8-4 m depth and rigid camera-to-world poses."""
    root = kinect_frames((0, 10, 500))
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
    raw = np.loadtxt(root / "frame-000500.pose.txt")
    np.testing.assert_allclose(scan.frames[2].T_world_camera[:3, 3], raw[:3, 3])
    np.testing.assert_allclose(scan.frames[2].T_world_camera[:3, :3], raw[:3, :3], atol=1e-3)


# ---------------------------------------------------------------------------------------------
# hostile files: each raises ScanError naming the file, never another exception


def _write_raw(root: Path, text_edit) -> None:
    """Edit transforms.json as text (json.dumps cannot write what some of these cases need)."""
    path = root / "transforms.json"
    path.write_text(text_edit(path.read_text()))


_HUGE = "9" * 400


@pytest.mark.parametrize("edit,words", [
    (lambda t: t.replace('"fl_x": 10.0', f'"fl_x": {_HUGE}'), "'fl_x' must be a finite number, got an integer of 400"),
    (lambda t: t.replace('"fl_x": 10.0', f'"fl_x": 10.0, "depth_unit_scale_factor": {_HUGE}'),
     "depth_unit_scale_factor must be a finite number"),
    (lambda t: t.replace('"transform_matrix": [[1.0', f'"transform_matrix": [[{_HUGE}', 1), "non-finite"),
    (lambda t: t.replace('"fl_x": 10.0', '"fl_x": ' + "9" * 5000), "not readable JSON"),
    (lambda t: t.replace('"fl_x": 10.0', '"fl_x": ' + "[" * 100000 + "]" * 100000), "not readable JSON"),
], ids=["400-digit focal", "400-digit depth scale", "400-digit pose entry", "5000-digit integer", "deep nesting"])
def test_huge_numbers_and_deep_nesting_raise_scan_error(tmp_path, edit, words):
    """Integers beyond a float, beyond Python's digit limit, or nesting beyond its recursion limit: ScanError."""
    root = _write_scan(tmp_path / "s")
    _write_raw(root, edit)
    _assert_refused(root, root / "transforms.json", words)


def test_deeply_nested_object_json_raises(tmp_path):
    root = _write_scan(tmp_path / "s")
    (root / "object.json").write_text("[" * 100000 + "]" * 100000)
    with pytest.raises(ScanError, match="not readable JSON") as info:
        read_scan(root)
    assert str(info.value).startswith(str((root / "object.json").resolve()))


@pytest.mark.parametrize("edit,words", [
    (_set("w", 1e300), "megapixels"),
    (lambda m: m.update(w=10_000, h=10_000, cx=5000.0, cy=5000.0), "megapixels"),
    (_set("fl_x", 1e-12), "field of view"),
    (_set_frame("transform_matrix", [[1, 0, 0, 1e300], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
     "from the world origin"),
    (_set_frame("transform_matrix", [[1e300, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "not rigid"),
    (_set_frame("file_path", "images/\0.png"), "not a usable path"),
    (_set_frame("file_path", "x" * 5000), "not a usable path"),
    (_set("camera_model", ["x" * 1000]), "camera_model"),
], ids=["w 1e300", "100 megapixels", "tiny focal", "far camera", "huge rotation", "NUL in path", "long path",
        "long camera model"])
def test_implausible_values_raise_scan_error(tmp_path, edit, words):
    """Values no camera or scan has are refused before they reach the maths (or an allocation)."""
    root = _write_scan(tmp_path / "s")
    _edit(root, edit)
    _assert_refused(root, root / "transforms.json", words)


def _png_claiming(path: Path, width: int, height: int) -> None:
    """Rewrite a PNG's header to claim another size (with a valid checksum), keeping its pixel data."""
    data = bytearray(path.read_bytes())
    data[16:24] = struct.pack(">II", width, height)
    data[29:33] = struct.pack(">I", zlib.crc32(bytes(data[12:29])))
    path.write_bytes(bytes(data))


def _bomb(name, width, height, words):
    def damage(root):
        _png_claiming(root / name, width, height)
        return root / name, words

    return damage


def _broken_chunk(name):
    """A zeroed byte in the first chunk after IHDR: Pillow raises SyntaxError ("broken PNG file")."""
    def damage(root):
        data = bytearray((root / name).read_bytes())
        data[36] = 0
        (root / name).write_bytes(bytes(data))
        return root / name, "cannot read image"

    return damage


def _truncated(name):
    def damage(root):
        data = (root / name).read_bytes()
        (root / name).write_bytes(data[: len(data) // 2])
        return root / name, "cannot read image"

    return damage


def _npy_header(shape: str, key: str = "'shape'"):
    """A .npy depth (of 96 bytes of data) whose header claims another shape, or has another key."""
    def damage(root):
        path = root / "depth/1.npy"
        np.save(path, np.full((H, W), 500, np.uint16))
        data = path.read_bytes()
        header_end = 10 + int.from_bytes(data[8:10], "little")
        header = data[10:header_end].decode("latin1").replace(f"({H}, {W})", shape).replace("'shape'", key)
        header = header.rstrip("\n ").ljust(header_end - 11) + "\n"
        path.write_bytes(data[:10] + header.encode("latin1") + data[header_end:])
        _edit(root, _set_frame("depth_file_path", "depth/1.npy", 1))
        return path, "cannot read depth array"

    return damage


_HOSTILE_FILES = [
    _bomb("depth/1.png", 100_000, 100_000, "cannot read image"),  # beyond Pillow's decompression-bomb limit
    _bomb("masks/1.png", 100_000, 100_000, "cannot read image"),
    _bomb("images/1.png", 100_000, 100_000, "cannot read image"),
    _bomb("depth/1.png", 9000, 9000, "w x h"),  # under Pillow's limit: refused by size before decoding
    _bomb("masks/1.png", 9000, 9000, "w x h"),
    _broken_chunk("masks/1.png"),
    _broken_chunk("depth/1.png"),
    _truncated("depth/1.png"),
    _truncated("masks/1.png"),
    _npy_header("(99999, 99999)"),  # 20 GB
    _npy_header("(99999999999999999999, 3)"),  # beyond a C long: OverflowError in numpy
    _npy_header(f"({H}, {W})", key="[]"),  # an unhashable key: TypeError in numpy
]


_HOSTILE_IDS = ["depth bomb", "mask bomb", "colour bomb", "depth 9000x9000", "mask 9000x9000", "mask broken chunk",
                "depth broken chunk", "depth truncated", "mask truncated", "npy 20 GB", "npy beyond C long",
                "npy list as key"]


@pytest.mark.parametrize("damage", _HOSTILE_FILES, ids=_HOSTILE_IDS)
def test_hostile_images_raise_scan_error_naming_them(tmp_path, damage):
    """Damaged or oversized image headers raise ScanError naming the image; no pixels are decoded first."""
    _assert_damage_named(_write_scan(tmp_path / "s"), damage)


def _far_7scenes_pose(root):
    T = np.eye(4)
    T[0, 3] = 1e300
    (root / "frame-000001.pose.txt").write_text(_pose_text(T))
    return root / "frame-000001.pose.txt", "from the world origin"


def _ragged_pose(root):
    (root / "frame-000001.pose.txt").write_text("1 0 0 0\n0 1 0\n0 0 1 0\n0 0 0 1\n")
    return root / "frame-000001.pose.txt", "got 4 rows of [3, 4] numbers"


def _binary_pose(root):
    (root / "frame-000001.pose.txt").write_bytes(b"\xff\xfe\x00\x81")
    return root / "frame-000001.pose.txt", "cannot read"


def _wide_k(root):
    (root / "camera-intrinsics.txt").write_text("0.001 0 4\n0 11 3\n0 0 1\n")
    return root / "camera-intrinsics.txt", "field of view"


_HOSTILE_7SCENES = [
    _far_7scenes_pose,
    _ragged_pose,
    _binary_pose,
    _wide_k,
    _bomb("frame-000000.depth.png", 100_000, 100_000, "cannot read image"),
    _bomb("frame-000000.depth.png", 9000, 9000, "megapixels"),  # the first depth image gives the camera's size
    _bomb("frame-000001.depth.png", 9000, 9000, "w x h"),
    _broken_chunk("frame-000001.depth.png"),
]


@pytest.mark.parametrize("damage", _HOSTILE_7SCENES, ids=["far pose", "ragged pose", "binary pose", "wide K",
                                                          "first depth bomb", "first depth 81 MP", "depth 9000x9000",
                                                          "depth broken chunk"])
def test_hostile_7scenes_files_raise_scan_error_naming_them(tmp_path, damage):
    """Damaged 7-Scenes files raise ScanError that starts with their path."""
    _assert_damage_named(_write_7scenes(tmp_path / "s"), damage)


# ---------------------------------------------------------------------------------------------
# views that cannot close the object: a warning, not an error


def _write_ring(root: Path, azimuths_deg, elevation_deg: float = 30.0) -> Path:
    """The tiny scan with its cameras on a ring 0.3 m around the origin, looking at it (the masked patch)."""
    from pipelines.synth.render import look_at

    _write_scan(root, frame_count=len(azimuths_deg))

    def ring(meta):
        el = np.radians(elevation_deg)
        for frame, az in zip(meta["frames"], np.radians(azimuths_deg)):
            eye = 0.3 * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
            frame["transform_matrix"] = (look_at(eye, (0.0, 0.0, 0.0)) @ OPENCV_FROM_OPENGL).tolist()

    _edit(root, ring)
    return root


@pytest.mark.parametrize("root,words", [
    (lambda p: _write_scan(p, frame_count=1), "1 view; at least 3 around the object are needed to close it"),
    (lambda p: _write_ring(p, (0, 120, 240), elevation_deg=80), "all 3 views look at the object from above"),
    (lambda p: _write_ring(p, (0, 30, 60, 90)), "the 4 views leave a 270 deg gap"),
    (lambda p: _write_ring(p, (0, 110, 230)), "the 3 views leave a 130 deg gap"),
], ids=["one view", "from above", "one side", "gap of 130 deg"])
def test_views_that_cannot_close_the_object_warn(tmp_path, root, words):
    """A single view, views from above only, or a gap over 120 deg: a warning naming the scan directory."""
    root = root(tmp_path / "s")
    with pytest.warns(UserWarning, match="needed to close it") as record:
        scan = read_scan(root)
    message = str(record[0].message)
    assert message.startswith(f"{root.resolve()}: ") and words in message, message
    assert len(scan.frames) >= 1


def test_views_all_around_do_not_warn(tmp_path):
    """Views at most 120 deg apart around the object read without a warning."""
    root = _write_ring(tmp_path / "s", (0, 100, 200, 290))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_scan(root)
