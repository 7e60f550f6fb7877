"""Fuzz targets of the object-source readers: scan directories (`read_scan`) and mesh files (`read_mesh`).

Each seed is small so that a mutation reads in milliseconds: a few 32x24 views of a box on a
table, rendered on the fly, in the nerfstudio layout (with and without poses) and the 7-Scenes
layout; and a watertight box in every mesh format. A mutation edits one file of the seed.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from pipelines.meshes import MeshError, read_mesh
from pipelines.posing import PosingConfig, PosingError
from pipelines.rgbd import ScanError
from pipelines.scan import read_scan
from benchmarks.fuzz import FuzzTarget, mutate_bytes, mutate_json

_SIZE = (32, 24)
_FOCAL_PX = 30.0
_VIEW_COUNT = 4

# one ICP level, no pose graph or model rounds: estimation then costs milliseconds, and the RGB-D
# odometry start still decodes every colour image
_CHEAP_POSING = PosingConfig(
    voxel_sizes_m=(0.01,), max_distance_voxels=(3.0,), initial_guesses=("identity", "rgbd_odometry"),
    neighbour_count=0, model_rounds=0, max_iterations=10, stride=1,
)


def _box_mesh():
    import trimesh

    return trimesh.creation.box((0.12, 0.08, 0.1))


def _render(root: Path, azimuth_span_deg: float) -> Path:
    from pipelines.synth.render import RenderConfig, render_scan

    config = RenderConfig(
        width=_SIZE[0], height=_SIZE[1], fx=_FOCAL_PX, fy=_FOCAL_PX, view_count=_VIEW_COUNT, elevations_deg=(35.0,),
        distance_range_m=(0.3, 0.32), azimuth_span_deg=azimuth_span_deg, color_format="png",
    )
    mesh = _box_mesh()
    mesh.apply_translation((0.0, 0.0, 0.05))
    render_scan(mesh, root, config, np.random.default_rng(0), "box", "oak")
    (root / "render.json").unlink()
    return root


def _nerfstudio_seed(folder: Path) -> Path:
    """Four posed views all around the box; the last frame's depth as a .npy array, the other form read."""
    root = _render(folder / "scan", 360.0)
    meta = json.loads((root / "transforms.json").read_text())
    last = meta["frames"][-1]
    png = root / last["depth_file_path"]
    from PIL import Image

    with Image.open(png) as im:
        np.save(png.with_suffix(".npy"), np.array(im).astype(np.uint16))
    png.unlink()
    last["depth_file_path"] = str(Path(last["depth_file_path"]).with_suffix(".npy"))
    (root / "transforms.json").write_text(json.dumps(meta, indent=1))
    return root


def _pose_free_seed(folder: Path) -> Path:
    """Four overlapping views of a 40 deg sweep, without poses."""
    root = _render(folder / "scan", 40.0)
    meta = json.loads((root / "transforms.json").read_text())
    for frame in meta["frames"]:
        del frame["transform_matrix"]
    (root / "transforms.json").write_text(json.dumps(meta, indent=1))
    return root


def _seven_scenes_seed(folder: Path) -> Path:
    """The nerfstudio seed's views rewritten as frame-XXXXXX.{color.png,depth.png,mask.png,pose.txt}."""
    rendered = _render(folder / "rendered", 360.0)
    meta = json.loads((rendered / "transforms.json").read_text())
    root = folder / "scan"
    root.mkdir()
    K = [[meta["fl_x"], 0.0, meta["cx"]], [0.0, meta["fl_y"], meta["cy"]], [0.0, 0.0, 1.0]]
    (root / "camera-intrinsics.txt").write_text("\n".join(" ".join(f"{x:g}" for x in row) for row in K) + "\n")
    opencv_from_opengl = np.diag([1.0, -1.0, -1.0, 1.0])
    for i, frame in enumerate(meta["frames"]):
        stem = root / f"frame-{i:06d}"
        (rendered / frame["file_path"]).rename(f"{stem}.color.png")
        (rendered / frame["depth_file_path"]).rename(f"{stem}.depth.png")
        (rendered / frame["mask_path"]).rename(f"{stem}.mask.png")
        T = np.array(frame["transform_matrix"]) @ opencv_from_opengl
        Path(f"{stem}.pose.txt").write_text("\n".join(" ".join(f"{x:.9e}" for x in row) for row in T) + "\n")
    (rendered / "object.json").rename(root / "object.json")
    return root


def _mutate_scan_file(root: Path, rng: np.random.Generator) -> None:
    """A structural or byte edit of one JSON file, or a byte edit of one other file of the scan."""
    listing = root / "transforms.json"
    if listing.exists() and rng.random() < 0.4:  # the listing decides what else is read: edit it most
        path = listing
    else:
        files = sorted(p for p in root.rglob("*") if p.is_file())
        path = files[int(rng.integers(0, len(files)))]
    (mutate_json if path.suffix == ".json" else mutate_bytes)(path, rng)


def _read_scan_quietly(root: Path, **kwargs) -> None:
    # a scan that reads with a coverage warning has read
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        read_scan(root, **kwargs)


_MESH_FORMATS = ("obj", "stl", "stl_ascii", "ply", "ply_ascii", "glb")


def _mesh_seed(folder: Path) -> Path:
    """The box in every format, one file each; a mutation keeps one of them."""
    box = _box_mesh()
    root = folder / "meshes"
    root.mkdir()
    for name in _MESH_FORMATS:
        kind, _, encoding = name.partition("_")
        kwargs = {"encoding": "ascii"} if encoding == "ascii" and kind == "ply" else {}
        data = box.export(file_type="stl_ascii" if name == "stl_ascii" else kind, **kwargs)
        (root / f"box_{name}.{kind}").write_bytes(data.encode() if isinstance(data, str) else data)
    return root


def _mutate_mesh(root: Path, rng: np.random.Generator) -> None:
    files = sorted(root.iterdir())
    keep = files[int(rng.integers(0, len(files)))]
    for p in files:
        if p != keep:
            p.unlink()
    mutate_bytes(keep, rng)


def _read_meshes(root: Path) -> None:
    for path in sorted(root.iterdir()):
        read_mesh(path)


SCAN_TARGETS = {
    "scan-nerfstudio": FuzzTarget(
        "scan-nerfstudio", _nerfstudio_seed, _mutate_scan_file, _read_scan_quietly, (ScanError,)
    ),
    "scan-pose-free": FuzzTarget(
        "scan-pose-free", _pose_free_seed, _mutate_scan_file,
        lambda root: _read_scan_quietly(root, posing=_CHEAP_POSING), (ScanError, PosingError),
    ),
    "scan-7scenes": FuzzTarget("scan-7scenes", _seven_scenes_seed, _mutate_scan_file, _read_scan_quietly, (ScanError,)),
    "mesh": FuzzTarget("mesh", _mesh_seed, _mutate_mesh, _read_meshes, (MeshError,)),
}
"""The readers of an object source, by name."""
