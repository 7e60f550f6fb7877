"""Views: frames resampled to undistorted pinhole cameras, and their depth back-projected into the world."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipelines.rgbd import Frame, Intrinsics


@dataclass(frozen=True, eq=False)
class View:
    """A frame with depth (and mask) resampled to an undistorted pinhole camera."""

    depth_m: np.ndarray
    mask: np.ndarray | None
    intrinsics: Intrinsics
    T_world_camera: np.ndarray

    @staticmethod
    def of(frame: Frame) -> "View":
        intr = frame.intrinsics
        depth, mask = frame.depth_m, frame.mask
        if intr.has_distortion:
            rows, cols = _undistort_lookup(intr)
            depth = depth[rows, cols]
            mask = None if mask is None else mask[rows, cols]
        return View(depth.astype(np.float32, copy=False), mask, intr, np.asarray(frame.T_world_camera, float))

    @property
    def K(self) -> np.ndarray:
        return self.intrinsics.matrix()

    def centre(self) -> np.ndarray:
        return self.T_world_camera[:3, 3]


def _undistort_lookup(intr: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """For each pixel of the ideal pinhole image, the distorted image's pixel it shows (nearest)."""
    u, v = np.meshgrid(np.arange(intr.width) + 0.5, np.arange(intr.height) + 0.5)
    x, y = (u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy
    r2 = x * x + y * y
    radial = 1 + intr.k1 * r2 + intr.k2 * r2 * r2
    xd = x * radial + 2 * intr.p1 * x * y + intr.p2 * (r2 + 2 * x * x)
    yd = y * radial + intr.p1 * (r2 + 2 * y * y) + 2 * intr.p2 * x * y
    cols = np.clip(np.floor(xd * intr.fx + intr.cx), 0, intr.width - 1).astype(np.intp)
    rows = np.clip(np.floor(yd * intr.fy + intr.cy), 0, intr.height - 1).astype(np.intp)
    return rows, cols


def backproject(view: View, stride: int, max_depth_m: float) -> tuple[np.ndarray, np.ndarray]:
    """World points [m] of every `stride`-th pixel with valid depth, and their mask flags."""
    intr = view.intrinsics
    s = max(1, int(stride))
    rows = np.arange(s // 2, intr.height, s)
    cols = np.arange(s // 2, intr.width, s)
    v, u = (a.ravel() for a in np.meshgrid(rows, cols, indexing="ij"))
    z = view.depth_m[v, u]
    ok = (z > 0) & (z <= max_depth_m)
    points = pixel_points(view, v[ok], u[ok])
    flags = view.mask[v[ok], u[ok]] if view.mask is not None else np.zeros(len(points), bool)
    return points, flags


def pixel_points(view: View, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """World points [m] of the pixels (rows, cols) from their depth, rays through the pixel centres."""
    intr = view.intrinsics
    z = view.depth_m[rows, cols].astype(np.float64)
    p = np.stack([(cols + 0.5 - intr.cx) / intr.fx * z, (rows + 0.5 - intr.cy) / intr.fy * z, z], axis=1)
    T = view.T_world_camera
    return p @ T[:3, :3].T + T[:3, 3]
