"""USD writer: the asset as a UsdPhysics rigid body in `NAME.usda`.

NAME is `exporters.names.file_stem` of the asset's name, and PRIM its
`usd_prim_name`; the body prim's `doc` and customData "twin:name" keep the name
as written. Layout of the stage (upAxis Z, metersPerUnit 1, kilogramsPerUnit 1):

    /PRIM                      Xform at `placement`; RigidBodyAPI, MassAPI,
                               NewtonMassAPI (`newton:inertia`), twin:* values
      visual                   Mesh (render purpose)
      collision/collision_NNN  Mesh, CollisionAPI + convexHull, guide purpose,
                               physics material bound with purpose "physics"
      PhysicsMaterial          Material with PhysicsMaterialAPI

Meshes are written inline (points, faceVertexCounts, faceVertexIndices), so the
file does not depend on OBJ readers. MassAPI holds mass, centerOfMass,
diagonalInertia and principalAxes; those are single precision by schema, so
`newton:inertia` (double[6]) and `twin:*` doubles carry the exact values.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

import numpy as np

from assets import Asset

from .names import file_stem, usd_prim_name
from .preconditions import exportable_inertial

__all__ = ["export_usd"]



def _quat_wxyz_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return float(w), float(x), float(y), float(z)


def _read_mesh(path: Path):
    """Vertices [m] and triangles of a mesh file, unprocessed (no merging or reordering)."""
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise ValueError(f"{path}: cannot read mesh ({exc})") from exc
    if len(mesh.vertices) == 0 or len(mesh.faces) == 0:
        raise ValueError(f"{path}: mesh has no vertices or faces")
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=int)


def _define_mesh(stage, prim_path: str, mesh_file: Path):
    from pxr import UsdGeom, Vt

    vertices, faces = _read_mesh(mesh_file)
    mesh = UsdGeom.Mesh.Define(stage, prim_path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(vertices.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(faces)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.reshape(-1).astype(np.int32)))
    # Scanned meshes are polygonal; the schema default (catmullClark) would smooth them.
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    mesh.CreateExtentAttr(Vt.Vec3fArray([tuple(lo), tuple(hi)]))
    return mesh


def _std_or_none(estimate) -> np.ndarray | None:
    return None if estimate.std is None else np.asarray(estimate.std, dtype=float)


def export_usd(asset: Asset, out_dir: Path) -> Path:
    """Write `out_dir/NAME.usda` for a rigid object, free or on a joint to the world.

    The body prim's frame is the object frame, placed at `asset.placement`.
    Mass [kg], COM [m] and inertia about the COM [kg m^2] (object-frame axes)
    are authored so that authored values win over collider-derived ones in
    every UsdPhysics importer; colliders therefore add no mass. Friction is
    the physics material's static and dynamic friction (unitless).

    Raises:
        ValueError: an unphysical inertia tensor, no collision parts, an empty joint
            range or unreadable mesh files. A base mesh is not written to USD.
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt

    out_dir = Path(out_dir)
    path = out_dir / f"{file_stem(asset.name)}.usda"

    inertial = exportable_inertial(asset, path, "export_usd")
    I = inertial.inertia_matrix()
    moments, axes = inertial.principal()

    out_dir.mkdir(parents=True, exist_ok=True)
    if path.exists():
        path.unlink()  # CreateNew refuses an existing layer
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)

    root_path = Sdf.Path.absoluteRootPath.AppendChild(usd_prim_name(asset.name))
    body = UsdGeom.Xform.Define(stage, root_path)
    prim = body.GetPrim()
    stage.SetDefaultPrim(prim)
    x, y, z, w = asset.placement.quaternion_xyzw
    body.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*asset.placement.position))
    body.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Quatd(w, x, y, z))

    UsdPhysics.RigidBodyAPI.Apply(prim)
    mass_api = UsdPhysics.MassAPI.Apply(prim)
    mass_api.CreateMassAttr(inertial.mass)
    mass_api.CreateCenterOfMassAttr(Gf.Vec3f(*inertial.com))
    mass_api.CreateDiagonalInertiaAttr(Gf.Vec3f(*moments))
    qw, qx, qy, qz = _quat_wxyz_from_matrix(axes)
    mass_api.CreatePrincipalAxesAttr(Gf.Quatf(qw, qx, qy, qz))
    # Newton reads this double-precision tensor before diagonalInertia/principalAxes.
    prim.AddAppliedSchema("NewtonMassAPI")
    prim.CreateAttribute("newton:inertia", Sdf.ValueTypeNames.DoubleArray, custom=False).Set(
        Vt.DoubleArray([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])
    )

    # Exact values and uncertainty in our own namespace; loaders ignore them.
    theta = asset.theta
    prim.CreateAttribute("twin:mass", Sdf.ValueTypeNames.Double).Set(inertial.mass)
    prim.CreateAttribute("twin:centerOfMass", Sdf.ValueTypeNames.Double3).Set(Gf.Vec3d(*inertial.com))
    prim.CreateAttribute("twin:inertia", Sdf.ValueTypeNames.Matrix3d).Set(Gf.Matrix3d(*I.reshape(-1)))
    prim.CreateAttribute("twin:friction", Sdf.ValueTypeNames.Double).Set(float(theta.friction.value))
    if (std := _std_or_none(theta.mass)) is not None:
        prim.CreateAttribute("twin:massStd", Sdf.ValueTypeNames.Double).Set(float(std))
    if (std := _std_or_none(theta.com)) is not None:
        prim.CreateAttribute("twin:centerOfMassStd", Sdf.ValueTypeNames.Double3).Set(Gf.Vec3d(*std.reshape(3)))
    if (std := _std_or_none(theta.inertia)) is not None:
        prim.CreateAttribute("twin:inertiaStd", Sdf.ValueTypeNames.Matrix3d).Set(Gf.Matrix3d(*std.reshape(-1)))
    if (std := _std_or_none(theta.friction)) is not None:
        prim.CreateAttribute("twin:frictionStd", Sdf.ValueTypeNames.Double).Set(float(std))
    prim.SetCustomDataByKey("twin:kind", asset.kind)
    # displayName is newer (USD 23.11) than many readers in use; doc and customData are known to all
    prim.SetDocumentation(asset.name)
    prim.SetCustomDataByKey("twin:name", asset.name)

    material = UsdShade.Material.Define(stage, root_path.AppendChild("PhysicsMaterial"))
    physics_material = UsdPhysics.MaterialAPI.Apply(material.GetPrim())
    # a jointed part's theta.friction is its joint's; its surfaces keep the material's
    mu = float(asset.theta.friction.value if asset.joint is None else asset.material.friction)
    physics_material.CreateStaticFrictionAttr(mu)
    physics_material.CreateDynamicFrictionAttr(mu)
    physics_material.CreateRestitutionAttr(float(asset.material.restitution))

    _define_mesh(stage, root_path.AppendChild("visual"), out_dir / asset.geometry.visual)

    UsdGeom.Scope.Define(stage, root_path.AppendChild("collision"))
    for rel in asset.geometry.collision:
        name = usd_prim_name(PurePosixPath(rel).stem)
        mesh = _define_mesh(stage, root_path.AppendChild("collision").AppendChild(name), out_dir / rel)
        mesh.CreatePurposeAttr(UsdGeom.Tokens.guide)
        collider = mesh.GetPrim()
        UsdPhysics.CollisionAPI.Apply(collider)
        # The parts are already convex (CoACD); convexDecomposition would make importers split them again.
        UsdPhysics.MeshCollisionAPI.Apply(collider).CreateApproximationAttr(UsdPhysics.Tokens.convexHull)
        UsdShade.MaterialBindingAPI.Apply(collider).Bind(
            material, UsdShade.Tokens.weakerThanDescendants, "physics"
        )

    if asset.joint is not None:
        _define_joint(stage, root_path, asset)
    stage.GetRootLayer().Save()
    return path


