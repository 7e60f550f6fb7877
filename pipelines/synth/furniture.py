"""Render a jointed part as it is scanned in practice: at q = 0 in its furniture, seen from the front.

Each of RigPI's parts (`jointed_paper_objects`) gets a carcass around it, standing on a floor (z = 0):

- drawer: a chest whose front is flush with the drawer's front; the drawer runs in a slot as deep as
  itself plus a clearance and a back panel (`DRAWER_BACK_M`);
- cabinet door: a base cabinet with a face frame; the door (partial overlay) lies against the frame,
  covering its opening by `DOOR_OVERLAP_M` and leaving `FRAME_REVEAL_M` of it in view around the door;
- oven door: an oven body whose front panel shows around the door and above it (the controls).

The cameras sit in a cone in front of the furniture (the part's outward face normal): azimuth within
+-`half_azimuth_deg`, elevation in `elevation_range_deg`, distance in `distance_range_m`, looking at the
part's centre. Depth covers the whole scene; masks mark the part only. The scan is written by
`render.render_views` in the same layout as `render_scan`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .render import RenderConfig, look_at, render_views

if TYPE_CHECKING:
    import trimesh

    from .jointed import JointedObject

__all__ = ["FurnitureConfig", "furniture_carcass", "front_normal", "render_furniture_scan"]

DRAWER_BACK_M = 0.020
"""Chest depth behind the drawer: 8 mm clearance and a 12 mm back panel [m]."""
FRAME_REVEAL_M = 0.028
"""Face frame (or oven front panel) left in view beside the door [m]."""
DOOR_OVERLAP_M = 0.012
"""How far the door covers the frame round its opening [m]."""
CARCASS_DEPTH_M = 0.35
"""Depth of the cabinet and oven bodies behind the door [m]."""
WALL_M = 0.018
"""Board thickness of carcass walls [m]."""
OVEN_PANEL_M = 0.08
"""Control panel above the oven door [m]."""
FLOOR_M = 3.0
"""Floor edge [m]: wide enough to be the dominant plane of every view."""


@dataclass(frozen=True)
class FurnitureConfig:
    """Cameras of a furniture scan; the image, noise and shading come from `render` (its ring,
    distance and azimuth fields are not used)."""

    render: RenderConfig = field(default_factory=lambda: RenderConfig(width=320, height=240, fx=300.0, fy=300.0,
                                                                      view_count=16))
    half_azimuth_deg: float = 60.0
    """Views within this angle either side of the part's outward normal, about world z [deg]."""
    elevation_range_deg: tuple[float, float] = (0.0, 40.0)
    """Camera elevation above the horizontal through the part's centre [deg], drawn uniformly per view."""
    distance_range_m: tuple[float, float] = (0.6, 1.5)
    """Camera distance from the part's centre [m], drawn uniformly per view."""
    look_at_jitter_m: float = 0.02
    """Standard deviation of the look-at point around the part's centre [m]."""


def front_normal(obj: "JointedObject") -> np.ndarray:
    """The part's outward face normal at q = 0 (world, unit, horizontal): the side the handle is on."""
    handle = np.asarray(obj.handle_m, float)
    half = 0.5 * np.asarray(obj.size_m, float)
    axis = int(np.argmax(np.abs(handle) / half))  # the face the handle sits on
    n = np.zeros(3)
    n[axis] = np.sign(handle[axis])
    return n


