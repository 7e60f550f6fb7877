"""`twin bench paper`: RigPI's free objects (cube, sphere, apple), held and moved, several noise draws each;
then its jointed ones (benchmarks/paper_jointed.py)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np


# RigPI (Table I): relative errors of mass and of Ixx, Iyy, Izz [%] on its free objects.
RIGPI_FREE = {"cube": (1.5, (8.6, 6.4, 7.1)), "sphere": (3.5, (7.4, 4.2, 8.2)), "apple": (1.7, (13.9, 6.6, 12.3))}

ENGINE_CHOICES = {"newton": ("newton",), "mujoco": ("mujoco",), "both": ("newton", "mujoco")}
"""The simulators that make a bench's recordings: twin's own Newton models (the ones identification fits)
or MuJoCo (`pipelines.synth.mujoco_engine`, a PD-servoed robot), so that a figure is not only measured on
the model it assumes."""


def engines(choice: str) -> tuple[str, ...]:
    """The engines an `engine` choice ("newton", "mujoco" or "both") runs, in table order."""
    if choice not in ENGINE_CHOICES:
        raise ValueError(f"engine: expected one of {tuple(ENGINE_CHOICES)}, got {choice!r}")
    return ENGINE_CHOICES[choice]


def paper_objects() -> dict:
    """Synthetic analogues of RigPI's free objects (truth in notes/anchors.md): mesh [m] and mass [kg].

    The apple is an ellipsoid of revolution whose moments match the paper's
    (1.22e-5, 1.22e-5, 1.12e-5 kg m^2 at 41.6 g): semi-axes 25.9, 25.9, 28.2 mm.
    """
    import trimesh

    apple = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    apple.apply_scale((0.0259, 0.0259, 0.0282))
    return {
        "cube": (trimesh.creation.box((0.04, 0.04, 0.04)), 0.02),
        "sphere": (trimesh.creation.icosphere(subdivisions=4, radius=0.025), 0.02),
        "apple": (apple, 0.0416),
    }


def paper_cases(seeds: int, duration_s: float, tmp: Path, names: tuple[str, ...] | None = None,
                engine: str = "newton"):
    """The recordings `bench_paper` makes (same objects, motions and noise draws), read back from MCAP.

    engine: "newton" (`simulate_held`) or "mujoco" (`simulate_held_mujoco`, default settings); both track
    the same multisine references and get the same noise draws, but MuJoCo's servoed robot only follows
    its reference, so the motions differ. Yields (name, truth, placement, prior, bounds, seed, trial,
    heldout) per object and seed.
    """
    from assets import Inertial, Pose
    from assets.materials import material_range
    from pipelines.identify import InertialBounds
    from assets.recording import PoseTrack, WrenchTrack
    from pipelines.logs import read_recording
    from pipelines.priors import uniform_density_prior
    from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held
    from pipelines.synth.mujoco_engine import simulate_held_mujoco
    from pipelines.synth.recording import write_recording

    simulate = {"newton": simulate_held, "mujoco": simulate_held_mujoco}[engine]
    for k, (name, (mesh, mass)) in enumerate(paper_objects().items()):
        if names is not None and name not in names:
            continue
        mesh = mesh.copy()
        mesh.density = mass / mesh.volume
        truth = Inertial(mass, (0.0, 0.0, 0.0), mesh.moment_inertia)
        half_height = 0.5 * (mesh.bounds[1, 2] - mesh.bounds[0, 2])
        placement = Pose((0.5, 0.0, half_height))
        grasp = Pose((0.0, 0.0, half_height), (1.0, 0.0, 0.0, 0.0))
        prior = uniform_density_prior(mesh.copy(), material_range(None))
        bounds = InertialBounds(prior.lower, prior.upper)
        motion_rng = np.random.default_rng(1000 + k)
        config = HeldMotionConfig(duration_s=duration_s)
        motions = {trial: simulate(truth, placement, grasp, config, motion_rng) for trial in ("trial", "heldout")}
        for seed in range(seeds):
            noise_rng = np.random.default_rng(seed)
            recordings = {}
            for trial, motion in motions.items():
                t_pose, position, quat, t_wrench, force, torque = measure(motion, SensorNoise(), noise_rng)
                path = tmp / f"{name}-{engine}-{seed}-{trial}.mcap"
                write_recording(path, pose=PoseTrack(t_pose, position, quat, "world", "gripper", "/tracker/pose"),
                                wrench=WrenchTrack(t_wrench, force, torque, "/ft_sensor/wrench", "gripper"))
                recordings[trial] = read_recording(path)
            yield name, truth, placement, prior, bounds, seed, recordings["trial"], recordings["heldout"]


def vlm_starts(name: str, truth, prior) -> dict:
    """Far starts like the paper's VLM guesses: the answers on record (the cube's Gemini and Intern-S1
    masses, at the prior's density shape), and for every object 4x the mass with 28x the inertia, the
    far end of the paper's reported VLM errors (300 % in mass, 2700 % in inertia)."""
    from assets import Inertial
    from benchmarks.priors import RIGPI_VLM_MASS

    starts = {model: Inertial(mass, prior.com, np.asarray(prior.inertia_matrix()) * mass / prior.mass)
              for model, mass in RIGPI_VLM_MASS.get(name, {}).items()}
    starts["4x m, 28x I"] = Inertial(4 * truth.mass, truth.com, 28 * np.asarray(truth.inertia_matrix()))
    return starts


