"""The nerfstudio layout: transforms.json and the images it lists (package docstring)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pipelines.rgbd import OPENCV_FROM_OPENGL, Frame, Intrinsics, ScanError, detail, short

from .files import (
    DEFAULT_DEPTH_SCALE_M,
    MAX_DEPTH_SCALE_M,
    UNPOSED,
    check_field_of_view,
    check_pixel_count,
    check_size,
    check_translation,
    image_size,
    read_depth,
    read_json,
    read_mask,
    rigid_transform,
)


_INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
_DISTORTION_KEYS = ("k1", "k2", "p1", "p2")
_SUPPORTED_CAMERA_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "RADIAL", "SIMPLE_RADIAL")


def read_nerfstudio(root: Path) -> tuple[Intrinsics, list, float, Path]:
    """Intrinsics, (frame, pose or None) pairs, depth scale and the listing file of a nerfstudio scan."""
    transforms_path = root / "transforms.json"
    meta = read_json(transforms_path)
    if not isinstance(meta, dict):
        raise ScanError(f"{transforms_path}: expected a JSON object at the top level")

    model = meta.get("camera_model", "OPENCV")
    if model not in _SUPPORTED_CAMERA_MODELS:
        raise ScanError(
            f"{transforms_path}: camera_model {short(model)} is not supported "
            f"(expected one of {_SUPPORTED_CAMERA_MODELS})"
        )
    depth_scale = _depth_scale(meta, transforms_path)

    frames_meta = meta.get("frames")
    if not isinstance(frames_meta, list) or not frames_meta:
        raise ScanError(f"{transforms_path}: no frames (expected a non-empty list under 'frames')")
    if all(k in meta for k in _INTRINSIC_KEYS) or not all(
        isinstance(f, dict) and all(k in f for k in _INTRINSIC_KEYS) for f in frames_meta
    ):
        intrinsics = _intrinsics(meta, transforms_path, "transforms.json")
    else:  # per-frame intrinsics only (as Polycam exports write them): the first frame's stands for the scan
        intrinsics = _intrinsics(frames_meta[0], transforms_path, "frame 0")
    # a scan either poses every frame or none (then the poses are estimated)
    pose_free = not any(isinstance(f, dict) and "transform_matrix" in f for f in frames_meta)
    frames = [
        _read_frame(i, f, meta, intrinsics, root, transforms_path, depth_scale, pose_free)
        for i, f in enumerate(frames_meta)
    ]
    return intrinsics, frames, depth_scale, transforms_path


def _finite(value) -> float | None:
    """value as a float when it is a finite JSON number, else None (a 400-digit integer overflows a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        value = float(value)
    except OverflowError:
        return None
    return value if math.isfinite(value) else None


def _depth_scale(meta: dict, transforms_path: Path) -> float:
    given = meta.get("depth_unit_scale_factor", DEFAULT_DEPTH_SCALE_M)
    value = _finite(given)
    if value is None:
        raise ScanError(
            f"{transforms_path}: depth_unit_scale_factor must be a finite number [m/unit], got {short(given)}"
        )
    if not 0.0 < value <= MAX_DEPTH_SCALE_M:
        raise ScanError(
            f"{transforms_path}: depth_unit_scale_factor {value!r} m/unit is out of range (0, {MAX_DEPTH_SCALE_M}]; "
            "typical values are 0.001 (mm) and 0.0001"
        )
    return value


def _number(d: dict, key: str, where: str, transforms_path: Path) -> float:
    if key not in d:
        raise ScanError(f"{transforms_path}: {where}: intrinsic '{key}' is missing")
    value = _finite(d[key])
    if value is None:
        raise ScanError(f"{transforms_path}: {where}: intrinsic '{key}' must be a finite number, got {short(d[key])}")
    return value


def _intrinsics(d: dict, transforms_path: Path, where: str) -> Intrinsics:
    fx, fy, cx, cy, w, h = (_number(d, k, where, transforms_path) for k in _INTRINSIC_KEYS)
    if fx <= 0 or fy <= 0:
        raise ScanError(
            f"{transforms_path}: {where}: focal lengths must be positive [pixels], got fl_x={fx}, fl_y={fy}"
        )
    if w != int(w) or h != int(h) or w < 1 or h < 1:
        raise ScanError(f"{transforms_path}: {where}: w and h must be positive integers [pixels], got w={w}, h={h}")
    check_pixel_count(transforms_path, w, h, f"{where}: w x h")
    check_field_of_view(f"{transforms_path}: {where}", fx, fy, int(w), int(h))
    if not (0 < cx < w and 0 < cy < h):
        raise ScanError(
            f"{transforms_path}: {where}: principal point ({cx}, {cy}) lies outside the {int(w)}x{int(h)} image"
        )
    dist = {k: _number(d, k, where, transforms_path) if k in d else 0.0 for k in _DISTORTION_KEYS}
    for k in ("k3", "k4"):
        if k in d and _number(d, k, where, transforms_path) != 0.0:
            raise ScanError(f"{transforms_path}: {where}: distortion '{k}' is not supported (only k1 k2 p1 p2)")
    return Intrinsics(fx=fx, fy=fy, cx=cx, cy=cy, width=int(w), height=int(h), **dist)


def _frame_intrinsics(i: int, f: dict, meta: dict, shared: Intrinsics, transforms_path: Path) -> Intrinsics:
    if not any(k in f for k in _INTRINSIC_KEYS + _DISTORTION_KEYS):
        return shared
    merged = {k: meta[k] for k in _INTRINSIC_KEYS + _DISTORTION_KEYS + ("k3", "k4") if k in meta}
    merged.update(f)
    return _intrinsics(merged, transforms_path, f"frame {i}")


def _pose_opencv(i: int, f: dict, transforms_path: Path) -> np.ndarray:
    where = f"{transforms_path}: frame {i} ({short(f.get('file_path', '?'))})"
    if "transform_matrix" not in f:
        raise ScanError(f"{where}: transform_matrix is missing")
    try:
        T = np.array(f["transform_matrix"], dtype=float)
    except (TypeError, ValueError) as e:
        raise ScanError(f"{where}: transform_matrix is not a numeric 4x4 matrix ({detail(e)})") from e
    except OverflowError as e:
        raise ScanError(f"{where}: transform_matrix has non-finite entries (an integer beyond a float's range)") from e
    if T.shape != (4, 4):
        raise ScanError(f"{where}: transform_matrix must be 4x4, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ScanError(f"{where}: transform_matrix has non-finite entries")
    check_translation(T, f"{where}: transform_matrix")
    return rigid_transform(T, f"{where}: transform_matrix") @ OPENCV_FROM_OPENGL


def _file(root: Path, rel, transforms_path: Path, what: str, i: int) -> Path:
    if not isinstance(rel, str) or not rel:
        raise ScanError(f"{transforms_path}: frame {i}: {what} must be a non-empty path string, got {short(rel)}")
    try:
        p = (root / rel).resolve()
        found = p.is_file()
    except (OSError, ValueError) as e:  # a NUL byte, a name too long for the file system
        raise ScanError(
            f"{transforms_path}: frame {i}: {what} {short(rel)} is not a usable path ({detail(e)})"
        ) from e
    if not found:
        raise ScanError(f"{p}: {what} of frame {i} not found (listed in {transforms_path})")
    return p


def _read_frame(
    i: int, f, meta: dict, shared: Intrinsics, root: Path, transforms_path: Path, depth_scale: float, pose_free: bool
) -> tuple[Frame, np.ndarray | None]:
    if not isinstance(f, dict):
        raise ScanError(f"{transforms_path}: frame {i} must be a JSON object, got {type(f).__name__}")
    intr = _frame_intrinsics(i, f, meta, shared, transforms_path)
    color_path = _file(root, f.get("file_path"), transforms_path, "colour image (file_path)", i)
    if not f.get("depth_file_path"):
        raise ScanError(
            f"{transforms_path}: frame {i} ({short(f.get('file_path'))}): depth is missing (no depth_file_path); "
            "twin needs an RGB-D scan"
        )
    depth_path = _file(root, f["depth_file_path"], transforms_path, "depth image (depth_file_path)", i)
    T = None if pose_free else _pose_opencv(i, f, transforms_path)
    check_size(color_path, image_size(color_path), intr, "colour image")
    depth = read_depth(depth_path, intr, depth_scale)
    mask_path = mask = None
    if f.get("mask_path"):
        mask_path = _file(root, f["mask_path"], transforms_path, "mask (mask_path)", i)
        mask = read_mask(mask_path, intr)
    if T is not None:
        T.setflags(write=False)
    frame = Frame(
        color_path=color_path,
        depth_m=depth,
        mask=mask,
        T_world_camera=UNPOSED,
        intrinsics=intr,
        depth_path=depth_path,
        mask_path=mask_path,
    )
    return frame, T
