"""Camera poses for RGB-D frames that come without them, and their error against given poses.

Method (`estimate_poses`):

1. Each frame's depth is back-projected (every `stride`-th pixel) into a cloud in
   its camera and downsampled at each of the coarse-to-fine `voxel_sizes_m`, with
   normals.
2. Odometry: for each consecutive pair, multi-scale point-to-plane ICP is started
   from each of `initial_guesses` (identity, the previous step's motion, and
   Open3D's RGB-D odometry, photometric plus geometric) and the result with the
   largest overlap (ICP fitness), then smallest residual, is kept. A pair no
   guess registers (fitness below `min_fitness`) raises `PosingError`: the
   frames do not overlap enough to chain.
3. Pose graph: each frame is also registered to up to `neighbour_count` earlier
   frames, starting from the chained estimate; these edges are marked uncertain,
   so Open3D's global optimisation (Levenberg-Marquardt with a line process)
   prunes the ones that disagree, and spreads the odometry's drift over the rest.
4. Frame-to-model: for `model_rounds` rounds, the frames are fused into a TSDF
   (Open3D VoxelBlockGrid) at the finest voxel size and each frame is registered
   by point-to-plane ICP to the fused surface, which averages the depth noise
   of all frames that see it.

The world frame is the first camera's (OpenCV axes: x right, y down, z forward),
in metres: depth fixes the scale. Depth-only ICP needs geometric structure: a
single plane (a bare table) leaves in-plane motion undetermined.

On 100 real Kinect frames of 7-Scenes (every 10th frame, 2-4 m depth, colour not
registered to depth) the frame-to-frame error against KinectFusion's poses has a
median of 0.3 deg and 8 mm; see BENCHMARKS.md (`twin bench reconstruct`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .rgbd import Frame, ScanError, decoded_pixels, open_image

__all__ = ["PoseErrors", "PoseEstimate", "PosingConfig", "PosingError", "estimate_poses", "pose_errors"]

InitialGuess = Literal["identity", "constant_velocity", "rgbd_odometry"]


class PosingError(RuntimeError):
    """The frames could not be posed; the message names the frames and why."""


@dataclass(frozen=True)
class PosingConfig:
    """Pose estimation settings; `None` means chosen from the data."""

    voxel_sizes_m: tuple[float, ...] | None = None
    """ICP voxel sizes, coarse to fine [m]. None: 4 %, 2 % and 1 % of the median depth
    (8, 4, 2 cm for a room seen from 2 m; 1.6, 0.8, 0.4 cm for an object at 40 cm)."""
    max_distance_voxels: tuple[float, ...] = (2.5, 2.0, 2.0)
    """ICP correspondence distance at each level [voxels of that level]; the coarsest level's
    bounds the motion between frames that can be recovered (~20 cm at 2 m depth)."""
    stride: int = 2
    """Pixel stride of the back-projection, 1-8."""
    depth_max_m: float = 4.0
    """Depth beyond this is ignored [m]."""
    initial_guesses: tuple[InitialGuess, ...] = ("identity", "constant_velocity", "rgbd_odometry")
    """Starting points of the odometry's ICP; the best registered result wins."""
    min_fitness: float = 0.3
    """Least share of a frame's points with a correspondence for a registration to count, 0-1."""
    neighbour_count: int = 3
    """Earlier frames each frame is registered to, besides its predecessor (pose-graph edges), 0-10."""
    edge_prune_threshold: float = 0.25
    """Line-process weight below which Open3D's global optimisation drops an uncertain edge, 0-1."""
    model_rounds: int = 2
    """Rounds of frame-to-model registration against the fused TSDF surface, 0-5."""
    max_iterations: int = 30
    """ICP iterations per level."""
    convergence: float = 1e-4
    """ICP stops when fitness and residual change by less than this fraction (Open3D's default is 1e-6)."""


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """Estimated camera poses.

    T_world_camera: camera-to-world [m], OpenCV axes, world = the first camera, shape [frame_count, 4, 4].
    stats: timings [s], odometry fitness and residuals, pose-graph edge counts; JSON-serialisable.
    """

    T_world_camera: np.ndarray
    stats: dict = field(default_factory=dict)