def bench_paper(seeds: int = 5, duration_s: float = 10.0, paper_optimizer: bool = False,
                from_vlm_starts: bool = False, engine: str = "both") -> list[dict]:
    """Each paper object held and moved for `duration_s`, recorded with `seeds` noise draws at the ATI
    sensor's resolution; identified through the MCAP files like a build; errors and spread per estimator
    and engine (`engines`), then the jointed objects under the same engines.

    With `paper_optimizer`, RigPI's own scheme (plain pose loss, 1/100-scale gradient steps) also
    runs on the same windows, started from the prior. With `from_vlm_starts`, the Newton fit also
    runs alone from each of `vlm_starts` (no least-squares start)."""
    from benchmarks.paper_jointed import bench_paper_jointed

    rows = free_rows(seeds, duration_s, paper_optimizer, from_vlm_starts, engine)
    _print_paper_table(rows)
    return rows + bench_paper_jointed(seeds, engine=engine)


def free_rows(seeds: int, duration_s: float, paper_optimizer: bool = False, from_vlm_starts: bool = False,
              engine: str = "both", names: tuple[str, ...] | None = None) -> list[dict]:
    """`bench_paper`'s rows of the free objects (`names`, default all): one per object, estimator and
    engine, in that order."""
    from pipelines.identify import IdentifyConfig, identify_free_body, identify_held, tracked_to_object
    from pipelines.identify.held import windows_from_recordings

    estimates: dict = {}
    truths: dict = {}
    for sim in engines(engine):
        with tempfile.TemporaryDirectory() as tmp:
            for name, truth, placement, prior, bounds, _, trial, heldout in paper_cases(seeds, duration_s, Path(tmp),
                                                                                        names, sim):
                truths[name] = truth
                X = tracked_to_object(trial, placement)
                held = identify_held([trial], heldout, X, prior.inertial, bounds, IdentifyConfig())
                found = {
                    "least_squares": (held.least_squares.inertial, held.least_squares.covariance),
                    "newton": (held.newton.inertial, held.newton.covariance),
                    "kept": (held.inertial, held.covariance),
                }
                if paper_optimizer:
                    paper = IdentifyConfig(optimizer="paper", smoothing_hz=None)
                    rigpi = identify_free_body(windows_from_recordings([trial], paper), X, [prior.inertial], bounds,
                                               paper)
                    found["rigpi_scheme"] = (rigpi.inertial, rigpi.covariance)
                if from_vlm_starts:
                    windows = windows_from_recordings([trial], IdentifyConfig())
                    for label, start in vlm_starts(name, truth, prior.inertial).items():
                        fit = identify_free_body(windows, X, [start], bounds, IdentifyConfig())
                        found[f"newton from {label}"] = (fit.inertial, fit.covariance)
                for estimator, value in found.items():
                    estimates.setdefault((name, estimator, sim), []).append(value)
    # the engines' rows of one object and estimator side by side
    pairs = dict.fromkeys((name, estimator) for name, estimator, _ in estimates)
    return [{"object": name, "estimator": estimator, "engine": sim,
             **spread(estimates[name, estimator, sim], truths[name])}
            for name, estimator in pairs for sim in engines(engine) if (name, estimator, sim) in estimates]


