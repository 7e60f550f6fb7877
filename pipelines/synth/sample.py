"""A complete sample with known truth: RGB-D scan, two recordings of a held object, truth.json."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from assets import Inertial, Pose

from ..logs import PoseTrack, WrenchTrack
from .held import ConcealedEffect, HeldMotionConfig, SensorNoise, measure, simulate_held
from .recording import write_recording
from .render import RenderConfig, render_scan


@dataclass(frozen=True)
class HeldSampleConfig:
    """What `twin synth` makes: an object at a placement, held by the grasp and moved twice."""

    name: str = "cube"
    material: str = "pla_printed"
    mass_kg: float = 0.02
    placement_xyz_m: tuple[float, float, float] = (0.5, 0.0, 0.0)
    """Where the mesh's footprint centre rests on the table (table top at this z) [m]."""
    placement_yaw_rad: float = 0.35
    grasp_height_fraction: float = 1.0
    """Grasp on the top face (1.0) or lower, as a fraction of the half height above the centroid."""
    motion: HeldMotionConfig = field(default_factory=HeldMotionConfig)
    noise: SensorNoise = field(default_factory=SensorNoise)
    render: RenderConfig = field(default_factory=RenderConfig)
    seed: int = 0
    effect: ConcealedEffect | None = None
    """Physics hidden in both recordings; recorded in truth.json."""


def make_held_sample(mesh, out_dir: Path, config: HeldSampleConfig = HeldSampleConfig()) -> Path:
    """Write out_dir/{scan/, trial.mcap, heldout.mcap, truth.json} for `mesh` (metres, any frame).

    The mesh is given uniform density for `mass_kg`, turned by the yaw and set on
    the table; the robot grasps it above its centroid, gripper pointing down.
    """
    import trimesh
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(config.seed)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    mesh = mesh.copy()
    mesh.apply_translation(-mesh.center_mass)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", config.placement_yaw_rad).as_matrix()
    mesh.apply_transform(T)
    lowest = mesh.bounds[0, 2]
    mesh.apply_translation(np.asarray(config.placement_xyz_m) - [0.0, 0.0, lowest])
    mesh_world: trimesh.Trimesh = mesh
    render_scan(mesh_world, out_dir / "scan", config.render, rng, name=config.name, material_hint=config.material)
    mesh_world.export(out_dir / "truth_mesh.obj")

    # Truth in world axes at the placement: the object frame the tool chooses is its own.
    density = config.mass_kg / mesh_world.volume
    mesh_world.density = density
    com_world = np.asarray(mesh_world.center_mass)
    inertia_world = np.asarray(mesh_world.moment_inertia)
    placement = Pose(tuple(com_world), (0.0, 0.0, 0.0, 1.0))
    com_shift = config.effect.params["com_shift"] if config.effect and config.effect.name == "nonuniform_density" \
        else (0.0, 0.0, 0.0)
    truth = Inertial(config.mass_kg, tuple(com_shift), inertia_world)
    top = mesh_world.bounds[1, 2] - com_world[2]
    grasp = Pose((0.0, 0.0, config.grasp_height_fraction * top), (1.0, 0.0, 0.0, 0.0))

    recordings = {}
    for name in ("trial", "heldout"):
        motion = simulate_held(truth, placement, grasp, config.motion, rng, effect=config.effect)
        t_pose, position, quat, t_wrench, force, torque = measure(motion, config.noise, rng, effect=config.effect)
        path = out_dir / f"{name}.mcap"
        write_recording(
            path,
            pose=PoseTrack(t_pose, position, quat, "world", "gripper", "/tracker/pose"),
            wrench=WrenchTrack(t_wrench, force, torque, "/ft_sensor/wrench", "gripper"),
        )
        recordings[name] = path.name

    doc = {
        "name": config.name,
        "kind": "free",
        "frame": "world axes at the scanned placement; COM in world",
        "mass": config.mass_kg,
        "com_world": com_world.tolist(),
        "inertia_world": inertia_world.tolist(),
        "principal_moments": np.linalg.eigvalsh(inertia_world).tolist(),
        "volume_m3": float(mesh_world.volume),
        "density_kg_m3": density,
        "grasp_in_object": {"position": list(grasp.position), "quaternion_xyzw": list(grasp.quaternion_xyzw)},
        "recordings": recordings,
        "effect": {"name": config.effect.name, "params": config.effect.params} if config.effect else None,
        "config": _jsonable(asdict(config)),
    }
    (out_dir / "truth.json").write_text(json.dumps(doc, indent=2) + "\n")
    return out_dir


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


@dataclass(frozen=True)
class JointedSampleConfig:
    """What `twin synth --object drawer|cabinet_door|oven_door` makes: the part scanned at q = 0, worked twice."""

    object: str = "drawer"
    motion_duration_s: float = 8.0
    noise: SensorNoise = field(default_factory=SensorNoise)
    render: RenderConfig = field(default_factory=RenderConfig)
    seed: int = 0
    effect: ConcealedEffect | None = None
    """A passive joint force (viscous_damping, spring, stribeck_friction) hidden in both recordings;
    recorded in truth.json."""


def make_jointed_sample(out_dir: Path, config: JointedSampleConfig = JointedSampleConfig()) -> Path:
    """Write out_dir/{scan/, part.obj, trial.mcap, heldout.mcap, truth.json} for one of RigPI's jointed objects."""
    from .jointed import JointedMotionConfig, jointed_paper_objects, simulate_jointed, write_jointed_recording

    objects = jointed_paper_objects()
    if config.object not in objects:
        raise ValueError(f"unknown jointed object {config.object!r}; choose one of {', '.join(objects)}")
    obj = objects[config.object]
    rng = np.random.default_rng(config.seed)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh_world = obj.mesh()
    mesh_world.apply_translation(obj.position_m)
    render_scan(mesh_world, out_dir / "scan", config.render, rng, name=obj.name, material_hint=None)
    mesh_world.export(out_dir / "part.obj")
    recordings = {}
    for name in ("trial", "heldout"):
        motion = simulate_jointed(obj, JointedMotionConfig(duration_s=config.motion_duration_s), rng,
                                  effect=config.effect)
        recordings[name] = write_jointed_recording(out_dir / f"{name}.mcap", obj, motion, config.noise, rng).name
    truth = obj.inertial()
    doc = {
        "name": obj.name, "kind": obj.joint_type,
        "frame": "object frame: origin at the part's COM at q = 0, world axes",
        "mass": obj.mass_kg, "com_world": list(obj.position_m), "inertia": truth.inertia_matrix().tolist(),
        "joint": {"type": obj.joint_type, "axis": list(obj.axis), "origin": list(obj.origin_m),
                  "friction": obj.friction, "travel": list(obj.travel)},
        "recordings": recordings,
        "effect": {"name": config.effect.name, "params": config.effect.params} if config.effect else None,
        "config": _jsonable(asdict(config)),
    }
    (out_dir / "truth.json").write_text(json.dumps(doc, indent=2) + "\n")
    return out_dir
