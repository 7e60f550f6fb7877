"""URDF writer: the asset as one link in `NAME.urdf` (or a base link and the part on its joint).

NAME is `exporters.names.file_stem` of the asset's name; robot, link and joint
names derive from `urdf_name`, and a comment keeps the name as written. The
link frame is the object frame. A lone floating link has no joint to
carry `asset.placement`, so the link sits at the origin and the placement is
recorded in a comment (and in asset.json). A drawer or door is a fixed base
link in world and the part on a prismatic or revolute joint placed at the
scan (q = 0); URDF turns a revolute child about its own frame's origin, so
there the part's link frame is the object frame moved onto the axis (the
point nearest the placement) and the part's inertial and meshes carry the
offset. Numbers are written with `repr`
(shortest exact round trip).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path, PurePosixPath

import numpy as np

from assets import Asset

from .names import base_name, file_stem, joint_name, urdf_name, xml_comment_text
from .preconditions import exportable_inertial

__all__ = ["export_urdf"]



def _num(values) -> str:
    """Space-separated shortest round-trip decimals."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _mesh_element(parent: ET.Element, tag: str, name: str, filename: str, offset=(0.0, 0.0, 0.0)) -> None:
    el = ET.SubElement(parent, tag, name=name)
    ET.SubElement(el, "origin", xyz=_num(offset), rpy="0 0 0")
    geometry = ET.SubElement(el, "geometry")
    ET.SubElement(geometry, "mesh", filename=filename)


def export_urdf(asset: Asset, out_dir: Path) -> Path:
    """Write `out_dir/NAME.urdf` for a rigid object, free or on a joint.

    One link, `urdf_name(asset.name)`: `<inertial>` with the COM [m] as origin (rpy 0), mass [kg]
    and the full tensor about the COM [kg m^2], object-frame axes; the visual
    mesh; one `<collision>` per convex part. Surface friction (unitless) has
    no standard tag and goes to both PyBullet's `<contact><lateral_friction>`
    and Gazebo's `<gazebo><mu1/><mu2/>`. A jointed part's joint gets `<dynamics
    damping friction>` and, with a spring, Gazebo's `springStiffness` and
    `springReference`. Mesh paths are relative to the URDF file (MuJoCo cannot
    open `package://`).

    Raises:
        ValueError: an unphysical inertia tensor, no collision parts or an empty joint range.
    """
    out_dir = Path(out_dir)
    path = out_dir / f"{file_stem(asset.name)}.urdf"
    name = urdf_name(asset.name)

    inertial = exportable_inertial(asset, path, "export_urdf")
    I = inertial.inertia_matrix()
    # a jointed part's theta.friction is its joint's; its surfaces keep the material's
    mu = repr(float(asset.theta.friction.value if asset.joint is None else asset.material.friction))
    p, q = asset.placement.position, asset.placement.quaternion_xyzw

    robot = ET.Element("robot", name=name)
    robot.append(ET.Comment(f" object name: {xml_comment_text(asset.name)} "))
    offset = np.zeros(3)
    if asset.joint is None:
        robot.append(
            ET.Comment(
                " A single floating link cannot carry a placement in URDF: the link frame is the object frame"
                f" at the origin. Scanned placement in world: position {_num(p)} m,"
                f" quaternion_xyzw {_num(q)} (also in asset.json). "
            )
        )
    else:
        offset = _write_base_and_joint(robot, asset, name)
    link = ET.SubElement(robot, "link", name=name)
    inertial_el = ET.SubElement(link, "inertial")
    ET.SubElement(inertial_el, "origin", xyz=_num(np.asarray(inertial.com) + offset), rpy="0 0 0")
    ET.SubElement(inertial_el, "mass", value=repr(inertial.mass))
    ET.SubElement(
        inertial_el, "inertia",
        ixx=_num(I[0, 0]), ixy=_num(I[0, 1]), ixz=_num(I[0, 2]),
        iyy=_num(I[1, 1]), iyz=_num(I[1, 2]), izz=_num(I[2, 2]),
    )  # fmt: skip
    visual = asset.geometry.visual
    _mesh_element(link, "visual", PurePosixPath(visual).stem, PurePosixPath(visual).as_posix(), offset)
    for rel in asset.geometry.collision:
        _mesh_element(link, "collision", PurePosixPath(rel).stem, PurePosixPath(rel).as_posix(), offset)
    contact = ET.SubElement(link, "contact")
    ET.SubElement(contact, "lateral_friction", value=mu)

    gazebo = ET.SubElement(robot, "gazebo", reference=name)
    ET.SubElement(gazebo, "mu1").text = mu
    ET.SubElement(gazebo, "mu2").text = mu

    ET.indent(robot, space="  ")
    out_dir.mkdir(parents=True, exist_ok=True)
    path.write_text('<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n")
    return path


def urdf_link_offset(asset: Asset) -> np.ndarray:
    """Object-frame origin in the part's URDF link frame [m]: zero unless revolute (see the module docstring)."""
    j = asset.joint
    if j is None or j.type != "revolute":
        return np.zeros(3)
    p = np.asarray(asset.placement.position)
    a, o = np.asarray(j.axis), np.asarray(j.origin)
    on_axis = o + a * (a @ (p - o))
    return asset.placement.rotation_matrix().T @ (p - on_axis)


def _write_base_and_joint(robot: ET.Element, asset: Asset, name: str) -> np.ndarray:
    """The fixed base link and the joint to the part (link `name`); returns the object-frame origin in the
    part's link frame."""
    from scipy.spatial.transform import Rotation

    j = asset.joint
    base = ET.SubElement(robot, "link", name=base_name(name))
    if asset.geometry.base:
        stem, rel = PurePosixPath(asset.geometry.base).stem, PurePosixPath(asset.geometry.base).as_posix()
        _mesh_element(base, "visual", stem, rel)
        _mesh_element(base, "collision", stem, rel)
    R = asset.placement.rotation_matrix()
    offset = urdf_link_offset(asset)
    joint = ET.SubElement(robot, "joint", name=joint_name(name), type=j.type)
    ET.SubElement(joint, "parent", link=base_name(name))
    ET.SubElement(joint, "child", link=name)
    ET.SubElement(joint, "origin", xyz=_num(np.asarray(asset.placement.position) - R @ offset),
                  rpy=_num(Rotation.from_matrix(R).as_euler("xyz")))
    ET.SubElement(joint, "axis", xyz=_num(R.T @ np.asarray(j.axis)))
    # effort and velocity bounds are the robot's business, not the part's: generous values
    ET.SubElement(joint, "limit", lower=repr(float(j.lower)), upper=repr(float(j.upper)), effort="1000.0",
                  velocity="100.0")
    ET.SubElement(joint, "dynamics", damping=repr(float(j.damping)), friction=repr(float(asset.theta.friction.value)))
    if j.stiffness:
        # a joint spring has no URDF tag; Gazebo's URDF reader takes it from the joint's <gazebo> extension
        gazebo = ET.SubElement(robot, "gazebo", reference=joint_name(name))
        ET.SubElement(gazebo, "springStiffness").text = repr(float(j.stiffness))
        ET.SubElement(gazebo, "springReference").text = repr(float(j.spring_ref))
    return offset
