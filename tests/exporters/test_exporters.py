"""Exporters write files that real loaders read back to the identified values."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from assets import Asset, Estimate, Geometry, Joint, Material, Pose, Theta
from exporters import ExportPaths, export_all, export_mjcf, export_urdf, export_usd

TOL = 1e-6
EXTENTS_M = np.array([0.06, 0.04, 0.03])
MASS_KG = 0.02
COM_M = (0.003, -0.002, 0.004)
FRICTION = 0.6


def _box_inertia() -> np.ndarray:
    """A solid box's tensor [kg m^2] turned off the axes, so every entry is non-zero."""
    a, b, c = EXTENTS_M
    moments = MASS_KG / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    R = Rotation.from_euler("xyz", [0.3, -0.5, 0.8]).as_matrix()
    I = R @ np.diag(moments) @ R.T
    return 0.5 * (I + I.T)  # exactly symmetric, as Inertial stores it


def make_asset(out_dir: Path, name: str = "box") -> Asset:
    """Write a box mesh and two convex halves under out_dir/meshes and describe them as an Asset."""
    meshes = out_dir / "meshes"
    meshes.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=EXTENTS_M).export(meshes / "visual.obj")
    half = (EXTENTS_M[0] / 2, EXTENTS_M[1], EXTENTS_M[2])
    for i, sign in enumerate((-1.0, 1.0)):
        T = np.eye(4)
        T[0, 3] = sign * EXTENTS_M[0] / 4
        trimesh.creation.box(extents=half, transform=T).export(meshes / f"collision_{i:03d}.obj")
    I = _box_inertia()
    theta = Theta(
        mass=Estimate(MASS_KG, 0.001),
        com=Estimate(COM_M, (1e-4, 1e-4, 1e-4)),
        inertia=Estimate(tuple(map(tuple, I)), tuple(map(tuple, 0.05 * np.abs(I)))),
        friction=Estimate(FRICTION, 0.05),
    )
    placement = Pose((0.4, -0.1, 0.05), tuple(Rotation.from_euler("zyx", [0.7, 0.2, -0.1]).as_quat()))
    return Asset(
        name=name,
        kind="free",
        placement=placement,
        theta=theta,
        geometry=Geometry("meshes/visual.obj", ("meshes/collision_000.obj", "meshes/collision_001.obj")),
        material=Material("wood", 600.0, FRICTION, 0.1),
    )


@pytest.fixture
def asset(tmp_path: Path) -> Asset:
    return make_asset(tmp_path)


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_export_all_writes_three_files_named_after_the_asset(asset: Asset, tmp_path: Path):
    """export_all writes NAME.urdf, NAME.xml and NAME.usda next to the meshes."""
    paths = export_all(asset, tmp_path)
    assert paths == ExportPaths(tmp_path / "box.urdf", tmp_path / "box.xml", tmp_path / "box.usda")
    assert all(Path(p).is_file() for p in (paths.urdf, paths.mjcf, paths.usd))
    assert paths.to_json(relative_to=tmp_path) == {"urdf": "box.urdf", "mjcf": "box.xml", "usd": "box.usda"}


