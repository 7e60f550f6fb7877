"""`twin bench paper`, jointed part: RigPI's drawer, cabinet door and oven door on their joints, several noise draws each."""

from __future__ import annotations

import itertools
import tempfile
from pathlib import Path

import numpy as np

# RigPI (Table I): relative errors of mass and of Ixx, Iyy, Izz [%], told which joint it faces.
RIGPI_JOINTED = {"drawer": (7.2, (11.2, 27.2, 19.6)), "cabinet_door": (2.4, (4.1, 5.1, 16.3)),
                 "oven_door": (3.9, (12.5, 9.4, 6.5))}


def jointed_truth(obj) -> dict:
    """What a one-joint motion determines, true values: mass (prismatic) or inertia about the axis and
    the gravity moment m*d about it (revolute), and the joint's Coulomb friction."""
    inertial = obj.inertial()
    a = np.asarray(obj.axis)
    truth = {"friction": obj.friction}
    if obj.joint_type == "prismatic":
        truth["mass"] = inertial.mass
    else:
        r = np.asarray(obj.position_m) - obj.origin_m
        r_perp = r - a * (a @ r)
        truth["axis_inertia"] = a @ inertial.inertia_matrix() @ a + inertial.mass * r_perp @ r_perp
        truth["gravity_moment"] = inertial.mass * np.linalg.norm(r_perp)
    return truth


def bench_paper_jointed(seeds: int = 5, duration_s: float = 8.0, engine: str = "both") -> list[dict]:
    """Each jointed object worked for `duration_s` twice (trial, held-out), recorded with `seeds` noise draws;
    kind, joint and physics found from the MCAP files as a build does. Prints one row per object and engine
    (`benchmarks.paper.engines`): Newton's computed-effort robot or MuJoCo's servoed hand welded to the handle,
    on the same joint reference and noise draws."""
    from assets.materials import material_range
    from pipelines.identify.jointed import identify_jointed
    from pipelines.identify.kind import detect_kind
    from pipelines.logs import read_recording
    from pipelines.priors import uniform_density_prior
    from pipelines.synth.held import SensorNoise
    from pipelines.synth.jointed import (
        JointedMotionConfig, jointed_paper_objects, simulate_jointed, write_jointed_recording,
    )
    from pipelines.synth.mujoco_engine import simulate_jointed_mujoco
    from benchmarks.crlb import jointed_exact_motion_bound
    from benchmarks.paper import engines

    simulators = {"newton": simulate_jointed, "mujoco": simulate_jointed_mujoco}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for (k, (name, obj)), sim in itertools.product(enumerate(jointed_paper_objects().items()), engines(engine)):
            # a fresh generator per engine: both draw the same joint reference and push offsets
            motion_rng = np.random.default_rng(2000 + k)
            config = JointedMotionConfig(duration_s=duration_s)
            motions = {trial: simulators[sim](obj, config, motion_rng) for trial in ("trial", "heldout")}
            prior = uniform_density_prior(obj.mesh(), material_range(None))
            truth = jointed_truth(obj)
            bound = jointed_exact_motion_bound(obj, motions["trial"], SensorNoise())
            found = []
            for seed in range(seeds):
                rng = np.random.default_rng(seed)
                rec = {trial: read_recording(write_jointed_recording(Path(tmp) / f"{name}-{sim}-{seed}-{trial}.mcap",
                                                                     obj, m, SensorNoise(), rng))
                       for trial, m in motions.items()}
                detection = detect_kind(rec["trial"])
                joint = detection.joint
                entry = {"kind": detection.kind}
                if joint is not None:
                    entry["axis_deg"] = float(np.degrees(np.arccos(min(1.0, abs(joint.axis @ obj.axis)))))
                    d = joint.origin - np.asarray(obj.origin_m)
                    a = np.asarray(obj.axis)
                    entry["point_mm"] = 1000 * float(np.linalg.norm(d - a * (a @ d))) if obj.joint_type == "revolute" else 0.0
                    if detection.kind == obj.joint_type:
                        result = identify_jointed([rec["trial"]], joint, obj.placement(), prior.inertial, rec["heldout"])
                        values = {n: (result.value(n), result.std(n)) for n in result.names}
                        if "gravity_moment_e1" in values:
                            md = np.array([values["gravity_moment_e1"][0], values["gravity_moment_e2"][0]])
                            i = [result.names.index("gravity_moment_e1"), result.names.index("gravity_moment_e2")]
                            s = np.sqrt(md @ result.covariance[np.ix_(i, i)] @ md) / np.linalg.norm(md)
                            values["gravity_moment"] = (float(np.linalg.norm(md)), float(s))
                        entry["values"] = values
                        here = Path(tmp) / f"{name}-{sim}-{seed}"
                        entry["mjcf_replay_ratio"] = (
                            mjcf_heldout_replay(here / "identified", obj, joint, result.inertial,
                                                result.value("friction"), rec["heldout"],
                                                grip_s=result.friction_grip_s())
                            / mjcf_heldout_replay(here / "truth", obj, joint, obj.inertial(), obj.friction,
                                                  rec["heldout"], grip_s=truth_grip_s(sim, result.step_s)))
                        entry["selected"] = result.selected
                        entry["prior_mass_covered"] = bool(prior.lower[0] <= obj.mass_kg <= prior.upper[0])
                found.append(entry)
            rows.append(_row(name, obj, truth, found, bound) | {"engine": sim})
    rows.append(random_joint_cases(20))
    _print(rows)
    return rows


