"""MJCF writer: the asset as a MuJoCo model file `NAME.xml`.

NAME is `exporters.names.file_stem` of the asset's name; model, body and
joint names derive from `mjcf_name`, and a comment keeps the name as written.
The body frame is the object frame, placed at `asset.placement`: on a free
joint, or for drawers and doors inside a fixed base body on `asset.joint`
(q = 0 at the placement, passive damping, `frictionloss` for the joint's
Coulomb friction, `range` for its limits). Numbers are written with `repr` (shortest exact round trip) because
`MjSpec.to_xml` rounds to 6 significant digits.

A pushed object (kind "sliding") also gets `scene.xml` beside it (`export_scene`):
the object file included, a support plane under it and the solver options a
push needs. The object's file never holds a plane (DESIGN.md), so it can be
dropped into any other scene.

Contact parameters, written explicitly on every colliding geom (and the plane),
chosen so that MuJoCo's soft contact behaves as Coulomb friction at the
identified mu:

- `friction="mu 0.005 0.0001"`: only the sliding coefficient is identified;
  torsional and rolling keep MuJoCo's defaults (inactive at condim 3).
- `condim="3"`: normal plus isotropic sliding friction. The moment that resists
  a pushed object's turning comes from sliding friction at its support contacts;
  condim 4's torsional friction would add to it, with a coefficient nobody measured.
- `solref="0.02 1"`, `solimp="0.9 0.95 0.001 0.5 2"`: MuJoCo's defaults, written
  so a reader sees them and another scene's `<default>` cannot change them
  silently. A time constant of 0.02 s is critically damped and needs a step of
  at most 0.01 s (MuJoCo: timeconst >= 2 timestep); Newton's importer maps it to
  its own default stiffness and damping (ke 2500, kd 100), so Newton is unchanged.
- scene.xml's `<option cone="elliptic" impratio="10">`: MuJoCo's default
  pyramidal cone with condim 3 bounds the friction force by a square's corners,
  so a push at 45 degrees to the contact frame's axes slides at 0.71 mu m g (and
  at 2 mu m g accelerates 30 % too fast); the elliptic cone is the exact circle.
  Soft friction constraints creep under any tangential load: at impratio 1 a
  block held at 0.9 mu m g creeps 0.3 mm in 0.5 s, at impratio 10 (MuJoCo's
  advice for elliptic cones) 0.04 mm, with sliding acceleration within 0.5 % of
  (F - mu m g) / m either way. These are scene options (MJCF has no per-body
  cone), so the object's own file keeps MuJoCo's defaults there.
- scene.xml's `<option timestep="0.001">`: half MuJoCo's default. A sliding
  block's path is steep in its contact's discretisation: the held-out pushes of
  `twin bench push` replayed at 2 ms differ from their replay at 0.5 ms by up to
  21 % of the error, at 1 ms by up to 8 % (docs/pushes.md).

Joint friction. MuJoCo's `frictionloss` is a soft constraint: within its bound
it drives the joint's acceleration towards -b q' (b = 2 / (dmax timeconst) from
`solreffriction`) and lets 1 - d of the load through (d from `solimpfriction`,
0.9 by default: a tenth). The identification measures how fast the friction
grips, `joint.friction_grip_s` (q'' = -q' / grip), and no leak, so the joint
gets `solreffriction="2 grip / 0.99 1"` and `solimpfriction="0.99 0.99 0.001
0.5 2"`. MuJoCo raises a time constant below two time steps to two
(a rigid grip at that step).

Support contacts. MuJoCo's mesh-plane (and box-plane) collision carries a flat
face at its corners, which resists turning about twice as much as an evenly
loaded face. The sliding identification chooses between the two from the pushes
(pipelines/identify/sliding/pushed.py `choose_support`, asset.json → provenance →
identify → support), and the export reproduces its choice (`support_points_m`):
"corners", the collision meshes alone; "uniform", 16 support points in NAME.xml,
spheres of 1 mm radius on a 4 x 4 grid over the bottom face (the
identification's grid), reaching 1 mm below the mesh so that they alone touch a
flat floor, carrying mu and the contact attributes, massless. Newton's MJCF
importer reads them as the same spheres; URDF and USD carry the meshes alone.

Friction of a pair: MuJoCo takes the larger of the two geoms' coefficients,
Newton's SemiImplicit solver and PhysX their mean. The identified mu is the
pair's (this object on the surface it was pushed over), so the object's geoms
and scene.xml's plane both carry it: every engine then uses mu. `priority` or
`solmix` would make the object's value win only in MuJoCo, so neither is written;
in another scene the floor's own coefficient takes part as that engine combines
them (a MuJoCo floor at the default 1 would win: give it mu, or a `<pair>`).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path, PurePosixPath

import numpy as np

from assets import Asset

from .names import base_name, file_stem, joint_name, mjcf_name, xml_comment_text
from .preconditions import exportable_inertial

__all__ = [
    "SCENE_FILE", "SCENE_OPTIONS", "SUPPORT_POINT", "export_mjcf", "export_scene", "support_height_m", "support_model",
    "support_points_m",
]

SCENE_FILE = "scene.xml"
"""The scene of a pushed object, beside its MJCF (asset.json → files → "scene")."""

# MuJoCo's defaults for the torsional and rolling coefficients; only sliding
# friction is identified.
_TORSION_FRICTION = 0.005
_ROLL_FRICTION = 0.0001

CONTACT = {"condim": "3", "solref": "0.02 1", "solimp": "0.9 0.95 0.001 0.5 2"}
"""Contact attributes of every colliding geom (module docstring)."""

FRICTION_IMPEDANCE = 0.99
"""solimpfriction's impedance of a jointed part whose friction grip was measured (module docstring)."""
SCENE_OPTIONS = {"timestep": "0.001", "gravity": "0 0 -9.81", "cone": "elliptic", "impratio": "10"}
"""scene.xml's `<option>`: step [s], gravity [m/s^2] and the friction cone (module docstring)."""