@dataclass(frozen=True)
class PoseErrors:
    """Errors of estimated camera poses against given ones.

    relative_rotation_deg, relative_translation_m: error of each consecutive frame-to-frame
      motion (no alignment needed), shape [frame_count - 1].
    absolute_rotation_deg, absolute_translation_m: error of each pose after the rigid transform
      that best aligns the estimated trajectory with the given one, shape [frame_count]: its
      rotation is the chordal mean of the per-frame orientation offsets, its translation the mean
      offset of the camera centres after that rotation. (Aligning the centres alone, as the TUM
      benchmark does, leaves the rotation ill-determined on short, nearly straight paths.)
    """

    relative_rotation_deg: np.ndarray
    relative_translation_m: np.ndarray
    absolute_rotation_deg: np.ndarray
    absolute_translation_m: np.ndarray

    def summary(self) -> dict:
        """Median, max and RMS of each error, JSON-serialisable."""
        out = {}
        for name in ("relative_rotation_deg", "relative_translation_m", "absolute_rotation_deg", "absolute_translation_m"):
            x = np.asarray(getattr(self, name), float)
            out[name] = {"median": float(np.median(x)), "max": float(x.max()), "rms": float(np.sqrt(np.mean(x**2)))}
        return out


def estimate_poses(frames: Sequence[Frame], config: PosingConfig = PosingConfig()) -> PoseEstimate:
    """Pose RGB-D frames by odometry (ICP from several starts), a pose graph and frame-to-model ICP.

    Args:
        frames: the views, in capture order (consecutive frames must overlap); their
            `T_world_camera` is not used.
        config: see `PosingConfig`.

    Returns:
        Poses with the first camera as world.

    Raises:
        PosingError: for fewer than two frames, a frame with too little valid depth, or a
            consecutive pair that no initial guess registers.
    """
    import open3d as o3d

    _check(frames, config)
    reg = o3d.pipelines.registration
    t0 = time.perf_counter()
    depths = np.concatenate([f.depth_m[f.depth_m > 0][::61] for f in frames])
    median_depth = float(np.median(depths))
    voxels = config.voxel_sizes_m or tuple(median_depth * s for s in (0.04, 0.02, 0.01))
    if len(config.max_distance_voxels) != len(voxels):
        raise PosingError(
            f"max_distance_voxels has {len(config.max_distance_voxels)} levels but voxel_sizes_m has {len(voxels)}"
        )
    distances = tuple(v * k for v, k in zip(voxels, config.max_distance_voxels))
    pyramids = [_pyramid(i, f, voxels, config) for i, f in enumerate(frames)]
    stats: dict = {"median_depth_m": median_depth, "voxel_sizes_m": list(voxels), "prepare_s": time.perf_counter() - t0}

    estimation = reg.TransformationEstimationPointToPlane()
    criteria = reg.ICPConvergenceCriteria(
        relative_fitness=config.convergence, relative_rmse=config.convergence, max_iteration=config.max_iterations
    )

    def icp(source: list, target: list, init: np.ndarray, first_level: int = 0):
        T, result = init, None
        for level in range(first_level, len(voxels)):
            result = reg.registration_icp(source[level], target[level], distances[level], T, estimation, criteria)
            T = np.asarray(result.transformation)
        return T, result

    # 1. odometry: the best of several starts for each consecutive pair
    t1 = time.perf_counter()
    rgbd = _RgbdOdometry(frames, config) if "rgbd_odometry" in config.initial_guesses else None
    poses = [np.eye(4)]
    motion = np.eye(4)
    odometry = []
    for i in range(1, len(frames)):
        best = None
        for guess in config.initial_guesses:
            if guess == "identity":
                init = np.eye(4)
            elif guess == "constant_velocity":
                if i == 1:
                    continue
                init = motion
            else:
                init = rgbd.motion(i, i - 1)
            T, result = icp(pyramids[i], pyramids[i - 1], init)
            score = (round(result.fitness, 3), -result.inlier_rmse)
            if best is None or score > best[0]:
                best = (score, T, result, guess)
        _, T, result, guess = best
        if result.fitness < config.min_fitness:
            raise PosingError(
                f"frames {i - 1} and {i} ({frames[i - 1].depth_path.name}, {frames[i].depth_path.name}) do not "
                f"overlap enough to register (ICP fitness {result.fitness:.2f} < min_fitness {config.min_fitness}); "
                "are they in capture order, with small motion between them?"
            )
        motion = T
        poses.append(poses[-1] @ T)
        odometry.append({"fitness": float(result.fitness), "rmse_m": float(result.inlier_rmse), "start": guess})
    stats["odometry_s"] = time.perf_counter() - t1
    stats["odometry"] = {
        "fitness_min": min(e["fitness"] for e in odometry),
        "rmse_median_m": float(np.median([e["rmse_m"] for e in odometry])),
        "starts": {g: sum(e["start"] == g for e in odometry) for g in config.initial_guesses},
    }

    # 2. pose graph with edges to earlier neighbours
    t2 = time.perf_counter()
    poses = np.array(poses)
    if config.neighbour_count > 0 and len(frames) > 2:
        graph = reg.PoseGraph()
        for T in poses:
            graph.nodes.append(reg.PoseGraphNode(T))
        finest = len(voxels) - 1
        for i in range(1, len(frames)):
            for j in range(max(0, i - 1 - config.neighbour_count), i):
                init = np.linalg.inv(poses[j]) @ poses[i]
                # the chained estimate is close: the finer levels suffice
                T, result = icp(pyramids[i], pyramids[j], init, len(voxels) - 2) if j < i - 1 else (init, None)
                if result is not None and result.fitness < config.min_fitness:
                    continue
                info = reg.get_information_matrix_from_point_clouds(
                    pyramids[i][finest], pyramids[j][finest], distances[finest], T
                )
                graph.edges.append(reg.PoseGraphEdge(i, j, T, info, uncertain=j < i - 1))
        option = reg.GlobalOptimizationOption(
            max_correspondence_distance=distances[-1],
            edge_prune_threshold=config.edge_prune_threshold,
            preference_loop_closure=1.0,
            reference_node=0,
        )
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            reg.global_optimization(
                graph, reg.GlobalOptimizationLevenbergMarquardt(), reg.GlobalOptimizationConvergenceCriteria(), option
            )
        poses = _rebased(np.array([node.pose for node in graph.nodes]))
        stats["pose_graph_edges"] = len(graph.edges)
    stats["pose_graph_s"] = time.perf_counter() - t2

    # 3. frame-to-model rounds
    t3 = time.perf_counter()
    finest = len(voxels) - 1
    for _ in range(config.model_rounds):
        model = _fused_cloud(frames, poses, voxels[finest], config)
        if len(model.points) < 100:
            break
        refined = []
        for i, T in enumerate(poses):
            result = reg.registration_icp(pyramids[i][finest], model, distances[finest], T, estimation, criteria)
            refined.append(np.asarray(result.transformation) if result.fitness >= config.min_fitness else T)
        poses = _rebased(np.array(refined))
    stats["model_s"] = time.perf_counter() - t3
    stats["total_s"] = time.perf_counter() - t0
    return PoseEstimate(T_world_camera=poses, stats=stats)


