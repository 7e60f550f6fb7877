"""Tests of benchmarks.reconstruct's pieces: truth meshes from CAD shells, Chamfer distance, summary, depth noise."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from benchmarks.reconstruct import (
    _chamfer,
    _hidden_space,
    _rest,
    _summarise,
    _watertight_from_mm,
)
from benchmarks.reconstruct_real import plane_depth_errors


def test_overlapping_open_shells_become_one_watertight_solid(tmp_path):
    """Two overlapping boxes in mm, one open where it enters the other, become one closed surface of their union [m]."""
    a = trimesh.creation.box((40.0, 20.0, 20.0))
    b = trimesh.creation.box((20.0, 20.0, 40.0))
    b.apply_translation((10.0, 0.0, 20.0))  # its bottom (z = 0) lies inside a
    b.update_faces(b.face_normals[:, 2] > -0.5)  # an open shell, as CAD exports leave them
    path = tmp_path / "part.ply"
    trimesh.util.concatenate([a, b]).export(path)
    mesh = _watertight_from_mm(path, cells=120)
    union_m3 = (40 * 20 * 20 + 20 * 20 * 30) * 1e-9
    assert mesh.is_watertight and mesh.volume == pytest.approx(union_m3, rel=0.04)
    np.testing.assert_allclose(mesh.extents, (0.04, 0.02, 0.05), atol=1e-3)
    assert len(mesh.split(only_watertight=False)) == 1


def test_chamfer_of_a_grown_sphere_is_the_growth():
    """The Chamfer distance between spheres of radius 20 and 20.5 mm is 0.5 mm, and 0 to itself."""
    a = trimesh.creation.icosphere(subdivisions=5, radius=0.02)
    b = trimesh.creation.icosphere(subdivisions=5, radius=0.0205)
    assert _chamfer(a, b, count=4000) == pytest.approx(0.0005, rel=0.05)
    assert _chamfer(a, a, count=4000) < 1e-5


def _camera_above(x: float, y: float, height: float):
    """A 640x480 view from `height` [m] over (x, y), looking straight down."""
    from types import SimpleNamespace

    from pipelines.rgbd import Intrinsics

    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # camera x along world x, z down
    T[:3, 3] = (x, y, height)
    return SimpleNamespace(T_world_camera=T, intrinsics=Intrinsics(600.0, 600.0, 320.0, 240.0, 640, 480))


def test_hidden_space_is_what_no_camera_sees():
    """Under a 40 mm slab on a 10 mm post, 10 mm up, no camera above sees anything: 15 cm^3, for 17 cm^3 of
    object. A camera low at the side sees all of it but the post's shadow; a plain box hides nothing."""
    import trimesh

    slab = trimesh.creation.box((0.04, 0.04, 0.01))
    slab.apply_translation((0.0, 0.0, 0.015))
    post = trimesh.creation.box((0.01, 0.01, 0.01))
    post.apply_translation((0.0, 0.0, 0.005))
    mushroom = trimesh.boolean.union([slab, post], engine="manifold")
    above = [_camera_above(0.0, 0.0, 0.4), _camera_above(0.05, 0.0, 0.4)]
    hidden = _hidden_space(mushroom, above, cells=80)
    assert hidden["hidden_pct"] == pytest.approx(100 * 15 / 17, abs=3.0)
    # filled, it makes a 40 x 40 x 20 mm box: the COM drops from (16 x 15 + 1 x 5) / 17 = 14.4 to 10 mm up
    assert hidden["hidden_com_shift_mm"] == pytest.approx((16 * 15 + 5) / 17 - 10.0, abs=0.1)

    side = _camera_above(0.0, 0.0, 0.4)  # then turned to look along +x from low at the side
    side.T_world_camera[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    side.T_world_camera[:3, 3] = (-0.3, 0.0, 0.005)
    # it sees all but the post's shadow, 15 x 10 x 10 mm behind it
    assert _hidden_space(mushroom, above + [side], cells=80)["hidden_pct"] == pytest.approx(100 * 1.5 / 17, abs=1.5)

    box = trimesh.creation.box((0.04, 0.04, 0.02))
    box.apply_translation((0.0, 0.0, 0.01))
    assert _hidden_space(box, above, cells=80) == pytest.approx({"hidden_pct": 0.0, "hidden_com_shift_mm": 0.0}, abs=0.05)


def test_rest_puts_a_box_flat_on_the_table():
    """A box standing on its small face is laid on a large one, on z = 0."""
    box = trimesh.creation.box((0.02, 0.04, 0.1))
    placed = _rest(box)
    assert placed.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
    assert placed.extents[2] == pytest.approx(0.02, abs=1e-6)


def test_summary_splits_by_size_and_counts_targets():
    """Objects under 5 cm are summarised apart; the worst object and the count within target are given."""
    rows = [
        {"object": "a", "family": "primitive", "size_m": 0.10, "noise": "low", "volume_error_pct": 1.0, "chamfer_mm": 0.2, "com_shift_mm": 0.1,
         "tsdf_ms_per_frame": 20.0, "decompose_s": 5.0},
        {"object": "b", "family": "workshop-tools", "size_m": 0.30, "noise": "low", "volume_error_pct": -5.0, "chamfer_mm": 0.5, "com_shift_mm": 2.0,
         "tsdf_ms_per_frame": 30.0, "hidden_pct": 4.0, "hidden_com_shift_mm": 1.0},
        {"object": "c", "size_m": 0.03, "noise": "low", "volume_error_pct": 9.0, "chamfer_mm": 0.1, "com_shift_mm": 0.1,
         "tsdf_ms_per_frame": 25.0},
    ]
    summary = _summarise(rows)
    large = summary["size >= 5 cm, low noise"]
    assert large["objects"] == 2 and large["volume_error_pct"]["worst"] == "b"
    assert large["volume_error_pct"]["within_target"] == 1 and large["com_shift_mm"]["max"] == 2.0
    assert summary["size < 5 cm, low noise"]["volume_error_pct"]["max"] == 9.0
    assert summary["tsdf_ms_per_frame"]["max"] == 30.0 and summary["decompose_s"]["median"] == 5.0
    assert summary["size >= 5 cm, workshop tools, low noise"]["objects"] == 1
    assert summary["size >= 5 cm, primitives and MIT push shapes, low noise"]["volume_error_pct"]["max"] == 1.0
    assert summary["hidden_over_target"] == {"b": {"volume_pct": 4.0, "com_shift_mm": 1.0}}


def test_unknown_object_name_is_refused_with_the_choices(tmp_path):
    """--names with a name not in the run fails before any work, naming it and the objects to choose from."""
    from benchmarks.reconstruct import bench_reconstruct

    with pytest.raises(ValueError, match=r"no object named 'Allen Kez'.*'cube 30 cm'"):
        bench_reconstruct(out_dir=tmp_path, data_root=tmp_path, sessions_only=True, names=("Allen Kez",))


def test_plane_depth_errors_recover_pixel_noise_and_waviness():
    """A table 0.7 m away, tilted 30 deg, with 2 mm white depth noise, a slow 3 mm waviness and a box on it:
    the pixel scatter is the white noise alone, the total about the plane holds the waviness too, and the
    box's pixels stay out."""
    K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
    v, u = np.mgrid[0:480, 0:640].astype(float)
    rays = np.stack([(u - 320) / 600, (v - 240) / 600, np.ones_like(u)], -1)
    normal = np.array([0.0, -np.sin(np.radians(30)), -np.cos(np.radians(30))])
    depth = 0.7 / -(rays @ normal)  # the plane n.x + 0.7 = 0 met along each ray
    points = rays * depth[..., None]
    wave = 0.003 * np.sin(2 * np.pi * points[..., 0] / 0.2)
    rng = np.random.default_rng(0)
    noisy = depth + wave + rng.normal(0, 0.002, depth.shape)
    noisy[200:280, 280:360] -= 0.05  # a box 5 cm proud of the table
    z, pixel, total = plane_depth_errors(noisy, K)
    sigma = lambda e: 1.4826 * np.median(np.abs(e - np.median(e)))  # noqa: E731
    assert sigma(pixel) == pytest.approx(0.002, rel=0.1)
    assert sigma(total) == pytest.approx(np.sqrt(0.002**2 + 0.003**2 / 2), rel=0.15)
    assert len(z) <= 480 * 640 - 80 * 80
