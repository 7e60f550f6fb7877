"""Read an object mesh given as SOURCE instead of a scan (DESIGN.md, "Object source").

The build needs a volume (mass, inertia, a convex decomposition), so a mesh is
accepted only when it is non-empty, finite, watertight and consistently wound;
a consistently wound mesh that is inside out (negative volume) is turned the
right way out. Sizes are checked after scaling to metres: no hand-held or
furniture object is over 3 m or under 3 mm across, and a mesh outside that
range was almost always written in another unit, which the error suggests.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh

__all__ = ["MESH_SUFFIXES", "MESH_UNITS", "MeshError", "read_mesh"]

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb")

MESH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
"""Metres per unit of each unit a mesh file may be written in."""

_UNIT_NAMES = {"m": "metres", "cm": "centimetres", "mm": "millimetres", "in": "inches"}
_SIZE_RANGE_M = (0.003, 3.0)  # largest bounding-box extent of a hand-held or furniture object
_MAX_FILE_BYTES = 1 << 30  # a mesh of tens of millions of triangles; bounds what loading allocates

# What trimesh's loaders raise for a damaged file, as found by `twin bench fuzz` (target "mesh"):
# ValueError from their parsing (UnicodeDecodeError and JSONDecodeError among them), IndexError and
# KeyError from indices and names a damaged file gets wrong, TypeError from dtypes it garbles,
# OverflowError from huge counts, NotImplementedError from unknown PLY encodings and
# UnboundLocalError from the binary PLY reader on an element without properties; OSError for
# files that cannot be read at all.
_LOADER_ERRORS = (ValueError, IndexError, KeyError, TypeError, OverflowError, NotImplementedError, UnboundLocalError,
                  OSError)


class MeshError(ValueError):
    """A mesh file cannot be used; the message starts with the file's path."""


def read_mesh(path: str | Path, units: str = "m", solid: bool = True) -> trimesh.Trimesh:
    """Load a mesh file and check that it encloses a plausible object's volume.

    Args:
        path: an .obj, .stl, .ply or .glb file (a .glb's meshes are merged into one).
        units: the unit the file is written in: "m", "cm", "mm" or "in".
        solid: the mesh must enclose a plausible object's volume (SOURCE); False for a surface that is
            only shown and collided with (a drawer's or door's fixed base), which may be open.

    Returns:
        The mesh in metres, outward-facing, watertight.

    Raises:
        MeshError: naming the file when it is missing, not one of MESH_SUFFIXES, over 1 GiB,
            unreadable, empty, has non-finite vertices, is not watertight or not consistently wound, or its
            largest bounding-box extent in metres is over 3 m or under 3 mm (with a hint at the
            unit that would fit).
    """
    import trimesh

    path = Path(path)
    if units not in MESH_UNITS:
        raise MeshError(f"{path}: unknown mesh units {units!r}; choose from {', '.join(MESH_UNITS)}")
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(f"{path}: not a mesh file (expected {', '.join(MESH_SUFFIXES)})")
    if not path.is_file():
        raise MeshError(f"{path}: mesh file not found")
    size = path.stat().st_size
    if size > _MAX_FILE_BYTES:
        raise MeshError(f"{path}: {size / 2**30:.1f} GiB is over the {_MAX_FILE_BYTES >> 30} GiB a mesh file may have")
    try:
        # non-finite vertices are refused below; numpy's warnings about them while loading say nothing more
        with _quiet(logging.getLogger("trimesh")), np.errstate(all="ignore"):
            mesh = trimesh.load(path, file_type=suffix[1:], force="mesh")
    except _LOADER_ERRORS as e:
        raise MeshError(f"{path}: cannot read mesh ({type(e).__name__}: {_one_line(e)})") from e
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path}: no triangles")
    if not np.all(np.isfinite(mesh.vertices)):
        raise MeshError(f"{path}: vertices with non-finite coordinates")
    if not solid:
        mesh.apply_scale(MESH_UNITS[units])
        return mesh
    if not mesh.is_watertight:
        raise MeshError(
            f"{path}: not watertight ({_open_edge_count(mesh)} edges border a hole or a non-manifold fan); "
            "the build needs a closed surface"
        )
    if not mesh.is_winding_consistent:
        raise MeshError(f"{path}: its triangles are not consistently wound (normals flip between neighbours)")
    mesh.apply_scale(MESH_UNITS[units])
    _check_size(path, mesh, units)
    if mesh.volume < 0:
        mesh.invert()
    if not mesh.volume > 0:
        raise MeshError(f"{path}: encloses no volume")
    return mesh


def _check_size(path: Path, mesh, units: str) -> None:
    across = float(mesh.extents.max())
    lo, hi = _SIZE_RANGE_M
    if lo <= across <= hi:
        return
    raw = across / MESH_UNITS[units]
    fits = [u for u in ("mm", "cm", "m", "in") if u != units and lo <= raw * MESH_UNITS[u] <= hi]
    if fits:
        hint = f"if the file is in {_UNIT_NAMES[fits[0]]}, pass --mesh-units {fits[0]}"
    else:
        hint = "check the file's unit"
    bound = f"over {hi:g} m" if across > hi else f"under {lo * 1000:g} mm"
    raise MeshError(f"{path}: {_length(across)} across (no hand-held or furniture object is {bound}); {hint}")


def _length(metres: float) -> str:
    if metres >= 1000.0:
        return f"{metres:.0f} m"
    if metres >= 1.0:
        return f"{metres:.3g} m"
    return f"{metres * 1000:.3g} mm"


def _open_edge_count(mesh) -> int:
    """Edges not shared by exactly two triangles."""
    counts = np.bincount(mesh.edges_unique_inverse, minlength=len(mesh.edges_unique))
    return int(np.count_nonzero(counts != 2))


@contextmanager
def _quiet(logger: logging.Logger):
    """trimesh logs the traceback of each format it tries and fails on; the MeshError says it once."""
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split()) or "no detail"
    return text if len(text) <= 200 else f"{text[:197]}..."
