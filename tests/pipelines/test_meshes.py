"""Tests of pipelines.meshes: reading a mesh SOURCE, and refusing what cannot be an object's volume."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

from pipelines.meshes import MESH_SUFFIXES, MeshError, read_mesh

EXTENTS = (0.12, 0.08, 0.1)


def _box(path: Path, scale: float = 1.0, **kwargs) -> Path:
    box = trimesh.creation.box(EXTENTS)
    box.apply_scale(scale)
    box.export(path, **kwargs)
    return path


@pytest.mark.parametrize("suffix", MESH_SUFFIXES)
def test_reads_a_watertight_box_in_every_format(tmp_path, suffix):
    """A 12 x 8 x 10 cm box reads as a volume of 0.96 L in metres from each format."""
    mesh = read_mesh(_box(tmp_path / f"box{suffix}"))
    assert mesh.is_volume
    np.testing.assert_allclose(mesh.extents, EXTENTS, rtol=1e-6)
    assert mesh.volume == pytest.approx(0.12 * 0.08 * 0.1, rel=1e-5)


@pytest.mark.parametrize("units,scale", [("mm", 1000.0), ("cm", 100.0), ("in", 1 / 0.0254), ("m", 1.0)])
def test_units_scale_to_metres(tmp_path, units, scale):
    mesh = read_mesh(_box(tmp_path / "box.stl", scale), units=units)
    np.testing.assert_allclose(mesh.extents, EXTENTS, rtol=1e-5)


def test_inside_out_box_is_turned_right_way_out(tmp_path):
    box = trimesh.creation.box(EXTENTS)
    box.invert()
    box.export(tmp_path / "inverted.obj")
    mesh = read_mesh(tmp_path / "inverted.obj")
    assert mesh.volume == pytest.approx(0.12 * 0.08 * 0.1, rel=1e-6)


@pytest.mark.parametrize("scale,units,words", [
    (1000.0, "m", "120 m across (no hand-held or furniture object is over 3 m); if the file is in millimetres, "
                  "pass --mesh-units mm"),
    (1.0, "mm", "0.12 mm across (no hand-held or furniture object is under 3 mm); if the file is in metres, "
                "pass --mesh-units m"),
    (1e5, "m", "12000 m across (no hand-held or furniture object is over 3 m); check the file's unit"),
    (1e-4, "m", "0.012 mm across (no hand-held or furniture object is under 3 mm); check the file's unit"),
], ids=["millimetres read as metres", "metres read as millimetres", "12 km", "12 microns"])
def test_implausible_sizes_raise_with_a_unit_hint(tmp_path, scale, units, words):
    path = _box(tmp_path / "part.stl", scale)
    with pytest.raises(MeshError) as info:
        read_mesh(path, units=units)
    assert str(info.value) == f"{path}: {words}"


def _open_box(path):
    box = trimesh.creation.box(EXTENTS)
    trimesh.Trimesh(box.vertices, box.faces[:-1]).export(path)
    return "not watertight"


def _flipped_face(path):
    box = trimesh.creation.box(EXTENTS)
    faces = box.faces.copy()
    faces[0] = faces[0][::-1]
    trimesh.Trimesh(box.vertices, faces, process=False).export(path)
    return "not consistently wound"


def _empty(path):
    path.write_bytes(b"")
    return "no triangles"


def _points_only(path):
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    return "no triangles"


def _text(path):
    path.write_text("hello\n")
    return "no triangles"


_DEFECTS = [("box.obj", _open_box), ("box.obj", _flipped_face), ("box.obj", _empty), ("box.obj", _points_only),
            ("box.obj", _text)]


@pytest.mark.parametrize("name,defect", _DEFECTS, ids=[d.__name__.strip("_") for _, d in _DEFECTS])
def test_meshes_without_a_volume_raise(tmp_path, name, defect):
    """Open, inconsistently wound or empty meshes raise MeshError naming the file and the defect."""
    path = tmp_path / name
    words = defect(path)
    with pytest.raises(MeshError) as info:
        read_mesh(path)
    assert str(info.value).startswith(f"{path}: ") and words in str(info.value), str(info.value)


def _stl_claiming_huge_count(path):
    """A binary STL whose header claims 2^32 - 1 triangles over 12 real ones."""
    data = bytearray(_box(path).read_bytes())
    data[80:84] = struct.pack("<I", 2**32 - 1)
    path.write_bytes(bytes(data))


def _ply_claiming_huge_count(path):
    data = _box(path).read_bytes()
    path.write_bytes(data.replace(b"element vertex 8", b"element vertex 4000000000", 1))


def _ply_element_without_properties(path):
    """trimesh's binary PLY reader fails with UnboundLocalError on an element that has no properties."""
    data = _box(path).read_bytes()
    path.write_bytes(data.replace(b"\nelement vertex", b"\nelement junk 0\nelement vertex", 1))


def _glb_damaged_json(path):
    data = bytearray(_box(path).read_bytes())
    data[30:40] = b"\xff" * 10
    path.write_bytes(bytes(data))


def _nan_vertex(path):
    box = trimesh.creation.box(EXTENTS)
    text = box.export(file_type="obj")
    path.write_text(text.replace("v 0.06", "v nan", 1))


_HOSTILE = [("box.stl", _stl_claiming_huge_count), ("box.ply", _ply_claiming_huge_count),
            ("box.ply", _ply_element_without_properties), ("box.glb", _glb_damaged_json), ("box.obj", _nan_vertex)]


@pytest.mark.parametrize("name,damage", _HOSTILE, ids=[d.__name__.strip("_") for _, d in _HOSTILE])
def test_hostile_files_raise_mesh_error_on_one_line(tmp_path, name, damage):
    """Headers claiming billions of elements, trimesh's own crashes, non-finite vertices: one-line MeshError."""
    path = tmp_path / name
    damage(path)
    with pytest.raises(MeshError) as info:
        read_mesh(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "\n" not in message and len(message) < 400, message


@pytest.mark.parametrize("name,units,words", [
    ("missing.obj", "m", "mesh file not found"),
    ("box.step", "m", "not a mesh file"),
    ("box.obj", "furlong", "unknown mesh units"),
])
def test_wrong_paths_and_units_raise(tmp_path, name, units, words):
    path = tmp_path / name
    if name == "box.obj":
        _box(path)
    with pytest.raises(MeshError, match=words) as info:
        read_mesh(path, units=units)
    assert str(info.value).startswith(f"{path}: ")
