"""`twin bench reconstruct`, real part: the Kinect frames of `rgbd/7scenes_tsdf_demo_subset` fused with their
given poses into a scene mesh and pictured, then posed without them (`pipelines.posing`), compared with the
given ones and fused again; and the real frames' depth noise about their dominant plane, by depth, beside the
synthetic levels (`benchmarks.reconstruct.NOISE_LEVELS`) it should stand for.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from benchmarks.reconstruct import NOISE_LEVELS


def run_kinect(data_root: Path, out_dir: Path, quick: bool) -> dict:
    from pipelines.posing import pose_errors
    from pipelines.reconstruct import SceneConfig, reconstruct_scene
    from pipelines.scan import read_scan

    root = data_root / "rgbd" / "7scenes_tsdf_demo_subset"
    if not root.is_dir():
        print(f"kinect: {root} not found; skipped")
        return {}
    out: dict = {}
    scan = read_scan(root)
    config = SceneConfig(voxel_size_m=0.01)
    scene = reconstruct_scene(scan, config)
    picture = _picture(scene.mesh, scan, out_dir / "kinect_given_poses.png")
    out["given_poses"] = {"frames": len(scan.frames), **scene.stats, "picture": str(picture)}
    print(f"\nkinect, given poses: {len(scan.frames)} frames fused at {config.voxel_size_m * 1000:g} mm, "
          f"{scene.stats['tsdf_s_per_frame'] * 1000:.1f} ms per 640x480 frame, {scene.stats['faces']} faces, "
          f"extent {scene.stats['extent_m']} m; picture: {picture}")

    if quick:  # the first 30 frames
        scan = read_scan(_subset(root, out_dir / "kinect_subset", 30))
    t0 = time.perf_counter()
    posed = read_scan(scan.root, poses="estimate")
    posing_s = time.perf_counter() - t0
    estimated = np.array([f.T_world_camera for f in posed.frames])
    errors = pose_errors(estimated, posed.given_T_world_camera)
    summary = errors.summary()
    # the given world, for the picture: the estimated poses moved by the aligning transform
    align = posed.given_T_world_camera[0] @ np.linalg.inv(estimated[0])
    scene_free = reconstruct_scene(posed, config)
    picture_free = _picture(scene_free.mesh, scan, out_dir / "kinect_estimated_poses.png", align)
    path_m = float(np.linalg.norm(np.diff(posed.given_T_world_camera[:, :3, 3], axis=0), axis=1).sum())
    out["estimated_poses"] = {"frames": len(posed.frames), "posing_s": posing_s, "path_length_m": path_m,
                              "errors": summary, "stats": posed.pose_stats, "picture": str(picture_free)}
    r, t = summary["relative_rotation_deg"], summary["relative_translation_m"]
    ar, at = summary["absolute_rotation_deg"], summary["absolute_translation_m"]
    print(f"kinect, pose-free: {len(posed.frames)} frames posed in {posing_s:.1f} s (camera path {path_m:.2f} m)")
    print(f"  frame-to-frame error: rotation median {r['median']:.2f} max {r['max']:.2f} deg, "
          f"translation median {1000 * t['median']:.1f} max {1000 * t['max']:.1f} mm")
    print(f"  absolute error after rigid alignment: rotation median {ar['median']:.2f} max {ar['max']:.2f} deg, "
          f"translation median {1000 * at['median']:.1f} max {1000 * at['max']:.1f} mm, rms {1000 * at['rms']:.1f} mm")
    print(f"  picture (fused with the estimated poses): {picture_free}")
    return out


def real_depth_noise(data_root: Path, bin_m: float = 0.2, max_depth_m: float = 1.6) -> list[dict]:
    """Depth noise of the real frames by depth (`plane_depth_errors`), beside the synthetic levels it should
    stand for: the robust sigma (1.4826 MAD) per depth bin over all frames of a set, up to `max_depth_m` (a
    scan's range, where the 3 cm band kept about the plane spans over 3 sigmas)."""
    import imageio.v3 as iio
    import yaml

    sets = []
    ycb = data_root / "rgbd" / "posecnn_ycb_demo"
    if (ycb / "meta.yml").is_file():
        K = np.array(yaml.safe_load((ycb / "meta.yml").read_text())["INTRINSICS"], float).reshape(3, 3)
        sets.append(("posecnn_ycb_demo", K, sorted(ycb.glob("*-depth.png"))))
    kinect = data_root / "rgbd" / "7scenes_tsdf_demo_subset"
    if (kinect / "camera-intrinsics.txt").is_file():
        K = np.loadtxt(kinect / "camera-intrinsics.txt")
        sets.append(("7scenes_tsdf_demo_subset", K, sorted(kinect.glob("frame-*.depth.png"))[::10]))
    rows = []
    print("\nreal depth noise about each frame's dominant plane (robust sigma per depth bin; pixel: each "
          "16x16-pixel tile's median removed first)")
    print(f"{'frames':<30} {'depth m':>7} {'pixel mm':>9} {'total mm':>9} {'synthetic low / high / sensor mm':>33}")
    for name, K, paths in sets:
        # uint16 millimetres in both sets
        parts = [plane_depth_errors(iio.imread(path).astype(float) / 1000.0, K) for path in paths]
        depth_m, pixel, total = (np.concatenate(x) for x in zip(*parts))
        for lo in np.arange(0.4, max_depth_m - 1e-9, bin_m):
            m = (depth_m >= lo) & (depth_m < lo + bin_m)
            if m.sum() < 5000:
                continue
            z = lo + bin_m / 2
            row = {"frames": name, "count": len(paths), "depth_m": z,
                   "pixel_sigma_m": 1.4826 * float(np.median(np.abs(pixel[m]))),
                   "total_sigma_m": 1.4826 * float(np.median(np.abs(total[m] - np.median(total[m])))),
                   **{f"synthetic_{level}_sigma_m": a + c * z * z for level, (a, c, _) in NOISE_LEVELS.items()}}
            rows.append(row)
            print(f"{name + f' ({len(paths)})':<30} {z:>7.1f} {1000 * row['pixel_sigma_m']:>9.2f} "
                  f"{1000 * row['total_sigma_m']:>9.2f} {1000 * row['synthetic_low_sigma_m']:>15.2f} / "
                  f"{1000 * row['synthetic_high_sigma_m']:5.2f} / {1000 * row['synthetic_sensor_sigma_m']:5.2f}")
    return rows


def plane_depth_errors(depth_m: np.ndarray, K: np.ndarray, tile_px: int = 16):
    """(depth [m], pixel error [m], total error [m]) of the pixels on one depth image's dominant plane.

    The plane (a table, a floor, a wall) is found as the reconstruction finds its support plane (`fit_plane`:
    RANSAC within 1 cm, refined by least squares, so reruns agree), and each pixel within 3 cm of it is
    compared with the depth at which its ray meets it. "total": that depth error, with the sensor's slow
    waviness and the surface's own flatness in it; "pixel": the same less its tile_px x tile_px tile's median,
    the scatter from pixel to pixel that fusion averages.
    """
    from scipy import ndimage

    from pipelines.reconstruct import ReconstructConfig, fit_plane

    v, u = np.nonzero((depth_m > 0) & (depth_m < 3.0))
    z = depth_m[v, u]
    points = np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z], 1)
    normal, offset, _ = fit_plane(points, 0.01, 0.005, np.zeros((1, 3)), ReconstructConfig())
    # the 1 cm band would clip the far bins' scatter; 3 cm keeps it, the MAD ignores the rest
    inliers = np.abs(points @ normal + offset) < 0.03
    q = points[inliers]
    slope = np.abs(q @ normal) / q[:, 2]  # d(distance to the plane) / d(depth) along each ray
    error = (q @ normal + offset) / np.maximum(slope, 0.2)
    _, tile = np.unique((u[inliers] // tile_px) * 10_000 + v[inliers] // tile_px, return_inverse=True)
    medians = np.asarray(ndimage.median(error, labels=tile, index=np.arange(tile.max() + 1)))
    return q[:, 2], error - medians[tile], error


def _subset(root: Path, dest: Path, count: int) -> Path:
    """A folder of symbolic links to the first `count` frames."""
    dest.mkdir(parents=True, exist_ok=True)
    names = ["camera-intrinsics.txt"] + [
        f"{p.name[: -len('.depth.png')]}.{s}" for p in sorted(root.glob("frame-*.depth.png"))[:count]
        for s in ("color.jpg", "depth.png", "pose.txt")
    ]
    for name in names:
        link = dest / name
        if not link.exists():
            link.symlink_to(root / name)
    return dest


def _picture(mesh, scan, path: Path, align: np.ndarray | None = None) -> Path:
    """The scene seen from behind the middle frame's camera (1 m back), in the given poses' world."""
    from pipelines.synth.render import render_mesh_image

    mesh = mesh.copy()
    if align is not None:
        mesh.apply_transform(align)
    T = np.array(scan.frames[len(scan.frames) // 2].T_world_camera, float)
    T[:3, 3] -= 1.0 * T[:3, 2]
    return render_mesh_image(mesh, path, T, fov_deg=70.0)