def truth_grip_s(engine: str, step_s: float) -> float | None:
    """The friction grip of the model that made the recordings: MuJoCo's own `frictionloss` (None: its
    defaults), Newton's rigid one (gripping within the replay's step)."""
    return None if engine == "mujoco" else step_s


def mjcf_heldout_replay(directory: Path, obj, joint, inertial, friction: float, heldout, effects=(),
                        grip_s: float | None = None) -> float:
    """RMSE [m] of the tracked frame when MuJoCo replays `heldout` (`replay_jointed_mujoco`, windows from
    measured states) with the MJCF twin exports for the part with this body and joint friction on `joint`,
    the friction's grip `grip_s` (None: MuJoCo's default) and the asset's `effects` (assets.Effect)."""
    from assets import Asset, Estimate, Geometry, Joint, Material, Theta
    from exporters.mjcf import export_mjcf
    from pipelines.validate import replay_jointed_mujoco

    (directory / "meshes").mkdir(parents=True, exist_ok=True)
    for stem in ("visual", "collision"):
        obj.mesh().export(directory / "meshes" / f"{stem}.obj")
    theta = Theta(Estimate(inertial.mass, 0.0), Estimate(inertial.com, 0.0), Estimate(inertial.inertia, 0.0),
                  Estimate(float(friction), 0.0))
    asset = Asset(obj.name, joint.type, obj.placement(), theta, Geometry("meshes/visual.obj", ("meshes/collision.obj",)),
                  Material("unknown", 1000.0, 0.5), Joint(joint.type, tuple(joint.axis), tuple(joint.origin), -10.0,
                                                          10.0, friction_grip_s=grip_s), effects=tuple(effects))
    return replay_jointed_mujoco(export_mjcf(asset, directory), asset, heldout, joint)["rmse_position_m"]


def random_joint_cases(count: int, seed: int = 7) -> dict:
    """Kind, axis and axis point found on `count` random drawers and doors (half each), tracker noise only."""
    from pipelines.identify.kind import detect_kind
    from pipelines.synth.jointed import random_joint_recording

    rng = np.random.default_rng(seed)
    right, angles, points = 0, [], []
    for case in range(count):
        joint_type = ("prismatic", "revolute")[case % 2]
        recording, axis, point = random_joint_recording(rng, joint_type)
        found = detect_kind(recording)
        right += found.kind == joint_type
        if found.joint is not None:
            angles.append(np.degrees(np.arccos(min(1.0, abs(found.joint.axis @ axis)))))
            if point is not None:
                d = found.joint.origin - point
                points.append(1000 * np.linalg.norm(d - axis * (axis @ d)))
    return {"object": f"{count} random", "joint": "both", "engine": "-", "kind_right": right, "draws": count,
            "axis_deg_max": float(max(angles)), "point_mm_max": float(max(points)), "selected": [],
            "prior_mass_covered": None}