def _define_joint(stage, body_path, asset: Asset) -> None:
    """The part's joint to the world (the fixed base), q = 0 at the placement.

    UsdPhysics joints turn about a named local axis: X, rotated onto
    `asset.joint.axis` by the local frames. Revolute limits are in degrees.
    Passive friction, damping and springs have no core attribute: Newton's and
    MuJoCo's own (`newton:damping` per degree on revolute joints, as Newton
    reads it; `mjc:damping`, `mjc:stiffness` per radian, `mjc:springref` in degrees).
    """
    from pxr import Gf, Sdf, UsdPhysics
    from scipy.spatial.transform import Rotation

    j = asset.joint
    a = np.asarray(j.axis, dtype=float)
    R_joint = Rotation.align_vectors([a], [[1.0, 0.0, 0.0]])[0]
    R_body = Rotation.from_quat(asset.placement.quaternion_xyzw)
    revolute = j.type == "revolute"
    joint = (UsdPhysics.RevoluteJoint if revolute else UsdPhysics.PrismaticJoint).Define(
        stage, body_path.AppendChild("joint"))
    joint.CreateBody1Rel().SetTargets([body_path])
    joint.CreateAxisAttr("X")
    quat = lambda r: Gf.Quatf(*(lambda x, y, z, w: (w, x, y, z))(*r.as_quat()))  # noqa: E731
    joint.CreateLocalPos0Attr(Gf.Vec3f(*j.origin))
    joint.CreateLocalRot0Attr(quat(R_joint))
    joint.CreateLocalPos1Attr(Gf.Vec3f(*R_body.inv().apply(np.asarray(j.origin) - asset.placement.position)))
    joint.CreateLocalRot1Attr(quat(R_body.inv() * R_joint))
    to_unit = np.degrees if revolute else float
    joint.CreateLowerLimitAttr(float(to_unit(j.lower)))
    joint.CreateUpperLimitAttr(float(to_unit(j.upper)))
    prim = joint.GetPrim()
    friction = float(asset.theta.friction.value)
    prim.CreateAttribute("newton:damping", Sdf.ValueTypeNames.Float).Set(
        float(j.damping * (np.pi / 180 if revolute else 1.0)))
    prim.CreateAttribute("newton:friction", Sdf.ValueTypeNames.Float).Set(friction)
    prim.CreateAttribute("mjc:frictionloss", Sdf.ValueTypeNames.Float).Set(friction)
    # MuJoCo's passive joint terms: damping and stiffness per radian (SI), the spring's rest angle in
    # degrees (MuJoCo's default compiler angle, as Newton's importer reads it)
    prim.CreateAttribute("mjc:damping", Sdf.ValueTypeNames.Float).Set(float(j.damping))
    prim.CreateAttribute("mjc:stiffness", Sdf.ValueTypeNames.Float).Set(float(j.stiffness))
    prim.CreateAttribute("mjc:springref", Sdf.ValueTypeNames.Float).Set(float(to_unit(j.spring_ref)))
    UsdPhysics.ArticulationRootAPI.Apply(stage.GetPrimAtPath(body_path))