def test_mjcf_loads_in_mujoco_with_the_exact_inertial(asset: Asset, tmp_path: Path):
    """MuJoCo reads back mass, COM, full tensor, friction and placement of the written MJCF."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(export_mjcf(asset, tmp_path)))
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "box")
    w, x, y, z = model.body_iquat[body]
    R = Rotation.from_quat([x, y, z, w]).as_matrix()
    assert model.body_mass[body] == pytest.approx(MASS_KG, rel=TOL)
    assert np.allclose(model.body_ipos[body], COM_M, atol=1e-12)
    assert _rel(R @ np.diag(model.body_inertia[body]) @ R.T, _box_inertia()) < TOL
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert np.allclose(model.body_pos[body], asset.placement.position)
    qx, qy, qz, qw = asset.placement.quaternion_xyzw
    assert np.allclose(model.body_quat[body], [qw, qx, qy, qz])
    colliding = [g for g in range(model.ngeom) if model.geom_contype[g] or model.geom_conaffinity[g]]
    assert len(colliding) == 2
    assert np.allclose(model.geom_friction[colliding, 0], FRICTION)
    assert model.ngeom == 3  # no floor for a free object


def test_mjcf_writes_numbers_at_full_precision(asset: Asset, tmp_path: Path):
    """The MJCF text holds every inertial number exactly (no 6-digit rounding)."""
    root = ET.parse(export_mjcf(asset, tmp_path)).getroot()
    inertial = root.find("worldbody/body/inertial")
    I = _box_inertia()
    full = [float(v) for v in inertial.get("fullinertia").split()]
    assert full == [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
    assert float(inertial.get("mass")) == MASS_KG
    assert root.find("compiler").get("angle") == "radian"
    assert root.find("worldbody/body/freejoint") is not None


def test_urdf_loads_in_yourdfpy_with_relative_meshes(asset: Asset, tmp_path: Path):
    """yourdfpy reads the URDF's inertial exactly and finds the visual and both collision meshes."""
    import yourdfpy

    path = export_urdf(asset, tmp_path)
    urdf = yourdfpy.URDF.load(
        str(path), build_collision_scene_graph=True, load_collision_meshes=True, force_collision_mesh=False
    )
    assert urdf.validate()
    inertial = urdf.link_map["box"].inertial
    assert inertial.mass == MASS_KG
    assert np.array_equal(inertial.origin[:3, 3], COM_M)
    assert np.array_equal(inertial.origin[:3, :3], np.eye(3))
    assert np.array_equal(inertial.inertia, _box_inertia())
    assert len(urdf.collision_scene.geometry) == 2
    assert len(urdf.scene.geometry) == 1
    root = ET.parse(path).getroot()
    assert all(not Path(m.get("filename")).is_absolute() for m in root.iter("mesh"))
    assert float(root.find("link/contact/lateral_friction").get("value")) == FRICTION
    assert float(root.find("gazebo/mu1").text) == float(root.find("gazebo/mu2").text) == FRICTION


