"""Reload the exported URDF, MJCF and USD files in real loaders and check them.

Each file is read by two loaders (MJCF: MuJoCo and Newton; URDF: yourdfpy and
Newton; USD: usd-core's UsdPhysics and Newton); a pushed object's scene.xml by
MuJoCo, which also lets it rest on its support plane. For every loader the mass
[kg], COM [m] and full inertia tensor about the COM [kg m^2], in the object
frame, are compared with `asset.theta`; so are surface friction and the
placement where the format and the loader carry them. Any disagreement above
the tolerance, or any file a loader cannot read, raises `ValidationError`.
Bodies, links, joints and prims are looked up by the names the writers gave
them, derived from `asset.name` by `exporters.names`.

`replay_held_mujoco`, `replay_pushed_mujoco` and `replay_jointed_mujoco` run the
exported files in MuJoCo on a held-out recording, in the windows the build
scores Newton's fit on, so the two simulators' errors stand side by side.

Relative errors:
    mass       |m - m0| / m0
    com        |c - c0| / max(L, 1e-9 m), L the object size (the visual mesh's
               bounding-box diagonal; sqrt(tr I / m) if that mesh is unreadable)
    inertia    ||I - I0||_F / ||I0||_F
    friction   |mu - mu0| / max(|mu0|, 1e-9)
    placement  max(|p - p0| / max(|p0|, L), rotation angle [rad]); Newton keeps
               poses in float32, hence |p0| in the scale
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from assets import Asset
from exporters.mjcf import SUPPORT_POINT
from exporters.names import joint_name, mjcf_name, urdf_name, usd_prim_name

__all__ = ["DEFAULT_TOLERANCE", "LOADERS", "LoaderCheck", "ValidationError", "ValidationReport", "replay_held_mujoco", "replay_pushed_model",
           "replay_pushed_mujoco",
           "validate_exports"]

DEFAULT_TOLERANCE = 1e-6
"""Largest relative error accepted (float32 storage in USD and Newton is ~6e-8)."""

_COM_FLOOR_M = 1e-9
_MJ_STEPS = 100
_REST_S = 0.5
"""How long a pushed object is left on its support plane in scene.xml [s] ..."""
_REST_MOVE_M = 1e-3
"""... and how far it may move meanwhile [m]: it settles into the soft contact by a fraction of that."""


class ValidationError(Exception):
    """An exported file that a loader cannot read, or reads with other values.

    Attributes:
        path: the offending file.
        message: what went wrong.
        report: the full `ValidationReport` when one was made, else None.
    """

    def __init__(self, path: Path | str, message: str, report: "ValidationReport | None" = None):
        self.path = Path(path)
        self.message = message
        self.report = report
        super().__init__(f"{self.path}: {message}")


@dataclass(frozen=True)
class LoaderCheck:
    """What one loader read from one file, in the object frame, and how far off it is.

    mass [kg]; com [m]; inertia [kg m^2] about the COM, object-frame axes;
    friction unitless (None where the format or loader does not carry it);
    placement position [m] and quaternion (x, y, z, w) of the body in world
    (None where not carried, e.g. URDF). `*_error` are relative errors (see
    the module docstring); `error` holds the load failure, if any.
    """

    loader: str
    format: str
    file: str
    ok: bool
    mass: float | None = None
    com: tuple[float, float, float] | None = None
    inertia: tuple[tuple[float, float, float], ...] | None = None
    friction: float | None = None
    position: tuple[float, float, float] | None = None
    quaternion_xyzw: tuple[float, float, float, float] | None = None
    mass_error: float | None = None
    com_error: float | None = None
    inertia_error: float | None = None
    friction_error: float | None = None
    placement_error: float | None = None
    max_error: float | None = None
    notes: tuple[str, ...] = ()
    error: str | None = None

    def to_json(self) -> dict[str, Any]:
        return _jsonable(asdict(self))


@dataclass(frozen=True)
class ValidationReport:
    """One `LoaderCheck` per loader and the overall verdict."""

    ok: bool
    tolerance: float
    object_size_m: float
    checks: tuple[LoaderCheck, ...]
    expected: dict = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """A JSON-serialisable dict (for asset.json provenance and the HTML report)."""
        return {
            "ok": self.ok,
            "tolerance": self.tolerance,
            "object_size_m": self.object_size_m,
            "expected": _jsonable(self.expected),
            "checks": [c.to_json() for c in self.checks],
        }

    def failures(self) -> tuple[LoaderCheck, ...]:
        return tuple(c for c in self.checks if not c.ok)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None  # NaN/inf are not JSON
    return x


@dataclass(frozen=True)
class _Reading:
    """Raw values a loader returned, object frame, SI."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    friction: float | None = None
    position: np.ndarray | None = None
    quaternion_xyzw: np.ndarray | None = None
    notes: tuple[str, ...] = ()