def pose_errors(estimated: np.ndarray, given: np.ndarray) -> PoseErrors:
    """Errors of estimated camera-to-world poses against given ones (both [frame_count, 4, 4], metres).

    The estimated poses may live in another world frame (e.g. the first camera's): the
    relative errors need no alignment, the absolute ones are taken after the rigid
    transform that best maps the estimated poses onto the given ones (see `PoseErrors`).
    """
    estimated, given = np.asarray(estimated, float), np.asarray(given, float)
    if estimated.shape != given.shape or estimated.ndim != 3 or estimated.shape[1:] != (4, 4):
        raise ValueError(f"pose_errors: expected two [n, 4, 4] arrays of one shape, got {estimated.shape} and {given.shape}")
    if len(given) < 2:
        raise ValueError("pose_errors: needs at least two poses")
    rel_e = np.linalg.inv(estimated[:-1]) @ estimated[1:]
    rel_g = np.linalg.inv(given[:-1]) @ given[1:]
    rel_rot = _angle_deg(rel_e[:, :3, :3], rel_g[:, :3, :3])
    rel_trans = np.linalg.norm(rel_e[:, :3, 3] - rel_g[:, :3, 3], axis=1)
    aligned = _alignment(estimated, given) @ estimated
    abs_rot = _angle_deg(aligned[:, :3, :3], given[:, :3, :3])
    abs_trans = np.linalg.norm(aligned[:, :3, 3] - given[:, :3, 3], axis=1)
    return PoseErrors(rel_rot, rel_trans, abs_rot, abs_trans)


# ---------------------------------------------------------------------------------------------


def _check(frames: Sequence[Frame], config: PosingConfig) -> None:
    if len(frames) < 2:
        raise PosingError(f"needs at least two frames to estimate motion, got {len(frames)}")
    if not 1 <= config.stride <= 8:
        raise PosingError(f"stride must be 1-8, got {config.stride}")
    if not config.initial_guesses:
        raise PosingError("initial_guesses is empty")
    if not 0.0 < config.min_fitness < 1.0:
        raise PosingError(f"min_fitness must lie in (0, 1), got {config.min_fitness}")


