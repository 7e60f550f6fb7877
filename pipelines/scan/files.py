"""The checked reading of a scan's files: JSON, depth and mask images, poses; each failure a `ScanError`
naming the file."""

from __future__ import annotations

import json
import tokenize
from pathlib import Path

import numpy as np

from pipelines.rgbd import Intrinsics, ScanError, decoded_pixels, detail, open_image


DEFAULT_DEPTH_SCALE_M = 0.001
MAX_DEPTH_SCALE_M = 0.1  # 1 unit = 10 cm would put 16-bit depth beyond 6 km: surely a mistake
_ROTATION_TOLERANCE = 1e-3  # max |R^T R - I| entry accepted before re-orthonormalising
_MAX_PIXELS = 50_000_000  # above any RGB-D camera (8K colour is 33 MP); bounds what one frame allocates
_MAX_CAMERA_DISTANCE_M = 1000.0  # from the world origin; further is not metres (and overflows the maths)
_MAX_FIELD_OF_VIEW_DEG = 170.0  # wider is a fisheye lens, or a focal length in the wrong unit


def read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as e:
        raise ScanError(f"{path}: cannot read ({detail(e)})") from e
    except json.JSONDecodeError as e:
        raise ScanError(f"{path}: not valid JSON ({detail(e)})") from e
    except ValueError as e:  # an integer of more digits than Python converts
        raise ScanError(f"{path}: not readable JSON ({detail(e)})") from e
    except RecursionError as e:
        raise ScanError(f"{path}: not readable JSON (nested too deeply)") from e


def check_pixel_count(path: Path, width: float, height: float, what: str) -> None:
    if width * height > _MAX_PIXELS:
        raise ScanError(
            f"{path}: {what} = {width:g}x{height:g} is over {_MAX_PIXELS / 1e6:g} megapixels, more than any RGB-D "
            "camera's"
        )


def check_field_of_view(where: str, fx: float, fy: float, width: int, height: int) -> None:
    fov = np.degrees(2.0 * np.arctan2([0.5 * width, 0.5 * height], [fx, fy]))
    if fov.max() > _MAX_FIELD_OF_VIEW_DEG:
        raise ScanError(
            f"{where}: focal lengths fx={fx:g}, fy={fy:g} give a {fov[0]:.0f} x {fov[1]:.0f} deg field of view on "
            f"{width}x{height} pixels, over {_MAX_FIELD_OF_VIEW_DEG:g} deg; fisheye cameras are not supported"
        )


def check_translation(T: np.ndarray, what: str) -> None:
    distance = float(np.abs(T[:3, 3]).max())
    if distance > _MAX_CAMERA_DISTANCE_M:
        raise ScanError(
            f"{what} puts the camera {distance:.3g} m from the world origin (over {_MAX_CAMERA_DISTANCE_M:g} m); "
            "expected a translation in metres"
        )


def rigid_transform(T: np.ndarray, what: str) -> np.ndarray:
    """T with its rotation re-orthonormalised, or ScanError if it is not a rigid transform.

    Exporters leave float noise and KinectFusion's poses drift off SO(3) by ~4e-4;
    anything further off is a wrong matrix, not noise.
    """
    if np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-6:
        raise ScanError(f"{what}: the last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    R = T[:3, :3]
    with np.errstate(over="ignore", invalid="ignore"):  # entries near 1e308 overflow: not rigid either way
        err = np.abs(R.T @ R - np.eye(3)).max()
        det = np.linalg.det(R)
    if not err <= _ROTATION_TOLERANCE or not det > 0:
        raise ScanError(
            f"{what} is not rigid (|R^T R - I| = {err:.3g}, det R = {det:.4g}); "
            "expected a rotation and a translation in metres"
        )
    U, _, Vt = np.linalg.svd(R)
    T = T.copy()
    T[:3, :3] = U @ Vt
    return T


def image_size(path: Path) -> tuple[int, int]:
    with open_image(path) as im:
        return im.size


def check_size(path: Path, size: tuple[int, int], intr: Intrinsics, what: str, source: str = "transforms.json") -> None:
    if size != (intr.width, intr.height):
        raise ScanError(
            f"{path}: {what} is {size[0]}x{size[1]} pixels but {source} says w x h = {intr.width}x{intr.height}"
        )


def read_depth(
    path: Path, intr: Intrinsics, scale_m: float, source: str = "transforms.json", invalid: int | None = None
) -> np.ndarray:
    if path.suffix.lower() == ".npy":
        raw = _read_depth_array(path, intr, source)
    else:
        with open_image(path) as im:
            check_size(path, im.size, intr, "depth image", source)
            if not im.mode.startswith("I;16"):
                raise ScanError(f"{path}: depth must be a 16-bit single-channel image, got PIL mode {im.mode!r}")
            raw = decoded_pixels(im, path).astype(np.uint16, copy=False)
    depth = raw.astype(np.float32) * np.float32(scale_m)
    if invalid is not None:
        depth[raw == invalid] = 0.0
    if not np.any(depth > 0):
        raise ScanError(f"{path}: depth image has no valid (non-zero) pixels")
    depth.setflags(write=False)
    return depth


def _read_depth_array(path: Path, intr: Intrinsics, source: str) -> np.ndarray:
    # memory-mapped, so that a header claiming a huge shape costs nothing before the size check
    try:
        raw = np.load(path, mmap_mode="r", allow_pickle=False)
    # numpy parses the header as a Python literal (TypeError for an unhashable key, OverflowError for a
    # dimension beyond C's long) and tokenizes version-1 headers
    except (OSError, ValueError, EOFError, TypeError, OverflowError, tokenize.TokenError) as e:
        raise ScanError(f"{path}: cannot read depth array ({detail(e)})") from e
    if not isinstance(raw, np.ndarray):
        raise ScanError(f"{path}: expected one .npy array, got a .npz archive")
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise ScanError(f"{path}: depth must be 16-bit (uint16, 2-D), got {raw.dtype} with shape {raw.shape}")
    check_size(path, (raw.shape[1], raw.shape[0]), intr, "depth array", source)
    return np.array(raw)


def read_mask(path: Path, intr: Intrinsics, source: str = "transforms.json") -> np.ndarray:
    with open_image(path) as im:
        if im.mode not in ("1", "L", "P", "LA", "RGB", "RGBA"):
            raise ScanError(f"{path}: mask must be an 8-bit image (object > 0), got PIL mode {im.mode!r}")
        check_size(path, im.size, intr, "mask", source)
        arr = decoded_pixels(im, path, "L" if im.mode == "P" else None)
    mask = (arr[..., 0] if arr.ndim == 3 else arr) > 0
    mask.setflags(write=False)
    return mask


UNPOSED = np.full((4, 4), np.nan)
"""Stands for a pose until the estimator fills it in; never returned by `read_scan`."""
UNPOSED.setflags(write=False)
