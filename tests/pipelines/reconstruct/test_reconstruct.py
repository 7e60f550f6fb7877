"""Tests of pipelines.reconstruct on rendered scans with known truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from pipelines.reconstruct import ReconstructConfig, ReconstructError, SceneConfig, reconstruct, reconstruct_scene
from pipelines.scan import read_scan
from pipelines.synth.render import RenderConfig, render_scan


# small and few images keep the tests fast; accuracy at full size is better (see the module docstring)
FAST = RenderConfig(width=320, height=240, fx=300.0, fy=300.0, view_count=12)


def _cube():
    mesh = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    mesh.apply_translation((0.45, -0.1, 0.02))  # resting on z = 0, away from the origin
    return mesh


def _sphere():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    mesh.apply_translation((-0.2, 0.3, 0.75 + 0.03))  # a 6 cm ball on a table top at z = 0.75
    return mesh


@pytest.fixture(scope="module", params=["cube", "sphere"])
def rendered(request, tmp_path_factory):
    truth = {"cube": _cube, "sphere": _sphere}[request.param]()
    root = render_scan(truth, tmp_path_factory.mktemp(request.param), FAST, np.random.default_rng(7), request.param)
    return truth, read_scan(root)


@pytest.mark.parametrize("use_masks", [True, False], ids=["masks", "no-masks"])
def test_volume_and_com_match_truth(rendered, use_masks):
    """The mesh is watertight, its volume within 5 % and its centre of mass within 2 mm of the truth."""
    truth, scan = rendered
    result = reconstruct(scan, ReconstructConfig(use_masks=use_masks))
    mesh = result.mesh
    assert mesh.is_watertight and mesh.is_volume and mesh.volume > 0
    assert result.stats["segmentation"] == ("masks" if use_masks else "plane+dbscan")
    assert abs(mesh.volume / truth.volume - 1) < 0.05
    assert np.linalg.norm(mesh.center_mass - truth.center_mass) < 0.002
    assert len(mesh.faces) <= ReconstructConfig().target_faces


@pytest.fixture(scope="module")
def reconstructed(rendered):
    return reconstruct(rendered[1])


def test_support_plane_is_the_table_top(rendered, reconstructed):
    """The support plane has an upward normal and passes through the object's lowest point."""
    truth, _ = rendered
    result = reconstructed
    normal, offset = result.support_plane
    assert normal[2] > 0.9999
    table_z = truth.bounds[0, 2]
    assert abs(-offset / normal[2] - table_z) < 5e-4
    assert abs(result.mesh.bounds[0, 2] - table_z) < 5e-4  # the underside was closed on the plane
    assert 0.0005 <= result.voxel_size_m <= 0.005


def test_reruns_are_identical(rendered, reconstructed):
    """Two runs on the same scan give the same mesh (seeded RANSAC)."""
    a, b = reconstructed, reconstruct(rendered[1])
    np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
    np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)


def test_empty_masks_raise(rendered):
    """Masks that mark nothing raise ReconstructError instead of returning a mesh of the table."""
    _, scan = rendered
    frames = tuple(dataclasses.replace(f, mask=np.zeros_like(f.mask)) for f in scan.frames)
    with pytest.raises(ReconstructError, match="masks"):
        reconstruct(dataclasses.replace(scan, frames=frames))


def test_depth_noise_is_measured_on_the_support_plane(reconstructed):
    """The depth noise estimated from the table (0.8 mm rendered, with 1 mm quantisation) sets a wide enough band."""
    stats = reconstructed.stats
    assert 0.5e-3 < stats["depth_noise_m"] < 1.2e-3
    assert stats["sdf_trunc_m"] >= ReconstructConfig().noise_trunc_sigmas * stats["depth_noise_m"] - 1e-12


def test_scene_fusion_keeps_table_and_object(rendered):
    """reconstruct_scene fuses everything (table and object) into an open mesh lying on the true surfaces."""
    truth, scan = rendered
    scene = reconstruct_scene(scan, SceneConfig(voxel_size_m=0.004, depth_trunc_m=1.0))
    vertices = np.asarray(scene.mesh.vertices)
    table_z = truth.bounds[0, 2]
    on_table = np.abs(vertices[:, 2] - table_z) < 0.002
    distance = np.abs(trimesh.proximity.signed_distance(truth, vertices[~on_table][::20]))
    assert on_table.mean() > 0.3 and np.median(distance) < 0.002
    assert scene.stats["frame_count"] == len(scan.frames) and scene.stats["tsdf_s_per_frame"] > 0


def test_real_kinect_frames_fuse_into_a_room(kinect_frames):
    """Five real 7-Scenes frames fused at 4 cm give one room-sized surface, metres across."""
    scene = reconstruct_scene(read_scan(kinect_frames(range(0, 50, 10))), SceneConfig(voxel_size_m=0.04))
    assert 1.5 < max(scene.mesh.extents) < 8.0 and len(scene.mesh.faces) > 2000
    assert scene.stats["pieces_kept"] <= 5  # one coherent surface, a few large pieces at most


def test_silhouette_pixels_are_left_out_of_the_fusion_on_both_sides_only():
    """A 5 mm step (an object's edge on the table) loses the pixel columns on both sides of it; a noisy flat
    surface (0.5 mm noise, a 3 mm limit: twice a 3-sigma truncation) keeps nearly all, and pixels beside a
    dropout keep theirs."""
    from pipelines.reconstruct.fusion import silhouettes_dropped

    rng = np.random.default_rng(0)
    depth = (0.4 + rng.normal(0.0, 0.5e-3, (60, 80))).astype(np.float32)
    depth[:, 40:] += 0.005
    depth[10, 10] = 0.0  # a dropout
    out = silhouettes_dropped(depth, 0.003)
    dropped = out == 0
    assert dropped[:, 39:41].all()
    assert dropped[9:12, 9:12].sum() == 1
    assert dropped.sum() - (2 * 60 + 1) < 0.005 * depth.size
    np.testing.assert_array_equal(out[~dropped], depth[~dropped])
    np.testing.assert_array_equal(silhouettes_dropped(depth, 0.0), depth)


def test_a_band_under_two_noise_sigmas_wide_leaves_the_wedges_under_a_hex_bar_open(tmp_path):
    """A hex bar lying on a face (6.9 mm across flats, 12 cm long) has a wedge 2 mm deep between the table and
    each lower face. At the real sensors' noise (smooth, 2 mm at 0.4 m) a truncation band three sigmas wide
    averages the wedges away (+11 % volume); the default 1.75 leaves them within 2 % (-0.2 %; two sigmas
    +2.8 %)."""
    bar = trimesh.creation.cylinder(radius=0.004, height=0.12, sections=6)
    bar.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (0, 1, 0)))  # its axis along x
    down = bar.face_normals[np.argmin(bar.face_normals[:, 2])]
    bar.apply_transform(trimesh.transformations.rotation_matrix(np.arctan2(down[1], -down[2]), (1, 0, 0)))
    bar.apply_translation((0.3 - bar.centroid[0], -0.1 - bar.centroid[1], -bar.bounds[0, 2]))
    sensor = RenderConfig(depth_noise_base_m=1.26e-3, depth_noise_quadratic_per_m=2.93e-3, depth_noise_smoothing_px=8.0)
    scan = read_scan(render_scan(bar, tmp_path, sensor, np.random.default_rng(3), "hex bar"))
    default = reconstruct(scan).mesh.volume / bar.volume - 1
    wide = reconstruct(scan, ReconstructConfig(noise_trunc_sigmas=3.0)).mesh.volume / bar.volume - 1
    assert abs(default) < 0.02 and wide > 0.08
