"""The loaders: each reads one exported file (MJCF, scene.xml, URDF, USD) into what it holds of the


body: mass, COM, inertia, friction, placement."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets import Asset
from exporters.mjcf import SUPPORT_POINT
from exporters.names import mjcf_name, urdf_name, usd_prim_name


MJ_STEPS = 100
REST_S = 0.5
"""How long a pushed object is left on its support plane in scene.xml [s] ..."""
_REST_MOVE_M = 1e-3
"""... and how far it may move meanwhile [m]: it settles into the soft contact by a fraction of that."""


@dataclass(frozen=True)
class Reading:
    """Raw values a loader returned, object frame, SI."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    friction: float | None = None
    position: np.ndarray | None = None
    quaternion_xyzw: np.ndarray | None = None
    notes: tuple[str, ...] = ()


def rotation_from_wxyz(q) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    w, x, y, z = (float(v) for v in q)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def _collision_mu(values: list[float], loader: str) -> float:
    """The one friction coefficient all collision shapes share."""
    if len(set(values)) != 1:
        raise ValueError(f"{loader} read different friction coefficients on the collision parts: {values}")
    return values[0]


def _read_mujoco(asset: Asset, path: Path) -> Reading:
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    name = mjcf_name(asset.name)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    if body < 0:
        raise ValueError(f"no body named {name!r}")
    R = rotation_from_wxyz(model.body_iquat[body])
    inertia = R @ np.diag(model.body_inertia[body]) @ R.T
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == body]
    colliding = [g for g in geoms if model.geom_contype[g] or model.geom_conaffinity[g]]
    # a pushed object's support points (exporters/mjcf.py `support_points_m`) collide beside its meshes
    support = [g for g in colliding if SUPPORT_POINT in (model.geom(g).name or "")]
    meshes = [g for g in colliding if g not in support]
    if len(meshes) != len(asset.geometry.collision):
        raise ValueError(f"expected {len(asset.geometry.collision)} colliding geoms, found {len(meshes)}"
                         + (f" beside {len(support)} support points" if support else ""))
    mu = _collision_mu([float(model.geom_friction[g, 0]) for g in colliding], "MuJoCo")

    # Step it: proves the model compiles into something that simulates.
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)  # xpos is zero until the first kinematics pass
    z0 = float(data.xpos[body, 2])
    for _ in range(MJ_STEPS):
        mujoco.mj_step(model, data)
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        raise ValueError(f"state not finite after {MJ_STEPS} steps")
    drop_m = z0 - float(data.xpos[body, 2])
    t_s = MJ_STEPS * model.opt.timestep
    free_fall_m = 0.5 * float(np.linalg.norm(model.opt.gravity)) * t_s**2
    # Nothing to touch (no floor is written), so the body must fall freely under g = 9.81 m/s^2.
    if model.opt.gravity[2] >= 0 or not 0.9 < drop_m / free_fall_m < 1.1:
        raise ValueError(
            f"body fell {drop_m:.4g} m in {t_s:g} s, expected about {free_fall_m:.4g} m "
            f"(gravity {model.opt.gravity.tolist()})"
        )
    w, x, y, z = model.body_quat[body]
    return Reading(
        mass=float(model.body_mass[body]),
        com=np.array(model.body_ipos[body], dtype=float),
        inertia=inertia,
        friction=mu,
        position=np.array(model.body_pos[body], dtype=float),
        quaternion_xyzw=np.array([x, y, z, w], dtype=float),
        notes=(f"stepped {MJ_STEPS} steps ({t_s:g} s), fell {drop_m:.4g} m",)
        + ((f"{len(support)} support points on the bottom face carry the identified friction",) if support else ()),
    )


def mujoco_free_body(model, asset: Asset, path: Path) -> tuple[int, int, int]:
    """(body id, qpos address, dof address) of the asset's body on its free joint."""
    import mujoco

    name = mjcf_name(asset.name)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    joint = model.body_jntadr[body] if body >= 0 else -1
    if body < 0 or model.body_jntnum[body] != 1 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"{path}: no body {name!r} on a free joint")
    return body, int(model.jnt_qposadr[joint]), int(model.jnt_dofadr[joint])