def _row(name, obj, truth, found, bound: dict) -> dict:
    """One object's draws summarised; bound: the trial's exact-motion bound per quantity
    (`jointed_exact_motion_bound`)."""
    row = {"object": name, "joint": obj.joint_type, "kind_right": sum(f["kind"] == obj.joint_type for f in found),
           "draws": len(found), "axis_deg_max": max(f.get("axis_deg", np.nan) for f in found),
           "point_mm_max": max(f.get("point_mm", np.nan) for f in found),
           "selected": sorted({f.get("selected", "-") for f in found}),
           "mjcf_replay_ratio": [f["mjcf_replay_ratio"] for f in found if "mjcf_replay_ratio" in f],
           "prior_mass_covered": all(f.get("prior_mass_covered", False) for f in found)}
    for quantity, true in truth.items():
        est = np.array([f["values"][quantity] for f in found if "values" in f and quantity in f["values"]])
        if len(est) == 0:
            continue
        err = 100 * (est[:, 0] / true - 1)
        row[quantity] = {"true": true, "mean_abs_err_pct": float(np.mean(np.abs(err))),
                         "max_abs_err_pct": float(np.max(np.abs(err))),
                         "cv_pct": float(100 * est[:, 0].std() / est[:, 0].mean()),
                         "covered_95": float(np.mean(np.abs(est[:, 0] - true) <= 1.96 * est[:, 1])),
                         "reported_std_pct": float(100 * np.mean(est[:, 1]) / true),
                         "bound_std_pct": float(100 * bound.get(quantity, np.nan) / true)}
    return row


def _print(rows: list[dict]) -> None:
    print(f"{'object':13} {'joint':9} {'engine':7} {'kind ok':>7} {'axis deg':>8} {'point mm':>8}  "
          f"{'quantity':15} {'true':>10} {'|err| %':>8} {'max %':>7} {'CV %':>6} {'std %':>6} {'bound %':>7} "
          f"{'95% cover':>9}")
    for r in rows:
        head = (f"{r['object']:13} {r['joint']:9} {r['engine']:7} {r['kind_right']:>3}/{r['draws']:<3} "
                f"{r['axis_deg_max']:8.3f} {r['point_mm_max']:8.2f}")
        for q in ("mass", "axis_inertia", "gravity_moment", "friction"):
            if q in r:
                v = r[q]
                print(f"{head}  {q:15} {v['true']:10.4g} {v['mean_abs_err_pct']:8.2f} {v['max_abs_err_pct']:7.2f} "
                      f"{v['cv_pct']:6.2f} {v['reported_std_pct']:6.2f} {v['bound_std_pct']:7.3f} {v['covered_95']:9.2f}")
                head = " " * len(head)
        if r["selected"]:
            ratio = r["mjcf_replay_ratio"]
            print(f"{'':13} estimator kept on the held-out trial: {', '.join(r['selected'])}; "
                  f"prior mass interval holds the truth: {r['prior_mass_covered']}; exported MJCF replays the "
                  f"held-out trial in MuJoCo at {np.mean(ratio):.2f}x (max {np.max(ratio):.2f}x) the truth's error")
        else:
            print(head)
    for name, (m, inertia) in RIGPI_JOINTED.items():
        print(f"{name:13} RigPI (paper, told the joint): mass {m:.1f} %, Ixx Iyy Izz {inertia[0]:.1f} {inertia[1]:.1f} "
              f"{inertia[2]:.1f} %, CV 5.6-12.5 % (mass), 6-25 % (friction)")