def _rotation_from_wxyz(q) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    w, x, y, z = (float(v) for v in q)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def _collision_mu(values: list[float], loader: str) -> float:
    """The one friction coefficient all collision shapes share."""
    if len(set(values)) != 1:
        raise ValueError(f"{loader} read different friction coefficients on the collision parts: {values}")
    return values[0]


# --- MJCF ---------------------------------------------------------------------------------------


def _read_mujoco(asset: Asset, path: Path) -> _Reading:
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    name = mjcf_name(asset.name)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    if body < 0:
        raise ValueError(f"no body named {name!r}")
    R = _rotation_from_wxyz(model.body_iquat[body])
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
    for _ in range(_MJ_STEPS):
        mujoco.mj_step(model, data)
    if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
        raise ValueError(f"state not finite after {_MJ_STEPS} steps")
    drop_m = z0 - float(data.xpos[body, 2])
    t_s = _MJ_STEPS * model.opt.timestep
    free_fall_m = 0.5 * float(np.linalg.norm(model.opt.gravity)) * t_s**2
    # Nothing to touch (no floor is written), so the body must fall freely under g = 9.81 m/s^2.
    if model.opt.gravity[2] >= 0 or not 0.9 < drop_m / free_fall_m < 1.1:
        raise ValueError(
            f"body fell {drop_m:.4g} m in {t_s:g} s, expected about {free_fall_m:.4g} m "
            f"(gravity {model.opt.gravity.tolist()})"
        )
    w, x, y, z = model.body_quat[body]
    return _Reading(
        mass=float(model.body_mass[body]),
        com=np.array(model.body_ipos[body], dtype=float),
        inertia=inertia,
        friction=mu,
        position=np.array(model.body_pos[body], dtype=float),
        quaternion_xyzw=np.array([x, y, z, w], dtype=float),
        notes=(f"stepped {_MJ_STEPS} steps ({t_s:g} s), fell {drop_m:.4g} m",)
        + ((f"{len(support)} support points on the bottom face carry the identified friction",) if support else ()),
    )


def _mujoco_free_body(model, asset: Asset, path: Path) -> tuple[int, int, int]:
    """(body id, qpos address, dof address) of the asset's body on its free joint."""
    import mujoco

    name = mjcf_name(asset.name)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    joint = model.body_jntadr[body] if body >= 0 else -1
    if body < 0 or model.body_jntnum[body] != 1 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"{path}: no body {name!r} on a free joint")
    return body, int(model.jnt_qposadr[joint]), int(model.jnt_dofadr[joint])


def _settle(model, data, body: int, seconds: float) -> float:
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


