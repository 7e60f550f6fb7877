"""The whole scene (room, furniture) fused into one mesh, for context."""

from __future__ import annotations

import time

import numpy as np

from pipelines.rgbd import Scan

from .config import ReconstructError, SceneConfig, SceneReconstruction
from .fusion import BLOCK
from .mesh import canonical
from .views import View


def reconstruct_scene(scan: Scan, config: SceneConfig = SceneConfig()) -> SceneReconstruction:
    """Fuse every frame's depth into one TSDF (Open3D VoxelBlockGrid, blocks allocated as seen) and mesh it.

    Args:
        scan: from `pipelines.scan.read_scan`, posed (given or estimated).
        config: see `SceneConfig`.

    Returns:
        The scene's surface mesh and statistics.

    Raises:
        ReconstructError: if no surface is found.
    """
    import open3d as o3d
    import open3d.core as o3c
    import trimesh

    t0 = time.perf_counter()
    device = o3c.Device("CPU:0")
    voxel = float(config.voxel_size_m)
    trunc = float(config.sdf_trunc_voxels)
    grid = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight"),
        attr_dtypes=(o3c.float32, o3c.float32),
        attr_channels=((1), (1)),
        voxel_size=voxel,
        block_resolution=BLOCK,
        block_count=50000,
        device=device,
    )
    views = [View.of(frame) for frame in scan.frames]
    t1 = time.perf_counter()
    for view in views:
        depth = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(view.depth_m)))
        K, extrinsic = o3c.Tensor(view.K), o3c.Tensor(np.linalg.inv(view.T_world_camera))
        blocks = grid.compute_unique_block_coordinates(depth, K, extrinsic, 1.0, config.depth_trunc_m, trunc)
        grid.integrate(blocks, depth, K, extrinsic, 1.0, config.depth_trunc_m, trunc)
    tsdf_s = time.perf_counter() - t1
    t2 = time.perf_counter()
    tm = grid.extract_triangle_mesh(weight_threshold=config.weight_threshold)
    vertices = tm.vertex.positions.numpy().astype(np.float64)
    faces = tm.triangle.indices.numpy().astype(np.int64)
    if len(faces) == 0:
        raise ReconstructError(f"{scan.root}: the fused scene has no surface (weight_threshold {config.weight_threshold})")
    mesh = canonical(trimesh.Trimesh(vertices, faces, process=True))
    pieces = mesh.split(only_watertight=False)
    kept = [p for p in pieces if len(p.faces) >= config.min_component_faces]
    if kept and len(kept) < len(pieces):
        mesh = trimesh.util.concatenate(kept)
    stats = {
        "frame_count": len(views),
        "tsdf_s_per_frame": tsdf_s / len(views),
        "extract_s": time.perf_counter() - t2,
        "block_count": int(grid.hashmap().size()),
        "faces": int(len(mesh.faces)),
        "pieces": len(pieces),
        "pieces_kept": len(kept) if kept else len(pieces),
        "extent_m": np.round(mesh.extents, 4).tolist(),
        "total_s": time.perf_counter() - t0,
    }
    return SceneReconstruction(mesh=mesh, voxel_size_m=voxel, stats=stats)