def settle(model, data, body: int, seconds: float) -> float:
    """Step `seconds` [s] from the model's initial state; returns how far the body's origin moved [m]."""
    import mujoco

    mujoco.mj_resetData(model, data)
    mujoco.mj_forward(model, data)
    p0 = data.xpos[body].copy()
    for _ in range(int(round(seconds / model.opt.timestep))):
        mujoco.mj_step(model, data)
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        raise ValueError(f"state not finite after {seconds:g} s on the support plane")
    return float(np.linalg.norm(data.xpos[body] - p0))


def _read_mujoco_scene(asset: Asset, path: Path) -> Reading:
    """The object as scene.xml includes it, its support plane's friction and its rest on that plane."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    body, _, _ = mujoco_free_body(model, asset, path)
    colliding = [g for g in range(model.ngeom)
                 if model.geom_bodyid[g] == body and (model.geom_contype[g] or model.geom_conaffinity[g])]
    mu = _collision_mu([float(model.geom_friction[g, 0]) for g in colliding], "MuJoCo")
    planes = [g for g in range(model.ngeom)
              if model.geom_bodyid[g] == 0 and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE]
    if len(planes) != 1:
        raise ValueError(f"expected one support plane in the world, found {len(planes)}")
    plane_mu = float(model.geom_friction[planes[0], 0])
    if plane_mu != mu:  # MuJoCo takes the larger: the pair's mu only if both carry it
        raise ValueError(f"support plane friction {plane_mu:g} differs from the object's {mu:g}")
    if model.opt.cone != mujoco.mjtCone.mjCONE_ELLIPTIC:
        raise ValueError("friction cone is not elliptic (a pyramidal cone is anisotropic: exporters/mjcf.py)")
    moved = settle(model, mujoco.MjData(model), body, REST_S)
    if moved > _REST_MOVE_M:
        raise ValueError(f"the object moved {1000 * moved:.3g} mm in {REST_S:g} s at rest on its support plane "
                         f"(at most {1000 * _REST_MOVE_M:g} mm): the plane is not under it")
    R = rotation_from_wxyz(model.body_iquat[body])
    w, x, y, z = model.body_quat[body]
    return Reading(
        mass=float(model.body_mass[body]),
        com=np.array(model.body_ipos[body], dtype=float),
        inertia=R @ np.diag(model.body_inertia[body]) @ R.T,
        friction=mu,
        position=np.array(model.body_pos[body], dtype=float),
        quaternion_xyzw=np.array([x, y, z, w], dtype=float),
        notes=(f"rested {REST_S:g} s on the support plane (top at z = {model.geom_pos[planes[0], 2]:.6g} m), "
               f"moved {1000 * moved:.3g} mm",),
    )


def _newton_reading(asset: Asset, builder, *, carries_friction: bool, carries_placement: bool,
                    support_points: int = 0) -> Reading:
    """Values from a Newton model finalized on the CPU: what its solvers actually see. support_points: the
    colliding spheres the file adds beside the collision meshes (exporters/mjcf.py `support_points_m`)."""
    import newton

    model = builder.finalize(device="cpu")
    labels = list(builder.body_label)
    if model.body_count != 1:
        raise ValueError(f"expected 1 body, Newton made {model.body_count}: {labels}")
    body = 0
    shape_body = model.shape_body.numpy()
    flags = model.shape_flags.numpy()
    colliding = [
        s for s in range(model.shape_count)
        if shape_body[s] == body and flags[s] & int(newton.ShapeFlags.COLLIDE_SHAPES)
    ]  # fmt: skip
    if len(colliding) != len(asset.geometry.collision) + support_points:
        raise ValueError(f"expected {len(asset.geometry.collision)} colliding shapes"
                         + (f" and {support_points} support points" if support_points else "")
                         + f", found {len(colliding)}")
    notes: list[str] = []
    friction = None
    mu_all = model.shape_material_mu.numpy()
    if carries_friction:
        friction = _collision_mu([float(mu_all[s]) for s in colliding], "Newton")
    else:
        notes.append(f"friction not carried; Newton uses its default mu = {float(mu_all[colliding[0]]):g}")
    position = quaternion = None
    if carries_placement:
        q = model.body_q.numpy()[body].astype(float)
        position, quaternion = q[:3], q[3:7]
    else:
        notes.append("placement not carried by the format; body at the origin")
    return Reading(
        mass=float(model.body_mass.numpy()[body]),
        com=model.body_com.numpy()[body].astype(float),
        inertia=model.body_inertia.numpy()[body].astype(float),
        friction=friction,
        position=position,
        quaternion_xyzw=quaternion,
        notes=tuple(notes),
    )


def _read_newton_mjcf(asset: Asset, path: Path) -> Reading:
    import newton

    import xml.etree.ElementTree as ET

    builder = newton.ModelBuilder()
    builder.add_mjcf(str(path))
    support = sum(SUPPORT_POINT in g.get("name", "") for g in ET.parse(path).iter("geom"))
    return _newton_reading(asset, builder, carries_friction=True, carries_placement=True, support_points=support)


def _read_yourdfpy(asset: Asset, path: Path) -> Reading:
    import yourdfpy

    urdf = yourdfpy.URDF.load(
        str(path), build_collision_scene_graph=True, load_collision_meshes=True, force_collision_mesh=False
    )
    if not urdf.validate():
        raise ValueError("yourdfpy's validate() rejected the file")
    name = urdf_name(asset.name)
    link = urdf.link_map.get(name)
    if link is None or link.inertial is None:
        raise ValueError(f"no link {name!r} with <inertial>")
    # yourdfpy skips missing meshes silently, so count what it loaded.
    n_collision = len(urdf.collision_scene.geometry) if urdf.collision_scene is not None else 0
    if n_collision != len(asset.geometry.collision):
        raise ValueError(f"loaded {n_collision} collision meshes, expected {len(asset.geometry.collision)}")
    if urdf.scene is None or len(urdf.scene.geometry) == 0:
        raise ValueError("visual mesh did not load")
    origin = np.asarray(link.inertial.origin, dtype=float)
    R = origin[:3, :3]
    return Reading(
        mass=float(link.inertial.mass),
        com=origin[:3, 3].copy(),
        inertia=R @ np.asarray(link.inertial.inertia, dtype=float) @ R.T,
        notes=("friction not parsed by yourdfpy (<contact>/<gazebo> written)", "placement not carried by URDF"),
    )


def _read_newton_urdf(asset: Asset, path: Path) -> Reading:
    import newton

    builder = newton.ModelBuilder()
    builder.add_urdf(str(path), floating=True)
    return _newton_reading(asset, builder, carries_friction=False, carries_placement=False)


_USD_VALIDATORS = (
    "usdValidation:StageMetadataChecker",
    "usdValidation:CompositionErrorTest",
    "usdValidation:AttributeTypeMismatch",
    "usdGeomValidators:StageMetadataChecker",
    "usdPhysicsValidators:RigidBodyChecker",
    "usdPhysicsValidators:ColliderChecker",
    "usdShadeValidators:MaterialBindingApiAppliedValidator",
    "usdShadeValidators:MaterialBindingRelationships",
)
"""usd-core's validators that apply to a rigid body (wheels ship no usdchecker)."""


