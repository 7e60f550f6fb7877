"""A complete sample with known truth: RGB-D scan, two recordings of a held object, truth.json."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from assets import Inertial, Pose

from .held import ConcealedEffect, HeldMotionConfig, SensorNoise, simulate_held
from .mujoco_engine import MujocoSettings, write_motion_recording
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


ENGINES = ("newton", "mujoco")


def _check_engine(engine: str, wrench_frame: str) -> None:
    from .mujoco_engine import WRENCH_FRAMES

    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {ENGINES}, got {engine!r}")
    if wrench_frame not in WRENCH_FRAMES:
        raise ValueError(f"wrench_frame: expected one of {WRENCH_FRAMES}, got {wrench_frame!r}")


def _engine_doc(engine: str, wrench_frame: str, mujoco: MujocoSettings) -> dict:
    doc = {"engine": engine, "wrench_frame": wrench_frame}
    if engine == "mujoco":
        doc["mujoco"] = asdict(mujoco)
    return doc


def make_held_sample(mesh, out_dir: Path, config: HeldSampleConfig = HeldSampleConfig(), *, engine: str = "newton",
                     wrench_frame: str = "gripper", mujoco: MujocoSettings = MujocoSettings()) -> Path:
    """Write out_dir/{scan/, trial.mcap, heldout.mcap, truth.json} for `mesh` (metres, any frame).

    The mesh is given uniform density for `mass_kg`, turned by the yaw and set on
    the table; the robot grasps it above its centroid, gripper pointing down.
    engine: "newton" (`simulate_held`) or "mujoco" (`simulate_held_mujoco` under `mujoco`);
    wrench_frame: "gripper" (the sensor's axes, turning with the tracked frame) or "world".
    """
    _check_engine(engine, wrench_frame)
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
        if engine == "mujoco":
            from .mujoco_engine import simulate_held_mujoco

            motion = simulate_held_mujoco(truth, placement, grasp, config.motion, rng, mujoco, effect=config.effect)
        else:
            motion = simulate_held(truth, placement, grasp, config.motion, rng, effect=config.effect)
        path = write_motion_recording(out_dir / f"{name}.mcap", motion, config.noise, rng, wrench_frame,
                                      effect=config.effect)
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
        "grasp_in_object": grasp.to_json(),
        "recordings": recordings,
        "effect": {"name": config.effect.name, "params": config.effect.params} if config.effect else None,
        **_engine_doc(engine, wrench_frame, mujoco),
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
    furniture: bool = False
    """Scan the part in its furniture, from the front, masks on the part only (`render_furniture_scan`, with
    `render`'s image, view count and noise) instead of alone on a table; the carcass is written as base.obj."""


def make_jointed_sample(out_dir: Path, config: JointedSampleConfig = JointedSampleConfig(), *,
                        engine: str = "newton", wrench_frame: str = "gripper",
                        mujoco: MujocoSettings = MujocoSettings()) -> Path:
    """Write out_dir/{scan/, part.obj, trial.mcap, heldout.mcap, truth.json} (and base.obj in furniture) for one
    of RigPI's jointed objects.

    engine, wrench_frame, mujoco: as for `make_held_sample` (`simulate_jointed` or `simulate_jointed_mujoco`)."""
    from .jointed import JointedMotionConfig, jointed_paper_objects, simulate_jointed

    _check_engine(engine, wrench_frame)

    objects = jointed_paper_objects()
    if config.object not in objects:
        raise ValueError(f"unknown jointed object {config.object!r}; choose one of {', '.join(objects)}")
    obj = objects[config.object]
    rng = np.random.default_rng(config.seed)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    mesh_world = obj.mesh()
    mesh_world.apply_translation(obj.position_m)
    if config.furniture:
        from .furniture import FurnitureConfig, furniture_carcass, render_furniture_scan

        render_furniture_scan(obj, out_dir / "scan", FurnitureConfig(render=config.render), rng)
        furniture_carcass(obj).export(out_dir / "base.obj")
    else:
        render_scan(mesh_world, out_dir / "scan", config.render, rng, name=obj.name, material_hint=None)
    mesh_world.export(out_dir / "part.obj")
    recordings = {}
    for name in ("trial", "heldout"):
        motion_config = JointedMotionConfig(duration_s=config.motion_duration_s)
        if engine == "mujoco":
            from .mujoco_engine import simulate_jointed_mujoco

            motion = simulate_jointed_mujoco(obj, motion_config, rng, mujoco, effect=config.effect)
        else:
            motion = simulate_jointed(obj, motion_config, rng, effect=config.effect)
        recordings[name] = write_motion_recording(out_dir / f"{name}.mcap", motion.held, config.noise, rng,
                                                  wrench_frame, joint=(f"{obj.name}_joint", motion)).name
    truth = obj.inertial()
    doc = {
        "name": obj.name, "kind": obj.joint_type,
        "frame": "object frame: origin at the part's COM at q = 0, world axes",
        "mass": obj.mass_kg, "com_world": list(obj.position_m), "inertia": truth.inertia_matrix().tolist(),
        "joint": {"type": obj.joint_type, "axis": list(obj.axis), "origin": list(obj.origin_m),
                  "friction": obj.friction, "travel": list(obj.travel)},
        "recordings": recordings,
        "effect": {"name": config.effect.name, "params": config.effect.params} if config.effect else None,
        **_engine_doc(engine, wrench_frame, mujoco),
        "config": _jsonable(asdict(config)),
    }
    (out_dir / "truth.json").write_text(json.dumps(doc, indent=2) + "\n")
    return out_dir
