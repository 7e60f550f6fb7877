"""Convex decomposition of a watertight mesh with CoACD, for collision geometry.

Each part is a convex hull with at most `max_ch_vertex` vertices (PhysX GPU wants
< 64 hulls of < 60 vertices). Results are cached as .npz (no pickle), keyed by
the sha256 of the mesh's vertex and face bytes, the config and CoACD's version,
so a rerun on the same mesh is free and identical. CoACD is seeded, so a fresh
run on the same input gives the same parts too.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

if TYPE_CHECKING:
    import trimesh

__all__ = ["ConvexParts", "DecomposeConfig", "DecomposeError", "decompose"]

_CACHE_FORMAT = 2


class DecomposeError(RuntimeError):
    """The mesh could not be decomposed into convex parts."""


@dataclass(frozen=True)
class DecomposeConfig:
    """CoACD settings (CoACD's own names and defaults unless noted) and the hull limits."""

    threshold: float = 0.05
    """Concavity threshold, 0.01-1 (CoACD's range): lower gives more, finer parts."""
    max_convex_hull: int = 64
    """Maximum number of parts, -1 for no limit (CoACD's default is -1; PhysX GPU wants < 64)."""
    max_ch_vertex: int = 60
    """Maximum vertices per part, >= 4 (CoACD's default is 256; PhysX wants < 64). Enforced after
    CoACD too, by keeping a farthest-point subset of the hull's vertices."""
    preprocess_mode: Literal["auto", "on", "off"] = "auto"
    """Manifold preprocessing: "auto" runs it only on non-manifold input."""
    preprocess_resolution: int = 50
    """Preprocessing voxel resolution, 20-100."""
    resolution: int = 2000
    """Sampling resolution of the Hausdorff concavity metric, 1000-10000."""
    mcts_nodes: int = 20
    """Monte-Carlo tree search child nodes, 10-40."""
    mcts_iterations: int = 150
    """Monte-Carlo tree search iterations, 60-2000."""
    mcts_max_depth: int = 3
    """Monte-Carlo tree search depth, 2-7."""
    pca: bool = False
    """Align cutting planes with the parts' principal axes first."""
    merge: bool = True
    """Merge parts afterwards where the result stays under the threshold (needed for max_convex_hull)."""
    decimate: bool = False
    """Let CoACD itself limit each hull to max_ch_vertex vertices. Off by default: the farthest-point
    reduction applied afterwards keeps more volume (a reconstructed 6 cm ball: union/mesh 0.99
    against 0.88 with CoACD's decimation)."""
    extrude: bool = False
    """Extrude neighbouring hulls along their overlap face (CoACD's option)."""
    extrude_margin: float = 0.01
    """Extrusion margin when `extrude` is on (CoACD's units, relative)."""
    apx_mode: Literal["ch", "box"] = "ch"
    """Part approximation: convex hulls ("ch") or boxes ("box")."""
    seed: int = 0
    """Random seed of CoACD's search: reruns give identical parts."""
    max_input_faces: int = 3000
    """Meshes with more faces are first simplified to this many (quadric decimation, kept only if
    still watertight); 0 passes the mesh as it is. CoACD's time grows with the face count (a
    scanned 3 cm cube: 14 s at 20 000 faces, 3.3 s at 2 000, union volume 1.025 and 1.018 of
    the mesh); collision parts do not need the visual mesh's detail. Volumes and surface
    deviation are measured against the mesh as given."""


@dataclass(frozen=True, eq=False)
class ConvexParts:
    """Convex collision parts of a mesh, in the mesh's frame [m].

    parts: convex hulls (trimesh.Trimesh), each watertight with <= max_ch_vertex vertices.
    volume_union_m3: volume of the union of the parts [m^3] (overlaps counted once).
    volume_mesh_m3: volume of the input mesh [m^3].
    stats: part count, hull vertex counts, timings [s], cache use, and the surface deviation of
      the union from the mesh: `surface_deviation_mean_m` / `_max_m`, the distance from points
      spread over the mesh's surface to the union's surface [m]; JSON-serialisable.
    """

    parts: tuple["trimesh.Trimesh", ...]
    volume_union_m3: float
    volume_mesh_m3: float
    stats: dict = field(default_factory=dict)


def decompose(
    mesh: "trimesh.Trimesh", config: DecomposeConfig = DecomposeConfig(), cache_dir: Path | None = None
) -> ConvexParts:
    """Split a watertight mesh into convex parts with CoACD, using the cache when it holds the answer.

    Args:
        mesh: trimesh.Trimesh [m], watertight.
        config: CoACD settings and hull limits.
        cache_dir: where results are stored as .npz; None disables caching.

    Returns:
        The convex parts.

    Raises:
        DecomposeError: if the mesh is empty, the config out of range, or CoACD returns nothing usable.
    """
    _check(mesh, config)
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    key = _cache_key(vertices, faces, config)
    path = None if cache_dir is None else Path(cache_dir) / f"coacd-{key}.npz"
    if path is not None and path.is_file():
        try:
            parts, volume_union, volume_mesh, stats = _load(path)
            return ConvexParts(parts, volume_union, volume_mesh, {**stats, "cache": "hit"})
        except (OSError, ValueError, KeyError):
            pass  # a damaged cache entry is recomputed and rewritten

    t0 = time.perf_counter()
    v_in, f_in = _simplified(vertices, faces, config.max_input_faces)
    simplify_s = time.perf_counter() - t0
    parts, stats = _run_coacd(v_in, f_in, config)
    stats.update(input_faces=int(len(f_in)), simplify_s=simplify_s)
    volume_mesh = float(mesh.volume)
    volume_union, deviation = _union_volume_and_deviation(parts, vertices, faces)
    stats.update(deviation)
    stats.update(
        part_count=len(parts),
        hull_vertex_counts=[int(len(p.vertices)) for p in parts],
        volume_union_m3=volume_union,
        volume_mesh_m3=volume_mesh,
        mesh_sha256=key,
    )
    if path is not None:
        _save(path, parts, volume_union, volume_mesh, stats)
    return ConvexParts(tuple(parts), volume_union, volume_mesh, {**stats, "cache": "miss" if path else "off"})



def _check(mesh, config: DecomposeConfig) -> None:
    if mesh is None or len(getattr(mesh, "faces", ())) == 0:
        raise DecomposeError("decompose: the mesh has no faces")
    if not 0.01 <= config.threshold <= 1.0:
        raise DecomposeError(f"decompose: threshold {config.threshold} is outside CoACD's range [0.01, 1]")
    if config.max_ch_vertex < 4:
        raise DecomposeError(f"decompose: max_ch_vertex {config.max_ch_vertex} < 4 cannot bound a volume")
    if config.max_input_faces < 0:
        raise DecomposeError(f"decompose: max_input_faces must be >= 0, got {config.max_input_faces}")
    if config.max_convex_hull == 0 or config.max_convex_hull < -1:
        raise DecomposeError(f"decompose: max_convex_hull must be -1 or positive, got {config.max_convex_hull}")
    if not mesh.is_watertight:
        raise DecomposeError("decompose: the mesh is not watertight; reconstruct or repair it first")


def _cache_key(vertices: np.ndarray, faces: np.ndarray, config: DecomposeConfig) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        coacd_version = version("coacd")
    except PackageNotFoundError:
        coacd_version = "unknown"
    h = hashlib.sha256()
    h.update(vertices.tobytes())
    h.update(faces.tobytes())
    h.update(json.dumps(asdict(config), sort_keys=True).encode())
    h.update(f"coacd={coacd_version};format={_CACHE_FORMAT}".encode())
    return h.hexdigest()


def _simplified(vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """The mesh decimated to at most `max_faces` faces if that keeps it watertight, else as given."""
    if max_faces <= 0 or len(faces) <= max_faces:
        return vertices, faces
    import open3d as o3d
    import trimesh

    shuffled = faces[np.random.default_rng(0).permutation(len(faces))]  # Open3D is slow on sorted faces
    legacy = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(shuffled))
    simple = legacy.simplify_quadric_decimation(target_number_of_triangles=int(max_faces))
    out = trimesh.Trimesh(np.asarray(simple.vertices), np.asarray(simple.triangles), process=True)
    out.update_faces(out.nondegenerate_faces())
    out.remove_unreferenced_vertices()
    if not (out.is_watertight and out.is_winding_consistent and out.volume > 0):
        return vertices, faces
    return np.ascontiguousarray(out.vertices, dtype=np.float64), np.ascontiguousarray(out.faces, dtype=np.int64)


def _run_coacd(vertices: np.ndarray, faces: np.ndarray, config: DecomposeConfig) -> tuple[list, dict]:
    import coacd

    coacd.set_log_level("error")
    t0 = time.perf_counter()
    raw = coacd.run_coacd(
        coacd.Mesh(vertices, faces),
        threshold=config.threshold,
        max_convex_hull=config.max_convex_hull,
        preprocess_mode=config.preprocess_mode,
        preprocess_resolution=config.preprocess_resolution,
        resolution=config.resolution,
        mcts_nodes=config.mcts_nodes,
        mcts_iterations=config.mcts_iterations,
        mcts_max_depth=config.mcts_max_depth,
        pca=config.pca,
        merge=config.merge,
        decimate=config.decimate,
        max_ch_vertex=config.max_ch_vertex,
        extrude=config.extrude,
        extrude_margin=config.extrude_margin,
        apx_mode=config.apx_mode,
        seed=config.seed,
    )
    coacd_s = time.perf_counter() - t0
    parts, reduced, dropped = [], 0, 0
    for part_vertices, _ in raw:
        hull = _hull(np.asarray(part_vertices, dtype=np.float64))
        if hull is None:
            dropped += 1
            continue
        if len(hull.vertices) > config.max_ch_vertex:
            hull = _reduce_hull(hull, config.max_ch_vertex)
            reduced += 1
            if hull is None:
                dropped += 1
                continue
        parts.append(hull)
    if not parts:
        raise DecomposeError(f"decompose: CoACD returned no usable convex part ({len(raw)} raw parts)")
    stats = {"coacd_s": coacd_s, "raw_part_count": len(raw), "reduced_hulls": reduced, "dropped_parts": dropped}
    return parts, stats


def _hull(points: np.ndarray):
    """The convex hull as a watertight trimesh, or None when the points span no volume."""
    import trimesh
    from scipy.spatial import QhullError

    if len(points) < 4:
        return None
    try:
        hull = trimesh.convex.convex_hull(points)
    except (QhullError, ValueError):
        return None
    if not hull.is_watertight or hull.volume <= 0:
        return None
    return hull


def _reduce_hull(hull, max_vertices: int):
    """Hull of a farthest-point subset of the hull's vertices: inside the original, deterministic."""
    v = np.asarray(hull.vertices)
    chosen = [int(np.argmax(np.linalg.norm(v - v.mean(axis=0), axis=1)))]
    dist = np.linalg.norm(v - v[chosen[0]], axis=1)
    while len(chosen) < max_vertices:
        i = int(np.argmax(dist))
        chosen.append(i)
        dist = np.minimum(dist, np.linalg.norm(v - v[i], axis=1))
    return _hull(v[chosen])  # at most max_vertices points, so at most that many hull vertices


def _union_volume_and_deviation(parts: list, vertices: np.ndarray, faces: np.ndarray) -> tuple[float, dict]:
    """Volume of the parts' union [m^3], and how far the mesh's surface lies from the union's [m]."""
    import trimesh

    union = None
    try:
        union = parts[0] if len(parts) == 1 else trimesh.boolean.union(parts, engine="manifold")
        volume = float(union.volume)
    except Exception:  # noqa: BLE001 - the union is a statistic; fall back to the sum (an upper bound)
        volume = float(sum(p.volume for p in parts))
    deviation = {}
    if union is not None and len(union.faces):
        import open3d as o3d

        mesh = trimesh.Trimesh(vertices, faces, process=False)
        points, _ = trimesh.sample.sample_surface_even(mesh, 5000, seed=0)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor(np.asarray(union.vertices, np.float32)), o3d.core.Tensor(np.asarray(union.faces, np.uint32))
        )
        d = scene.compute_distance(o3d.core.Tensor(np.asarray(points, np.float32))).numpy()
        deviation = {"surface_deviation_mean_m": float(d.mean()), "surface_deviation_max_m": float(d.max())}
    return volume, deviation