def _read_mujoco_scene(asset: Asset, path: Path) -> _Reading:
    """The object as scene.xml includes it, its support plane's friction and its rest on that plane."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    body, _, _ = _mujoco_free_body(model, asset, path)
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
    moved = _settle(model, mujoco.MjData(model), body, _REST_S)
    if moved > _REST_MOVE_M:
        raise ValueError(f"the object moved {1000 * moved:.3g} mm in {_REST_S:g} s at rest on its support plane "
                         f"(at most {1000 * _REST_MOVE_M:g} mm): the plane is not under it")
    R = _rotation_from_wxyz(model.body_iquat[body])
    w, x, y, z = model.body_quat[body]
    return _Reading(
        mass=float(model.body_mass[body]),
        com=np.array(model.body_ipos[body], dtype=float),
        inertia=R @ np.diag(model.body_inertia[body]) @ R.T,
        friction=mu,
        position=np.array(model.body_pos[body], dtype=float),
        quaternion_xyzw=np.array([x, y, z, w], dtype=float),
        notes=(f"rested {_REST_S:g} s on the support plane (top at z = {model.geom_pos[planes[0], 2]:.6g} m), "
               f"moved {1000 * moved:.3g} mm",),
    )


def _newton_reading(asset: Asset, builder, *, carries_friction: bool, carries_placement: bool,
                    support_points: int = 0) -> _Reading:
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
    return _Reading(
        mass=float(model.body_mass.numpy()[body]),
        com=model.body_com.numpy()[body].astype(float),
        inertia=model.body_inertia.numpy()[body].astype(float),
        friction=friction,
        position=position,
        quaternion_xyzw=quaternion,
        notes=tuple(notes),
    )


def _read_newton_mjcf(asset: Asset, path: Path) -> _Reading:
    import newton

    import xml.etree.ElementTree as ET

    builder = newton.ModelBuilder()
    builder.add_mjcf(str(path))
    support = sum(SUPPORT_POINT in g.get("name", "") for g in ET.parse(path).iter("geom"))
    return _newton_reading(asset, builder, carries_friction=True, carries_placement=True, support_points=support)


# --- URDF ---------------------------------------------------------------------------------------


def _read_yourdfpy(asset: Asset, path: Path) -> _Reading:
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
    return _Reading(
        mass=float(link.inertial.mass),
        com=origin[:3, 3].copy(),
        inertia=R @ np.asarray(link.inertial.inertia, dtype=float) @ R.T,
        notes=("friction not parsed by yourdfpy (<contact>/<gazebo> written)", "placement not carried by URDF"),
    )


def _read_newton_urdf(asset: Asset, path: Path) -> _Reading:
    import newton

    builder = newton.ModelBuilder()
    builder.add_urdf(str(path), floating=True)
    return _newton_reading(asset, builder, carries_friction=False, carries_placement=False)


# --- USD ----------------------------------------------------------------------------------------


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


def _read_usd_physics(asset: Asset, path: Path) -> _Reading:
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
    R = _rotation_from_wxyz((axes.GetReal(), *imaginary))
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
    return _Reading(
        mass=float(mass),
        com=np.array(com, dtype=float),
        inertia=inertia,
        friction=_collision_mu(mus, "UsdPhysics"),
        position=np.array(world.ExtractTranslation(), dtype=float),
        quaternion_xyzw=np.array([qi[0], qi[1], qi[2], q.GetReal()], dtype=float),
        notes=("inertia rebuilt from diagonalInertia and principalAxes (float32 by schema)", *cautions),
    )


def _read_newton_usd(asset: Asset, path: Path) -> _Reading:
    import newton

    builder = newton.ModelBuilder()
    builder.add_usd(str(path))
    return _newton_reading(asset, builder, carries_friction=True, carries_placement=True)


Reader = Callable[[Asset, Path], _Reading]

LOADERS: dict[str, tuple[tuple[str, Reader], ...]] = {
    "mjcf": (("mujoco", _read_mujoco), ("newton.add_mjcf", _read_newton_mjcf)),
    "urdf": (("yourdfpy", _read_yourdfpy), ("newton.add_urdf", _read_newton_urdf)),
    "usd": (("pxr.UsdPhysics", _read_usd_physics), ("newton.add_usd", _read_newton_usd)),
    "scene": (("mujoco", _read_mujoco_scene),),
}
"""Format key (as in asset.json → files) → (loader name, reader) pairs; "scene" is a pushed object's scene.xml."""


# --- comparison ---------------------------------------------------------------------------------


def _object_size_m(asset: Asset, out_dir: Path) -> float:
    """Bounding-box diagonal of the visual mesh [m]; gyration length if it cannot be read."""
    import trimesh

    try:
        mesh = trimesh.load(out_dir / asset.geometry.visual, force="mesh", process=False)
        size = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
        if math.isfinite(size) and size > 0:
            return size
    except Exception:  # fall back below; the loaders report unreadable meshes themselves
        pass
    inertial = asset.theta.inertial()
    return float(math.sqrt(np.trace(inertial.inertia_matrix()) / inertial.mass))


def _compare(asset: Asset, reading: _Reading, size_m: float) -> dict[str, float | None]:
    from scipy.spatial.transform import Rotation

    inertial = asset.theta.inertial()
    I0 = inertial.inertia_matrix()
    errors: dict[str, float | None] = {
        "mass_error": abs(reading.mass - inertial.mass) / inertial.mass,
        "com_error": float(np.linalg.norm(reading.com - np.array(inertial.com))) / max(size_m, _COM_FLOOR_M),
        "inertia_error": float(np.linalg.norm(reading.inertia - I0) / np.linalg.norm(I0)),
        "friction_error": None,
        "placement_error": None,
    }
    if reading.friction is not None:
        mu0 = float(asset.theta.friction.value)
        errors["friction_error"] = abs(reading.friction - mu0) / max(abs(mu0), 1e-9)
    if reading.position is not None and reading.quaternion_xyzw is not None:
        p0 = np.array(asset.placement.position)
        q0 = np.array(asset.placement.quaternion_xyzw)
        # atan2-based magnitude: acos(|q . q0|) loses half the digits near identity.
        angle = float((Rotation.from_quat(q0).inv() * Rotation.from_quat(reading.quaternion_xyzw)).magnitude())
        scale = max(float(np.linalg.norm(p0)), size_m)
        errors["placement_error"] = max(float(np.linalg.norm(reading.position - p0)) / scale, angle)
    return errors