SUPPORT_POINT = "_support_point_"
"""Infix of the support points' geom names (`support_points_m`): BODY_support_point_K."""
SUPPORT_POINT_RADIUS_M = 1e-3
"""Radius of a support point's sphere [m]."""
SUPPORT_POINT_DROP_M = 1e-3
"""How far a support point's sphere reaches below the collision mesh's lowest point [m]: enough that the mesh
stays clear of a flat floor under the object's weight (MuJoCo's default contact sinks about 0.2 mm) and
while a push tilts it, small beside any object's height."""
_SUPPORT_GRID = 4
"""Support points per side of the bottom face: the sliding identification's grid
(pipelines/identify/sliding/body.py `support_points`)."""


def _num(values) -> str:
    """Space-separated shortest round-trip decimals."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _mesh_name(rel_path: str) -> str:
    return PurePosixPath(rel_path).stem


def _friction_grip(grip_s: float | None) -> dict[str, str]:
    """A joint's `solreffriction`/`solimpfriction` gripping as measured (module docstring); none unmeasured."""
    if grip_s is None:
        return {}
    return {"solreffriction": _num((2 * grip_s / FRICTION_IMPEDANCE, 1.0)),
            "solimpfriction": _num((FRICTION_IMPEDANCE, FRICTION_IMPEDANCE, 0.001, 0.5, 2.0))}


def _friction(mu: float) -> dict[str, str]:
    return {"friction": _num((mu, _TORSION_FRICTION, _ROLL_FRICTION)), **CONTACT}


def support_model(asset: Asset) -> str | None:
    """The support a pushed object's identification chose ("uniform" or "corners",
    asset.json → provenance → identify → support → model), or None: not pushed, or not recorded."""
    if asset.kind != "sliding":
        return None
    identify = (asset.provenance or {}).get("identify", {})
    return (identify.get("support") or {}).get("model") or identify.get("config", {}).get("support")


def support_points_m(asset: Asset, out_dir: Path) -> np.ndarray:
    """Centres of the support points [n, 3] in the object frame [m]: for a pushed object whose identification
    chose the "uniform" support, the cell centres of a 4 x 4 grid over the bottom face of the collision
    meshes' bounding box (world axes at the placement), each a sphere of `SUPPORT_POINT_RADIUS_M` reaching
    `SUPPORT_POINT_DROP_M` below the lowest vertex; none otherwise ("corners": MuJoCo's mesh-plane contact
    carries the object at the face's corners by itself). Mesh paths are relative to `out_dir`."""
    if support_model(asset) != "uniform":
        return np.zeros((0, 3))
    import trimesh

    R = asset.placement.rotation_matrix()
    vertices = np.concatenate([np.asarray(trimesh.load(Path(out_dir) / rel, force="mesh", process=False).vertices,
                                          dtype=float) for rel in asset.geometry.collision]) @ R.T
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    cells = (np.arange(_SUPPORT_GRID) + 0.5) / _SUPPORT_GRID
    z = lo[2] - SUPPORT_POINT_DROP_M + SUPPORT_POINT_RADIUS_M
    world = np.array([(lo[0] + u * (hi[0] - lo[0]), lo[1] + v * (hi[1] - lo[1]), z) for u in cells for v in cells])
    return world @ R


