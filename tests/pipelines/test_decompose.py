"""Tests of pipelines.decompose: real CoACD runs on small meshes, bounds on parts, the cache."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pipelines.decompose import ConvexParts, DecomposeConfig, DecomposeError, decompose


def _l_shape():
    """An L of two 2 cm-thick bars (6 cm long and 6 cm tall) unioned into one watertight solid."""
    foot = trimesh.creation.box(extents=(0.06, 0.02, 0.02))
    foot.apply_translation((0.03, 0.01, 0.01))
    post = trimesh.creation.box(extents=(0.02, 0.02, 0.06))
    post.apply_translation((0.01, 0.01, 0.03))
    mesh = trimesh.boolean.union([foot, post], engine="manifold")
    assert mesh.is_watertight
    return mesh


def _check_parts(result: ConvexParts, config: DecomposeConfig) -> None:
    assert 2 <= len(result.parts) <= config.max_convex_hull
    for part in result.parts:
        assert part.is_watertight and part.volume > 0
        assert len(part.vertices) <= config.max_ch_vertex
        assert part.convex_hull.volume == pytest.approx(part.volume, rel=1e-6)  # convex


def test_l_shape_splits_into_bounded_convex_parts(tmp_path):
    """An L becomes a few convex parts whose union has the L's volume."""
    mesh, config = _l_shape(), DecomposeConfig()
    result = decompose(mesh, config, tmp_path)
    _check_parts(result, config)
    assert result.volume_mesh_m3 == pytest.approx(mesh.volume)
    assert result.volume_union_m3 == pytest.approx(mesh.volume, rel=0.02)
    assert result.stats["surface_deviation_mean_m"] < 2e-4 and result.stats["surface_deviation_max_m"] < 2e-3
    assert result.stats["cache"] == "miss"


def test_second_call_hits_the_cache_with_identical_parts(tmp_path):
    """A second call with the same mesh and config loads the .npz and returns the same parts."""
    mesh, config = _l_shape(), DecomposeConfig()
    first = decompose(mesh, config, tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1
    np.load(files[0], allow_pickle=False)  # stored without pickle
    second = decompose(mesh, config, tmp_path)
    assert second.stats["cache"] == "hit"
    assert len(second.parts) == len(first.parts)
    for a, b in zip(first.parts, second.parts):
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
    assert second.volume_union_m3 == first.volume_union_m3
    other = decompose(mesh, DecomposeConfig(threshold=0.1), tmp_path)  # another config: another entry
    assert other.stats["cache"] == "miss" and len(list(tmp_path.glob("*.npz"))) == 2


def test_seeded_runs_are_identical_without_cache():
    """Two uncached runs with the same seed give identical parts."""
    mesh = _l_shape()
    a, b = decompose(mesh, DecomposeConfig(), None), decompose(mesh, DecomposeConfig(), None)
    assert a.stats["cache"] == "off"
    assert [p.vertices.tolist() for p in a.parts] == [p.vertices.tolist() for p in b.parts]


def test_hull_vertex_limit_is_enforced():
    """Hulls are cut down to max_ch_vertex vertices even when CoACD's own limit is off."""
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.02)
    config = DecomposeConfig(max_ch_vertex=20, decimate=False)
    result = decompose(sphere, config, None)
    assert all(len(p.vertices) <= 20 for p in result.parts)
    assert result.stats["reduced_hulls"] >= 1
    assert 0.5 < result.volume_union_m3 / result.volume_mesh_m3 <= 1.0 + 1e-9  # inside the sphere
    assert 0 < result.stats["surface_deviation_mean_m"] < result.stats["surface_deviation_max_m"] < 0.005


def test_open_mesh_is_rejected():
    """A mesh with a hole raises DecomposeError."""
    box = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    box.update_faces(np.arange(len(box.faces)) > 0)
    with pytest.raises(DecomposeError, match="watertight"):
        decompose(box, DecomposeConfig(), None)


def test_dense_mesh_is_simplified_before_coacd():
    """A 5120-face ball goes to CoACD as at most max_input_faces faces; volumes refer to the mesh as given."""
    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.02)
    result = decompose(ball, DecomposeConfig(max_input_faces=500), None)
    assert result.stats["input_faces"] <= 500
    assert result.volume_mesh_m3 == pytest.approx(ball.volume)
    assert 0.8 < result.volume_union_m3 / result.volume_mesh_m3 <= 1.0 + 1e-9  # one hull of <= 60 vertices
    assert result.stats["surface_deviation_mean_m"] < 1e-3
    untouched = decompose(ball, DecomposeConfig(max_input_faces=0, max_convex_hull=1), None)
    assert untouched.stats["input_faces"] == len(ball.faces)
