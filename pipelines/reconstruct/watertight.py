"""The watertight mesh of the scanned object: segment, fuse, close, clean (the package docstring)."""

from __future__ import annotations

import time

import numpy as np

from pipelines.rgbd import Scan

from .config import ReconstructConfig, ReconstructError, Reconstruction
from .embedded import reconstruct_embedded, support_evidence
from .fusion import close_field, extract_mesh, fuse, refine_poses
from .mesh import largest_volume, lower_cap, simplify_watertight, smooth_mesh
from .segment import segment
from .views import View


def reconstruct(scan: Scan, config: ReconstructConfig = ReconstructConfig()) -> Reconstruction:
    """Segment, fuse and close the scanned object into a watertight mesh in the world frame.

    Args:
        scan: from `pipelines.scan.read_scan`.
        config: see `ReconstructConfig`.

    Returns:
        The mesh, support plane and statistics.

    Raises:
        ReconstructError: if no object or plane is found, or the mesh cannot be made watertight.
    """
    import open3d as o3d

    o3d.utility.random.seed(config.seed)
    stats: dict = {"frame_count": len(scan.frames)}
    t0 = time.perf_counter()
    views = [View.of(frame) for frame in scan.frames]

    segmentation = segment(views, config, scan)
    normal, offset = segmentation.plane
    stats.update(segmentation.stats)
    stats["segment_s"] = time.perf_counter() - t0

    stats["support"] = support_evidence(views, segmentation, config)
    if not stats["support"]["rests"] and segmentation.stats["segmentation"] == "masks":
        return reconstruct_embedded(scan, views, segmentation, config, stats, t0)

    extent = segmentation.extent_m
    noise_m = segmentation.depth_noise_m
    size = segmentation.hi - segmentation.lo

    def box_for(voxel: float) -> tuple[float, np.ndarray]:
        trunc_m = max(config.sdf_trunc_voxels * voxel, config.noise_trunc_sigmas * noise_m)
        # per axis, so a flat or long object's box stays flat or long
        margin = config.region_margin * np.maximum(size, 0.25 * extent) + trunc_m + 3 * voxel
        return trunc_m, margin

    if config.voxel_size_m is not None:
        voxel = float(config.voxel_size_m)
    else:  # the box's margins depend on the voxel: a few passes settle it
        voxel = config.voxel_size_range_m[1]
        for _ in range(4):
            _, margin = box_for(voxel)
            volume = float(np.prod(size + 2 * margin))
            voxel = float(np.clip((volume / config.voxel_budget) ** (1 / 3), *config.voxel_size_range_m))
    trunc_m, margin = box_for(voxel)
    lo = segmentation.lo - margin
    hi = segmentation.hi + margin

    voxel_count = float(np.prod(np.ceil((hi - lo) / voxel)))
    if voxel_count > config.max_voxels:
        raise ReconstructError(
            f"{scan.root}: the object's box ({np.round(hi - lo, 3).tolist()} m) needs {voxel_count:.3g} voxels of "
            f"{voxel * 1000:.2f} mm, more than max_voxels={config.max_voxels}; was the object segmented "
            "(give masks), or set a larger voxel_size_m"
        )
    t1 = time.perf_counter()
    grid = fuse(views, lo, hi, voxel, trunc_m, config)
    stats["tsdf_s_per_frame"] = (time.perf_counter() - t1) / len(views)
    stats["voxel_count"] = int(grid.tsdf.size)
    if config.pose_refine_rounds > 0:
        t_icp = time.perf_counter()
        max_distance = config.pose_refine_max_distance_m or 8.0 * voxel
        centre = 0.5 * (segmentation.lo + segmentation.hi)
        corrections = []
        for _ in range(config.pose_refine_rounds):
            views, moved = refine_poses(views, grid, lo, hi, centre, max_distance, config)
            corrections.append(moved)
            grid = fuse(views, lo, hi, voxel, trunc_m, config)
        stats["pose_refine_s"] = time.perf_counter() - t_icp
        stats["pose_correction_m"] = corrections  # per round: the largest shift of the object's centre

    t2 = time.perf_counter()
    cut_m = config.cut_height_voxels * voxel
    close_field(grid, views, normal, offset, cut_m, trunc_m, config.depth_trunc_m)
    stats["close_s"] = time.perf_counter() - t2

    t3 = time.perf_counter()
    mesh = extract_mesh(grid)
    stats["faces_extracted"] = int(len(mesh.faces))
    mesh = largest_volume(mesh, scan)
    lower_cap(mesh, normal, offset, cut_m + 1e-3 * voxel)
    smooth_mesh(mesh, normal, offset, config.smoothing_iterations)
    mesh = simplify_watertight(mesh, config.target_faces, scan.root)
    stats["extract_s"] = time.perf_counter() - t3
    stats.update(
        faces=int(len(mesh.faces)),
        volume_m3=float(mesh.volume),
        voxel_size_m=voxel,
        sdf_trunc_m=trunc_m,
        cut_height_m=cut_m,
        region_lo_m=lo.tolist(),
        region_hi_m=hi.tolist(),
        extent={"closing": "support_plane", "seen": ["surface above the support plane"],
                "assumed": {"underside": "flat, on the support plane"}},
        total_s=time.perf_counter() - t0,
    )
    return Reconstruction(
        mesh=mesh,
        support_plane=(normal, float(offset)),
        object_points_count=int(len(segmentation.object_points)),
        voxel_size_m=voxel,
        observed_points=segmentation.object_points,
        stats=stats,
    )