def _check(asset: Asset, fmt: str, loader: str, reader: Reader, path: Path, size_m: float, tol: float) -> LoaderCheck:
    # Loaders warn (e.g. Newton on a missing mesh) and carry on; keep what they said with the check.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            reading = reader(asset, path)
        except Exception as exc:  # any loader failure is a finding, reported per loader
            said = "".join(f"; {w.category.__name__}: {w.message}" for w in caught)
            return LoaderCheck(
                loader=loader, format=fmt, file=str(path), ok=False, error=f"{type(exc).__name__}: {exc}{said}"
            )
    said = tuple(f"{w.category.__name__}: {w.message}" for w in caught)
    errors = _compare(asset, reading, size_m)
    finite = [e for e in errors.values() if e is not None]
    max_error = max(finite) if all(math.isfinite(e) for e in finite) else math.inf
    return LoaderCheck(
        loader=loader,
        format=fmt,
        file=str(path),
        ok=max_error <= tol,
        mass=reading.mass,
        com=tuple(float(v) for v in reading.com),
        inertia=tuple(tuple(float(v) for v in row) for row in reading.inertia),
        friction=reading.friction,
        position=None if reading.position is None else tuple(float(v) for v in reading.position),
        quaternion_xyzw=None if reading.quaternion_xyzw is None else tuple(float(v) for v in reading.quaternion_xyzw),
        max_error=max_error,
        notes=reading.notes + said,
        **errors,
    )


def _paths_from(paths: Any, out_dir: Path) -> dict[str, Path]:
    """{"mjcf"|"urdf"|"usd"|"scene": absolute path} from a mapping (asset.json files) or an object with attributes."""
    found: dict[str, Path] = {}
    for key in LOADERS:
        value = paths.get(key) if isinstance(paths, Mapping) else getattr(paths, key, None)
        if value is not None:
            p = Path(value)
            found[key] = p if p.is_absolute() else out_dir / p
    return found


def validate_exports(
    asset: Asset, out_dir: Path, paths: Any, *, tolerance: float = DEFAULT_TOLERANCE, strict: bool = True
) -> ValidationReport:
    """Reload the exported files with every loader and compare with `asset.theta`.

    Args:
        asset: the asset the files were written from.
        out_dir: the output directory (mesh paths and relative `paths` resolve here).
        paths: the written files: a mapping with keys "urdf", "mjcf", "usd" (as
            asset.json → files; other keys ignored) or an object with those
            attributes (e.g. `exporters.ExportPaths`); "scene" too where written. Formats
            left out are not checked.
        tolerance: largest accepted relative error (see the module docstring).
        strict: raise on failure (default); with False, return the failing report.

    Returns:
        The report; `report.ok` is True when every loader agrees within `tolerance`.

    Raises:
        ValidationError: a loader failed to read a file or disagreed; `.report`
            holds the full report.
    """
    out_dir = Path(out_dir)
    files = _paths_from(paths, out_dir)
    if not files:
        raise ValidationError(out_dir, f"no exported files to validate (expected keys {tuple(LOADERS)})")
    size_m = _object_size_m(asset, out_dir)
    checks = []
    for fmt, path in files.items():
        if not path.is_file():
            checks.append(LoaderCheck(loader="(file)", format=fmt, file=str(path), ok=False, error="file not found"))
            continue
        for loader, reader in LOADERS[fmt]:
            checks.append(_check(asset, fmt, loader, reader, path, size_m, tolerance))
    inertial = asset.theta.inertial()
    report = ValidationReport(
        ok=all(c.ok for c in checks),
        tolerance=tolerance,
        object_size_m=size_m,
        checks=tuple(checks),
        expected={
            "mass": inertial.mass,
            "com": inertial.com,
            "inertia": inertial.inertia,
            "friction": float(asset.theta.friction.value),
            "position": asset.placement.position,
            "quaternion_xyzw": asset.placement.quaternion_xyzw,
        },
    )
    if strict and not report.ok:
        bad = report.failures()
        lines = [
            f"{c.loader} ({c.format}): {c.error}" if c.error else f"{c.loader} ({c.format}): max relative error "
            f"{c.max_error:.3g} > {tolerance:g} ({_worst(c)})"
            for c in bad
        ]
        raise ValidationError(bad[0].file, "; ".join(lines), report)
    return report


def _worst(check: LoaderCheck) -> str:
    names = ("mass_error", "com_error", "inertia_error", "friction_error", "placement_error")
    values = {n: getattr(check, n) for n in names if getattr(check, n) is not None}
    name = max(values, key=lambda n: values[n])
    return f"{name.removesuffix('_error')} {values[name]:.3g}"



# --- jointed parts ------------------------------------------------------------------------------


