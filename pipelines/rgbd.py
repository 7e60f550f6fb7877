"""An RGB-D scan as read: its cameras, its views and where they came from, and the checked opening of
image files (header first, pixels on demand), shared by the scan reader and the pose estimator.

Conventions (settled by `pipelines.scan`, relied on everywhere downstream):

- `Frame.T_world_camera` is camera-to-world in OpenCV axes (x right, y down,
  looking along +z), the convention of Open3D's TSDF and of the pinhole maths;
  `OPENCV_FROM_OPENGL` converts from nerfstudio's OpenGL camera axes.
- Depth is z-depth (along the optical axis) in metres, float32, 0 = invalid.
- Pixel (u, v) covers [u, u+1) x [v, v+1); its centre is (u + 0.5, v + 0.5), so
  its ray in the camera is ((u + 0.5 - cx) / fx, (v + 0.5 - cy) / fy, 1).

Anything malformed raises `ScanError`, whose message starts with the path of the
offending file.
"""

from __future__ import annotations

import struct
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np


ScanLayout = Literal["nerfstudio", "7scenes"]
OPENCV_FROM_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])
"""Right-multiply a camera-to-world matrix in OpenGL axes by this to get OpenCV axes (and back)."""


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


def short(value) -> str:
    """repr of a value from the user's file, cut to fit a one-line message."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**20:
        return f"an integer of {len(str(abs(value)))} digits"  # JSON holds none beyond Python's printing limit
    return _cut(repr(value), 80)


def detail(e: BaseException) -> str:
    """An exception's message on one line, cut to fit in ours (a parser may quote a whole damaged header)."""
    return _cut(" ".join(str(e).split()) or type(e).__name__, 200)


def _cut(text: str, limit: int) -> str:
    return text if len(text) <= limit else f"{text[:limit - 3]}..."


def _pillow_errors() -> tuple[type[BaseException], ...]:
    """What Pillow raises for a damaged or oversized image file (UnidentifiedImageError is an OSError)."""
    from PIL import Image

    return (Image.DecompressionBombError, OSError, ValueError, SyntaxError, EOFError, struct.error, zlib.error)


def open_image(path: Path):
    """The image with its header read and its pixels not yet decoded (a context manager)."""
    from PIL import Image

    with warnings.catch_warnings():
        # sizes are checked against the camera's before decoding, a far tighter bound than Pillow's
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            return Image.open(path)
        except _pillow_errors() as e:
            raise ScanError(f"{path}: cannot read image ({detail(e)})") from e


def decoded_pixels(im, path: Path, mode: str | None = None) -> np.ndarray:
    """The pixels of an opened image, decoded now (and converted to `mode` if given)."""
    try:
        return np.array(im.convert(mode) if mode else im)
    except _pillow_errors() as e:
        raise ScanError(f"{path}: cannot read image ({detail(e)})") from e