def _usd_validator_findings(stage) -> tuple[list[str], list[str]]:
    """(errors, warnings) from usd-core's own validators."""
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    validators = [registry.GetOrLoadValidatorByName(n) for n in _USD_VALIDATORS if registry.HasValidator(n)]
    errors, cautions = [], []
    for finding in UsdValidation.ValidationContext(validators).Validate(stage):
        text = f"{finding.GetName()}: {finding.GetMessage()}"
        (errors if finding.GetType() == UsdValidation.ValidationErrorType.Error else cautions).append(text)
    return errors, cautions


def _read_usd_physics(asset: Asset, path: Path) -> Reading:
    from pxr import Usd, UsdGeom, UsdPhysics, UsdShade

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise ValueError("usd-core could not open the stage")
    errors, cautions = _usd_validator_findings(stage)
    if errors:
        raise ValueError("usd-core validators: " + "; ".join(errors))
    if UsdGeom.GetStageUpAxis(stage) != UsdGeom.Tokens.z:
        raise ValueError(f"upAxis is {UsdGeom.GetStageUpAxis(stage)!r}, expected 'Z'")
    if UsdGeom.GetStageMetersPerUnit(stage) != 1.0 or UsdPhysics.GetStageKilogramsPerUnit(stage) != 1.0:
        raise ValueError("metersPerUnit and kilogramsPerUnit must be 1")
    prim = stage.GetDefaultPrim()
    if not prim or not prim.HasAPI(UsdPhysics.RigidBodyAPI) or not prim.HasAPI(UsdPhysics.MassAPI):
        raise ValueError("default prim is missing or lacks RigidBodyAPI/MassAPI")
    if prim.GetName() != usd_prim_name(asset.name):
        raise ValueError(f"default prim is {prim.GetName()!r}, expected {usd_prim_name(asset.name)!r}")
    mass_api = UsdPhysics.MassAPI(prim)
    mass = mass_api.GetMassAttr().Get()
    com = mass_api.GetCenterOfMassAttr().Get()
    diagonal = mass_api.GetDiagonalInertiaAttr().Get()
    axes = mass_api.GetPrincipalAxesAttr().Get()
    if mass is None or com is None or diagonal is None or axes is None:
        raise ValueError("MassAPI needs mass, centerOfMass, diagonalInertia and principalAxes authored")
    imaginary = axes.GetImaginary()
    R = rotation_from_wxyz((axes.GetReal(), *imaginary))
    inertia = R @ np.diag(np.array(diagonal, dtype=float)) @ R.T

    colliders = [p for p in Usd.PrimRange(prim) if p.HasAPI(UsdPhysics.CollisionAPI)]
    if len(colliders) != len(asset.geometry.collision):
        raise ValueError(f"found {len(colliders)} colliders, expected {len(asset.geometry.collision)}")
    mus = []
    for collider in colliders:
        material, _ = UsdShade.MaterialBindingAPI(collider).ComputeBoundMaterial("physics")
        if not material or not material.GetPrim().HasAPI(UsdPhysics.MaterialAPI):
            raise ValueError(f"{collider.GetPath()} has no physics material bound")
        mus.append(float(UsdPhysics.MaterialAPI(material.GetPrim()).GetDynamicFrictionAttr().Get()))
    world = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    q = world.ExtractRotationQuat()
    qi = q.GetImaginary()
    return Reading(
        mass=float(mass),
        com=np.array(com, dtype=float),
        inertia=inertia,
        friction=_collision_mu(mus, "UsdPhysics"),
        position=np.array(world.ExtractTranslation(), dtype=float),
        quaternion_xyzw=np.array([qi[0], qi[1], qi[2], q.GetReal()], dtype=float),
        notes=("inertia rebuilt from diagonalInertia and principalAxes (float32 by schema)", *cautions),
    )


def _read_newton_usd(asset: Asset, path: Path) -> Reading:
    import newton

    builder = newton.ModelBuilder()
    builder.add_usd(str(path))
    return _newton_reading(asset, builder, carries_friction=True, carries_placement=True)


Reader = Callable[[Asset, Path], Reading]
LOADERS: dict[str, tuple[tuple[str, Reader], ...]] = {
    "mjcf": (("mujoco", _read_mujoco), ("newton.add_mjcf", _read_newton_mjcf)),
    "urdf": (("yourdfpy", _read_yourdfpy), ("newton.add_urdf", _read_newton_urdf)),
    "usd": (("pxr.UsdPhysics", _read_usd_physics), ("newton.add_usd", _read_newton_usd)),
    "scene": (("mujoco", _read_mujoco_scene),),
}
"""Format key (as in asset.json → files) → (loader name, reader) pairs; "scene" is a pushed object's scene.xml."""