def _read_mujoco_jointed(asset: Asset, path: Path) -> dict:
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    name = mjcf_name(asset.name)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint_name(name))
    if body < 0 or joint < 0:
        raise ValueError(f"no body {name!r} with joint {joint_name(name)!r}")
    R_iner = _rotation_from_wxyz(model.body_iquat[body])
    R_body = data.xmat[body].reshape(3, 3).copy()
    dof = model.jnt_dofadr[joint]
    kinds = {int(mujoco.mjtJoint.mjJNT_SLIDE): "prismatic", int(mujoco.mjtJoint.mjJNT_HINGE): "revolute"}
    reading = {
        "mass": float(model.body_mass[body]), "com": np.array(model.body_ipos[body]),
        "inertia": R_iner @ np.diag(model.body_inertia[body]) @ R_iner.T,
        "type": kinds.get(int(model.jnt_type[joint]), "other"), "axis": R_body @ model.jnt_axis[joint],
        "point": data.xanchor[joint].copy(),
        "lower": float(model.jnt_range[joint, 0]), "upper": float(model.jnt_range[joint, 1]),
        "damping": float(model.dof_damping[dof]), "friction": float(model.dof_frictionloss[dof]),
    }
    for _ in range(_MJ_STEPS):  # it must simulate
        mujoco.mj_step(model, data)
    if not np.all(np.isfinite(data.qpos)):
        raise ValueError(f"state not finite after {_MJ_STEPS} steps")
    return reading


def _read_newton_jointed(asset: Asset, path: Path, fmt: str) -> dict:
    import newton
    from scipy.spatial.transform import Rotation

    builder = newton.ModelBuilder()
    {"mjcf": builder.add_mjcf, "urdf": builder.add_urdf, "usd": builder.add_usd}[fmt](str(path))
    model = builder.finalize(device="cpu")
    # labels are paths ("model/worldbody/body", "robot/link", "/prim"); the names cannot hold a "/"
    labels = [str(label).split("/")[-1] for label in builder.body_label]
    name = {"mjcf": mjcf_name, "urdf": urdf_name, "usd": usd_prim_name}[fmt](asset.name)
    if name not in labels:
        raise ValueError(f"no body {name!r} among {labels}")
    body = labels.index(name)
    joint = int(np.flatnonzero(model.joint_child.numpy() == body)[0])
    dof = int(model.joint_qd_start.numpy()[joint])
    X_p = model.joint_X_p.numpy()[joint].astype(float)
    parent = int(model.joint_parent.numpy()[joint])
    X_parent = model.body_q.numpy()[parent].astype(float) if parent >= 0 else np.array([0, 0, 0, 0, 0, 0, 1.0])
    R_parent, R_p = Rotation.from_quat(X_parent[3:]), Rotation.from_quat(X_p[3:])
    kinds = {int(newton.JointType.PRISMATIC): "prismatic", int(newton.JointType.REVOLUTE): "revolute"}
    com = model.body_com.numpy()[body].astype(float)
    if fmt == "urdf":
        from exporters.urdf import urdf_link_offset

        com = com - urdf_link_offset(asset)
    return {
        "mass": float(model.body_mass.numpy()[body]), "com": com,
        "inertia": model.body_inertia.numpy()[body].astype(float),
        "type": kinds.get(int(model.joint_type.numpy()[joint]), "other"),
        "axis": (R_parent * R_p).apply(model.joint_axis.numpy()[dof].astype(float)),
        "point": X_parent[:3] + R_parent.apply(X_p[:3]),
        "lower": float(model.joint_limit_lower.numpy()[dof]), "upper": float(model.joint_limit_upper.numpy()[dof]),
        "damping": float(builder.joint_damping[dof]), "friction": float(builder.joint_friction[dof]),
    }


def _read_yourdfpy_jointed(asset: Asset, path: Path) -> dict:
    import yourdfpy

    from exporters.urdf import urdf_link_offset

    urdf = yourdfpy.URDF.load(str(path), build_collision_scene_graph=True, load_collision_meshes=True,
                              force_collision_mesh=False)
    if not urdf.validate():
        raise ValueError("yourdfpy's validate() rejected the file")
    name = urdf_name(asset.name)
    link, joint = urdf.link_map.get(name), urdf.joint_map.get(joint_name(name))
    if link is None or link.inertial is None or joint is None:
        raise ValueError(f"no link {name!r} with <inertial> on joint {joint_name(name)!r}")
    origin = np.asarray(link.inertial.origin, dtype=float)
    T = np.asarray(joint.origin, dtype=float)
    return {
        "mass": float(link.inertial.mass), "com": origin[:3, 3] - urdf_link_offset(asset),
        "inertia": origin[:3, :3] @ np.asarray(link.inertial.inertia, dtype=float) @ origin[:3, :3].T,
        "type": joint.type, "axis": T[:3, :3] @ np.asarray(joint.axis, dtype=float), "point": T[:3, 3],
        "lower": float(joint.limit.lower), "upper": float(joint.limit.upper),
        "damping": float(joint.dynamics.damping), "friction": float(joint.dynamics.friction),
    }


