"""The cases of `twin bench diagnose`: which effect is concealed, how large, and the recordings made of it.

Each case is a held cube or sphere moved by the simulated robot, RigPI's drawer, cabinet door or oven door
worked on its joint, or (MuJoCo) a block pushed across a table, with one effect of a random magnitude hidden
in the trial and held-out recordings alike, or none. The recordings are made by twin's own Newton code
(`simulate_held`, `simulate_jointed`; the cases of `make_cases`, unchanged) or by MuJoCo
(`simulate_held_mujoco`, `simulate_jointed_mujoco`, `write_pushed_mujoco`; `make_mujoco_cases`), a
different robot, integrator and joint friction, so that the diagnosis is not judged only on data made by
the model it fits. MuJoCo cases alternate the wrench message's frame: the world's axes, or the moving
sensor's (a pushed block's: the pusher's fixed sensor frame).

The magnitude is drawn log-uniformly as a multiple ("ratio") of the sensor's noise, from about it to large
(`RATIO_RANGE`, `MUJOCO_RATIO_RANGE`): per-sample force or torque for bias, damping and drag; 2 ms per unit for delay; a millimetre per unit
for the COM shift. On a joint the unit is the per-sample joint effort noise sigma (the force noise, times
the handle's lever on a hinge): damping b = ratio sigma / v, v = 0.8 travel/s a typical joint speed; spring
k = ratio sigma / (travel / 4) about a rest position inside the travel; Stribeck excess f_s - f_c = 5 ratio
sigma (it acts only near reversals), v_s 5-20 % of v. Outside the vocabulary (MuJoCo, `OOV_EFFECTS`): a
friction that rises by 10 ratio sigma over a stretch of 20-30 % of the travel (`binding_friction`) or while
the part moves one way (`directional_friction`); the right answer is an `unexplained` entry whose state
range overlaps the true one. Pushes: damping b = ratio x the force noise / 0.15 m/s, delay 2 ms x ratio.
The diagnosis is told nothing of it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pipelines.synth.effects import EFFECTS, JOINT_EFFECTS, concealed_effect, concealed_joint_effect, joint_effort_noise

FREE_OBJECTS = ("cube", "sphere")
JOINT_OBJECTS = ("drawer", "cabinet_door", "oven_door")
JOINT_DURATION_S = 8.0
"""Length of each jointed recording [s]: after the 0.4 s hold and the 1 s fade-in, 6.6 s of motion in the
0.3-1.2 Hz band, a few open/close cycles as a user would record them. In 4 s recordings (2.6 s of motion,
one or two cycles) a spring or damping below about ratio 5 trades against the Coulomb friction and the
mass: four of twelve came back 22-40 % off."""
RATIO_RANGE = (0.5, 8.0)
"""Effect size as a multiple of the per-sample sensor noise (see `concealed_effect`)."""
MUJOCO_RATIO_RANGE = (1.0, 8.0)
"""The MuJoCo list's sizes: from the noise itself up, as the diagnosis's specification asks ("from barely above
the noise to large"). Below it (0.5-0.85 x on a joint) even the model that made the recording replays the
held-out one no better than the body without the effect, so no choice could be judged right or wrong."""


@dataclass(frozen=True)
class Case:
    """One recording pair: object (a FREE_OBJECTS shape, a JOINT_OBJECTS part or a pushed "block"), concealed
    effect (None: clean), its size ratio and seed."""

    shape: str
    effect: object
    ratio: float
    seed: int
    engine: str = "newton"
    """The simulator that makes the recordings (ENGINES)."""
    wrench_frame: str = "gripper"
    """The wrench message's frame: "world", or the moving sensor's ("gripper"; a push's "sensor")."""


def make_cases(concealed: int, clean: int, seed: int) -> list[Case]:
    """`concealed` cases cycling through every effect on free and jointed objects, `clean` without
    (alternately free and jointed), shuffled."""
    from pipelines.synth.held import SensorNoise
    from pipelines.synth.jointed import jointed_paper_objects

    parts = jointed_paper_objects()
    kinds = [(name, False) for name in EFFECTS] + [(name, True) for name in JOINT_EFFECTS]
    rng = np.random.default_rng(seed)
    cases = []
    for k in range(concealed):
        name, jointed = kinds[k % len(kinds)]
        lo, hi = (1.5, 10.0) if name == "nonuniform_density" else RATIO_RANGE
        ratio = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        if jointed:
            part = JOINT_OBJECTS[(k // len(kinds)) % len(JOINT_OBJECTS)]
            effect = concealed_joint_effect(name, ratio, rng, parts[part], SensorNoise())
        else:
            part = FREE_OBJECTS[(k // len(kinds)) % len(FREE_OBJECTS)]
            effect = concealed_effect(name, ratio, rng, SensorNoise())
        cases.append(Case(part, effect, ratio, int(rng.integers(1 << 30))))
    cases += [Case((FREE_OBJECTS[(k // 2) % 2] if k % 2 == 0 else JOINT_OBJECTS[(k // 2) % 3]), None, 0.0,
                   int(rng.integers(1 << 30))) for k in range(clean)]
    rng.shuffle(cases)
    return cases


def free_case_mesh(case: Case):
    """(mass [kg], mesh at that density) of a free case: a 4 cm, 20 g cube or a 5 cm, 50 g sphere."""
    import trimesh

    mass, mesh = ((0.02, trimesh.creation.box((0.04,) * 3)) if case.shape == "cube"
                  else (0.05, trimesh.creation.icosphere(subdivisions=3, radius=0.025)))
    mesh.density = mass / mesh.volume
    return mass, mesh


def free_case_body(case: Case):
    """(uniform-density prior, true body, placement, grasp) of a free case (`free_case_mesh`) held at its top,
    its COM shifted by a concealed `nonuniform_density`."""
    from assets import Inertial, Pose

    mass, mesh = free_case_mesh(case)
    uniform = Inertial(mass, (0.0, 0.0, 0.0), np.asarray(mesh.moment_inertia))
    truth = uniform
    if case.effect is not None and case.effect.name == "nonuniform_density":
        truth = replace(uniform, com=tuple(case.effect.params["com_shift"]))
    placement = Pose((0.5, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0))
    return uniform, truth, placement, Pose((0.0, 0.0, float(mesh.bounds[1, 2])), (1.0, 0.0, 0.0, 0.0))


def record_case(case: Case, directory: Path, duration_s: float):
    """Simulate the case's trial and held-out recordings into `directory`; returns (trial, holdout, prior,
    X_tracked_body) as `diagnose_held` takes them."""
    from assets.recording import PoseTrack, WrenchTrack
    from pipelines.logs import read_recording
    from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held
    from pipelines.synth.recording import write_recording

    rng = np.random.default_rng(case.seed)
    effect = case.effect
    uniform, truth, placement, grasp = free_case_body(case)
    motion_config = HeldMotionConfig(duration_s=duration_s, substeps=4)
    out = []
    for name in ("trial", "heldout"):
        motion = simulate_held(truth, placement, grasp, motion_config, rng, effect=effect)
        t_pose, position, quat, t_wrench, force, torque = measure(motion, SensorNoise(), rng, effect=effect)
        path = directory / f"{name}.mcap"
        write_recording(path, pose=PoseTrack(t_pose, position, quat, "world", "gripper", "/tracker/pose"),
                        wrench=WrenchTrack(t_wrench, force, torque, "/ft_sensor/wrench", "gripper"))
        out.append(read_recording(path))
    return out[0], out[1], uniform, grasp.inverse()


def record_joint_case(case: Case, directory: Path, duration_s: float = JOINT_DURATION_S):
    """Simulate the jointed case's trial and held-out recordings into `directory`; returns (trial, holdout,
    joint, placement, prior) as `diagnose_jointed` takes them (the joint as `detect_kind` finds it)."""
    from assets.materials import material_range
    from pipelines.identify.kind import detect_kind
    from pipelines.logs import read_recording
    from pipelines.priors import uniform_density_prior
    from pipelines.synth.held import SensorNoise
    from pipelines.synth.jointed import (
        JointedMotionConfig, jointed_paper_objects, simulate_jointed, write_jointed_recording,
    )

    obj = jointed_paper_objects()[case.shape]
    rng = np.random.default_rng(case.seed)
    out = []
    for name in ("trial", "heldout"):
        motion = simulate_jointed(obj, JointedMotionConfig(duration_s=duration_s), rng, effect=case.effect)
        out.append(read_recording(write_jointed_recording(directory / f"{name}.mcap", obj, motion, SensorNoise(),
                                                          rng)))
    joint = detect_kind(out[0]).joint
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    return out[0], out[1], joint, obj.placement(), prior


def true_model_fit(case: Case, holdout, X_tracked_body, prior, window_s: float):
    """Held-out replay of the model that made a free case's recordings (the true body and the concealed effect),
    scored as the diagnosis scores its own models (`replay_held`, same windows and smoothing): the error no
    model of these recordings is expected to beat, and what a found effect can at best reduce the base
    model's error to."""
    from pipelines.diagnose import replay_held
    from pipelines.diagnose.effects import bias_in_tracked_axes, effect_vector, remove_bias

    effect, truth, coefficients, delay_s = case.effect, prior, {}, 0.0
    if effect is not None:
        params = effect.params
        if effect.name == "nonuniform_density":
            truth = replace(prior, com=tuple(params["com_shift"]))
        elif effect.name == "time_delay":
            delay_s = params["seconds"]
        elif effect.name == "sensor_bias" and not bias_in_tracked_axes(holdout):  # constant in world axes
            holdout = remove_bias(holdout, params["force"], params["torque"])
        elif effect.name == "sensor_bias":
            coefficients = {"sensor_bias": np.concatenate([params["force"], params["torque"]])}
        elif effect.name == "viscous_damping":
            coefficients = {"viscous_damping": np.array([params["b"], params.get("b_angular", 0.0)])}
        elif effect.name == "quadratic_drag":
            coefficients = {"quadratic_drag": np.array([params["c"]])}
    return replay_held(holdout, X_tracked_body, truth, effect_vector(coefficients), delay_s, window_s)[0]


def true_joint_model_fit(case: Case, holdout, joint, placement, window_s: float):
    """`true_model_fit` for a jointed case: the part's true body and friction (the joint body's prior values with
    the truth as its prior) and its concealed passive force, on the joint `detect_kind` found, replayed as
    `diagnose_jointed` replays."""
    from pipelines.diagnose import replay_fit
    from pipelines.identify.jointed import JointedConfig, joint_body, replay_jointed
    from pipelines.synth.jointed import jointed_paper_objects

    obj = jointed_paper_objects()[case.shape]
    truth, effect = obj.inertial(), case.effect
    config = JointedConfig(window_s=window_s)
    body = joint_body(joint, placement, truth, config, (effect.name,) if effect is not None else ())
    values = body.prior_values(obj.friction)
    if effect is not None:
        p = effect.params
        sign = float(np.sign(joint.axis @ np.asarray(obj.axis)))  # q found along the true axis or against it
        values[body.base_count:-1] = ([p["b"]] if effect.name == "viscous_damping" else  # JOINT_EFFECT_PARAMS' order
                                    [p["k"], sign * p["k"] * p["q0"]] if effect.name == "spring" else
                                    [p["f_s"] - p["f_c"], p["v_s"]])
    _, q_sim, windows = replay_jointed(holdout, joint, placement, truth, body, values, config)
    return replay_fit(joint, q_sim, windows)




OOV_EFFECTS = ("binding_friction", "directional_friction")
"""Joint frictions outside the vocabulary (`JointFrictionProfile`), MuJoCo cases only."""
PUSH_EFFECTS = ("viscous_damping", "time_delay")
"""Concealed in the MuJoCo pushes."""
PUSH_SPEED_M_S = 0.15
PUSH_FORCE_NOISE_N = 0.05
ENGINES = ("newton", "mujoco")


def oov_joint_effect(name: str, ratio: float, rng: np.random.Generator, obj, noise):
    """A JointFrictionProfile of `name` on `obj` whose extra friction is 10 `ratio` times its effort noise:
    over a stretch of 20-30 % of the travel (binding), or while the part moves one way (directional)."""
    from pipelines.synth.mujoco_engine import JointFrictionProfile

    extra = 10 * ratio * joint_effort_noise(obj, noise)
    lo, hi = obj.travel
    if name == "binding_friction":
        width = (hi - lo) * float(rng.uniform(0.2, 0.3))
        a = float(rng.uniform(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo) - width))
        return JointFrictionProfile(name, {"q_range": [a, a + width], "extra": extra})
    if name == "directional_friction":
        return JointFrictionProfile(name, {"sign": float(rng.choice([-1.0, 1.0])), "extra": extra})
    raise ValueError(f"{name}: not an out-of-vocabulary joint effect ({', '.join(OOV_EFFECTS)})")


def push_effect(name: str, ratio: float, rng: np.random.Generator):
    """A concealed push effect as `PushConfig` fields (see module docstring)."""
    from pipelines.synth.held import ConcealedEffect

    if name == "viscous_damping":
        return ConcealedEffect(name, {"b": ratio * PUSH_FORCE_NOISE_N / PUSH_SPEED_M_S})
    if name == "time_delay":
        return ConcealedEffect(name, {"seconds": float(rng.choice([-1, 1]) * ratio * 2e-3)})
    raise ValueError(f"{name}: not a push effect ({', '.join(PUSH_EFFECTS)})")


def make_mujoco_cases(concealed: int, clean: int, seed: int) -> list[Case]:
    """`concealed` MuJoCo cases cycling through every effect on free, jointed and pushed objects and the
    out-of-vocabulary joint frictions, `clean` without (free, jointed and pushed in turn), shuffled; each
    kind's cases alternate the wrench message's frame (world, then the sensor's)."""
    from pipelines.synth.held import SensorNoise
    from pipelines.synth.jointed import jointed_paper_objects

    parts = jointed_paper_objects()
    kinds = ([(name, "free") for name in EFFECTS] + [(name, "joint") for name in JOINT_EFFECTS]
             + [(name, "oov") for name in OOV_EFFECTS] + [(name, "push") for name in PUSH_EFFECTS])
    rng = np.random.default_rng(seed + 1_000_003)  # a stream of its own: the Newton cases stay as they were
    cases = []
    for k in range(concealed):
        name, where = kinds[k % len(kinds)]
        turn = k // len(kinds)
        lo, hi = (1.5, 10.0) if name == "nonuniform_density" else MUJOCO_RATIO_RANGE
        ratio = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        frame = ("world", "sensor" if where == "push" else "gripper")[turn % 2]
        if where in ("joint", "oov"):
            part = ("drawer", "cabinet_door")[turn % 2] if where == "oov" else JOINT_OBJECTS[turn % 3]
            make = concealed_joint_effect if where == "joint" else oov_joint_effect
            effect = make(name, ratio, rng, parts[part], SensorNoise())
        elif where == "push":
            part, effect = "block", push_effect(name, ratio, rng)
        else:
            part, effect = FREE_OBJECTS[turn % 2], concealed_effect(name, ratio, rng, SensorNoise())
        cases.append(Case(part, effect, ratio, int(rng.integers(1 << 30)), "mujoco", frame))
    shapes = [FREE_OBJECTS[0], JOINT_OBJECTS[0], FREE_OBJECTS[1], JOINT_OBJECTS[1], "block", JOINT_OBJECTS[2]]
    cases += [Case(shapes[k % len(shapes)], None, 0.0, int(rng.integers(1 << 30)), "mujoco",
                   ("world", "sensor" if shapes[k % len(shapes)] == "block" else "gripper")[(k // len(shapes)) % 2])
              for k in range(clean)]
    rng.shuffle(cases)
    return cases


def record_mujoco_case(case: Case, directory: Path, duration_s: float):
    """`record_case` with MuJoCo's robot (`simulate_held_mujoco`), the wrench in `case.wrench_frame`."""
    from pipelines.logs import read_recording
    from pipelines.synth.held import HeldMotionConfig, SensorNoise
    from pipelines.synth.mujoco_engine import simulate_held_mujoco, write_motion_recording

    rng = np.random.default_rng(case.seed)
    effect = case.effect
    uniform, truth, placement, grasp = free_case_body(case)
    body_effect = effect if effect is not None and effect.name in ("viscous_damping", "quadratic_drag") else None
    out = []
    for name in ("trial", "heldout"):
        motion = simulate_held_mujoco(truth, placement, grasp, HeldMotionConfig(duration_s=duration_s), rng,
                                      effect=body_effect)
        path = write_motion_recording(directory / f"{name}.mcap", motion, SensorNoise(), rng, case.wrench_frame,
                                      effect=effect)
        out.append(read_recording(path))
    return out[0], out[1], uniform, grasp.inverse()


def record_mujoco_joint_case(case: Case, directory: Path, duration_s: float = JOINT_DURATION_S):
    """`record_joint_case` with MuJoCo's hand, joint and friction (`simulate_jointed_mujoco`)."""
    from assets.materials import material_range
    from pipelines.identify.kind import detect_kind
    from pipelines.logs import read_recording
    from pipelines.priors import uniform_density_prior
    from pipelines.synth.held import SensorNoise
    from pipelines.synth.jointed import JointedMotionConfig, jointed_paper_objects
    from pipelines.synth.mujoco_engine import simulate_jointed_mujoco, write_motion_recording

    obj = jointed_paper_objects()[case.shape]
    rng = np.random.default_rng(case.seed)
    out = []
    for name in ("trial", "heldout"):
        motion = simulate_jointed_mujoco(obj, JointedMotionConfig(duration_s=duration_s), rng, effect=case.effect)
        out.append(read_recording(write_motion_recording(directory / f"{name}.mcap", motion.held, SensorNoise(),
                                                         rng, case.wrench_frame,
                                                         joint=(f"{obj.name}_joint", motion))))
    joint = detect_kind(out[0]).joint
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    return out[0], out[1], joint, obj.placement(), prior


PUSH_HALF_M = (0.05, 0.05, 0.005)
PUSH_MASS_KG = 0.75


def record_push_case(case: Case, directory: Path):
    """A MuJoCo push (`write_pushed_mujoco`: its box on a plane, a servoed pusher) and a held-out one from the
    other side of the centre line; returns (trial, holdout, PlanarBody prior, mu prior)."""
    from pipelines.identify.sliding import PlanarBody
    from pipelines.logs import read_recording
    from pipelines.synth.mujoco_push import write_pushed_mujoco
    from pipelines.synth.push import PushConfig
    from benchmarks.push import box_izz

    rng = np.random.default_rng(case.seed)
    concealed = {}
    if case.effect is not None:
        concealed = ({"damping_n_s_m": case.effect.params["b"]} if case.effect.name == "viscous_damping" else
                     {"delay_s": case.effect.params["seconds"]})
    out = []
    for k, side in enumerate((1.0, -1.0)):
        path = directory / f"push_{k}.mcap"
        write_pushed_mujoco(path, PushConfig(half_extents_m=PUSH_HALF_M, mass_kg=PUSH_MASS_KG, mu=0.3,
                                             offset_m=side * float(rng.uniform(0.01, 0.02)),
                                             seed=int(rng.integers(1 << 30)), **concealed),
                            wrench_frame=case.wrench_frame)
        out.append(read_recording(path))
    return out[0], out[1], PlanarBody(PUSH_HALF_M, PUSH_MASS_KG, box_izz(PUSH_MASS_KG, PUSH_HALF_M)), 0.5


def true_push_replays(case: Case, holdout, body, window_s: float) -> dict:
    """The held-out push replayed in MuJoCo by the model that made it (`pushed_block_xml` without its
    pusher, driven by the recorded force), with the concealed effect as a pushed asset carries it
    (`pushed_effects`) and without: position RMSE [m] of each, and whether the effect replays it better: the
    free and jointed rows' test of whether the held-out recording tells the effect (there the base fit is the
    reference; a push's base fit is Newton's sliding model, another simulator than the truth)."""
    import mujoco

    from assets import Effect
    from pipelines.synth.mujoco_push import PushContact, pushed_block_xml, push_settings
    from pipelines.synth.push import PushConfig
    from pipelines.validate import pushed_effects, replay_pushed_model

    config = PushConfig(half_extents_m=PUSH_HALF_M, mass_kg=PUSH_MASS_KG, mu=0.3)
    concealed = () if case.effect is None else (
        Effect("viscous_damping", {"b": case.effect.params["b"], "b_angular": 0.0}, {})
        if case.effect.name == "viscous_damping" else Effect("time_delay", dict(case.effect.params), {}),)
    model = mujoco.MjModel.from_xml_string(pushed_block_xml(config, push_settings(), PushContact(), pusher=False))
    out = {label: replay_pushed_model(model, "block", body, holdout, window_s, effects=effects)
           for label, effects in (("with", pushed_effects(concealed)), ("without", None))}
    with_m, without_m = out["with"]["rmse_position_m"], out["without"]["rmse_position_m"]
    return {"with_m": with_m, "without_m": without_m, "tells": bool(concealed) and with_m < without_m}


def case_kind(case: Case) -> str:
    """"free", "joint" or "push"."""
    return "joint" if case.shape in JOINT_OBJECTS else "push" if case.shape == "block" else "free"


def true_body(case: Case):
    """The body that made the recordings (object frame), as the diagnosis reports its own."""
    from pipelines.synth.jointed import jointed_paper_objects

    if case_kind(case) == "joint":
        return jointed_paper_objects()[case.shape].inertial()
    import trimesh

    from assets import Inertial

    mass, mesh = ((0.02, trimesh.creation.box((0.04,) * 3)) if case.shape == "cube"
                  else (0.05, trimesh.creation.icosphere(subdivisions=3, radius=0.025)))
    mesh.density = mass / mesh.volume
    com = (0.0, 0.0, 0.0)
    if case.effect is not None and case.effect.name == "nonuniform_density":
        com = tuple(case.effect.params["com_shift"])
    return Inertial(mass, com, np.asarray(mesh.moment_inertia))


def determined_quantity(case: Case, inertial) -> float:
    """What a joint's motion determines of the part's body: a drawer's mass [kg], a door's moment about its
    hinge [kg m^2] (through the true axis; object frame at the part's COM at q = 0, world axes)."""
    from pipelines.synth.jointed import jointed_paper_objects

    obj = jointed_paper_objects()[case.shape]
    if obj.joint_type == "prismatic":
        return float(inertial.mass)
    a = np.asarray(obj.axis, dtype=float)
    d = np.asarray(inertial.com) - (np.asarray(obj.origin_m) - np.asarray(obj.position_m))
    d = d - a * (a @ d)
    return float(a @ inertial.inertia_matrix() @ a + inertial.mass * d @ d)


def true_state_range(case: Case, joint) -> dict | None:
    """Where an out-of-vocabulary joint friction acts, in the found joint's coordinate (its axis may point
    against the true one): {"q": [a, b]} or {"qd": [a, b]}; None for any other case."""
    from pipelines.synth.jointed import jointed_paper_objects

    if case.effect is None or case.effect.name not in OOV_EFFECTS:
        return None
    sign = float(np.sign(joint.axis @ np.asarray(jointed_paper_objects()[case.shape].axis)))
    if case.effect.name == "binding_friction":
        a, b = (sign * np.asarray(case.effect.params["q_range"])).tolist()
        return {"q": [min(a, b), max(a, b)]}
    return {"qd": [0.0, np.inf] if sign * case.effect.params["sign"] > 0 else [-np.inf, 0.0]}


def overlaps(where: dict, truth: dict) -> bool:
    """Whether an `unexplained` entry's state range overlaps the true one (the same key)."""
    for key, (a, b) in truth.items():
        if key in where:
            lo, hi = where[key]
            if lo <= b and hi >= a:
                return True
    return False
