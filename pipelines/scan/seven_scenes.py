"""The 7-Scenes / tsdf-fusion layout: Kinect-style frames in one folder (package docstring)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from pipelines.rgbd import Frame, Intrinsics, ScanError, detail

from .files import (
    MAX_DEPTH_SCALE_M,
    UNPOSED,
    check_field_of_view,
    check_pixel_count,
    check_size,
    check_translation,
    image_size,
    read_depth,
    read_mask,
    rigid_transform,
)


SEVEN_SCENES_INTRINSICS = "camera-intrinsics.txt"
_SEVEN_SCENES_DEPTH = re.compile(r"^frame-(\d+)\.depth\.png$")
_SEVEN_SCENES_COLOR_SUFFIXES = (".color.jpg", ".color.png")
_SEVEN_SCENES_INVALID_DEPTH = 65535  # Kinect's "no reading" besides 0


def seven_scenes_depths(root: Path) -> list[tuple[int, Path]]:
    """(frame number, depth path) of every frame-XXXXXX.depth.png, in frame order."""
    found = []
    for p in root.iterdir():
        m = _SEVEN_SCENES_DEPTH.match(p.name)
        if m:
            found.append((int(m.group(1)), p))
    return sorted(found)


def checked_depth_unit(value, root: Path) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScanError(f"{root}: depth_unit_m must be a finite number [m/unit], got {value!r}")
    if not 0.0 < value <= MAX_DEPTH_SCALE_M:
        raise ScanError(f"{root}: depth_unit_m {value!r} m/unit is out of range (0, {MAX_DEPTH_SCALE_M}]")
    return float(value)


def _read_matrix(path: Path, shape: tuple[int, int], what: str) -> np.ndarray:
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ScanError(f"{path}: cannot read ({detail(e)})") from e
    try:
        rows = [[float(x) for x in line.split()] for line in text.splitlines() if line.strip()]
    except ValueError as e:
        raise ScanError(f"{path}: {what} is not a whitespace-separated numeric matrix ({detail(e)})") from e
    if len(rows) != shape[0] or any(len(r) != shape[1] for r in rows):
        raise ScanError(f"{path}: {what} must be {shape[0]}x{shape[1]}, got {len(rows)} rows of "
                        f"{sorted({len(r) for r in rows})} numbers")
    M = np.array(rows, dtype=float)
    if not np.all(np.isfinite(M)):
        raise ScanError(f"{path}: {what} has non-finite entries")
    return M


def _seven_scenes_intrinsics(path: Path, width: int, height: int, size_from: Path) -> Intrinsics:
    if not path.is_file():
        raise ScanError(
            f"{path}: missing camera-intrinsics.txt (3x3 K in pixels; 7-Scenes' Kinect depth camera is "
            "585 0 320 / 0 585 240 / 0 0 1)"
        )
    K = _read_matrix(path, (3, 3), "the camera matrix K")
    if abs(K[0, 1]) > 1e-9 or np.abs(K[1:, 0]).max() > 1e-9 or abs(K[2, 1]) > 1e-9 or abs(K[2, 2] - 1) > 1e-9:
        raise ScanError(f"{path}: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew), got {K.tolist()}")
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if fx <= 0 or fy <= 0:
        raise ScanError(f"{path}: focal lengths must be positive [pixels], got fx={fx}, fy={fy}")
    if not (0 < cx < width and 0 < cy < height):
        raise ScanError(
            f"{path}: principal point ({cx}, {cy}) lies outside the {width}x{height} image ({size_from.name})"
        )
    check_field_of_view(str(path), fx, fy, width, height)
    return Intrinsics(fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy), width=width, height=height)


def _seven_scenes_pose(path: Path) -> np.ndarray:
    T = _read_matrix(path, (4, 4), "the camera-to-world pose")
    check_translation(T, f"{path}: the pose")
    T = rigid_transform(T, f"{path}: the pose")
    T.setflags(write=False)
    return T


def read_seven_scenes(root: Path, depth_scale: float) -> tuple[Intrinsics, list, Path]:
    """Intrinsics, (frame, pose or None) pairs and the intrinsics file of a 7-Scenes scan."""
    intrinsics_path = root / SEVEN_SCENES_INTRINSICS
    depths = seven_scenes_depths(root)
    if not depths:
        raise ScanError(f"{root}: no frames (expected frame-XXXXXX.depth.png files beside {intrinsics_path.name})")
    first = depths[0][1]
    width, height = image_size(first)
    check_pixel_count(first, width, height, "the depth image's size")
    intrinsics = _seven_scenes_intrinsics(intrinsics_path, width, height, first)
    source = f"the first depth image ({first.name})"
    frames = []
    for i, (_, depth_path) in enumerate(depths):
        stem = depth_path.name[: -len(".depth.png")]
        colors = [root / f"{stem}{suffix}" for suffix in _SEVEN_SCENES_COLOR_SUFFIXES]
        color_path = next((p for p in colors if p.is_file()), None)
        if color_path is None:
            raise ScanError(f"{colors[0]}: colour image of frame {i} not found (nor {colors[1].name})")
        check_size(color_path, image_size(color_path), intrinsics, "colour image", source)
        depth = read_depth(depth_path, intrinsics, depth_scale, source, invalid=_SEVEN_SCENES_INVALID_DEPTH)
        pose_path = root / f"{stem}.pose.txt"
        T = _seven_scenes_pose(pose_path) if pose_path.exists() else None
        mask_path = root / f"{stem}.mask.png"
        mask = read_mask(mask_path, intrinsics, source) if mask_path.exists() else None
        frame = Frame(
            color_path=color_path.resolve(),
            depth_m=depth,
            mask=mask,
            T_world_camera=UNPOSED,
            intrinsics=intrinsics,
            depth_path=depth_path.resolve(),
            mask_path=mask_path.resolve() if mask is not None else None,
        )
        frames.append((frame, T))
    return intrinsics, frames, intrinsics_path