JOINTED_LOADERS = {
    "mjcf": (("mujoco", _read_mujoco_jointed), ("newton", lambda a, p: _read_newton_jointed(a, p, "mjcf"))),
    "urdf": (("yourdfpy", _read_yourdfpy_jointed), ("newton", lambda a, p: _read_newton_jointed(a, p, "urdf"))),
    "usd": (("newton", lambda a, p: _read_newton_jointed(a, p, "usd")),),
}
"""Loaders of a drawer's or door's files: each returns the part's body and its joint, world frame."""


def validate_jointed_exports(asset: Asset, out_dir: Path, paths: Any, *, tolerance: float = DEFAULT_TOLERANCE) -> dict:
    """Reload a jointed asset's MJCF, URDF and USD with MuJoCo, Newton and yourdfpy; compare body and joint.

    Body: mass, COM and inertia relative errors as for free bodies. Joint: the
    type, the axis direction [rad], the distance of the loader's joint point
    from `asset.joint`'s axis line [m] (relative to the part's size), the
    limits, damping and friction (relative). Returns {loader (format): readings
    and errors}; raises ValidationError naming the file on any failure.
    """
    out_dir = Path(out_dir)
    files = {k: v for k, v in _paths_from(paths, out_dir).items() if k in JOINTED_LOADERS}
    j = asset.joint
    inertial = asset.theta.inertial()
    size_m = _object_size_m(asset, out_dir)
    a, o = np.asarray(j.axis), np.asarray(j.origin)
    rel = lambda x, ref, scale=None: float(abs(x - ref) / (scale or max(abs(ref), 1e-12)))  # noqa: E731
    out = {}
    for fmt, path in files.items():
        for loader, reader in JOINTED_LOADERS[fmt]:
            try:
                r = reader(asset, path)
            except Exception as exc:  # every loader raises its own types
                raise ValidationError(path, f"{loader} could not load it: {exc}") from exc
            d = r["point"] - o
            errors = {
                "mass": rel(r["mass"], inertial.mass),
                "com": float(np.linalg.norm(r["com"] - inertial.com) / size_m),
                "inertia": float(np.linalg.norm(r["inertia"] - inertial.inertia_matrix())
                                 / np.linalg.norm(inertial.inertia_matrix())),
                "axis_rad": float(np.arccos(np.clip(r["axis"] @ a / np.linalg.norm(r["axis"]), -1, 1))),
                "axis_point": float(np.linalg.norm(d - a * (a @ d)) / size_m) if j.type == "revolute" else 0.0,
                "lower": rel(r["lower"], j.lower, max(j.upper - j.lower, 1e-12)),
                "upper": rel(r["upper"], j.upper, max(j.upper - j.lower, 1e-12)),
                "damping": rel(r["damping"], j.damping, max(abs(j.damping), 1e-9)),
                "friction": rel(r["friction"], float(asset.theta.friction.value)),
            }
            bad = {k: v for k, v in errors.items() if not v <= tolerance}
            if r["type"] != j.type or bad:
                raise ValidationError(path, f"{loader} read joint {r['type']!r} (expected {j.type!r}), "
                                            f"errors over {tolerance:g}: {bad}")
            out[f"{loader} ({fmt})"] = {"errors": errors, "type": r["type"], "friction": r["friction"],
                                        "damping": r["damping"], "limits": [r["lower"], r["upper"]]}
    return out


