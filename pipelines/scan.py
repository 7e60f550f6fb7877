"""Read an RGB-D scan directory in the nerfstudio layout (DESIGN.md, "Inputs").

    scan_dir/
      transforms.json   fl_x fl_y cx cy w h, optional k1 k2 p1 p2,
                        depth_unit_scale_factor [m per depth unit, default 0.001],
                        frames: [{file_path, depth_file_path, mask_path?, transform_matrix}]
      images/...  depth/... (16-bit PNG)  masks/... (optional, 8-bit, object > 0)
      object.json       optional: {"name", "material", "notes"}

Conventions this reader settles for everything downstream:

- `transform_matrix` is camera-to-world in nerfstudio's OpenGL camera axes
  (x right, y up, looking along -z). `Frame.T_world_camera` is converted to
  OpenCV axes (x right, y down, looking along +z), the convention of Open3D's
  TSDF and of the pinhole maths below.
- Depth is z-depth (along the optical axis) in metres, float32, 0 = invalid.
- Pixel (u, v) covers [u, u+1) x [v, v+1); its centre is (u + 0.5, v + 0.5), so
  its ray in the camera is ((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy, 1).

Everything is checked on reading; anything malformed raises `ScanError`, whose
message starts with the path of the offending file.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Frame", "Intrinsics", "Scan", "ScanError", "read_scan", "OPENCV_FROM_OPENGL"]

OPENCV_FROM_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])
"""Right-multiply a camera-to-world matrix in OpenGL axes by this to get OpenCV axes (and back)."""

_DEFAULT_DEPTH_SCALE_M = 0.001
_MAX_DEPTH_SCALE_M = 0.1  # 1 unit = 10 cm would put 16-bit depth beyond 6 km: surely a mistake
_MEDIAN_DEPTH_RANGE_M = (0.03, 30.0)  # a scan whose median depth falls outside is mis-scaled
_ROTATION_TOLERANCE = 1e-3  # max |R^T R - I| entry accepted before re-orthonormalising
_INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
_DISTORTION_KEYS = ("k1", "k2", "p1", "p2")
_SUPPORTED_CAMERA_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "RADIAL", "SIMPLE_RADIAL")


class ScanError(ValueError):
    """A scan directory is malformed; the message starts with the offending file's path."""


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole camera with OpenCV radial-tangential distortion.

    fx, fy, cx, cy [pixels]; width, height [pixels]; k1, k2, p1, p2 unitless
    (OpenCV's model, applied to normalised coordinates). Pixel centres are at
    (u + 0.5, v + 0.5).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K [pixels]."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def has_distortion(self) -> bool:
        return any(d != 0.0 for d in (self.k1, self.k2, self.p1, self.p2))


@dataclass(frozen=True, eq=False)
class Frame:
    """One RGB-D view.

    color_path: the colour image (not loaded).
    depth_m: z-depth [m], float32, shape [height, width]; 0 where invalid. Read-only.
    mask: object mask, bool, shape [height, width] (True = object), or None. Read-only.
    T_world_camera: camera-to-world transform, OpenCV camera axes (x right, y down,
      z forward) [m], float64, shape [4, 4].
    intrinsics: this frame's camera (usually the scan's shared one).
    depth_path, mask_path: the files the arrays came from.
    """

    color_path: Path
    depth_m: np.ndarray
    mask: np.ndarray | None
    T_world_camera: np.ndarray
    intrinsics: Intrinsics
    depth_path: Path
    mask_path: Path | None = None


@dataclass(frozen=True, eq=False)
class Scan:
    """A scan: where it came from, what the user said about the object, and its views.

    root: the scan directory. name: from object.json, else the directory's name.
    material_hint, notes: from object.json (None when not given).
    intrinsics: the scan's camera (top-level keys of transforms.json).
    frames: the views, in file order.
    """

    root: Path
    name: str
    material_hint: str | None
    notes: str | None
    intrinsics: Intrinsics
    frames: tuple[Frame, ...]


def read_scan(path: str | Path) -> Scan:
    """Read and check a scan directory in the nerfstudio layout.

    Args:
        path: the scan directory (or its transforms.json).

    Returns:
        The scan, depth in metres, poses in OpenCV axes.

    Raises:
        ScanError: naming the offending file for a missing transforms.json, bad
            intrinsics, no frames, a frame without depth, missing or unreadable
            files, depth that is not 16-bit, image sizes that differ from w/h,
            non-finite or non-rigid poses, or an implausible depth scale.
    """
    path = Path(path)
    root = path.parent if path.name == "transforms.json" else path
    root = root.resolve()
    transforms_path = root / "transforms.json"
    if not root.is_dir():
        raise ScanError(f"{root}: scan directory not found")
    if not transforms_path.is_file():
        raise ScanError(f"{transforms_path}: missing transforms.json (the nerfstudio layout needs one)")
    meta = _read_json(transforms_path)
    if not isinstance(meta, dict):
        raise ScanError(f"{transforms_path}: expected a JSON object at the top level")

    model = meta.get("camera_model", "OPENCV")
    if model not in _SUPPORTED_CAMERA_MODELS:
        raise ScanError(
            f"{transforms_path}: camera_model {model!r} is not supported (expected one of {_SUPPORTED_CAMERA_MODELS})"
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

    frames = tuple(
        _read_frame(i, f, meta, intrinsics, root, transforms_path, depth_scale) for i, f in enumerate(frames_meta)
    )

    valid = np.concatenate([f.depth_m[f.depth_m > 0][::97] for f in frames])
    median_m = float(np.median(valid))
    lo, hi = _MEDIAN_DEPTH_RANGE_M
    if not lo <= median_m <= hi:
        raise ScanError(
            f"{transforms_path}: depth_unit_scale_factor {depth_scale:g} m/unit gives a median depth of "
            f"{median_m:.4g} m, outside the plausible [{lo}, {hi}] m; is the depth unit right?"
        )

    name, material, notes = _object_info(root / "object.json", default_name=root.name)
    return Scan(root=root, name=name, material_hint=material, notes=notes, intrinsics=intrinsics, frames=frames)


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as e:
        raise ScanError(f"{path}: cannot read ({e})") from e
    except json.JSONDecodeError as e:
        raise ScanError(f"{path}: not valid JSON ({e})") from e


def _depth_scale(meta: dict, transforms_path: Path) -> float:
    value = meta.get("depth_unit_scale_factor", _DEFAULT_DEPTH_SCALE_M)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScanError(f"{transforms_path}: depth_unit_scale_factor must be a finite number [m/unit], got {value!r}")
    if not 0.0 < value <= _MAX_DEPTH_SCALE_M:
        raise ScanError(
            f"{transforms_path}: depth_unit_scale_factor {value!r} m/unit is out of range (0, {_MAX_DEPTH_SCALE_M}]; "
            "typical values are 0.001 (mm) and 0.0001"
        )
    return float(value)


def _number(d: dict, key: str, where: str, transforms_path: Path) -> float:
    if key not in d:
        raise ScanError(f"{transforms_path}: {where}: intrinsic '{key}' is missing")
    value = d[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScanError(f"{transforms_path}: {where}: intrinsic '{key}' must be a finite number, got {value!r}")
    return float(value)


def _intrinsics(d: dict, transforms_path: Path, where: str) -> Intrinsics:
    fx, fy, cx, cy, w, h = (_number(d, k, where, transforms_path) for k in _INTRINSIC_KEYS)
    if fx <= 0 or fy <= 0:
        raise ScanError(
            f"{transforms_path}: {where}: focal lengths must be positive [pixels], got fl_x={fx}, fl_y={fy}"
        )
    if w != int(w) or h != int(h) or w < 1 or h < 1:
        raise ScanError(f"{transforms_path}: {where}: w and h must be positive integers [pixels], got w={w}, h={h}")
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
    where = f"{transforms_path}: frame {i} ({f.get('file_path', '?')})"
    if "transform_matrix" not in f:
        raise ScanError(f"{where}: transform_matrix is missing")
    try:
        T = np.array(f["transform_matrix"], dtype=float)
    except (TypeError, ValueError) as e:
        raise ScanError(f"{where}: transform_matrix is not a numeric 4x4 matrix ({e})") from e
    if T.shape != (4, 4):
        raise ScanError(f"{where}: transform_matrix must be 4x4, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ScanError(f"{where}: transform_matrix has non-finite entries")
    if np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-6:
        raise ScanError(f"{where}: transform_matrix's last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    R = T[:3, :3]
    err = np.abs(R.T @ R - np.eye(3)).max()
    if err > _ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        raise ScanError(
            f"{where}: transform_matrix is not rigid (|R^T R - I| = {err:.3g}, det R = {np.linalg.det(R):.4g}); "
            "expected a rotation and a translation in metres"
        )
    U, _, Vt = np.linalg.svd(R)  # remove the float noise exporters leave
    T[:3, :3] = U @ Vt
    return T @ OPENCV_FROM_OPENGL


def _file(root: Path, rel, transforms_path: Path, what: str, i: int) -> Path:
    if not isinstance(rel, str) or not rel:
        raise ScanError(f"{transforms_path}: frame {i}: {what} must be a non-empty path string, got {rel!r}")
    p = (root / rel).resolve()
    if not p.is_file():
        raise ScanError(f"{p}: {what} of frame {i} not found (listed in {transforms_path})")
    return p


def _open_image(path: Path):
    from PIL import Image

    try:
        im = Image.open(path)
        im.load()
        return im
    except (OSError, ValueError) as e:
        raise ScanError(f"{path}: cannot read image ({e})") from e


def _image_size(path: Path) -> tuple[int, int]:
    from PIL import Image

    try:
        with Image.open(path) as im:  # reads the header only
            return im.size
    except (OSError, ValueError) as e:
        raise ScanError(f"{path}: cannot read image ({e})") from e


def _check_size(path: Path, size: tuple[int, int], intr: Intrinsics, what: str) -> None:
    if size != (intr.width, intr.height):
        raise ScanError(
            f"{path}: {what} is {size[0]}x{size[1]} pixels but transforms.json says w x h = {intr.width}x{intr.height}"
        )


def _read_depth(path: Path, intr: Intrinsics, scale_m: float) -> np.ndarray:
    if path.suffix.lower() == ".npy":
        try:
            raw = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise ScanError(f"{path}: cannot read depth array ({e})") from e
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise ScanError(f"{path}: depth must be 16-bit (uint16, 2-D), got {raw.dtype} with shape {raw.shape}")
    else:
        im = _open_image(path)
        if not im.mode.startswith("I;16"):
            raise ScanError(f"{path}: depth must be a 16-bit single-channel image, got PIL mode {im.mode!r}")
        raw = np.array(im).astype(np.uint16, copy=False)
    _check_size(path, (raw.shape[1], raw.shape[0]), intr, "depth image")
    depth = raw.astype(np.float32) * np.float32(scale_m)
    if not np.any(depth > 0):
        raise ScanError(f"{path}: depth image has no valid (non-zero) pixels")
    depth.setflags(write=False)
    return depth


def _read_mask(path: Path, intr: Intrinsics) -> np.ndarray:
    im = _open_image(path)
    if im.mode not in ("1", "L", "P", "LA", "RGB", "RGBA"):
        raise ScanError(f"{path}: mask must be an 8-bit image (object > 0), got PIL mode {im.mode!r}")
    _check_size(path, im.size, intr, "mask")
    if im.mode == "P":
        im = im.convert("L")
    arr = np.array(im)
    mask = (arr[..., 0] if arr.ndim == 3 else arr) > 0
    mask.setflags(write=False)
    return mask


def _read_frame(
    i: int, f, meta: dict, shared: Intrinsics, root: Path, transforms_path: Path, depth_scale: float
) -> Frame:
    if not isinstance(f, dict):
        raise ScanError(f"{transforms_path}: frame {i} must be a JSON object, got {type(f).__name__}")
    intr = _frame_intrinsics(i, f, meta, shared, transforms_path)
    color_path = _file(root, f.get("file_path"), transforms_path, "colour image (file_path)", i)
    if not f.get("depth_file_path"):
        raise ScanError(
            f"{transforms_path}: frame {i} ({f.get('file_path')}): depth is missing (no depth_file_path); "
            "twin needs an RGB-D scan"
        )
    depth_path = _file(root, f["depth_file_path"], transforms_path, "depth image (depth_file_path)", i)
    T = _pose_opencv(i, f, transforms_path)
    _check_size(color_path, _image_size(color_path), intr, "colour image")
    depth = _read_depth(depth_path, intr, depth_scale)
    mask_path = mask = None
    if f.get("mask_path"):
        mask_path = _file(root, f["mask_path"], transforms_path, "mask (mask_path)", i)
        mask = _read_mask(mask_path, intr)
    T.setflags(write=False)
    return Frame(
        color_path=color_path,
        depth_m=depth,
        mask=mask,
        T_world_camera=T,
        intrinsics=intr,
        depth_path=depth_path,
        mask_path=mask_path,
    )


def _object_info(path: Path, default_name: str) -> tuple[str, str | None, str | None]:
    if not path.exists():
        return default_name, None, None
    info = _read_json(path)
    if not isinstance(info, dict):
        raise ScanError(f"{path}: expected a JSON object with optional 'name', 'material', 'notes'")
    out = []
    for key in ("name", "material", "notes"):
        value = info.get(key)
        if value is not None and not isinstance(value, str):
            raise ScanError(f"{path}: '{key}' must be a string, got {value!r}")
        out.append(value.strip() if isinstance(value, str) and value.strip() else None)
    name, material, notes = out
    return name or default_name, material, notes
