"""Render a synthetic RGB-D scan of a mesh resting on a table, in the nerfstudio layout.

The scan is written exactly as `pipelines.scan.read_scan` reads it (DESIGN.md,
"Inputs"): colour images, 16-bit z-depth PNGs, 8-bit masks (object = 255),
`transforms.json` with camera-to-world poses in OpenGL axes, and `object.json`.

Cameras sit on rings around the object, looking at its centre. Depth carries
the noise of a structured-light / time-of-flight sensor: Gaussian with standard
deviation sigma(z) = sigma_0 + c * z^2, independent per pixel or smooth over a
few pixels, quantised to the depth unit, with dropout at random pixels, at
grazing angles and at depth discontinuities.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

if TYPE_CHECKING:
    import trimesh

__all__ = ["RenderConfig", "look_at", "render_mesh_image", "render_scan", "render_views"]


@dataclass(frozen=True)
class RenderConfig:
    """How to render a synthetic scan."""

    width: int = 640
    """Image width [pixels]."""
    height: int = 480
    """Image height [pixels]."""
    fx: float = 600.0
    """Horizontal focal length [pixels]; the principal point is the image centre."""
    fy: float = 600.0
    """Vertical focal length [pixels]."""
    view_count: int = 24
    """Number of views, spread evenly over the rings in `elevations_deg`."""
    elevations_deg: tuple[float, ...] = (25.0, 45.0, 65.0)
    """Camera elevation of each ring above the table plane [deg], 0-90."""
    distance_range_m: tuple[float, float] = (0.35, 0.5)
    """Camera distance from the object's centre [m], drawn uniformly per view."""
    azimuth_span_deg: float = 360.0
    """Azimuth range each ring's views are spread over [deg], 0-360; less than 360 gives an arc
    (a hand-held sweep whose consecutive views overlap, as pose-free scans need)."""
    azimuth_jitter_deg: float = 5.0
    """Uniform jitter of each view's azimuth [deg]."""
    look_at_jitter_m: float = 0.005
    """Standard deviation of the look-at point around the object's centre [m]."""
    depth_noise_base_m: float = 0.5e-3
    """Depth noise floor sigma_0 [m]."""
    depth_noise_quadratic_per_m: float = 1.5e-3
    """Depth noise growth c [1/m]: sigma(z) = sigma_0 + c z^2 (0.74 mm at 0.4 m)."""
    depth_noise_smoothing_px: float = 0.0
    """0 draws the depth noise independently per pixel. Above 0 it is a smooth field: white noise filtered by a
    Gaussian of this standard deviation [pixels] and rescaled to unit variance, then scaled by sigma(z), as the
    depth of real structured-light and stereo sensors moves in patches (the posecnn_ycb_demo frames at 0.7 m
    differ by 0.2 mm between neighbouring pixels and by 2.2 mm between pixels 16 apart; 8 pixels fits)."""
    depth_unit_m: float = 0.001
    """Depth quantisation and the written depth_unit_scale_factor [m per unit]."""
    depth_range_m: tuple[float, float] = (0.1, 3.0)
    """Sensor range [m]; depth outside reads 0 (invalid)."""
    dropout_random: float = 0.01
    """Fraction of pixels dropped at random, 0-1."""
    dropout_grazing_cos: float = 0.25
    """Below this |cos| of the incidence angle a pixel is dropped with probability
    1 - |cos| / dropout_grazing_cos."""
    dropout_edge: float = 0.5
    """Probability of dropping a pixel at a depth discontinuity, 0-1."""
    edge_jump_m: float = 0.01
    """Depth difference to a neighbouring pixel that marks a discontinuity [m]."""
    table_size_m: tuple[float, float] = (0.3, 0.3)
    """Table top extent along world x and y [m], centred under the object."""
    table_thickness_m: float = 0.03
    """Table thickness [m]."""
    object_rgb: tuple[int, int, int] = (196, 84, 60)
    """Object albedo, 8-bit RGB."""
    table_rgb: tuple[int, int, int] = (150, 132, 105)
    """Table albedo, 8-bit RGB."""
    texture_amplitude: float = 0.15
    """Relative amplitude of the world-fixed procedural texture, 0-1."""
    color_noise: float = 2.0
    """Per-pixel colour noise standard deviation [8-bit levels]."""
    color_format: Literal["jpg", "png"] = "jpg"
    """Colour image file format."""
    jpeg_quality: int = 85
    """JPEG quality, 1-95."""
    write_masks: bool = True
    """Write object masks (masks/, object = 255) and list them in transforms.json."""
    pose_noise_translation_m: float = 0.0
    """Standard deviation of the error added to each written camera position [m]
    (rendering uses the true pose)."""
    pose_noise_rotation_deg: float = 0.0
    """Standard deviation of the error added to each written camera orientation [deg]."""


