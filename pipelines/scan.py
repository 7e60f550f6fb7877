"""Read an RGB-D scan directory (DESIGN.md, "Inputs"); the layout is detected.

The nerfstudio layout (primary):

    scan_dir/
      transforms.json   fl_x fl_y cx cy w h, optional k1 k2 p1 p2,
                        depth_unit_scale_factor [m per depth unit, default 0.001],
                        frames: [{file_path, depth_file_path, mask_path?, transform_matrix}]
      images/...  depth/... (16-bit PNG)  masks/... (optional, 8-bit, object > 0)
      object.json       optional: {"name", "material", "notes"}

The 7-Scenes / tsdf-fusion layout (Kinect-style frames in one folder):

    scan_dir/
      camera-intrinsics.txt          3x3 K [pixels] (of the depth camera)
      frame-XXXXXX.depth.png         16-bit depth [mm unless told otherwise]; 0 and 65535 invalid
      frame-XXXXXX.color.jpg|.png    colour, the depth image's size (not necessarily registered)
      frame-XXXXXX.pose.txt          4x4 camera-to-world [m], OpenCV camera axes (optional, see below)
      frame-XXXXXX.mask.png          optional object mask (8-bit, object > 0)
      object.json                    optional, as above

Frames without poses (no `transform_matrix` in any nerfstudio frame, no
`.pose.txt` in the 7-Scenes layout) are posed by `pipelines.posing` (RGB-D
odometry refined by ICP); their world frame is then the first camera's. A scan
whose poses are given can be re-posed the same way (`poses="estimate"`) to
measure the estimator against the given poses, which are kept in
`Scan.given_T_world_camera`.

Conventions this reader settles for everything downstream:

- `transform_matrix` is camera-to-world in nerfstudio's OpenGL camera axes
  (x right, y up, looking along -z). `Frame.T_world_camera` is converted to
  OpenCV axes (x right, y down, looking along +z), the convention of Open3D's
  TSDF and of the pinhole maths below.
- Depth is z-depth (along the optical axis) in metres, float32, 0 = invalid.
- Pixel (u, v) covers [u, u+1) x [v, v+1); its centre is (u + 0.5, v + 0.5), so
  its ray in the camera is ((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy, 1).

Everything is checked on reading; anything malformed raises `ScanError`, whose
message starts with the path of the offending file. Image headers are checked
against the camera's size before any pixel is decoded, so a file whose header
claims a huge image allocates nothing. A scan whose views leave a side of the
object unseen reads with a warning (see `read_scan`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import struct
import tokenize
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

if TYPE_CHECKING:
    from .posing import PosingConfig

__all__ = ["Frame", "Intrinsics", "Scan", "ScanError", "read_scan", "OPENCV_FROM_OPENGL", "ScanLayout", "PoseSource"]

ScanLayout = Literal["nerfstudio", "7scenes"]
PoseSource = Literal["auto", "given", "estimate"]

OPENCV_FROM_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])
"""Right-multiply a camera-to-world matrix in OpenGL axes by this to get OpenCV axes (and back)."""

_DEFAULT_DEPTH_SCALE_M = 0.001
_MAX_DEPTH_SCALE_M = 0.1  # 1 unit = 10 cm would put 16-bit depth beyond 6 km: surely a mistake
_MEDIAN_DEPTH_RANGE_M = (0.03, 30.0)  # a scan whose median depth falls outside is mis-scaled
_ROTATION_TOLERANCE = 1e-3  # max |R^T R - I| entry accepted before re-orthonormalising
_INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
_DISTORTION_KEYS = ("k1", "k2", "p1", "p2")
_SUPPORTED_CAMERA_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "RADIAL", "SIMPLE_RADIAL")
_SEVEN_SCENES_INTRINSICS = "camera-intrinsics.txt"
_SEVEN_SCENES_DEPTH = re.compile(r"^frame-(\d+)\.depth\.png$")
_SEVEN_SCENES_COLOR_SUFFIXES = (".color.jpg", ".color.png")
_SEVEN_SCENES_INVALID_DEPTH = 65535  # Kinect's "no reading" besides 0
_MAX_PIXELS = 50_000_000  # above any RGB-D camera (8K colour is 33 MP); bounds what one frame allocates
_MAX_CAMERA_DISTANCE_M = 1000.0  # from the world origin; further is not metres (and overflows the maths)
_MAX_FIELD_OF_VIEW_DEG = 170.0  # wider is a fisheye lens, or a focal length in the wrong unit
_MAX_AZIMUTH_GAP_DEG = 120.0  # see _warn_if_uncovered
_OVERHEAD_ELEVATION_DEG = 75.0


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
    intrinsics: the scan's camera (top-level keys of transforms.json, or camera-intrinsics.txt).
    frames: the views, in file order.
    layout: the directory layout it was read from.
    pose_source: "given" (read from the scan) or "estimated" (by `pipelines.posing`; world frame =
      the first camera's, OpenCV axes).
    given_T_world_camera: when the poses were estimated although the scan gives them, the given
      ones [m], OpenCV axes, shape [frame_count, 4, 4]; else None.
    pose_stats: the pose estimator's statistics (empty for given poses), JSON-serialisable.
    """

    root: Path
    name: str
    material_hint: str | None
    notes: str | None
    intrinsics: Intrinsics
    frames: tuple[Frame, ...]
    layout: ScanLayout = "nerfstudio"
    pose_source: Literal["given", "estimated"] = "given"
    given_T_world_camera: np.ndarray | None = None
    pose_stats: dict = field(default_factory=dict)


