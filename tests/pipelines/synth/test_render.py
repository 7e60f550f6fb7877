"""Tests of pipelines.synth.render: the written scan reads back and agrees with the geometry."""

from __future__ import annotations

import json

import numpy as np
import trimesh
from PIL import Image

from pipelines.scan import read_scan
from pipelines.synth.render import RenderConfig, look_at, render_mesh_image, render_scan

SMALL = RenderConfig(width=160, height=120, fx=150.0, fy=150.0, view_count=4, elevations_deg=(40.0, 60.0))


def _cube():
    mesh = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    mesh.apply_translation((0.2, 0.1, 0.02))
    return mesh


def test_writes_the_nerfstudio_layout(tmp_path):
    """Images, 16-bit depth, 8-bit masks, transforms.json and object.json are written and read back."""
    root = render_scan(_cube(), tmp_path / "scan", SMALL, np.random.default_rng(0), "cube", "pla")
    meta = json.loads((root / "transforms.json").read_text())
    assert len(meta["frames"]) == 4 and meta["depth_unit_scale_factor"] == 0.001
    depth = Image.open(root / meta["frames"][0]["depth_file_path"])
    assert depth.mode == "I;16" and depth.size == (160, 120)
    assert Image.open(root / meta["frames"][0]["mask_path"]).mode == "L"
    scan = read_scan(root)
    assert scan.name == "cube" and scan.material_hint == "pla"
    assert all(f.mask is not None and f.mask.any() for f in scan.frames)


def test_depth_and_masks_agree_with_the_mesh(tmp_path):
    """Masked depth back-projects onto the cube's surface, to within the sensor noise."""
    cube = _cube()
    scan = read_scan(render_scan(cube, tmp_path / "scan", SMALL, np.random.default_rng(1), "cube"))
    for frame in scan.frames:
        intr, T = frame.intrinsics, frame.T_world_camera
        v, u = np.nonzero(frame.mask & (frame.depth_m > 0))
        z = frame.depth_m[v, u].astype(float)
        p = np.stack([(u + 0.5 - intr.cx) / intr.fx * z, (v + 0.5 - intr.cy) / intr.fy * z, z], axis=1)
        world = p @ T[:3, :3].T + T[:3, 3]
        distance = np.abs(cube.nearest.signed_distance(world))
        assert np.median(distance) < 1e-3 and np.percentile(distance, 95) < 3e-3


def test_same_seed_gives_identical_files(tmp_path):
    """Rendering twice with the same seed writes byte-identical depth images."""
    a = render_scan(_cube(), tmp_path / "a", SMALL, np.random.default_rng(3))
    b = render_scan(_cube(), tmp_path / "b", SMALL, np.random.default_rng(3))
    for name in ("depth/frame_00000.png", "depth/frame_00003.png", "transforms.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes()


def test_mesh_picture_frames_the_mesh(tmp_path):
    """render_mesh_image writes a PNG of the asked size: shaded object in the middle, white around it."""
    path = render_mesh_image(_cube(), tmp_path / "pics" / "cube.png", width=120, height=90)
    image = np.asarray(Image.open(path).convert("RGB"))
    assert image.shape == (90, 120, 3)
    assert (image[0, 0] == 255).all() and (image[-1, -1] == 255).all()
    assert (image[45, 60] < 250).all()
    camera = look_at((0.2, -0.3, 0.3), (0.2, 0.1, 0.02))
    np.testing.assert_allclose(camera[:3, :3].T @ camera[:3, :3], np.eye(3), atol=1e-12)
    assert render_mesh_image(_cube(), tmp_path / "other.png", camera, width=40, height=30).is_file()


def test_smooth_depth_noise_keeps_its_sigma_and_moves_in_patches():
    """With depth_noise_smoothing_px the noise keeps sigma(z) but neighbouring pixels move together: on a flat
    wall 0.7 m away, pixels 1 apart differ by far less than white noise's sqrt(2) sigma, pixels 64 apart by it."""
    from pipelines.synth.render import _sensor_depth

    z = np.full((480, 640), 0.7)
    ones = np.ones_like(z, bool)
    for smoothing, lag1 in ((0.0, np.sqrt(2)), (8.0, 0.1)):
        config = RenderConfig(depth_noise_base_m=2e-3, depth_noise_quadratic_per_m=0.0, depth_unit_m=2e-5,
                              dropout_random=0.0, dropout_grazing_cos=0.0, dropout_edge=0.0,
                              depth_noise_smoothing_px=smoothing)
        noise = _sensor_depth(z, ones, ones.astype(float), config, np.random.default_rng(0)) * 2e-5 - 0.7
        np.testing.assert_allclose(noise.std(), 2e-3, rtol=0.05)
        near = np.std(noise[:, 1:] - noise[:, :-1]) / 2e-3
        far = np.std(noise[:, 64:] - noise[:, :-64]) / 2e-3
        np.testing.assert_allclose(near, lag1, rtol=0.3)
        np.testing.assert_allclose(far, np.sqrt(2), rtol=0.1)