def _pyramid(i: int, frame: Frame, voxels: tuple[float, ...], config: PosingConfig) -> list:
    """The frame's cloud in its camera [m], downsampled at each voxel size, with normals."""
    import open3d as o3d

    intr = frame.intrinsics
    s = config.stride
    rows = np.arange(s // 2, intr.height, s)
    cols = np.arange(s // 2, intr.width, s)
    z = frame.depth_m[np.ix_(rows, cols)].astype(np.float64)
    u, v = np.meshgrid(cols + 0.5, rows + 0.5)
    ok = (z > 0) & (z <= config.depth_max_m)
    if ok.sum() < 100:
        raise PosingError(f"{frame.depth_path}: frame {i} has too little valid depth ({int(ok.sum())} points) to register")
    z, u, v = z[ok], u[ok], v[ok]
    points = np.stack([(u - intr.cx) / intr.fx * z, (v - intr.cy) / intr.fy * z, z], axis=1)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    levels = []
    for voxel in voxels:
        level = cloud.voxel_down_sample(voxel)
        level.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel, max_nn=30))
        levels.append(level)
    return levels


class _RgbdOdometry:
    """Open3D's multi-scale RGB-D odometry (photometric + point-to-plane terms) between two frames."""

    def __init__(self, frames: Sequence[Frame], config: PosingConfig):
        self.frames, self.config = frames, config
        self._images: dict[int, object] = {}

    def _image(self, i: int):
        import open3d as o3d
        import open3d.core as o3c

        if i not in self._images:
            if len(self._images) > 4:
                self._images.pop(min(self._images))
            f = self.frames[i]
            depth = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(f.depth_m)))
            color = _read_color(f.color_path, f.intrinsics)
            self._images[i] = o3d.t.geometry.RGBDImage(color, depth) if color is not None else None
        return self._images[i]

    def motion(self, source: int, target: int) -> np.ndarray:
        """T_target_source, or identity when the colour is unusable or the odometry fails."""
        import open3d.core as o3c
        from open3d.t.pipelines import odometry

        a, b = self._image(source), self._image(target)
        if a is None or b is None:
            return np.eye(4)
        K = o3c.Tensor(self.frames[source].intrinsics.matrix())
        criteria = [odometry.OdometryConvergenceCriteria(n) for n in (20, 10, 5)]
        try:
            result = odometry.rgbd_odometry_multi_scale(
                a, b, K, o3c.Tensor(np.eye(4)), 1.0, float(self.config.depth_max_m), criteria, odometry.Method.Hybrid
            )
        except RuntimeError:
            return np.eye(4)
        T = result.transformation.numpy()
        return T if np.all(np.isfinite(T)) else np.eye(4)


def _read_color(path, intr):
    """Colour as an Open3D float image in [0, 1], or None when it cannot be read or differs in size."""
    import open3d as o3d
    import open3d.core as o3c

    try:
        with open_image(path) as im:
            if im.size != (intr.width, intr.height):  # checked before decoding: the header may claim any size
                return None
            rgb = decoded_pixels(im, path, "RGB").astype(np.float32) / 255.0
    except ScanError:
        return None
    return o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(rgb)))


def _fused_cloud(frames: Sequence[Frame], poses: np.ndarray, voxel: float, config: PosingConfig):
    """The TSDF-fused surface of all frames as a cloud with normals (world frame)."""
    import open3d as o3d
    import open3d.core as o3c

    device = o3c.Device("CPU:0")
    grid = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight"),
        attr_dtypes=(o3c.float32, o3c.float32),
        attr_channels=((1), (1)),
        voxel_size=voxel,
        block_resolution=8,
        block_count=20000,
        device=device,
    )
    trunc = 3.0
    for f, T in zip(frames, poses):
        depth = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(f.depth_m)))
        K, extrinsic = o3c.Tensor(f.intrinsics.matrix()), o3c.Tensor(np.linalg.inv(T))
        blocks = grid.compute_unique_block_coordinates(depth, K, extrinsic, 1.0, config.depth_max_m, trunc)
        grid.integrate(blocks, depth, K, extrinsic, 1.0, config.depth_max_m, trunc)
    cloud = grid.extract_point_cloud(weight_threshold=2.0).to_legacy().voxel_down_sample(voxel)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel, max_nn=30))
    return cloud


def _rebased(poses: np.ndarray) -> np.ndarray:
    """The same trajectory with the first camera as world."""
    return np.linalg.inv(poses[0]) @ poses


def _angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle of Ra^T Rb [deg], per leading index."""
    c = (np.trace(np.swapaxes(Ra, -1, -2) @ Rb, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def _alignment(estimated: np.ndarray, given: np.ndarray) -> np.ndarray:
    """The rigid T with T @ estimated ~ given: chordal mean rotation, then the mean centre offset."""
    M = np.einsum("nij,nkj->ik", given[:, :3, :3], estimated[:, :3, :3])  # sum of R_given R_estimated^T
    U, _, Vt = np.linalg.svd(M)
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.mean(given[:, :3, 3] - estimated[:, :3, 3] @ R.T, axis=0)
    return T