def render_scan(
    mesh_world: "trimesh.Trimesh",
    out_dir: Path,
    config: RenderConfig = RenderConfig(),
    rng: np.random.Generator | None = None,
    name: str = "object",
    material_hint: str | None = None,
) -> Path:
    """Raytrace an RGB-D scan of `mesh_world` resting on a table and write it to `out_dir`.

    Args:
        mesh_world: trimesh.Trimesh in world coordinates [m], z up. The table's top
            is placed at the mesh's lowest z, so the object rests on it.
        out_dir: the scan directory to write (created; existing files are overwritten).
        config: cameras, sensor noise, scene.
        rng: all randomness (view jitter, noise, dropout); default seed 0.
        name, material_hint: written to object.json.

    Returns:
        out_dir.
    """
    import trimesh

    rng = np.random.default_rng(0) if rng is None else rng
    vertices = np.asarray(mesh_world.vertices, dtype=np.float64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = 0.5 * (lo + hi)
    table = trimesh.creation.box(extents=(*config.table_size_m, config.table_thickness_m))
    table.apply_translation((centre[0], centre[1], lo[2] - 0.5 * config.table_thickness_m))
    poses = _camera_poses(config, centre, rng)
    return render_views(mesh_world, [table], poses, out_dir, config, rng, name, material_hint)


def render_views(
    part_world: "trimesh.Trimesh",
    surroundings: "list[trimesh.Trimesh]",
    poses: list[np.ndarray],
    out_dir: Path,
    config: RenderConfig = RenderConfig(),
    rng: np.random.Generator | None = None,
    name: str = "object",
    material_hint: str | None = None,
) -> Path:
    """Raytrace the part among its surroundings from the given cameras and write the scan to `out_dir`.

    Depth covers the whole scene; masks mark the part only (what a segmenter given the part would mark).

    Args:
        part_world: trimesh.Trimesh in world coordinates [m]: the masked object.
        surroundings: other meshes in world coordinates [m] (table, furniture carcass, floor), unmasked
            and shaded with `table_rgb`.
        poses: camera-to-world [4, 4], OpenCV axes (z forward, y down), one per frame.
        out_dir: the scan directory to write (created; existing files are overwritten).
        config: image size, focal lengths, sensor noise, shading.
        rng: the noise and dropout; default seed 0.
        name, material_hint: written to object.json.

    Returns:
        out_dir.
    """
    import open3d as o3d
    from PIL import Image

    rng = np.random.default_rng(0) if rng is None else rng
    out_dir = Path(out_dir)
    for sub in ("images", "depth") + (("masks",) if config.write_masks else ()):
        (out_dir / sub).mkdir(parents=True, exist_ok=True)

    scene = o3d.t.geometry.RaycastingScene()
    object_id = scene.add_triangles(
        o3d.core.Tensor(np.asarray(part_world.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(part_world.faces, dtype=np.uint32)),
    )
    for other in surroundings:
        scene.add_triangles(
            o3d.core.Tensor(np.asarray(other.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(other.faces, dtype=np.uint32)),
        )

    w, h = config.width, config.height
    cx, cy = 0.5 * w, 0.5 * h
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)  # pixel centres
    rays_camera = np.stack([(u - cx) / config.fx, (v - cy) / config.fy, np.ones_like(u)], axis=-1)

    frames = []
    for i, T_world_camera in enumerate(poses):
        R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
        directions = rays_camera @ R.T  # z-component 1 in the camera: t_hit is z-depth
        rays = np.concatenate([np.broadcast_to(t, directions.shape), directions], axis=-1).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays))
        z = hit["t_hit"].numpy().astype(np.float64)
        ids = hit["geometry_ids"].numpy()
        normals = hit["primitive_normals"].numpy().astype(np.float64)
        valid = np.isfinite(z)
        z[~valid] = 0.0
        is_object = valid & (ids == object_id)

        unit_dirs = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
        cos_incidence = np.abs(np.einsum("hwk,hwk->hw", normals, unit_dirs))
        depth = _sensor_depth(z, valid, cos_incidence, config, rng)
        points = t + z[..., None] * directions
        color = _shade(points, normals, unit_dirs, valid, is_object, config, rng)

        stem = f"frame_{i:05d}"
        color_rel = f"images/{stem}.{config.color_format}"
        if config.color_format == "jpg":
            Image.fromarray(color).save(out_dir / color_rel, quality=config.jpeg_quality)
        else:
            Image.fromarray(color).save(out_dir / color_rel)
        depth_rel = f"depth/{stem}.png"
        Image.fromarray(depth).save(out_dir / depth_rel)
        frame = {"file_path": color_rel, "depth_file_path": depth_rel}
        if config.write_masks:
            mask_rel = f"masks/{stem}.png"
            Image.fromarray((is_object * 255).astype(np.uint8)).save(out_dir / mask_rel)
            frame["mask_path"] = mask_rel
        written = _perturb_pose(T_world_camera, config, rng)
        frame["transform_matrix"] = (written @ _OPENGL_FROM_OPENCV).tolist()
        frames.append(frame)

    transforms = {
        "camera_model": "OPENCV",
        "fl_x": config.fx,
        "fl_y": config.fy,
        "cx": cx,
        "cy": cy,
        "w": w,
        "h": h,
        "k1": 0.0,
        "k2": 0.0,
        "p1": 0.0,
        "p2": 0.0,
        "depth_unit_scale_factor": config.depth_unit_m,
        "frames": frames,
    }
    (out_dir / "transforms.json").write_text(json.dumps(transforms, indent=1))
    info = {"name": name, "material": material_hint, "notes": "synthetic scan rendered by pipelines.synth.render"}
    (out_dir / "object.json").write_text(json.dumps(info, indent=1))
    (out_dir / "render.json").write_text(json.dumps(_jsonable(asdict(config)), indent=1))
    return out_dir


