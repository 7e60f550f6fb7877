"""MJCF writer: the asset as a MuJoCo model file `NAME.xml`.

NAME is `exporters.names.file_stem` of the asset's name; model, body and
joint names derive from `mjcf_name`, and a comment keeps the name as written.
The body frame is the object frame, placed at `asset.placement`: on a free
joint, or for drawers and doors inside a fixed base body on `asset.joint`
(q = 0 at the placement, passive damping, `frictionloss` for the joint's
Coulomb friction, `range` for its limits). Numbers are written with `repr` (shortest exact round trip) because
`MjSpec.to_xml` rounds to 6 significant digits.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path, PurePosixPath

import numpy as np

from assets import Asset

from .names import base_name, file_stem, joint_name, mjcf_name, xml_comment_text
from .preconditions import exportable_inertial

__all__ = ["export_mjcf"]

"""Kinds written as one body on a free joint (no support plane: DESIGN.md)."""

# MuJoCo's defaults for the torsional and rolling coefficients; only sliding
# friction is identified.
_TORSION_FRICTION = 0.005
_ROLL_FRICTION = 0.0001


def _num(values) -> str:
    """Space-separated shortest round-trip decimals."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _mesh_name(rel_path: str) -> str:
    return PurePosixPath(rel_path).stem


def export_mjcf(asset: Asset, out_dir: Path) -> Path:
    """Write `out_dir/NAME.xml` for a rigid object, free or on a joint.

    Inertial: mass [kg], COM [m] and the full tensor about the COM [kg m^2],
    object frame. Collision: one mesh geom per convex part with sliding
    friction `asset.theta.friction.value`. Visual: a massless, non-colliding
    mesh geom in group 2. Mesh paths in `asset.geometry` are relative to
    `out_dir`.

    Raises:
        ValueError: an unphysical inertia tensor, no collision parts, an empty joint
            range or clashing mesh file stems.
    """
    out_dir = Path(out_dir)
    path = out_dir / f"{file_stem(asset.name)}.xml"
    body_name = mjcf_name(asset.name)
    mesh_paths = [asset.geometry.visual, *asset.geometry.collision, *filter(None, [asset.geometry.base])]
    names = [_mesh_name(p) for p in mesh_paths]
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: mesh file stems must be unique, got {names}")
    # meshdir is the deepest folder holding every mesh, so file= stays short.
    meshdir = os.path.commonpath([str(PurePosixPath(p).parent) for p in mesh_paths]) or "."

    inertial = exportable_inertial(asset, path, "export_mjcf")
    I = inertial.inertia_matrix()
    # a jointed part's theta.friction is its joint's; its surfaces keep the material's
    mu = float(asset.theta.friction.value if asset.joint is None else asset.material.friction)
    x, y, z, w = asset.placement.quaternion_xyzw

    # Newton prefixes its labels with the model name ("model/worldbody/body"), so it is no free text either
    root = ET.Element("mujoco", model=body_name)
    root.append(ET.Comment(f" object name: {xml_comment_text(asset.name)} "))
    ET.SubElement(root, "compiler", angle="radian", meshdir=meshdir, autolimits="true")
    ET.SubElement(root, "option", gravity="0 0 -9.81")
    assets_el = ET.SubElement(root, "asset")
    for name, rel in zip(names, mesh_paths):
        ET.SubElement(assets_el, "mesh", name=name, file=os.path.relpath(rel, meshdir).replace(os.sep, "/"))

    world = ET.SubElement(root, "worldbody")
    if asset.joint is None:
        world.append(ET.Comment(" object frame at the scanned placement; no support plane for free objects "))
        parent = world
    else:
        world.append(ET.Comment(" fixed base in world; the part at its scanned placement (q = 0) on its joint "))
        parent = ET.SubElement(world, "body", name=base_name(body_name))
        if asset.geometry.base:
            ET.SubElement(parent, "geom", name=names[-1], type="mesh", mesh=names[-1],
                          friction=_num((mu, _TORSION_FRICTION, _ROLL_FRICTION)))
    body = ET.SubElement(parent, "body", name=body_name, pos=_num(asset.placement.position), quat=_num((w, x, y, z)))
    if asset.joint is None:
        ET.SubElement(body, "freejoint", name=f"{body_name}_free")
    else:
        j = asset.joint
        R = asset.placement.rotation_matrix()
        ET.SubElement(
            body, "joint", name=joint_name(body_name), type="slide" if j.type == "prismatic" else "hinge",
            pos=_num(R.T @ (np.asarray(j.origin) - asset.placement.position)), axis=_num(R.T @ np.asarray(j.axis)),
            range=_num((j.lower, j.upper)), damping=repr(float(j.damping)),
            frictionloss=repr(float(asset.theta.friction.value)), stiffness=repr(float(j.stiffness)),
            springref=repr(float(j.spring_ref)),
        )
    ET.SubElement(
        body,
        "inertial",
        pos=_num(inertial.com),
        mass=repr(inertial.mass),
        # MuJoCo's order: Ixx Iyy Izz Ixy Ixz Iyz.
        fullinertia=_num((I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])),
    )
    # density=0 keeps the visual mesh from adding mass if inertiafromgeom is ever forced on.
    ET.SubElement(
        body, "geom", name=names[0], type="mesh", mesh=names[0],
        contype="0", conaffinity="0", density="0", group="2",
    )
    for name in names[1:1 + len(asset.geometry.collision)]:
        ET.SubElement(
            body, "geom", name=name, type="mesh", mesh=name, group="3",
            friction=_num((mu, _TORSION_FRICTION, _ROLL_FRICTION)),
        )

    if asset.joint is not None and asset.geometry.base:
        # the joint guides the part through the base (a carcass around a drawer): they must not collide
        ET.SubElement(ET.SubElement(root, "contact"), "exclude", body1=base_name(body_name), body2=body_name)
    ET.indent(root, space="  ")
    out_dir.mkdir(parents=True, exist_ok=True)
    path.write_text(ET.tostring(root, encoding="unicode") + "\n")
    return path