def read_scan(
    path: str | Path,
    *,
    poses: PoseSource = "auto",
    posing: "PosingConfig | None" = None,
    depth_unit_m: float | None = None,
) -> Scan:
    """Read and check a scan directory; its layout (nerfstudio or 7-Scenes) is detected.

    Args:
        path: the scan directory (or its transforms.json).
        poses: "auto" uses the scan's poses, or estimates them when it has none; "given"
            requires them; "estimate" estimates them even when given (keeping the given ones
            in `Scan.given_T_world_camera`, to measure the estimator).
        posing: settings of the pose estimator (default `PosingConfig()`).
        depth_unit_m: metres per depth unit of the 7-Scenes layout (default 0.001, millimetres);
            the nerfstudio layout states its own (`depth_unit_scale_factor`).

    Returns:
        The scan, depth in metres, poses in OpenCV axes.

    Warns:
        UserWarning: naming the scan directory when its views cannot close the object: a single
            view, or views that leave an azimuth gap over 120 deg around it (criterion in
            `_warn_if_uncovered`). The scan still reads; the fused mesh is then closed by guesswork
            on the unseen side.

    Raises:
        ScanError: naming the offending file for a directory of neither layout, bad
            intrinsics, no frames, a frame without depth, missing or unreadable files, depth
            that is not 16-bit, image sizes that differ from the camera's, images over 50
            megapixels, non-finite or non-rigid poses, cameras over 1 km from the world origin,
            poses given for some frames only, missing poses with
            poses="given", an implausible depth scale, or frames the estimator cannot pose.
    """
    path = Path(path)
    root = path.parent if path.name == "transforms.json" else path
    root = root.resolve()
    if not root.is_dir():
        raise ScanError(f"{root}: scan directory not found")
    if poses not in ("auto", "given", "estimate"):
        raise ScanError(f"{root}: poses must be 'auto', 'given' or 'estimate', got {poses!r}")
    if (root / "transforms.json").is_file():
        if depth_unit_m is not None:
            raise ScanError(f"{root / 'transforms.json'}: the nerfstudio layout gives its depth unit in "
                            "depth_unit_scale_factor; do not pass depth_unit_m")
        layout: ScanLayout = "nerfstudio"
        intrinsics, frames, depth_scale, listing = _read_nerfstudio(root)
    elif (root / _SEVEN_SCENES_INTRINSICS).is_file() or any(_seven_scenes_depths(root)):
        layout = "7scenes"
        depth_scale = _DEFAULT_DEPTH_SCALE_M if depth_unit_m is None else _checked_depth_unit(depth_unit_m, root)
        intrinsics, frames, listing = _read_seven_scenes(root, depth_scale)
    else:
        raise ScanError(
            f"{root / 'transforms.json'}: missing transforms.json (the nerfstudio layout needs one), and no "
            f"frame-XXXXXX.depth.png files of the 7-Scenes layout either"
        )

    valid = np.concatenate([f.depth_m[f.depth_m > 0][::97] for f, _ in frames])
    median_m = float(np.median(valid))
    lo, hi = _MEDIAN_DEPTH_RANGE_M
    if not lo <= median_m <= hi:
        unit = "depth_unit_scale_factor" if layout == "nerfstudio" else "depth unit"
        raise ScanError(
            f"{listing}: {unit} {depth_scale:g} m/unit gives a median depth of "
            f"{median_m:.4g} m, outside the plausible [{lo}, {hi}] m; is the depth unit right?"
        )

    posed = [T is not None for _, T in frames]
    if any(posed) and not all(posed):
        i = posed.index(False)
        raise ScanError(f"{frames[i][0].depth_path}: frame {i} has no pose while others have; "
                        "give every frame a pose or none")
    if not any(posed) and poses == "given":
        raise ScanError(f"{listing}: the scan gives no camera poses (poses='given')")
    given = np.stack([T for _, T in frames]) if all(posed) else None
    name, material, notes = _object_info(root / "object.json", default_name=root.name)
    scan = Scan(
        root=root,
        name=name,
        material_hint=material,
        notes=notes,
        intrinsics=intrinsics,
        frames=tuple(dataclasses.replace(f, T_world_camera=T) if T is not None else f for f, T in frames),
        layout=layout,
    )
    if given is not None and poses != "estimate":
        _warn_if_uncovered(scan)
        return scan
    from .posing import PosingConfig, PosingError, estimate_poses

    try:
        estimate = estimate_poses(scan.frames, posing or PosingConfig())
    except PosingError as e:
        raise ScanError(f"{listing}: could not estimate the camera poses ({e})") from e
    posed_frames = []
    for f, T in zip(scan.frames, estimate.T_world_camera):
        T = np.array(T, dtype=float)
        T.setflags(write=False)
        posed_frames.append(dataclasses.replace(f, T_world_camera=T))
    scan = dataclasses.replace(
        scan, frames=tuple(posed_frames), pose_source="estimated", given_T_world_camera=given, pose_stats=estimate.stats
    )
    _warn_if_uncovered(scan)
    return scan