def spread(estimates, truth) -> dict:
    """Mean absolute and worst relative errors [%], COM error [mm], coefficient of variation [%], and how
    often the reported 95 % intervals of mass and Ixx, Iyy, Izz contain the truth."""
    values = [inertial for inertial, _ in estimates]
    flat = np.array([[v.mass, *np.diag(v.inertia_matrix())] for v in values])
    std = np.array([np.sqrt(np.maximum(np.diag(cov)[[0, 4, 5, 6]], 0)) for _, cov in estimates])
    true_flat = np.array([truth.mass, *np.diag(truth.inertia_matrix())])
    covered = np.abs(flat - true_flat) <= 1.96 * std
    masses = np.array([v.mass for v in values])
    principal = np.array([np.linalg.eigvalsh(v.inertia_matrix()) for v in values])
    true_principal = np.linalg.eigvalsh(truth.inertia_matrix())
    mass_err = 100 * (masses / truth.mass - 1)
    inertia_err = 100 * (principal / true_principal - 1)
    com_err = np.array([1000 * np.linalg.norm(np.asarray(v.com) - truth.com) for v in values])
    return {
        "mass_error_pct": float(np.mean(np.abs(mass_err))),
        "mass_error_max_pct": float(np.max(np.abs(mass_err))),
        "inertia_error_pct": np.mean(np.abs(inertia_err), axis=0).tolist(),
        "inertia_error_max_pct": float(np.max(np.abs(inertia_err))),
        "com_error_max_mm": float(com_err.max()),
        "mass_cv_pct": float(100 * masses.std() / masses.mean()),
        "inertia_cv_pct": float(np.max(100 * principal.std(axis=0) / principal.mean(axis=0))),
        "interval_coverage": float(covered.mean()),
    }


def _print_paper_table(rows: list[dict]) -> None:
    print(f"{'object':7} {'estimator':24} {'engine':7} {'mass %':>7} {'max':>6} "
          f"{'principal moments % (mean |err|)':>33} {'max':>6} {'COM mm':>7} {'CV m %':>7} {'CV I %':>7} "
          f"{'95% cover':>9}")
    for r in rows:
        pm = " ".join(f"{x:6.2f}" for x in r["inertia_error_pct"])
        print(f"{r['object']:7} {r['estimator']:24} {r['engine']:7} {r['mass_error_pct']:7.2f} "
              f"{r['mass_error_max_pct']:6.2f} {pm:>33} {r['inertia_error_max_pct']:6.2f} {r['com_error_max_mm']:7.3f} "
              f"{r['mass_cv_pct']:7.2f} {r['inertia_cv_pct']:7.2f} {r['interval_coverage']:9.2f}")
    for name, (m, inertia) in RIGPI_FREE.items():
        pm = " ".join(f"{x:6.2f}" for x in inertia)
        print(f"{name:7} {'RigPI (paper)':24} {'-':7} {m:7.2f} {'':>6} {pm:>33} {'':>6} {'':>7} {'5.6-12.5':>7} "
              f"{'11-22':>7}")