def test_usd_mass_api_and_newton_inertia_match(asset: Asset, tmp_path: Path):
    """UsdPhysics MassAPI (diagonal + principal axes) and newton:inertia both give the tensor back."""
    from pxr import Usd, UsdGeom, UsdPhysics

    stage = Usd.Stage.Open(str(export_usd(asset, tmp_path)))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdPhysics.GetStageKilogramsPerUnit(stage) == 1.0
    prim = stage.GetDefaultPrim()
    assert prim.GetPath() == "/box" and prim.HasAPI(UsdPhysics.RigidBodyAPI)
    mass_api = UsdPhysics.MassAPI(prim)
    q = mass_api.GetPrincipalAxesAttr().Get()
    R = Rotation.from_quat([*q.GetImaginary(), q.GetReal()]).as_matrix()
    rebuilt = R @ np.diag(mass_api.GetDiagonalInertiaAttr().Get()) @ R.T
    assert mass_api.GetMassAttr().Get() == pytest.approx(MASS_KG, rel=TOL)
    assert np.allclose(mass_api.GetCenterOfMassAttr().Get(), COM_M, rtol=0, atol=1e-9)
    assert _rel(rebuilt, _box_inertia()) < TOL
    ixx, iyy, izz, ixy, ixz, iyz = prim.GetAttribute("newton:inertia").Get()
    I = _box_inertia()
    assert [ixx, iyy, izz, ixy, ixz, iyz] == [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
    assert prim.GetAttribute("twin:massStd").Get() == 0.001
    world = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    assert np.allclose(world.ExtractTranslation(), asset.placement.position, atol=1e-12)


def test_usd_colliders_are_convex_hulls_with_a_physics_material(asset: Asset, tmp_path: Path):
    """Each convex part is a guide Mesh collider (convexHull) bound to the friction material for physics."""
    from pxr import Usd, UsdGeom, UsdPhysics, UsdShade

    stage = Usd.Stage.Open(str(export_usd(asset, tmp_path)))
    colliders = [p for p in stage.Traverse() if p.HasAPI(UsdPhysics.CollisionAPI)]
    assert [p.GetName() for p in colliders] == ["collision_000", "collision_001"]
    for prim in colliders:
        assert UsdPhysics.MeshCollisionAPI(prim).GetApproximationAttr().Get() == UsdPhysics.Tokens.convexHull
        assert UsdGeom.Imageable(prim).GetPurposeAttr().Get() == UsdGeom.Tokens.guide
        assert len(UsdGeom.Mesh(prim).GetPointsAttr().Get()) == 8
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial("physics")
        physics = UsdPhysics.MaterialAPI(material.GetPrim())
        assert physics.GetDynamicFrictionAttr().Get() == pytest.approx(FRICTION)
        assert physics.GetStaticFrictionAttr().Get() == pytest.approx(FRICTION)
    visual = UsdGeom.Mesh(stage.GetPrimAtPath("/box/visual"))
    assert len(visual.GetFaceVertexCountsAttr().Get()) == 12
    assert not visual.GetPrim().HasAPI(UsdPhysics.CollisionAPI)


@pytest.mark.parametrize("joint_type", ["prismatic", "revolute"])
def test_jointed_asset_reads_back_with_its_joint(asset: Asset, tmp_path: Path, joint_type: str):
    """A drawer or door (tilted axis, turned placement, base mesh) reads back in MuJoCo, Newton (all three files)
    and yourdfpy
    with the same body, joint type, axis, axis point, limits, damping and friction."""
    from pipelines.validate import validate_jointed_exports

    trimesh.creation.box(extents=(0.5, 0.5, 0.02)).export(tmp_path / "meshes" / "base.obj")
    axis = np.array([0.2, -0.3, 0.93])
    joint = Joint(joint_type, tuple(axis / np.linalg.norm(axis)), (0.35, -0.12, 0.02), -0.05, 0.9, damping=0.03)
    part = replace(asset, kind=joint_type, joint=joint, geometry=replace(asset.geometry, base="meshes/base.obj"))
    paths = export_all(part, tmp_path)
    readings = validate_jointed_exports(part, tmp_path, paths)
    assert set(readings) == {"mujoco (mjcf)", "newton (mjcf)", "yourdfpy (urdf)", "newton (urdf)", "newton (usd)"}
    for reading in readings.values():
        assert reading["friction"] == pytest.approx(FRICTION, rel=1e-6)
        assert reading["limits"] == pytest.approx([-0.05, 0.9], abs=1e-6)

    from pxr import Usd, UsdPhysics

    stage = Usd.Stage.Open(str(paths.usd))
    usd_joint = stage.GetPrimAtPath("/box/joint")
    assert usd_joint.IsA(UsdPhysics.RevoluteJoint if joint_type == "revolute" else UsdPhysics.PrismaticJoint)
    upper = UsdPhysics.Joint(usd_joint).GetPrim().GetAttribute("physics:upperLimit").Get()
    assert upper == pytest.approx(np.degrees(0.9) if joint_type == "revolute" else 0.9, rel=1e-6)


@pytest.mark.parametrize("joint_type", ["prismatic", "revolute"])
def test_joint_damping_and_spring_reach_every_format(asset: Asset, tmp_path: Path, joint_type: str):
    """A diagnosed joint damping and spring (stiffness about a rest position) come back from MuJoCo's MJCF
    model, the URDF's <dynamics> and Gazebo spring tags, and the USD joint's newton:/mjc: attributes."""
    import mujoco
    import yourdfpy
    from pxr import Usd

    joint = Joint(joint_type, (0.0, 0.0, 1.0), (0.35, -0.12, 0.02), -0.05, 0.9, damping=0.03, stiffness=0.4,
                  spring_ref=0.2)
    paths = export_all(replace(asset, kind=joint_type, joint=joint), tmp_path)
    model = mujoco.MjModel.from_xml_path(str(paths.mjcf))
    assert model.dof_damping[0] == pytest.approx(0.03)
    assert model.jnt_stiffness[0] == pytest.approx(0.4)
    assert model.qpos_spring[0] == pytest.approx(0.2)
    urdf_joint = yourdfpy.URDF.load(str(paths.urdf), load_meshes=False).joint_map["box_joint"]
    assert float(urdf_joint.dynamics.damping) == pytest.approx(0.03)
    gazebo = ET.parse(paths.urdf).getroot().find("gazebo[@reference='box_joint']")
    assert float(gazebo.find("springStiffness").text) == pytest.approx(0.4)
    assert float(gazebo.find("springReference").text) == pytest.approx(0.2)
    stage = Usd.Stage.Open(str(paths.usd))
    prim = stage.GetPrimAtPath("/box/joint")
    per_unit = np.pi / 180 if joint_type == "revolute" else 1.0
    assert prim.GetAttribute("newton:damping").Get() == pytest.approx(0.03 * per_unit)
    assert prim.GetAttribute("mjc:stiffness").Get() == pytest.approx(0.4)
    assert prim.GetAttribute("mjc:springref").Get() == pytest.approx(0.2 / per_unit)


def test_a_measured_friction_grip_reaches_mujoco(asset: Asset, tmp_path: Path):
    """MuJoCo's frictionloss drives q'' towards -2 q' / (dmax timeconst) while it holds: a measured grip of 10 ms
    gives that rate and leaks 1 %; an unmeasured grip leaves MuJoCo's defaults."""
    import mujoco

    for grip_s, solref, solimp in ((0.01, (2 * 0.01 / 0.99, 1.0), (0.99, 0.99)), (None, (0.02, 1.0), (0.9, 0.95))):
        joint = Joint("prismatic", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), -0.1, 0.3, friction_grip_s=grip_s)
        model = mujoco.MjModel.from_xml_path(str(export_mjcf(replace(asset, kind="prismatic", joint=joint), tmp_path)))
        assert model.dof_solref[0] == pytest.approx(solref)
        assert model.dof_solimp[0][:2] == pytest.approx(solimp)
        assert 2 / (model.dof_solimp[0][1] * model.dof_solref[0][0]) == pytest.approx(1 / (grip_s or 0.0095), rel=1e-3)