def _read_nerfstudio(root: Path) -> tuple[Intrinsics, list, float, Path]:
    """Intrinsics, (frame, pose or None) pairs, depth scale and the listing file of a nerfstudio scan."""
    transforms_path = root / "transforms.json"
    meta = _read_json(transforms_path)
    if not isinstance(meta, dict):
        raise ScanError(f"{transforms_path}: expected a JSON object at the top level")

    model = meta.get("camera_model", "OPENCV")
    if model not in _SUPPORTED_CAMERA_MODELS:
        raise ScanError(
            f"{transforms_path}: camera_model {_short(model)} is not supported "
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


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as e:
        raise ScanError(f"{path}: cannot read ({_detail(e)})") from e
    except json.JSONDecodeError as e:
        raise ScanError(f"{path}: not valid JSON ({_detail(e)})") from e
    except ValueError as e:  # an integer of more digits than Python converts
        raise ScanError(f"{path}: not readable JSON ({_detail(e)})") from e
    except RecursionError as e:
        raise ScanError(f"{path}: not readable JSON (nested too deeply)") from e


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
    given = meta.get("depth_unit_scale_factor", _DEFAULT_DEPTH_SCALE_M)
    value = _finite(given)
    if value is None:
        raise ScanError(
            f"{transforms_path}: depth_unit_scale_factor must be a finite number [m/unit], got {_short(given)}"
        )
    if not 0.0 < value <= _MAX_DEPTH_SCALE_M:
        raise ScanError(
            f"{transforms_path}: depth_unit_scale_factor {value!r} m/unit is out of range (0, {_MAX_DEPTH_SCALE_M}]; "
            "typical values are 0.001 (mm) and 0.0001"
        )
    return value


def _number(d: dict, key: str, where: str, transforms_path: Path) -> float:
    if key not in d:
        raise ScanError(f"{transforms_path}: {where}: intrinsic '{key}' is missing")
    value = _finite(d[key])
    if value is None:
        raise ScanError(f"{transforms_path}: {where}: intrinsic '{key}' must be a finite number, got {_short(d[key])}")
    return value


def _short(value) -> str:
    """repr of a value from the user's file, cut to fit a one-line message."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**20:
        return f"an integer of {len(str(abs(value)))} digits"  # JSON holds none beyond Python's printing limit
    return _cut(repr(value), 80)


def _detail(e: BaseException) -> str:
    """An exception's message on one line, cut to fit in ours (a parser may quote a whole damaged header)."""
    return _cut(" ".join(str(e).split()) or type(e).__name__, 200)


def _cut(text: str, limit: int) -> str:
    return text if len(text) <= limit else f"{text[:limit - 3]}..."


def _intrinsics(d: dict, transforms_path: Path, where: str) -> Intrinsics:
    fx, fy, cx, cy, w, h = (_number(d, k, where, transforms_path) for k in _INTRINSIC_KEYS)
    if fx <= 0 or fy <= 0:
        raise ScanError(
            f"{transforms_path}: {where}: focal lengths must be positive [pixels], got fl_x={fx}, fl_y={fy}"
        )
    if w != int(w) or h != int(h) or w < 1 or h < 1:
        raise ScanError(f"{transforms_path}: {where}: w and h must be positive integers [pixels], got w={w}, h={h}")
    _check_pixel_count(transforms_path, w, h, f"{where}: w x h")
    _check_field_of_view(f"{transforms_path}: {where}", fx, fy, int(w), int(h))
    if not (0 < cx < w and 0 < cy < h):
        raise ScanError(
            f"{transforms_path}: {where}: principal point ({cx}, {cy}) lies outside the {int(w)}x{int(h)} image"
        )
    dist = {k: _number(d, k, where, transforms_path) if k in d else 0.0 for k in _DISTORTION_KEYS}
    for k in ("k3", "k4"):
        if k in d and _number(d, k, where, transforms_path) != 0.0:
            raise ScanError(f"{transforms_path}: {where}: distortion '{k}' is not supported (only k1 k2 p1 p2)")
    return Intrinsics(fx=fx, fy=fy, cx=cx, cy=cy, width=int(w), height=int(h), **dist)


def _check_pixel_count(path: Path, width: float, height: float, what: str) -> None:
    if width * height > _MAX_PIXELS:
        raise ScanError(
            f"{path}: {what} = {width:g}x{height:g} is over {_MAX_PIXELS / 1e6:g} megapixels, more than any RGB-D "
            "camera's"
        )


def _check_field_of_view(where: str, fx: float, fy: float, width: int, height: int) -> None:
    fov = np.degrees(2.0 * np.arctan2([0.5 * width, 0.5 * height], [fx, fy]))
    if fov.max() > _MAX_FIELD_OF_VIEW_DEG:
        raise ScanError(
            f"{where}: focal lengths fx={fx:g}, fy={fy:g} give a {fov[0]:.0f} x {fov[1]:.0f} deg field of view on "
            f"{width}x{height} pixels, over {_MAX_FIELD_OF_VIEW_DEG:g} deg; fisheye cameras are not supported"
        )


def _frame_intrinsics(i: int, f: dict, meta: dict, shared: Intrinsics, transforms_path: Path) -> Intrinsics:
    if not any(k in f for k in _INTRINSIC_KEYS + _DISTORTION_KEYS):
        return shared
    merged = {k: meta[k] for k in _INTRINSIC_KEYS + _DISTORTION_KEYS + ("k3", "k4") if k in meta}
    merged.update(f)
    return _intrinsics(merged, transforms_path, f"frame {i}")


def _pose_opencv(i: int, f: dict, transforms_path: Path) -> np.ndarray:
    where = f"{transforms_path}: frame {i} ({_short(f.get('file_path', '?'))})"
    if "transform_matrix" not in f:
        raise ScanError(f"{where}: transform_matrix is missing")
    try:
        T = np.array(f["transform_matrix"], dtype=float)
    except (TypeError, ValueError) as e:
        raise ScanError(f"{where}: transform_matrix is not a numeric 4x4 matrix ({_detail(e)})") from e
    except OverflowError as e:
        raise ScanError(f"{where}: transform_matrix has non-finite entries (an integer beyond a float's range)") from e
    if T.shape != (4, 4):
        raise ScanError(f"{where}: transform_matrix must be 4x4, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ScanError(f"{where}: transform_matrix has non-finite entries")
    _check_translation(T, f"{where}: transform_matrix")
    return _rigid(T, f"{where}: transform_matrix") @ OPENCV_FROM_OPENGL


def _check_translation(T: np.ndarray, what: str) -> None:
    distance = float(np.abs(T[:3, 3]).max())
    if distance > _MAX_CAMERA_DISTANCE_M:
        raise ScanError(
            f"{what} puts the camera {distance:.3g} m from the world origin (over {_MAX_CAMERA_DISTANCE_M:g} m); "
            "expected a translation in metres"
        )


def _rigid(T: np.ndarray, what: str) -> np.ndarray:
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


def _file(root: Path, rel, transforms_path: Path, what: str, i: int) -> Path:
    if not isinstance(rel, str) or not rel:
        raise ScanError(f"{transforms_path}: frame {i}: {what} must be a non-empty path string, got {_short(rel)}")
    try:
        p = (root / rel).resolve()
        found = p.is_file()
    except (OSError, ValueError) as e:  # a NUL byte, a name too long for the file system
        raise ScanError(
            f"{transforms_path}: frame {i}: {what} {_short(rel)} is not a usable path ({_detail(e)})"
        ) from e
    if not found:
        raise ScanError(f"{p}: {what} of frame {i} not found (listed in {transforms_path})")
    return p


def _pillow_errors() -> tuple[type[BaseException], ...]:
    """What Pillow raises for a damaged or oversized image file (UnidentifiedImageError is an OSError)."""
    from PIL import Image

    return (Image.DecompressionBombError, OSError, ValueError, SyntaxError, EOFError, struct.error, zlib.error)


def _open_image(path: Path):
    """The image with its header read and its pixels not yet decoded (a context manager)."""
    from PIL import Image

    with warnings.catch_warnings():
        # sizes are checked against the camera's before decoding, a far tighter bound than Pillow's
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            return Image.open(path)
        except _pillow_errors() as e:
            raise ScanError(f"{path}: cannot read image ({_detail(e)})") from e


def _pixels(im, path: Path, mode: str | None = None) -> np.ndarray:
    """The pixels of an opened image, decoded now (and converted to `mode` if given)."""
    try:
        return np.array(im.convert(mode) if mode else im)
    except _pillow_errors() as e:
        raise ScanError(f"{path}: cannot read image ({_detail(e)})") from e


def _image_size(path: Path) -> tuple[int, int]:
    with _open_image(path) as im:
        return im.size


def _check_size(path: Path, size: tuple[int, int], intr: Intrinsics, what: str, source: str = "transforms.json") -> None:
    if size != (intr.width, intr.height):
        raise ScanError(
            f"{path}: {what} is {size[0]}x{size[1]} pixels but {source} says w x h = {intr.width}x{intr.height}"
        )


def _read_depth(
    path: Path, intr: Intrinsics, scale_m: float, source: str = "transforms.json", invalid: int | None = None
) -> np.ndarray:
    if path.suffix.lower() == ".npy":
        raw = _read_depth_array(path, intr, source)
    else:
        with _open_image(path) as im:
            _check_size(path, im.size, intr, "depth image", source)
            if not im.mode.startswith("I;16"):
                raise ScanError(f"{path}: depth must be a 16-bit single-channel image, got PIL mode {im.mode!r}")
            raw = _pixels(im, path).astype(np.uint16, copy=False)
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
        raise ScanError(f"{path}: cannot read depth array ({_detail(e)})") from e
    if not isinstance(raw, np.ndarray):
        raise ScanError(f"{path}: expected one .npy array, got a .npz archive")
    if raw.dtype != np.uint16 or raw.ndim != 2:
        raise ScanError(f"{path}: depth must be 16-bit (uint16, 2-D), got {raw.dtype} with shape {raw.shape}")
    _check_size(path, (raw.shape[1], raw.shape[0]), intr, "depth array", source)
    return np.array(raw)


def _read_mask(path: Path, intr: Intrinsics, source: str = "transforms.json") -> np.ndarray:
    with _open_image(path) as im:
        if im.mode not in ("1", "L", "P", "LA", "RGB", "RGBA"):
            raise ScanError(f"{path}: mask must be an 8-bit image (object > 0), got PIL mode {im.mode!r}")
        _check_size(path, im.size, intr, "mask", source)
        arr = _pixels(im, path, "L" if im.mode == "P" else None)
    mask = (arr[..., 0] if arr.ndim == 3 else arr) > 0
    mask.setflags(write=False)
    return mask


def _read_frame(
    i: int, f, meta: dict, shared: Intrinsics, root: Path, transforms_path: Path, depth_scale: float, pose_free: bool
) -> tuple[Frame, np.ndarray | None]:
    if not isinstance(f, dict):
        raise ScanError(f"{transforms_path}: frame {i} must be a JSON object, got {type(f).__name__}")
    intr = _frame_intrinsics(i, f, meta, shared, transforms_path)
    color_path = _file(root, f.get("file_path"), transforms_path, "colour image (file_path)", i)
    if not f.get("depth_file_path"):
        raise ScanError(
            f"{transforms_path}: frame {i} ({_short(f.get('file_path'))}): depth is missing (no depth_file_path); "
            "twin needs an RGB-D scan"
        )
    depth_path = _file(root, f["depth_file_path"], transforms_path, "depth image (depth_file_path)", i)
    T = None if pose_free else _pose_opencv(i, f, transforms_path)
    _check_size(color_path, _image_size(color_path), intr, "colour image")
    depth = _read_depth(depth_path, intr, depth_scale)
    mask_path = mask = None
    if f.get("mask_path"):
        mask_path = _file(root, f["mask_path"], transforms_path, "mask (mask_path)", i)
        mask = _read_mask(mask_path, intr)
    if T is not None:
        T.setflags(write=False)
    frame = Frame(
        color_path=color_path,
        depth_m=depth,
        mask=mask,
        T_world_camera=_UNPOSED,
        intrinsics=intr,
        depth_path=depth_path,
        mask_path=mask_path,
    )
    return frame, T


_UNPOSED = np.full((4, 4), np.nan)
"""Stands for a pose until the estimator fills it in; never returned by `read_scan`."""
_UNPOSED.setflags(write=False)


# ---------------------------------------------------------------------------------------------
# 7-Scenes / tsdf-fusion layout


def _seven_scenes_depths(root: Path) -> list[tuple[int, Path]]:
    """(frame number, depth path) of every frame-XXXXXX.depth.png, in frame order."""
    found = []
    for p in root.iterdir():
        m = _SEVEN_SCENES_DEPTH.match(p.name)
        if m:
            found.append((int(m.group(1)), p))
    return sorted(found)


def _checked_depth_unit(value, root: Path) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScanError(f"{root}: depth_unit_m must be a finite number [m/unit], got {value!r}")
    if not 0.0 < value <= _MAX_DEPTH_SCALE_M:
        raise ScanError(f"{root}: depth_unit_m {value!r} m/unit is out of range (0, {_MAX_DEPTH_SCALE_M}]")
    return float(value)


def _read_matrix(path: Path, shape: tuple[int, int], what: str) -> np.ndarray:
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ScanError(f"{path}: cannot read ({_detail(e)})") from e
    try:
        rows = [[float(x) for x in line.split()] for line in text.splitlines() if line.strip()]
    except ValueError as e:
        raise ScanError(f"{path}: {what} is not a whitespace-separated numeric matrix ({_detail(e)})") from e
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
    _check_field_of_view(str(path), fx, fy, width, height)
    return Intrinsics(fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy), width=width, height=height)


def _seven_scenes_pose(path: Path) -> np.ndarray:
    T = _read_matrix(path, (4, 4), "the camera-to-world pose")
    _check_translation(T, f"{path}: the pose")
    T = _rigid(T, f"{path}: the pose")
    T.setflags(write=False)
    return T


def _read_seven_scenes(root: Path, depth_scale: float) -> tuple[Intrinsics, list, Path]:
    """Intrinsics, (frame, pose or None) pairs and the intrinsics file of a 7-Scenes scan."""
    intrinsics_path = root / _SEVEN_SCENES_INTRINSICS
    depths = _seven_scenes_depths(root)
    if not depths:
        raise ScanError(f"{root}: no frames (expected frame-XXXXXX.depth.png files beside {intrinsics_path.name})")
    first = depths[0][1]
    width, height = _image_size(first)
    _check_pixel_count(first, width, height, "the depth image's size")
    intrinsics = _seven_scenes_intrinsics(intrinsics_path, width, height, first)
    source = f"the first depth image ({first.name})"
    frames = []
    for i, (_, depth_path) in enumerate(depths):
        stem = depth_path.name[: -len(".depth.png")]
        colors = [root / f"{stem}{suffix}" for suffix in _SEVEN_SCENES_COLOR_SUFFIXES]
        color_path = next((p for p in colors if p.is_file()), None)
        if color_path is None:
            raise ScanError(f"{colors[0]}: colour image of frame {i} not found (nor {colors[1].name})")
        _check_size(color_path, _image_size(color_path), intrinsics, "colour image", source)
        depth = _read_depth(depth_path, intrinsics, depth_scale, source, invalid=_SEVEN_SCENES_INVALID_DEPTH)
        pose_path = root / f"{stem}.pose.txt"
        T = _seven_scenes_pose(pose_path) if pose_path.exists() else None
        mask_path = root / f"{stem}.mask.png"
        mask = _read_mask(mask_path, intrinsics, source) if mask_path.exists() else None
        frame = Frame(
            color_path=color_path.resolve(),
            depth_m=depth,
            mask=mask,
            T_world_camera=_UNPOSED,
            intrinsics=intrinsics,
            depth_path=depth_path.resolve(),
            mask_path=mask_path.resolve() if mask is not None else None,
        )
        frames.append((frame, T))
    return intrinsics, frames, intrinsics_path


def _warn_if_uncovered(scan: Scan) -> None:
    """Warn, naming the scan directory, when its views cannot see every side of the object.

    Criterion: seen from above, the horizontal directions from the object's centre to the
    cameras must leave no azimuth gap over 120 deg. A view sees the sides that face it within
    about 60 deg (beyond, the depth grazes the surface and drops out), so consecutive views at
    most 120 deg apart see every side; at least three views are needed. Cameras within 15 deg of
    straight above (or below) the centre see the top only and count for no azimuth. "Above" is
    world +z for the given poses of the nerfstudio layout; the 7-Scenes world and the estimated
    one (the first camera's) have no known up, so there it is the first camera's up (-y: cameras
    are held upright). The centre is the median over the views of the point each one sees at the
    median pixel and median depth of its mask (of its valid depth without a mask).
    """
    n = len(scan.frames)
    if n < 3:
        views = "1 view" if n == 1 else f"{n} views"
        warnings.warn(f"{scan.root}: {views}; at least 3 around the object are needed to close it", stacklevel=3)
        return
    poses = np.array([f.T_world_camera for f in scan.frames])
    centre = np.median([_seen_point(f) for f in scan.frames], axis=0)
    given_up = scan.layout == "nerfstudio" and scan.pose_source == "given"
    up = np.array([0.0, 0.0, 1.0]) if given_up else -poses[0, :3, 1]
    offsets = poses[:, :3, 3] - centre
    heights = offsets @ up
    horizontal = offsets - np.outer(heights, up)
    side = np.linalg.norm(horizontal, axis=1) > np.tan(np.radians(90.0 - _OVERHEAD_ELEVATION_DEG)) * np.abs(heights)
    if not side.any():
        warnings.warn(
            f"{scan.root}: all {n} views look at the object from above; views around it (no azimuth gap over "
            f"{_MAX_AZIMUTH_GAP_DEG:g} deg) are needed to close it",
            stacklevel=3,
        )
        return
    e1 = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    azimuths = np.sort(np.degrees(np.arctan2(horizontal[side] @ e2, horizontal[side] @ e1)))
    gap = float(np.max(np.diff(np.append(azimuths, azimuths[0] + 360.0))))
    if gap > _MAX_AZIMUTH_GAP_DEG:
        overhead = f", {n - int(side.sum())} of them from above" if not side.all() else ""
        warnings.warn(
            f"{scan.root}: the {n} views{overhead} leave a {gap:.0f} deg gap in azimuth around the object; "
            f"views all around it (no gap over {_MAX_AZIMUTH_GAP_DEG:g} deg) are needed to close it",
            stacklevel=3,
        )


def _seen_point(frame: Frame) -> np.ndarray:
    """The world point a frame sees at the median pixel and median depth of its mask (or valid depth) [m]."""
    valid = frame.depth_m > 0
    if frame.mask is not None and (frame.mask & valid).any():
        valid = frame.mask & valid
    v, u = np.nonzero(valid)
    z = float(np.median(frame.depth_m[valid]))
    intr = frame.intrinsics
    ray = np.array([(np.median(u) + 0.5 - intr.cx) / intr.fx, (np.median(v) + 0.5 - intr.cy) / intr.fy, 1.0])
    return frame.T_world_camera[:3, :3] @ (z * ray) + frame.T_world_camera[:3, 3]


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
            raise ScanError(f"{path}: '{key}' must be a string, got {_short(value)}")
        out.append(value.strip() if isinstance(value, str) and value.strip() else None)
    name, material, notes = out
    return name or default_name, material, notes