def export_mjcf(asset: Asset, out_dir: Path) -> Path:
    """Write `out_dir/NAME.xml` for a rigid object, free or on a joint.

    Inertial: mass [kg], COM [m] and the full tensor about the COM [kg m^2],
    object frame. Collision: one mesh geom per convex part with sliding
    friction `asset.theta.friction.value` and the contact attributes `CONTACT`. Visual: a massless, non-colliding
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
        world.append(ET.Comment(" object frame at the scanned placement; no support plane here (DESIGN.md) "))
        parent = world
    else:
        world.append(ET.Comment(" fixed base in world; the part at its scanned placement (q = 0) on its joint "))
        parent = ET.SubElement(world, "body", name=base_name(body_name))
        if asset.geometry.base:
            ET.SubElement(parent, "geom", name=names[-1], type="mesh", mesh=names[-1], **_friction(mu))
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
            springref=repr(float(j.spring_ref)), **_friction_grip(j.friction_grip_s),
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
        ET.SubElement(body, "geom", name=name, type="mesh", mesh=name, group="3", **_friction(mu))
    support = support_points_m(asset, out_dir)
    if len(support):
        body.append(ET.Comment(" support points: the bottom face carries the weight evenly, as the identification "
                               "assumed (a mesh alone would stand on its corners) "))
    for k, centre in enumerate(support):
        ET.SubElement(body, "geom", name=f"{body_name}{SUPPORT_POINT}{k}", type="sphere",
                      size=repr(SUPPORT_POINT_RADIUS_M), pos=_num(centre), density="0", group="3", **_friction(mu))

    if asset.joint is not None and asset.geometry.base:
        # the joint guides the part through the base (a carcass around a drawer): they must not collide
        ET.SubElement(ET.SubElement(root, "contact"), "exclude", body1=base_name(body_name), body2=body_name)
    ET.indent(root, space="  ")
    out_dir.mkdir(parents=True, exist_ok=True)
    path.write_text(ET.tostring(root, encoding="unicode") + "\n")
    return path


def support_height_m(asset: Asset, out_dir: Path) -> float:
    """World height [m] of the lowest collision-mesh vertex (or support point's sphere, `support_points_m`)
    with the object at `asset.placement`: the surface it rests on. Mesh paths in `asset.geometry` are
    relative to `out_dir`."""
    import trimesh

    R, p = asset.placement.rotation_matrix(), np.asarray(asset.placement.position, dtype=float)
    lowest = []
    for rel in asset.geometry.collision:
        vertices = np.asarray(trimesh.load(Path(out_dir) / rel, force="mesh", process=False).vertices, dtype=float)
        lowest.append(float(np.min(vertices @ R[2] + p[2])))
    support = support_points_m(asset, out_dir)
    if len(support):  # the support points' spheres reach below the mesh
        lowest.append(float(np.min(support @ R[2] + p[2])) - SUPPORT_POINT_RADIUS_M)
    return min(lowest)


def export_scene(asset: Asset, out_dir: Path, mjcf_path: Path) -> Path:
    """Write `out_dir/scene.xml` for a pushed object: `mjcf_path` (its file, beside it) included, a
    support plane and the solver options of a push (module docstring).

    The plane's top is at `support_height_m` (world z [m]), under the object's placement; it carries
    the identified friction `asset.theta.friction.value` with the object's contact attributes, so MuJoCo
    takes mu for the pair. Options: `SCENE_OPTIONS` (gravity -9.81 m/s^2 along world z, 1 ms step,
    elliptic cone, impratio 10).
    """
    out_dir = Path(out_dir)
    path = out_dir / SCENE_FILE
    body_name = mjcf_name(asset.name)
    mu = float(asset.theta.friction.value)
    x, y, _ = asset.placement.position
    root = ET.Element("mujoco", model=f"{body_name}_scene")
    root.append(ET.Comment(f" {xml_comment_text(asset.name)} on the surface it was pushed over "))
    ET.SubElement(root, "include", file=Path(mjcf_path).name)
    ET.SubElement(root, "option", **SCENE_OPTIONS)
    world = ET.SubElement(root, "worldbody")
    world.append(ET.Comment(" the support surface: its top at the object's lowest point; the pair's friction "))
    # size 0 0: an infinite plane; the third number is only the rendered grid's spacing [m]
    ET.SubElement(world, "geom", name=f"{body_name}_support", type="plane",
                  pos=_num((x, y, support_height_m(asset, out_dir))), size="0 0 0.05", **_friction(mu))
    ET.indent(root, space="  ")
    path.write_text(ET.tostring(root, encoding="unicode") + "\n")
    return path
