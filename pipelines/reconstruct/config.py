"""Settings and results of the reconstruction, and its error."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh


class ReconstructError(RuntimeError):
    """The scan could not be turned into a watertight object mesh; the message says why and what to try."""


@dataclass(frozen=True)
class ReconstructConfig:
    """Segmentation, TSDF fusion and cleanup settings; `None` means chosen from the data."""

    voxel_size_m: float | None = None
    """TSDF voxel edge [m]. None: the edge that fills the fusion box with about `voxel_budget` voxels,
    clamped to `voxel_size_range_m`. Sizing by the box rather than the largest extent gives flat and
    elongated objects (tools, plates) voxels as fine as compact ones for the same cost."""
    voxel_budget: int = 2_000_000
    """Voxels of the fusion box when `voxel_size_m` is None. TSDF time grows with it: about 15 ns per
    voxel per 640x480 frame on two CPU cores, so 2 M voxels cost about 30 ms per frame."""
    voxel_size_range_m: tuple[float, float] = (0.0005, 0.005)
    """Clamp for the automatic voxel size [m]."""
    sdf_trunc_voxels: float = 3.0
    """TSDF truncation distance [voxels], 2-10; raised to `noise_trunc_sigmas` depth-noise sigmas when larger.
    Voxels up to this far behind an observed surface count as inside, so a wide band fills the unseen
    wedge under a round part resting on the table (a hammer lying flat: +14 % volume at 5 voxels of
    2.2 mm, +4.4 % at 3 voxels of 1 mm)."""
    noise_trunc_sigmas: float = 1.75
    """The truncation is at least this many standard deviations of the depth noise, measured on the
    support plane (median absolute residual along the rays). A band narrower than the noise erodes
    the surface: a 3 cm cube under 2 mm noise lost 8.7 % of its volume at 5 voxels of 0.5 mm (1.25 sigmas),
    0.3 % at 10, and a screwdriver lost 4.7 % at 1.5 sigmas. A wider one fills concave corners narrower
    than itself: a hex key lying on a face has a 1.7 mm wedge between the table and each lower face, and
    under 2.2 mm of depth noise at 0.4 m it came out +9.8 % at 3 sigmas, +3.2 % at 2 and +0.6 % at 1.75 (a
    screwdriver +6.5, +0.5 and -1.7 %), while primitives and push shapes of 5 cm and more stayed within
    2.1 % of their volume (within 1.0 % at 3 sigmas)."""
    depth_trunc_m: float = 3.0
    """Depth beyond this is ignored [m]."""
    silhouette_jump_truncations: float = 0.0
    """Pixels whose 3x3 neighbourhood spans more than this many truncation distances in depth (silhouettes)
    are left out of the fusion; 0 keeps them. Sampled at pixel centres, silhouettes erode the surface by
    about 0.05 mm (two noise-free scans of a 5 mm bar, intersected: -3.6 %, and -0.3 % without them), but the table beside a round object's silhouette
    is also what carves the wedge under it (a 5 cm ball: -0.3 % with them, +0.9 % without). One session
    keeps them; merged sessions (`SessionsConfig`) drop them at 2: their intersection keeps the inner of
    the surfaces everywhere, so erosion adds up, while the other session carves the wedges. Twice the
    truncation keeps noise (9 samples span about 3 sigmas) from dropping pixels on smooth surfaces."""
    use_masks: bool = True
    """Segment with the scan's masks when every frame has one; else by plane and clustering."""
    segmentation_stride: int = 4
    """Pixel stride of the back-projection used for segmentation and plane fitting, 1-16."""
    plane_distance_m: float | None = None
    """RANSAC inlier distance for the support plane [m]. None: max(2 mm, 0.5 % of the median depth)."""
    plane_ransac_iterations: int = 2000
    """RANSAC iterations for the support plane."""
    object_min_height_m: float | None = None
    """Without masks: points this far above the plane are object candidates [m]. None: 2 x plane_distance_m."""
    cluster_eps_m: float | None = None
    """DBSCAN neighbourhood radius [m]. None: 3 x the back-projected pixel footprint x stride."""
    cluster_min_points: int = 10
    """DBSCAN minimum cluster size [points]."""
    pose_refine_rounds: int = 0
    """Rounds of frame-to-model point-to-plane ICP that correct the camera poses before the final
    fusion, 0-5; 0 trusts the poses as given. The mean correction is removed, so the object stays
    where the input poses put it. Worth it when poses are off by more than ~1 mm at the object
    (it halved the volume loss of a 4 cm cube under 1 mm / 0.3 deg pose noise, -12 % to -6 %);
    with accurate poses it costs ~0.5 % of volume, as frames settle onto the slightly eroded model."""
    pose_refine_max_distance_m: float | None = None
    """ICP correspondence distance [m]; should exceed the pose error at the object. None: 8 voxels."""
    region_margin: float = 0.15
    """Margin around the segmented object for the fusion box, per axis as a fraction of the object's size
    along it (at least a quarter of its largest extent), plus the truncation."""
    cut_height_voxels: float = 1.5
    """Height above the support plane where the table is cut away [voxels]; the slab below is extruded. The
    slab is the cut's cross-section carried down to the table, so it overfills wherever the object narrows
    towards its contact: a 30 cm ball (3.4 mm voxels) was 1.68 mm off in COM at 3 voxels, 1.42 mm at 1.5."""
    smoothing_iterations: int = 10
    """Taubin smoothing steps (lambda 0.5, mu -0.53; volume-preserving) on the marching-cubes mesh, 0-50.
    On the 4 cm test cube, 10 steps cut the mean surface error from 0.10 to 0.08 mm."""
    max_voxels: int = 40_000_000
    """Refuse fusion boxes with more voxels than this (memory: ~20 bytes per voxel)."""
    target_faces: int = 20000
    """Face count after quadric decimation; 0 keeps the marching-cubes mesh."""
    seed: int = 0
    """Seed of Open3D's RANSAC, so reruns give identical meshes."""
    raised_gap_m: float = 0.02
    """The object does not rest on the support plane when its lowest observed points [m] lie higher than
    this and than `raised_gap_fraction` of its observed height. A round object hides its underside: a 30 cm
    ball seen from 25-65 deg elevation shows nothing lower than 80 mm, 36 % of its observed height; RigPI's
    doors and drawer in their furniture start 1.3-2.1 of their heights up."""
    raised_gap_fraction: float = 1.0
    """See `raised_gap_m`."""
    embedded_contiguity: float = 0.75
    """The object is embedded in other geometry (a drawer front flush with its chest, a door against its
    carcass: 0.94-0.99) when at least this fraction of the pixels just outside its masks continue its surface
    in depth, and its lowest points are 10 mm clear of the plane. An object on a table continues into it
    along its footprint only (the bench's objects: 0.00-0.64; a hex key lying flat, 0.76, is not clear)."""
    carcass_band_px: tuple[float, float] = (1.0, 3.0)
    """An embedded part's carcass step is read from the pixels just outside each view's mask against those
    just inside: the bands' gap from the mask's border and their width [pixels]. Narrow, so that depth noise
    moving in patches cancels between them; wider bands read a 2 mm step 5 % thick or more."""
    panel_thickness_m: tuple[float, float] = (0.018, 0.006)
    """Thickness of an embedded part whose depth nothing shows [m]: value and standard uncertainty
    (cabinet doors and panels are 12-25 mm boards)."""
    drawer_back_allowance_m: tuple[float, float] = (0.02, 0.01)
    """A drawer (the scan's name says so) flush with its carcass runs to the carcass's back less this [m]:
    value and standard uncertainty (a 6-12 mm back panel and 5-15 mm clearance)."""


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """The reconstructed object.

    mesh: trimesh.Trimesh, world frame [m], watertight, outward normals, at the scanned placement:
      resting on the support plane, or, for a part embedded in furniture, its front extruded backwards.
    support_plane: (normal [3], offset [m]) with normal . x + offset = 0 on the
      plane, normal pointing up (towards the cameras), world frame.
    object_points_count: back-projected points segmented as the object.
    observed_points: those points, world frame [m], shape [n, 3], thinned to about one per pixel
      footprint: the surface the cameras actually saw, as opposed to what closing added.
    voxel_size_m: TSDF voxel edge used [m].
    stats: timings [s], counts and intermediate values, JSON-serialisable.
    """

    mesh: "trimesh.Trimesh"
    support_plane: tuple[np.ndarray, float]
    object_points_count: int
    voxel_size_m: float
    observed_points: np.ndarray
    stats: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SceneConfig:
    """TSDF fusion of a whole scene (a room seen by a Kinect): no segmentation, no closing."""

    voxel_size_m: float = 0.02
    """TSDF voxel edge [m]."""
    sdf_trunc_voxels: float = 4.0
    """TSDF truncation distance [voxels]."""
    depth_trunc_m: float = 4.0
    """Depth beyond this is ignored [m]."""
    weight_threshold: float = 2.0
    """Surface only where at least this many views observed the voxel."""
    min_component_faces: int = 500
    """Connected pieces of the mesh with fewer faces are dropped (depth speckle)."""


@dataclass(frozen=True, eq=False)
class SceneReconstruction:
    """The fused surface of a scene.

    mesh: trimesh.Trimesh, world frame [m]; open (a scene has no inside).
    voxel_size_m: TSDF voxel edge used [m].
    stats: timings [s] (`tsdf_s_per_frame` covers block allocation and integration), counts.
    """

    mesh: "trimesh.Trimesh"
    voxel_size_m: float
    stats: dict = field(default_factory=dict)
