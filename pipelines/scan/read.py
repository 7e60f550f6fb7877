"""`read_scan`: the layout detected and read, the depth scale and poses checked, missing poses estimated."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Literal

import numpy as np

from pipelines.posing import PosingConfig, PosingError, estimate_poses
from pipelines.rgbd import Frame, Scan, ScanError, ScanLayout, short

from .files import DEFAULT_DEPTH_SCALE_M, read_json
from .nerfstudio import read_nerfstudio
from .seven_scenes import SEVEN_SCENES_INTRINSICS, checked_depth_unit, read_seven_scenes, seven_scenes_depths


PoseSource = Literal["auto", "given", "estimate"]
_MEDIAN_DEPTH_RANGE_M = (0.03, 30.0)  # a scan whose median depth falls outside is mis-scaled
_MAX_AZIMUTH_GAP_DEG = 120.0  # see _warn_if_uncovered
_OVERHEAD_ELEVATION_DEG = 75.0


def read_scan(
    path: str | Path,
    *,
    poses: PoseSource = "auto",
    posing: PosingConfig | None = None,
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
        intrinsics, frames, depth_scale, listing = read_nerfstudio(root)
    elif (root / SEVEN_SCENES_INTRINSICS).is_file() or any(seven_scenes_depths(root)):
        layout = "7scenes"
        depth_scale = DEFAULT_DEPTH_SCALE_M if depth_unit_m is None else checked_depth_unit(depth_unit_m, root)
        intrinsics, frames, listing = read_seven_scenes(root, depth_scale)
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
    info = read_json(path)
    if not isinstance(info, dict):
        raise ScanError(f"{path}: expected a JSON object with optional 'name', 'material', 'notes'")
    out = []
    for key in ("name", "material", "notes"):
        value = info.get(key)
        if value is not None and not isinstance(value, str):
            raise ScanError(f"{path}: '{key}' must be a string, got {short(value)}")
        out.append(value.strip() if isinstance(value, str) and value.strip() else None)
    name, material, notes = out
    return name or default_name, material, notes