def replay_jointed_mujoco(mjcf_path: Path, asset: Asset, recording, joint_fit, config=None) -> dict:
    # joint_fit: the JointFit asset.joint was written from (same axis, so the same q)
    """Windowed replay of `recording` in MuJoCo from the exported MJCF: the measured joint effort as
    `qfrc_applied`, each window started from the measured state, the joint's friction and damping
    as MuJoCo models them (`frictionloss`, `damping`). RMSE of q and of the tracked frame's position."""
    import mujoco

    from pipelines.identify.jointed import JointedConfig, joint_windows, q_and_position_rmse

    config = config or JointedConfig()
    w = joint_windows(recording, joint_fit, config)
    model = mujoco.MjModel.from_xml_path(str(mjcf_path))
    model.opt.timestep = w.dt_s
    data = mujoco.MjData(model)
    joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint_name(mjcf_name(asset.name)))
    qpos, dof = model.jnt_qposadr[joint], model.jnt_dofadr[joint]
    S, W = w.q.shape[0] - 1, w.q.shape[1]
    q = np.zeros((S, W))
    for k in range(W):
        mujoco.mj_resetData(model, data)
        data.qpos[qpos], data.qvel[dof] = w.q_start[k], w.qd_start[k]
        for step in range(S * w.substeps):
            data.qfrc_applied[dof] = w.effort[step, k]
            mujoco.mj_step(model, data)
            if (step + 1) % w.substeps == 0:
                q[(step + 1) // w.substeps - 1, k] = data.qpos[qpos]
    return q_and_position_rmse(joint_fit, q, w.q[1:])


def replay_held_mujoco(mjcf_path: Path, asset: Asset, recording, X_tracked_body, window_s: float,
                       substeps: int = 4) -> dict:
    """The exported MJCF replaying a held body's recording in MuJoCo, on the windows the build scores Newton on.

    Each window starts from the measured pose and the velocity estimated from the poses (unsmoothed, as
    the build's own replay); at each step the measured force [N, world] acts on the body and the
    measured torque about the tracked origin is moved to the COM, where `xfrc_applied` acts. Returns the
    RMSE of the tracked frame's position [m] and rotation [rad]. X_tracked_body: the object frame in the
    tracked frame (`Pose`).
    """
    import mujoco
    from scipy.spatial.transform import Rotation

    from .identify.windows import make_windows

    pose, wrench = recording.pose, recording.wrench
    w = make_windows(pose.t_s, pose.position, pose.quat_xyzw, wrench.t_s, wrench.force, wrench.torque,
                     window_s=window_s, substeps=substeps)
    model = mujoco.MjModel.from_xml_path(str(mjcf_path))
    model.opt.timestep = w.dt_s
    data = mujoco.MjData(model)
    body, qadr, vadr = _mujoco_free_body(model, asset, mjcf_path)
    p_tb, R_tb = np.asarray(X_tracked_body.position), X_tracked_body.rotation_matrix()
    tracked_in_body = -R_tb.T @ p_tb
    position_error, rotation_error = [], []
    for k in range(w.window_count):
        mujoco.mj_resetData(model, data)
        R_t, p_t = Rotation.from_quat(w.measured_quat_xyzw[0, k]).as_matrix(), w.measured_position[0, k]
        R_b, p_b = R_t @ R_tb, p_t + R_t @ p_tb
        v_t, omega = w.start_twist[k, :3], w.start_twist[k, 3:]
        data.qpos[qadr:qadr + 3] = p_b
        data.qpos[qadr + 3:qadr + 7] = np.roll(Rotation.from_matrix(R_b).as_quat(), 1)  # MuJoCo: w x y z
        data.qvel[vadr:vadr + 3] = v_t + np.cross(omega, p_b - p_t)  # free joint: world linear velocity
        data.qvel[vadr + 3:vadr + 6] = R_b.T @ omega  # and body-axes angular velocity
        mujoco.mj_forward(model, data)
        for step in range(w.step_count):
            p_track = data.xpos[body] + data.xmat[body].reshape(3, 3) @ tracked_in_body
            force, torque = w.wrench[step, k, :3], w.wrench[step, k, 3:]
            data.xfrc_applied[body, :3] = force
            data.xfrc_applied[body, 3:] = torque + np.cross(p_track - data.xipos[body], force)
            mujoco.mj_step(model, data)
            if (step + 1) % w.substeps == 0:
                s = (step + 1) // w.substeps
                R = data.xmat[body].reshape(3, 3)
                position_error.append(data.xpos[body] + R @ tracked_in_body - w.measured_position[s, k])
                R_meas = Rotation.from_quat(w.measured_quat_xyzw[s, k]).as_matrix()
                rotation_error.append(Rotation.from_matrix((R @ R_tb.T).T @ R_meas).magnitude())
    e = np.asarray(position_error)
    return {"rmse_position_m": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
            "rmse_rotation_rad": float(np.sqrt(np.mean(np.square(rotation_error)))),
            "windows": int(w.window_count), "window_s": float(w.window_s)}


def replay_pushed_mujoco(scene_path: Path, asset: Asset, recording, window_s: float = 0.5, config=None) -> dict:
    """Windowed replay of a push in MuJoCo from the exported scene.xml (the object on its support plane).

    The windows are the identification's (`pipelines.identify.sliding.push_windows` with `config`, a
    `SlidingConfig`, at `window_s` [s] and the scene's time step): back to back where the pusher touches
    the object and it slides, the force offset of the sensor taken out as the build does
    (`estimate_force_bias`). Each starts from the measured planar state: the tracked frame's x, y and the
    heading of its x axis [rad] are the object frame's (the sliding model's convention), the height and
    tilt those the object settles to on the plane; the start velocity (vx, vy [m/s], yaw rate [rad/s]) is
    the slope of a quadratic through the poses around the start. At every step the measured horizontal
    pusher force [N, world] acts at the measured contact point, taken at the COM's height (the height a
    pusher meets the object at only tilts it, and planar recordings put it at z = 0), through
    `xfrc_applied` as that force at the COM plus its moment. The recorded force is what acted; a kinematic
    pusher would replay the pusher's path instead and need its shape and contact stiffness, which the
    recordings do not carry. Effects in `asset.effects` are not applied.

    Returns SI values: "rmse_position_m" and "rmse_heading_rad" over every pose sample of every window
    (as asset.json → fit), "rmse_final_position_m" and "rmse_final_heading_rad" over the windows' last
    samples, per window "t_start_s", "final_position_error_m" and "final_heading_error_rad", and
    "windows", "window_s", "timestep_s".
    """
    import mujoco
    import trimesh

    from pipelines.identify.sliding import PlanarBody

    scene_path = Path(scene_path)
    model = mujoco.MjModel.from_xml_path(str(scene_path))
    vertices = np.concatenate([trimesh.load(scene_path.parent / rel, force="mesh", process=False).vertices
                               for rel in asset.geometry.collision])
    inertial = asset.theta.inertial()
    planar = PlanarBody(tuple(0.5 * (vertices.max(axis=0) - vertices.min(axis=0))), inertial.mass,
                        float(inertial.inertia_matrix()[2, 2]))
    return replay_pushed_model(model, mjcf_name(asset.name), planar, recording, window_s, config, where=scene_path)


def replay_pushed_model(model, body_name: str, planar, recording, window_s: float = 0.5, config=None,
                        where: Path | str = "model") -> dict:
    """`replay_pushed_mujoco` on a compiled MuJoCo model whose body `body_name` sits on a free joint above a
    support plane: the exported scene, or the model that made a synthetic recording (its truth), so both
    replay the same windows the same way. planar: the `PlanarBody` the windows are cut for (its half
    extents set how near the pusher counts as touching); the model's own time step is the replay's."""
    from dataclasses import replace

    import mujoco
    from scipy.spatial.transform import Rotation

    from pipelines.identify.sliding import SlidingConfig, estimate_force_bias, push_windows

    data = mujoco.MjData(model)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
    joint = model.body_jntadr[body] if body >= 0 else -1
    if body < 0 or model.body_jntnum[body] != 1 or model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"{where}: no body {body_name!r} on a free joint")
    qadr, vadr = int(model.jnt_qposadr[joint]), int(model.jnt_dofadr[joint])
    _settle(model, data, body, _REST_S)
    rest_z = float(data.qpos[qadr + 2])
    R_rest = _rotation_from_wxyz(data.qpos[qadr + 3:qadr + 7])
    tilt = Rotation.from_euler("z", -math.atan2(R_rest[1, 0], R_rest[0, 0])).as_matrix() @ R_rest

    config = replace(config or SlidingConfig(), window_s=window_s, dt_s=float(model.opt.timestep))
    w = push_windows(recording, planar, config, estimate_force_bias(recording, config))
    model.opt.timestep = w.dt_s
    force, contact = w.window_force, w.contact
    S, W = w.sample_count, w.window_count
    simulated = np.zeros((S, W, 3))
    for k in range(W):
        x, y, yaw, vx, vy, yaw_rate = w.start[k]
        R = Rotation.from_euler("z", yaw).as_matrix() @ tilt
        mujoco.mj_resetData(model, data)
        data.qpos[qadr:qadr + 3] = (x, y, rest_z)
        data.qpos[qadr + 3:qadr + 7] = np.roll(Rotation.from_matrix(R).as_quat(), 1)  # MuJoCo: w x y z
        data.qvel[vadr:vadr + 3] = (vx, vy, 0.0)  # free joint: the body origin's velocity, world axes
        data.qvel[vadr + 3:vadr + 6] = R.T @ np.array([0.0, 0.0, yaw_rate])  # and body-axes angular velocity
        mujoco.mj_forward(model, data)
        for step in range(w.step_count):
            f = np.array([*force[step, k], 0.0])
            arm = np.array([*(contact[step, k] - data.xipos[body, :2]), 0.0])
            data.xfrc_applied[body] = np.r_[f, np.cross(arm, f)]
            mujoco.mj_step(model, data)
            if (step + 1) % w.substeps == 0:
                # qpos, not xpos: mj_step leaves the kinematics at the state before its integration
                x_axis = _rotation_from_wxyz(data.qpos[qadr + 3:qadr + 7])[:, 0]
                heading = math.atan2(x_axis[1], x_axis[0])
                simulated[(step + 1) // w.substeps - 1, k] = (*data.qpos[qadr:qadr + 2], heading)
    measured = w.measured[1:]
    position = np.linalg.norm(simulated[..., :2] - measured[..., :2], axis=-1)
    heading = np.angle(np.exp(1j * (simulated[..., 2] - measured[..., 2])))  # the short way round
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    return {"rmse_position_m": rms(position), "rmse_heading_rad": rms(heading),
            "rmse_final_position_m": rms(position[-1]), "rmse_final_heading_rad": rms(heading[-1]),
            "t_start_s": w.t_start_s.tolist(), "final_position_error_m": position[-1].tolist(),
            "final_heading_error_rad": np.abs(heading[-1]).tolist(),
            "windows": int(W), "window_s": float(w.span_s), "timestep_s": float(w.dt_s)}
