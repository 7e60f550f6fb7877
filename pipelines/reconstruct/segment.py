"""Segmentation: the support plane and the object's points above it (or in its masks)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipelines.rgbd import Scan

from .config import ReconstructConfig, ReconstructError
from .views import View, backproject


@dataclass(frozen=True, eq=False)
class Segmentation:
    plane: tuple[np.ndarray, float]
    depth_noise_m: float  # standard deviation of depth along the rays, measured on the support plane
    object_points: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    extent_m: float
    stats: dict
    footprint_m: float  # back-projected size of a segmentation sample at the median depth
    background_points: np.ndarray  # unmasked points (with masks; else empty), world [m]


def segment(views: list[View], config: ReconstructConfig, scan: Scan) -> Segmentation:
    import open3d as o3d

    clouds = [backproject(v, config.segmentation_stride, config.depth_trunc_m) for v in views]
    points = np.concatenate([c[0] for c in clouds])
    flags = np.concatenate([c[1] for c in clouds])
    origins = np.concatenate([np.broadcast_to(v.centre(), c[0].shape) for v, c in zip(views, clouds)])
    if len(points) < 100:
        raise ReconstructError(f"{scan.root}: too few valid depth pixels ({len(points)}) to reconstruct")
    depths = np.concatenate([v.depth_m[v.depth_m > 0][::53] for v in views])
    median_depth = float(np.median(depths))
    focal = float(np.mean([v.intrinsics.fx for v in views]))
    footprint = median_depth / focal * max(1, config.segmentation_stride)
    plane_thr = config.plane_distance_m or max(0.002, 0.005 * median_depth)
    min_height = config.object_min_height_m or 2.0 * plane_thr
    eps = config.cluster_eps_m or 3.0 * footprint
    cameras = np.array([v.centre() for v in views])

    use_masks = config.use_masks and all(v.mask is not None for v in views)
    if use_masks:
        if not flags.any():
            raise ReconstructError(f"{scan.root}: the masks mark no pixel with valid depth as the object")
        background = points[~flags]
        if len(background) < 100:
            raise ReconstructError(f"{scan.root}: too few unmasked points to fit the support plane")
        normal, offset, rms = fit_plane(background, plane_thr, footprint, cameras, config)
        noise = _depth_noise(background, origins[~flags], normal, offset, plane_thr)
        candidates = points[flags]
        method = "masks"
    else:
        normal, offset, rms = fit_plane(points, plane_thr, footprint, cameras, config)
        noise = _depth_noise(points, origins, normal, offset, plane_thr)
        candidates = points[points @ normal + offset > min_height]
        method = "plane+dbscan"
    if len(candidates) < config.cluster_min_points:
        raise ReconstructError(
            f"{scan.root}: no object found above the support plane ({len(candidates)} candidate points); "
            "give masks or lower object_min_height_m"
        )
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(candidates)).voxel_down_sample(footprint)
    sample = np.asarray(pcd.points)
    labels = np.asarray(pcd.cluster_dbscan(eps=eps, min_points=config.cluster_min_points))
    chosen = _choose_cluster(sample, labels, views, use_masks)
    if chosen is None:
        raise ReconstructError(f"{scan.root}: DBSCAN found no object cluster (eps {eps:.4g} m); set cluster_eps_m")
    obj = sample[labels == chosen]
    footprint_pts = obj - np.outer(obj @ normal + offset, normal)  # the object's shadow on the plane
    both = np.concatenate([obj, footprint_pts])
    lo, hi = both.min(axis=0), both.max(axis=0)
    extent = float((hi - lo).max())
    stats = {
        "segmentation": method,
        "plane_rms_m": rms,
        "depth_noise_m": noise,
        "plane_distance_m": plane_thr,
        "median_depth_m": median_depth,
        "cluster_count": int(labels.max() + 1),
        "object_extent_m": extent,
    }
    background = points[~flags] if use_masks else np.empty((0, 3))
    return Segmentation((normal, offset), noise, obj, lo, hi, extent, stats, footprint, background)


def fit_plane(
    points: np.ndarray, threshold: float, footprint: float, cameras: np.ndarray, config: ReconstructConfig
) -> tuple[np.ndarray, float, float]:
    """RANSAC plane, refined by least squares on its inliers; normal towards the cameras."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(footprint)
    if len(pcd.points) < 3:
        raise ReconstructError("too few points to fit the support plane")
    model, _ = pcd.segment_plane(
        distance_threshold=threshold, ransac_n=3, num_iterations=config.plane_ransac_iterations
    )
    normal, offset = np.asarray(model[:3], float), float(model[3])
    scale = np.linalg.norm(normal)
    normal, offset = normal / scale, offset / scale
    # least squares on the inliers until they stop changing: the result no longer depends on
    # which (multi-threaded, hence unrepeatable) RANSAC sample won, so reruns are identical
    previous = None
    for _ in range(30):
        selected = np.abs(points @ normal + offset) < threshold
        if previous is not None and np.array_equal(selected, previous):
            break
        previous = selected
        inliers = points[selected]
        centroid = inliers.mean(axis=0)
        _, _, Vt = np.linalg.svd(inliers - centroid, full_matrices=False)
        normal = Vt[2] * np.sign(Vt[2] @ normal)
        offset = -float(normal @ centroid)
    if np.mean(cameras @ normal + offset) < 0:
        normal, offset = -normal, -offset
    rms = float(np.sqrt(np.mean((inliers @ normal + offset) ** 2)))
    return normal, offset, rms


def _depth_noise(points: np.ndarray, origins: np.ndarray, normal: np.ndarray, offset: float, threshold: float) -> float:
    """Depth noise [m] as seen on the plane: robust (MAD) spread of the residuals, measured along the rays."""
    residual = points @ normal + offset
    near = np.abs(residual) < 3.0 * threshold
    rays = points[near] - origins[near]
    cos = np.abs(rays @ normal) / np.linalg.norm(rays, axis=1)
    along_ray = residual[near] / np.maximum(cos, 0.2)
    if len(along_ray) < 100:
        return 0.0
    return float(1.4826 * np.median(np.abs(along_ray - np.median(along_ray))))


def _choose_cluster(points: np.ndarray, labels: np.ndarray, views: list[View], use_masks: bool) -> int | None:
    """The object's cluster: the largest with masks, else the one nearest the image centres."""
    ids, counts = np.unique(labels[labels >= 0], return_counts=True)
    if len(ids) == 0:
        return None
    if use_masks:
        return int(ids[np.argmax(counts)])
    keep = counts >= 0.05 * counts.max()
    ids = ids[keep]
    scores = []
    for i in ids:
        c = points[labels == i].mean(axis=0)
        r = []
        for v in views:
            T = v.T_world_camera
            p = T[:3, :3].T @ (c - T[:3, 3])
            if p[2] <= 0:
                continue
            intr = v.intrinsics
            u, w = intr.fx * p[0] / p[2] + intr.cx, intr.fy * p[1] / p[2] + intr.cy
            r.append(np.hypot((u - 0.5 * intr.width) / intr.width, (w - 0.5 * intr.height) / intr.height))
        scores.append(np.mean(r) if r else np.inf)
    return int(ids[int(np.argmin(scores))])