_OPENGL_FROM_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])


def _jsonable(d: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world [m] in OpenCV axes (z forward, y down) for a camera at `eye` looking at `target`,
    with `up` (world, default +z) pointing up in the image."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def _camera_poses(config: RenderConfig, centre: np.ndarray, rng: np.random.Generator) -> list[np.ndarray]:
    rings = len(config.elevations_deg)
    counts = [config.view_count // rings + (r < config.view_count % rings) for r in range(rings)]
    poses = []
    for r, (elevation, count) in enumerate(zip(config.elevations_deg, counts)):
        for k in range(count):
            azimuth = np.deg2rad(config.azimuth_span_deg) * (k + r / rings) / max(count, 1)
            azimuth += np.deg2rad(rng.uniform(-1, 1) * config.azimuth_jitter_deg)
            distance = rng.uniform(*config.distance_range_m)
            el = np.deg2rad(elevation)
            eye = centre + distance * np.array([np.cos(el) * np.cos(azimuth), np.cos(el) * np.sin(azimuth), np.sin(el)])
            target = centre + rng.normal(0.0, config.look_at_jitter_m, 3)
            poses.append(look_at(eye, target))
    return poses


def _sensor_depth(
    z: np.ndarray, valid: np.ndarray, cos_incidence: np.ndarray, config: RenderConfig, rng: np.random.Generator
) -> np.ndarray:
    """Noisy, quantised z-depth in depth units (uint16), 0 where invalid."""
    sigma = config.depth_noise_base_m + config.depth_noise_quadratic_per_m * z**2
    unit = rng.standard_normal(z.shape)
    if config.depth_noise_smoothing_px > 0:
        from scipy import ndimage

        unit = ndimage.gaussian_filter(unit, config.depth_noise_smoothing_px)
        unit /= unit.std()
    noisy = z + sigma * unit
    keep = valid & (noisy >= config.depth_range_m[0]) & (noisy <= config.depth_range_m[1])
    keep &= rng.random(z.shape) >= config.dropout_random
    if config.dropout_grazing_cos > 0:
        p_drop = np.clip(1.0 - cos_incidence / config.dropout_grazing_cos, 0.0, 1.0)
        keep &= rng.random(z.shape) >= p_drop
    zf = np.where(valid, z, 1e6)  # escaped rays: far away, so their border is an edge
    edge = np.zeros(z.shape, bool)
    for axis in (0, 1):
        jump = np.abs(np.diff(zf, axis=axis)) > config.edge_jump_m
        if axis == 0:
            edge[1:] |= jump
            edge[:-1] |= jump
        else:
            edge[:, 1:] |= jump
            edge[:, :-1] |= jump
    keep &= ~(edge & (rng.random(z.shape) < config.dropout_edge))
    units = np.rint(noisy / config.depth_unit_m)
    return np.where(keep, np.clip(units, 0, 65535), 0).astype(np.uint16)


def _perturb_pose(T: np.ndarray, config: RenderConfig, rng: np.random.Generator) -> np.ndarray:
    """The pose as a tracker would report it: the true one plus small random errors."""
    if config.pose_noise_translation_m <= 0 and config.pose_noise_rotation_deg <= 0:
        return T
    from scipy.spatial.transform import Rotation

    out = T.copy()
    rotvec = np.deg2rad(config.pose_noise_rotation_deg) * rng.standard_normal(3)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix() @ T[:3, :3]
    out[:3, 3] += config.pose_noise_translation_m * rng.standard_normal(3)
    return out


def _shade(
    points: np.ndarray,
    normals: np.ndarray,
    unit_dirs: np.ndarray,
    valid: np.ndarray,
    is_object: np.ndarray,
    config: RenderConfig,
    rng: np.random.Generator,
) -> np.ndarray:
    """Lambertian colour image (uint8 HxWx3): a key light from above, a headlight, ambient."""
    key = np.array([0.3, 0.2, 0.93], dtype=np.float32)
    key /= np.linalg.norm(key)
    n, d = normals[valid].astype(np.float32), unit_dirs[valid].astype(np.float32)  # shade hits only
    cos = np.einsum("nk,nk->n", n, d)
    facing = np.where((cos > 0)[:, None], -n, n)
    light = 0.25 + 0.45 * np.clip(facing @ key, 0, None) + 0.3 * np.abs(cos)
    p = points[valid].astype(np.float32) / np.float32(0.01)  # texture coordinates in centimetres, fixed to the world
    texture = (
        np.sin(p[:, 0] * 1.3 + np.sin(p[:, 1] * 0.7))
        + np.sin(p[:, 1] * 1.7 + np.sin(p[:, 2] * 0.9))
        + np.sin(p[:, 2] * 2.1 + np.sin(p[:, 0] * 1.1))
    ) / 3.0
    albedo = np.where(
        is_object[valid][:, None], np.array(config.object_rgb, np.float32), np.array(config.table_rgb, np.float32)
    )
    color = np.full(valid.shape + (3,), 40.0, dtype=np.float32)  # dark background where rays escape
    color[valid] = albedo * (light * (1.0 + config.texture_amplitude * texture))[:, None]
    color += np.float32(config.color_noise) * rng.standard_normal(color.shape, dtype=np.float32)
    return np.clip(np.rint(color), 0, 255).astype(np.uint8)


def render_mesh_image(
    mesh: "trimesh.Trimesh",
    path: Path,
    T_world_camera: np.ndarray | None = None,
    width: int = 960,
    height: int = 720,
    fov_deg: float = 60.0,
    rgb: tuple[int, int, int] = (200, 200, 205),
) -> Path:
    """Raytrace a shaded picture of a mesh (a headlight and a key light, white background) to a PNG.

    Args:
        mesh: trimesh.Trimesh [m]; need not be watertight.
        path: the PNG to write (parent directories are created).
        T_world_camera: camera-to-world, OpenCV axes; None looks at the mesh's centre from
            azimuth 35 deg, elevation 30 deg (world z up), far enough to frame it.
        width, height: image size [pixels]. fov_deg: horizontal field of view [deg].
        rgb: surface albedo, 8-bit.

    Returns:
        path.
    """
    import open3d as o3d
    from PIL import Image

    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    f = 0.5 * width / np.tan(np.deg2rad(fov_deg) / 2)
    if T_world_camera is None:
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        centre, radius = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo)
        distance = radius / np.sin(np.deg2rad(min(fov_deg, fov_deg * height / width)) / 2) * 1.05
        az, el = np.deg2rad(35.0), np.deg2rad(30.0)
        eye = centre + distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        T_world_camera = look_at(eye, centre)
    T = np.asarray(T_world_camera, float)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32))
    )
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    rays_camera = np.stack([(u - width / 2) / f, (v - height / 2) / f, np.ones_like(u)], axis=-1)
    directions = rays_camera @ T[:3, :3].T
    rays = np.concatenate([np.broadcast_to(T[:3, 3], directions.shape), directions], axis=-1).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))
    valid = np.isfinite(hit["t_hit"].numpy())
    normals = hit["primitive_normals"].numpy().astype(np.float64)
    unit = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    head = np.abs(np.einsum("hwk,hwk->hw", normals, unit))
    key = T[:3, :3] @ np.array([-0.4, -0.6, -0.7])  # from the upper left, in camera terms
    key /= np.linalg.norm(key)
    facing = np.where((np.einsum("hwk,hwk->hw", normals, unit) > 0)[..., None], -normals, normals)
    light = 0.15 + 0.55 * head + 0.3 * np.clip(facing @ -key, 0, None)
    color = np.where(valid[..., None], np.array(rgb, float) * light[..., None], 255.0)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.clip(np.rint(color), 0, 255).astype(np.uint8)).save(path)
    return path