def _save(path: Path, parts: list, volume_union: float, volume_mesh: float, stats: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {
        "vertices": np.concatenate([p.vertices for p in parts]).astype(np.float64),
        "faces": np.concatenate([p.faces for p in parts]).astype(np.int64),
        "vertex_counts": np.array([len(p.vertices) for p in parts], dtype=np.int64),
        "face_counts": np.array([len(p.faces) for p in parts], dtype=np.int64),
        "volumes_m3": np.array([volume_union, volume_mesh], dtype=np.float64),
        "stats_json": np.array(json.dumps(stats)),
    }
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, **arrays)
        os.replace(tmp, path)  # atomic: parallel runs never see half a file
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _load(path: Path) -> tuple[tuple, float, float, dict]:
    import trimesh

    with np.load(path, allow_pickle=False) as z:
        vertices, faces = z["vertices"], z["faces"]
        vertex_counts, face_counts = z["vertex_counts"], z["face_counts"]
        volume_union, volume_mesh = (float(x) for x in z["volumes_m3"])
        stats = json.loads(str(z["stats_json"]))
    parts = []
    v0 = f0 = 0
    for nv, nf in zip(vertex_counts, face_counts):
        parts.append(trimesh.Trimesh(vertices[v0 : v0 + nv], faces[f0 : f0 + nf], process=False))
        v0, f0 = v0 + nv, f0 + nf
    return tuple(parts), volume_union, volume_mesh, stats
