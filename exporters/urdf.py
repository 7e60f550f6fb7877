"""URDF writer: the asset as one link in `NAME.urdf`.

The link frame is the object frame. A lone floating link has no joint to
carry `asset.placement`, so the link sits at the origin and the placement is
recorded in a comment (and in asset.json). Numbers are written with `repr`
(shortest exact round trip).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path, PurePosixPath

import numpy as np

from assets import Asset

from .preconditions import exportable_inertial

__all__ = ["export_urdf"]



def _num(values) -> str:
    """Space-separated shortest round-trip decimals."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _mesh_element(parent: ET.Element, tag: str, name: str, filename: str) -> None:
    el = ET.SubElement(parent, tag, name=name)
    ET.SubElement(el, "origin", xyz="0 0 0", rpy="0 0 0")
    geometry = ET.SubElement(el, "geometry")
    ET.SubElement(geometry, "mesh", filename=filename)


def export_urdf(asset: Asset, out_dir: Path) -> Path:
    """Write `out_dir/NAME.urdf` for a free (or sliding) rigid object.

    One link NAME: `<inertial>` with the COM [m] as origin (rpy 0), mass [kg]
    and the full tensor about the COM [kg m^2], object-frame axes; the visual
    mesh; one `<collision>` per convex part. Surface friction (unitless) has
    no standard tag and goes to both PyBullet's `<contact><lateral_friction>`
    and Gazebo's `<gazebo><mu1/><mu2/>`. Mesh paths are relative to the
    URDF file (MuJoCo cannot open `package://`).

    Raises:
        ValueError: for kinds other than "free"/"sliding", an unphysical inertia
            tensor or no collision parts.
    """
    out_dir = Path(out_dir)
    path = out_dir / f"{asset.name}.urdf"

    inertial = exportable_inertial(asset, path, "export_urdf")
    I = inertial.inertia_matrix()
    mu = repr(float(asset.theta.friction.value))
    p, q = asset.placement.position, asset.placement.quaternion_xyzw

    robot = ET.Element("robot", name=asset.name)
    robot.append(
        ET.Comment(
            " A single floating link cannot carry a placement in URDF: the link frame is the object frame"
            f" at the origin. Scanned placement in world: position {_num(p)} m,"
            f" quaternion_xyzw {_num(q)} (also in asset.json). "
        )
    )
    link = ET.SubElement(robot, "link", name=asset.name)
    inertial_el = ET.SubElement(link, "inertial")
    ET.SubElement(inertial_el, "origin", xyz=_num(inertial.com), rpy="0 0 0")
    ET.SubElement(inertial_el, "mass", value=repr(inertial.mass))
    ET.SubElement(
        inertial_el, "inertia",
        ixx=_num(I[0, 0]), ixy=_num(I[0, 1]), ixz=_num(I[0, 2]),
        iyy=_num(I[1, 1]), iyz=_num(I[1, 2]), izz=_num(I[2, 2]),
    )  # fmt: skip
    visual = asset.geometry.visual
    _mesh_element(link, "visual", PurePosixPath(visual).stem, PurePosixPath(visual).as_posix())
    for rel in asset.geometry.collision:
        _mesh_element(link, "collision", PurePosixPath(rel).stem, PurePosixPath(rel).as_posix())
    contact = ET.SubElement(link, "contact")
    ET.SubElement(contact, "lateral_friction", value=mu)

    gazebo = ET.SubElement(robot, "gazebo", reference=asset.name)
    ET.SubElement(gazebo, "mu1").text = mu
    ET.SubElement(gazebo, "mu2").text = mu

    ET.indent(robot, space="  ")
    out_dir.mkdir(parents=True, exist_ok=True)
    path.write_text('<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n")
    return path
