"""Fusion: the views in a TSDF voxel grid, frame-to-model pose refinement, and the closed field's surface."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import ReconstructConfig, ReconstructError
from .mesh import canonical
from .views import View, backproject


BLOCK = 8  # voxels per VoxelBlockGrid block side


def refine_poses(
    views: list[View],
    grid: "_Grid",
    lo: np.ndarray,
    hi: np.ndarray,
    centre: np.ndarray,
    max_distance: float,
    config: ReconstructConfig,
) -> tuple[list[View], float]:
    """Register each view's points to the fused surface (point-to-plane ICP), removing the mean correction.

    Returns the corrected views and the largest remaining shift of the object's centre [m].
    """
    import open3d as o3d
    from scipy.spatial.transform import Rotation

    model = grid.vbg.extract_point_cloud(weight_threshold=3.0).to_legacy()
    if len(model.points) < 100:
        return views, 0.0
    model.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=4 * grid.voxel_size_m, max_nn=30))
    estimation = o3d.pipelines.registration.TransformationEstimationPointToPlane()
    criteria = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=30)
    stride = max(1, config.segmentation_stride // 2)
    corrections = []
    for view in views:
        points, _ = backproject(view, stride, config.depth_trunc_m)
        points = points[np.all((points >= lo) & (points <= hi), axis=1)]
        C = np.eye(4)
        if len(points) >= 100:
            source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
            result = o3d.pipelines.registration.registration_icp(
                source, model, max_distance, np.eye(4), estimation, criteria
            )
            if result.fitness > 0.5:
                C = np.asarray(result.transformation)
        corrections.append(C)
    # remove the mean correction (as a rotation about the object's centre and a shift of it)
    rotvecs = np.array([Rotation.from_matrix(C[:3, :3]).as_rotvec() for C in corrections])
    shifts = np.array([C[:3, :3] @ centre + C[:3, 3] - centre for C in corrections])
    mean = np.eye(4)
    mean[:3, :3] = Rotation.from_rotvec(rotvecs.mean(axis=0)).as_matrix()
    mean[:3, 3] = centre + shifts.mean(axis=0) - mean[:3, :3] @ centre
    unbias = np.linalg.inv(mean)
    out, moved = [], 0.0
    for view, C in zip(views, corrections):
        C = unbias @ C
        moved = max(moved, float(np.linalg.norm(C[:3, :3] @ centre + C[:3, 3] - centre)))
        out.append(View(view.depth_m, view.mask, view.intrinsics, C @ view.T_world_camera))
    return out, moved


@dataclass(eq=False)
class _Grid:
    """A dense voxel box taken from the VoxelBlockGrid; arrays indexed [x, y, z]."""

    vbg: object
    buf_indices: np.ndarray  # active buffer index of each block, shape [nbx, nby, nbz]
    origin_index: np.ndarray  # integer voxel coordinates of [0, 0, 0]
    voxel_size_m: float
    tsdf: np.ndarray  # [-1, 1], in units of the truncation distance
    weight: np.ndarray  # number of views that updated the voxel

    def points(self, flat_index: np.ndarray) -> np.ndarray:
        """World positions [m] of voxels given by flat [x, y, z] index."""
        ijk = np.stack(np.unravel_index(flat_index, self.tsdf.shape), axis=1)
        return (ijk + self.origin_index) * self.voxel_size_m


def fuse(
    views: list[View], lo: np.ndarray, hi: np.ndarray, voxel: float, trunc_m: float, config: ReconstructConfig
) -> _Grid:
    import open3d as o3d
    import open3d.core as o3c

    block_m = voxel * BLOCK
    b_lo = np.floor(lo / block_m).astype(int)
    b_hi = np.floor(hi / block_m).astype(int)
    nb = b_hi - b_lo + 1
    keys = np.stack(np.meshgrid(*(np.arange(a, b + 1) for a, b in zip(b_lo, b_hi)), indexing="ij"), axis=-1)
    keys = keys.reshape(-1, 3).astype(np.int32)
    device = o3c.Device("CPU:0")
    vbg = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight"),
        attr_dtypes=(o3c.float32, o3c.float32),
        attr_channels=((1), (1)),
        voxel_size=voxel,
        block_resolution=BLOCK,
        block_count=int(len(keys)) + 16,
        device=device,
    )
    block_coords = o3c.Tensor(keys, device=device)
    buf, ok = vbg.hashmap().activate(block_coords)
    if not ok.numpy().all():
        raise ReconstructError("could not allocate the TSDF voxel blocks")
    jump_m = config.silhouette_jump_truncations * trunc_m
    for view in views:
        vbg.integrate(
            block_coords,
            o3d.t.geometry.Image(o3c.Tensor(silhouettes_dropped(view.depth_m, jump_m))),
            o3c.Tensor(view.K),
            o3c.Tensor(np.linalg.inv(view.T_world_camera)),
            depth_scale=1.0,
            depth_max=float(config.depth_trunc_m),
            trunc_voxel_multiplier=float(trunc_m / voxel),
        )
    # integrate() activates the blocks again, which may rehash the map and move them: look them up now
    buf, ok = vbg.hashmap().find(block_coords)
    if not ok.numpy().all():
        raise ReconstructError("lost TSDF voxel blocks during integration")
    buf_indices = buf.numpy().astype(np.int64).reshape(nb)
    grid = _Grid(vbg, buf_indices, b_lo * BLOCK, voxel, np.empty(0), np.empty(0))
    grid.tsdf = _dense(vbg.attribute("tsdf").numpy(), buf_indices)
    grid.weight = _dense(vbg.attribute("weight").numpy(), buf_indices)
    return grid


def silhouettes_dropped(depth_m: np.ndarray, jump_m: float) -> np.ndarray:
    """The depth image [m] without the pixels whose 3x3 neighbourhood spans more than `jump_m` in depth
    (0: no measurement); `jump_m` 0 keeps every pixel.

    Integration samples each voxel's depth at the centre of the pixel it falls in, so near a silhouette a
    voxel up to half a pixel inside the object can take the background's depth (a full truncation of free
    space) and one just outside can take the object's. The first outweighs the views that see the voxel
    just inside: every silhouette eroded, 0.05 mm all round on noise-free scans, 3-4 % of a 5 mm bar's
    volume. Without these pixels, the space beside an edge is decided by the views that see it away from
    their silhouettes (the bar: -3.6 % -> -0.3 %, noise-free).
    """
    from scipy import ndimage

    if jump_m <= 0:
        return np.ascontiguousarray(depth_m, dtype=np.float32)
    valid = depth_m > 0
    nearest = ndimage.minimum_filter(np.where(valid, depth_m, np.inf), size=3, mode="nearest")
    farthest = ndimage.maximum_filter(np.where(valid, depth_m, -np.inf), size=3, mode="nearest")
    return np.ascontiguousarray(np.where(farthest - nearest > jump_m, 0.0, depth_m), dtype=np.float32)


def _dense(values: np.ndarray, buf_indices: np.ndarray) -> np.ndarray:
    """Blocks [buf, z, y, x, 1] -> dense [x, y, z] over the block box."""
    nb = buf_indices.shape
    blocks = values[buf_indices.reshape(-1), ..., 0].reshape(*nb, BLOCK, BLOCK, BLOCK)  # bx by bz z y x
    dense = blocks.transpose(0, 5, 1, 4, 2, 3)  # bx x by y bz z
    return np.ascontiguousarray(dense.reshape(nb[0] * BLOCK, nb[1] * BLOCK, nb[2] * BLOCK))


def _store(dense: np.ndarray, values: np.ndarray, buf_indices: np.ndarray) -> None:
    """Inverse of `_dense`: write a dense [x, y, z] array back into the blocks."""
    nb = buf_indices.shape
    blocks = dense.reshape(nb[0], BLOCK, nb[1], BLOCK, nb[2], BLOCK).transpose(0, 2, 4, 5, 3, 1)
    values[buf_indices.reshape(-1), ..., 0] = blocks.reshape(-1, BLOCK, BLOCK, BLOCK)


def close_field(
    grid: _Grid,
    views: list[View],
    normal: np.ndarray,
    offset: float,
    cut_m: float,
    trunc_m: float,
    depth_trunc_m: float,
) -> None:
    """Decide the unobserved voxels and intersect with the half-space above the cut, in place."""
    field = grid.tsdf.reshape(-1)
    undecided = np.flatnonzero(grid.weight.reshape(-1) <= 0)
    field[undecided] = 1.0  # empty unless some view sees it behind a surface
    p = grid.points(undecided).astype(np.float32)
    for view in views:  # a voxel leaves the list at the first view it is hidden in
        if not len(undecided):
            break
        T = view.T_world_camera.astype(np.float32)
        q = (p - T[:3, 3]) @ T[:3, :3]
        intr = view.intrinsics
        z = q[:, 2]
        zs = np.where(z > 1e-6, z, np.float32(1.0))
        u = np.floor(intr.fx * q[:, 0] / zs + intr.cx)
        v = np.floor(intr.fy * q[:, 1] / zs + intr.cy)
        inside = np.flatnonzero((z > 1e-6) & (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height))
        d = view.depth_m[v[inside].astype(np.intp), u[inside].astype(np.intp)]
        behind = (d > 0) & (d <= depth_trunc_m) & (d < z[inside] - trunc_m)
        hidden = inside[behind]
        field[undecided[hidden]] = -1.0
        keep = np.ones(len(undecided), bool)
        keep[hidden] = False
        undecided, p = undecided[keep], p[keep]
    # intersect with the half-space above the cut: the table goes, the footprint closes
    t = grid.tsdf
    axes = [(np.arange(n) + o) * grid.voxel_size_m for n, o in zip(t.shape, grid.origin_index)]
    heights = (
        normal[0] * axes[0][:, None, None] + normal[1] * axes[1][None, :, None] + normal[2] * axes[2][None, None, :]
    ) + offset
    np.maximum(t, np.clip((cut_m - heights) / trunc_m, -1.0, 1.0).astype(t.dtype), out=t)
    for axis in range(3):  # an empty border closes every surface
        sl = [slice(None)] * 3
        sl[axis] = slice(0, 2)
        t[tuple(sl)] = 1.0
        sl[axis] = slice(-2, None)
        t[tuple(sl)] = 1.0


def extract_mesh(grid: _Grid):
    """Marching cubes on the closed field, through Open3D's VoxelBlockGrid."""
    import trimesh

    _store(grid.tsdf, grid.vbg.attribute("tsdf").numpy(), grid.buf_indices)
    grid.vbg.attribute("weight").numpy()[grid.buf_indices.reshape(-1)] = 1.0
    tm = grid.vbg.extract_triangle_mesh(weight_threshold=0.5)
    vertices = tm.vertex.positions.numpy().astype(np.float64)
    faces = tm.triangle.indices.numpy().astype(np.int64)
    if len(faces) == 0:
        raise ReconstructError("marching cubes found no surface: nothing solid above the support plane")
    mesh = trimesh.Trimesh(vertices, faces, process=True)
    return canonical(mesh)