def furniture_carcass(obj: "JointedObject") -> "trimesh.Trimesh":
    """The furniture around the part at q = 0, world [m], standing on z = 0, watertight.

    Built from boxes in the frame (along the front, up, inwards) and differenced with manifold3d.
    """
    import trimesh

    n = front_normal(obj)
    up = np.array([0.0, 0.0, 1.0])
    side = np.cross(up, n)  # horizontal, along the front
    size = np.asarray(obj.size_m, float)
    centre = np.asarray(obj.position_m, float)
    width, height, thickness = abs(side @ size), size[2], abs(n @ size)
    front = centre @ n + 0.5 * thickness  # the part's front face, along n
    bottom, top = centre[2] - 0.5 * height, centre[2] + 0.5 * height

    def box(half_width: float, z0: float, z1: float, d_front: float, d_back: float):
        """A box across [-half_width, half_width] about the part's centre along the front, z0..z1 up,
        from d_front to d_back behind the part's front face."""
        mesh = trimesh.creation.box((2 * half_width, z1 - z0, d_back - d_front))
        T = np.eye(4)
        T[:3, 0], T[:3, 1], T[:3, 2] = side, up, n  # right-handed: side x up = n
        T[:3, 3] = centre - (centre @ n) * n + (front - 0.5 * (d_front + d_back)) * n
        T[2, 3] = 0.5 * (z0 + z1)
        mesh.apply_transform(T)
        return mesh

    if obj.joint_type == "prismatic":  # the chest: front flush with the drawer's
        outer = box(0.5 * width + 0.12, 0.0, top + 0.08, 0.0, thickness + DRAWER_BACK_M)
        slot = box(0.5 * width, bottom, top, -0.01, thickness + DRAWER_BACK_M - 0.012)
        return trimesh.boolean.difference([outer, slot], engine="manifold")
    # cabinet and oven: the door's back lies against the carcass front
    # a door on a horizontal hinge drops down: an oven's, with its control panel above
    extra_top = FRAME_REVEAL_M if abs(obj.axis[2]) > 0.5 else OVEN_PANEL_M
    outer = box(0.5 * width + FRAME_REVEAL_M, 0.0, top + extra_top, thickness, thickness + CARCASS_DEPTH_M)
    opening = box(0.5 * width - DOOR_OVERLAP_M, bottom + DOOR_OVERLAP_M, top - DOOR_OVERLAP_M,
                  thickness - 0.01, thickness + CARCASS_DEPTH_M - WALL_M)
    return trimesh.boolean.difference([outer, opening], engine="manifold")


def render_furniture_scan(
    obj: "JointedObject",
    out_dir: Path,
    config: FurnitureConfig = FurnitureConfig(),
    rng: np.random.Generator | None = None,
) -> Path:
    """Raytrace an RGB-D scan of `obj` at q = 0 in its furniture on a floor, masks on the part only.

    Args:
        obj: the part; its box (`obj.mesh()`) at `obj.position_m`, world [m], z up.
        out_dir: the scan directory to write (nerfstudio layout, as `render_scan`).
        config: the camera cone and the sensor.
        rng: all randomness (views, noise, dropout); default seed 0.

    Returns:
        out_dir.
    """
    import trimesh

    rng = np.random.default_rng(0) if rng is None else rng
    part = obj.mesh()
    part.apply_translation(obj.position_m)
    floor = trimesh.creation.box((FLOOR_M, FLOOR_M, 0.05))
    centre = np.asarray(obj.position_m, float)
    floor.apply_translation((centre[0], centre[1], -0.025))
    poses = _cone_poses(config, centre, front_normal(obj), rng)
    return render_views(part, [furniture_carcass(obj), floor], poses, out_dir, config.render, rng,
                        name=obj.name.replace("_", " "))


def _cone_poses(config: FurnitureConfig, centre: np.ndarray, normal: np.ndarray,
                rng: np.random.Generator) -> list[np.ndarray]:
    """Cameras spread evenly over the azimuth span (jittered by a tenth of their spacing), elevation and
    distance drawn per view, looking at the part's centre."""
    count = config.render.view_count
    base = np.arctan2(normal[1], normal[0])
    spacing = 2 * np.deg2rad(config.half_azimuth_deg) / count
    poses = []
    for k in range(count):
        azimuth = base - np.deg2rad(config.half_azimuth_deg) + spacing * (k + 0.5 + rng.uniform(-0.1, 0.1))
        elevation = np.deg2rad(rng.uniform(*config.elevation_range_deg))
        distance = rng.uniform(*config.distance_range_m)
        direction = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                              np.sin(elevation)])
        target = centre + rng.normal(0.0, config.look_at_jitter_m, 3)
        poses.append(look_at(centre + distance * direction, target))
    return poses