def test_empty_joint_range_is_refused(asset: Asset, tmp_path: Path):
    """A joint whose lower limit is not below its upper one is refused by every writer, naming the range."""
    drawer = replace(asset, kind="prismatic", joint=Joint("prismatic", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.3, 0.3))
    for export in (export_urdf, export_mjcf, export_usd):
        with pytest.raises(ValueError, match="range"):
            export(drawer, tmp_path)


def test_unphysical_tensor_is_refused(asset: Asset, tmp_path: Path):
    """A tensor breaking the triangle inequality is refused rather than 'balanced' or rejected by a loader."""
    bad = np.diag([1e-6, 1e-6, 5e-6])
    theta = replace(asset.theta, inertia=Estimate(tuple(map(tuple, bad)), None))
    for export in (export_urdf, export_mjcf, export_usd):
        with pytest.raises(ValueError, match="triangle"):
            export(replace(asset, theta=theta), tmp_path)


def test_sliding_kind_and_odd_names_still_load(tmp_path: Path):
    """A 'sliding' asset named 'mug-1 (red)' exports to 'mug-1 (red).*' files whose body MuJoCo, yourdfpy and
    usd-core find as 'mug_1_red' (tests/exporters/test_names.py has the rules)."""
    import mujoco
    import yourdfpy
    from pxr import Usd

    asset = replace(make_asset(tmp_path, name="mug-1 (red)"), kind="sliding")
    paths = export_all(asset, tmp_path)
    assert paths.mjcf == tmp_path / "mug-1 (red).xml"
    model = mujoco.MjModel.from_xml_path(str(paths.mjcf))
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "mug_1_red") == 1
    assert "mug_1_red" in yourdfpy.URDF.load(str(paths.urdf)).link_map
    stage = Usd.Stage.Open(str(paths.usd))  # keep the stage alive while its prims are used
    assert stage.GetDefaultPrim().GetName() == "mug_1_red"
