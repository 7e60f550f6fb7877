"""`twin build`: scan or mesh plus recordings in, identified and validated assets out.

The stages run in order; each is a function of typed inputs. Outputs go to a
temporary directory beside OUT and replace it only when everything is written
and validated, so a failed build leaves a previous OUT untouched.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from contextlib import contextmanager, nullcontext
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable, Literal

import numpy as np

from twin.output import staged_output


class BuildError(RuntimeError):
    """A build failed for a reason the user can act on; the message names the file."""


@dataclass(frozen=True)
class BuildConfig:
    """Everything a build depends on; printed into asset.json provenance."""

    source: Path
    logs: tuple[Path, ...]
    scans: tuple[Path, ...] = ()
    """Further scan sessions of the object, registered to SOURCE's and intersected with it (pipelines/sessions)."""
    output: Path = Path("out")
    holdout: Path | None = None
    material: str | None = None
    name: str | None = None
    method: Literal["newton", "ls"] = "newton"
    window_s: float = 0.1
    max_iterations: int = 30
    optimizer: Literal["gauss-newton", "paper"] = "gauss-newton"
    cache_dir: Path = Path.home() / ".cache" / "twin"
    vlm: str | None = None
    vlm_model: str | None = None
    kind: Literal["free", "sliding", "prismatic", "revolute"] | None = None
    base_mesh: Path | None = None
    diagnose: bool = True
    """Look for missing physics after identification (pipelines/diagnose): free, pushed and jointed bodies."""
    topics: tuple[tuple[str, str], ...] = ()
    """(role, topic) overrides for reading the recordings."""
    frames: tuple[tuple[str, str], ...] = ()
    """(role, frame id) for wrench or contact messages whose header leaves it empty."""
    wrench_rotation_xyzw: tuple[float, float, float, float] | None = None
    wrench_reaction: bool = False
    """The wrench messages give the force on the sensor (the object's reaction): negate them."""
    push_min_speed_m_s: float = 0.01
    """Pushed objects: a window is fitted only where the object's median speed exceeds this [m/s]."""
    force: bool = False
    """Write into an existing folder that holds files twin did not write (they are kept)."""
    mesh_units: str | None = None
    """Length unit of a mesh SOURCE ("m", "cm", "mm", "in"); None: metres."""
    mass_kg: tuple[float, float] | None = None
    """The object's weighed mass and its standard uncertainty [kg], a measurement the fit uses."""

    def read(self, path: Path):
        """One recording, read with this build's topic, frame and rotation options (MCAP), or a
        MIT pushing-dataset trial (.h5 or .json, whose layout fixes roles and frames)."""
        from pipelines.logs import read_recording

        if Path(path).suffix in (".h5", ".json"):
            from pipelines.push_dataset import read_push_trial

            return read_push_trial(path)

        return read_recording(path, dict(self.topics), dict(self.frames), self.wrench_rotation_xyzw,
                              self.wrench_reaction)


@dataclass
class StageTimer:
    """Wall time per stage, reported through `log`; on a terminal a spinner with the elapsed time shows
    that a long stage (reconstruction, decomposition, identification, diagnosis) is alive."""

    log: Callable[[str], None]
    seconds: dict = field(default_factory=dict)
    live: bool = field(default_factory=lambda: sys.stderr.isatty() and not os.environ.get("CI"))
    """Show the spinner: on a terminal, never in a CI log."""

    def run(self, name: str, fn, *args, **kwargs):
        self.log(f"{name} ...")
        t0 = time.perf_counter()
        with _spinner(name) if self.live else nullcontext():
            out = fn(*args, **kwargs)
        self.seconds[name] = time.perf_counter() - t0
        self.log(f"{name} done in {self.seconds[name]:.1f} s")
        return out


@contextmanager
def _spinner(name: str):
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    # transient and on stderr: the log lines on stdout stay as they are, in a file or a CI log alike
    with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                  console=Console(stderr=True), transient=True, redirect_stdout=True) as progress:
        progress.add_task(name, total=None)
        yield


def quiet_warp() -> None:
    """Warp without its load and CUDA-driver chatter: a build's log is its stage lines, its errors one line each."""
    import warp as wp

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # no per-module load lines in the progress log
    # Warp's native init prints a CUDA-driver notice straight to fd 2 on machines without a GPU: errors are
    # one line each, so the notice is kept out (a GPU machine loses nothing, a failed init still raises)
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        sys.stderr.flush()
        os.dup2(devnull, 2)
        wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def build(config: BuildConfig, log: Callable[[str], None] = print) -> Path:
    """Run every stage and write config.output atomically; returns the output directory."""
    from twin.checks import check_build

    check_build(config)  # within the first second, before the heavy imports
    quiet_warp()
    from assets import Pose
    from pipelines.decompose import DecomposeConfig, decompose
    from pipelines.identify.kind import detect_kind
    from pipelines.priors import VlmConfig, ask_vlm, describe_object, estimate_prior, scan_image

    t_start = time.perf_counter()
    timer = StageTimer(log)

    # The inputs are read first: they are quick, and a bad file should fail before minutes of geometry.
    source = timer.run("scan" if Path(config.source).is_dir() else "mesh", _read_source, config)
    choice = choose_material(config.material, source[0].material_hint if isinstance(source, list) else None, log)
    trials = [timer.run(f"logs {p.name}", config.read, p) for p in config.logs]
    holdout = timer.run(f"logs {config.holdout.name}", config.read, config.holdout) if config.holdout else None
    detection = timer.run("kind", detect_kind, trials[0], config.kind)
    log(f"motion: {detection.kind}" + (" (--kind)" if detection.forced else f" (BIC {detection.bic})"))
    mesh_world, name, scan_stats = timer.run("reconstruct", _object_mesh, config, source)
    for session in scan_stats.get("sessions", [])[1:]:
        r = session["registration"]
        log(f"session {session['root']}: registered with fitness {r['fitness']:.3f}, RMSE {1000 * r['rmse_m']:.2f} mm")
    name = config.name or name
    placement = Pose(tuple(mesh_world.center_mass), (0.0, 0.0, 0.0, 1.0))
    mesh_object = mesh_world.copy()
    mesh_object.apply_translation(-np.asarray(placement.position))

    parts = timer.run(
        "decompose", decompose, mesh_object, DecomposeConfig(), cache_dir=Path(config.cache_dir) / "coacd"
    )
    named = choice.entry.name if choice.entry else None
    guess = None
    if config.vlm:  # any failure is a warning and None: the build goes on with the offline prior
        vlm = VlmConfig(url=config.vlm, model=config.vlm_model, cache_dir=Path(config.cache_dir) / "vlm")
        guess = timer.run("vlm", ask_vlm, vlm, scan_image(config.source), describe_object(mesh_object, name, named))
        log(f"VLM: {guess.material}, {guess.mass_kg} kg, confidence {guess.confidence}" if guess else
            "VLM: no usable answer; using the offline prior")
    prior = timer.run("priors", estimate_prior, mesh_object, choice.entry, guess, weighed=config.mass_kg)
    if choice.entry is None and prior.details["fusion"]["material_from"] == "vlm":
        choice = replace(choice, source="vlm")
    if detection.joint is not None:
        from twin.jointed import build_jointed

        return build_jointed(config, trials, holdout, detection, mesh_object, placement, parts, prior, choice,
                             name, scan_stats, timer, log, t_start)
    return _build_body(config, trials, holdout, detection, mesh_object, placement, parts, prior, choice, name,
                       scan_stats, timer, log, t_start)


@contextmanager
def kind_hint(detection, recording):
    """An identification that fails on a kind the motion only suggested names the option that would help:
    a pushed block read as held, say, ends in a singular fit rather than in anything a user can act on."""
    try:
        yield
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
        if detection.forced or isinstance(exc, BuildError):
            raise
        others = [k for k in ("free", "sliding", "prismatic", "revolute") if k != detection.kind]
        raise BuildError(f"{recording.path}: identification as a {detection.kind} body failed ({exc}); the kind was "
                         f"read from the motion: if the object was not {detection.kind}, pass --kind "
                         f"{'|'.join(others)}") from exc


def _build_body(config, trials, holdout, detection, mesh_object, placement, parts, prior, choice, name, scan_stats,
                timer, log, t_start) -> Path:
    """A free or pushed body from its recordings to the written output."""
    from assets import Asset, Estimate, Fit, Geometry, Theta, asset_to_json, write_asset
    from exporters import export_all
    from pipelines.diagnose import CANDIDATES, DiagnoseConfig, diagnose_held
    from pipelines.identify import (
        IdentifyConfig, InertialBounds, identify_held, tracked_to_object, with_weighed_mass,
    )
    from pipelines.validate import validate_exports
    from pipelines.priors import part_pseudo_inertias
    from twin.summary import bounds_flags, doubtful_flags, dominated_flags

    diagnosis, dominated = None, set()
    if detection.kind == "sliding":
        from pipelines.diagnose import diagnose_pushed
        from pipelines.identify.sliding import SUPPORTS, SlidingConfig, identify_pushed

        body, mu_prior = _sliding_body(mesh_object, prior)
        with kind_hint(detection, trials[0]):
            pushed = timer.run("identify", identify_pushed, trials, holdout, body, mu_prior,
                               SlidingConfig(moving_speed_m_s=config.push_min_speed_m_s), supports=SUPPORTS)
        # the support the pushes chose: the diagnosis, the replay and the export use it too
        sconfig = pushed.config
        if pushed.support is not None:
            log(f"  {pushed.support.words}")
        refit = None
        if config.diagnose:
            diagnosis, refit = timer.run("diagnose", diagnose_pushed, trials, [holdout] if holdout else [], body,
                                         mu_prior, sconfig, DiagnoseConfig())
            _log_diagnosis(diagnosis, log)
        theta, fit, identify_provenance, loss_history, traces = _sliding_result(pushed, refit, diagnosis, body,
                                                                                 prior)
        theta = weighed_where_prior(theta, config.mass_kg)
        log(f"  friction {theta.friction.value:.3f} +- {theta.friction.std:.3f} "
            f"({identify_provenance['identify']['friction_from']})")
    else:
        X_tracked_body = tracked_to_object(trials[0], placement)
        id_config = IdentifyConfig(window_s=config.window_s, max_iterations=config.max_iterations,
                                   optimizer=config.optimizer)
        with kind_hint(detection, trials[0]):
            held = timer.run(
                "identify", identify_held, trials, holdout, X_tracked_body, prior.inertial,
                InertialBounds(prior.lower, prior.upper), id_config, config.method, _progress_logger(log),
                parts=part_pseudo_inertias(parts.parts),
            )
        log(f"  kept the {held.choice}")
        inertial, covariance = held.inertial, held.covariance
        dominated = set(held.prior_dominated)
        fit_baseline, fit_final = held.fits["baseline"], held.fits[held.selected]
        if config.diagnose:
            diagnosis = timer.run("diagnose", diagnose_held, trials, holdout, X_tracked_body, prior.uniform,
                                  DiagnoseConfig(window_s=config.window_s))
            _log_diagnosis(diagnosis, log)
            if any(e.name in CANDIDATES for e in diagnosis.effects):
                # the identification lacked the effect, so its estimate is biased: the refit with it is kept
                inertial, fit_final = diagnosis.inertial["after"], diagnosis.fits["after"]
                fit_baseline = diagnosis.fits["before"]
                dominated = set()

        if config.mass_kg is not None:
            inertial, covariance = with_weighed_mass(inertial, covariance, *config.mass_kg)
            log(f"  with the weighed {config.mass_kg[0]:.4g} kg: mass {inertial.mass:.4g} kg")
        std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
        inertia_std = np.array([[std[4], std[7], std[8]], [std[7], std[5], std[9]], [std[8], std[9], std[6]]])
        ci = lambda v, s: (np.asarray(v) - 1.96 * np.asarray(s), np.asarray(v) + 1.96 * np.asarray(s))  # noqa: E731
        # a quantity whose every component the recordings left to the geometry prior is the prior's
        source = lambda names: "prior" if dominated >= set(names) else "measured"  # noqa: E731
        theta = Theta(
            mass=Estimate(inertial.mass, std[0], source=source(["mass"]), interval95=ci(inertial.mass, std[0]),
                          prior=prior.provenance()),
            com=Estimate(inertial.com, tuple(std[1:4]), source=source(["com_x", "com_y", "com_z"]),
                         interval95=ci(inertial.com, std[1:4])),
            inertia=Estimate(inertial.inertia, inertia_std, source=source(["Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz"]),
                             interval95=ci(inertial.inertia, inertia_std)),
            friction=Estimate(
                prior.friction[0], (prior.friction[2] - prior.friction[1]) / 4, source="prior",
                interval95=(prior.friction[1], prior.friction[2]),
            ),
        )
        fit = Fit(fit_baseline, fit_final, id_config.window_s)
        loss_history, traces = held.loss_history, held.traces
        identify_provenance = {
            "identify": {"method": config.method, **held.provenance()},
            **({"diagnose": diagnosis.provenance()} if diagnosis else {}),
            "tracked_frame_in_object": {"position": list(X_tracked_body.inverse().position),
                                        "quaternion_xyzw": list(X_tracked_body.inverse().quaternion_xyzw)},
        }

    out = Path(config.output)
    with staged_output(out, config.force) as tmp:
        collision = _write_meshes(tmp, mesh_object, parts)
        asset = Asset(
            name=name,
            kind=detection.kind,
            placement=placement,
            theta=theta,
            geometry=Geometry("meshes/visual.obj", collision, extent=scan_stats.get("extent")),
            material=choice.material(prior.material.name, float(theta.mass.value / mesh_object.volume),
                                     theta.friction.value),
            fit=fit,
            effects=diagnosis.effects if diagnosis else (),
            unexplained=diagnosis.unexplained if diagnosis else (),
            flags=(bounds_flags(theta, prior.lower, prior.upper) + dominated_flags(dominated)
                   + doubtful_flags(diagnosis.doubtful if diagnosis else ())),
            # the exporters read the identification's choices from it (a pushed object's support)
            provenance=identify_provenance,
        )
        paths = timer.run("export", export_all, asset, tmp)
        files = {**paths.to_json(relative_to=tmp), "report": "report.html"}
        validation = timer.run("validate", validate_exports, asset, tmp, files)
        replay = {}
        if detection.kind == "free":
            replay = _replay_free(timer, tmp / files["mjcf"], asset, holdout or trials[0], X_tracked_body,
                                  fit.window_s, diagnosis, log)
        else:
            replay = _replay_pushed(timer, tmp / files["scene"], asset, holdout or trials[0], fit.window_s, sconfig,
                                    log)
        provenance = {
            "config": json.loads(json.dumps(asdict(config), default=str)),
            "scan": scan_stats,
            "decompose": parts.stats | {"volume_union_m3": parts.volume_union_m3, "volume_mesh_m3": parts.volume_mesh_m3},
            "prior": prior.provenance(),
            "kind": detection.to_json(),
            **identify_provenance,
            "validation": validation.to_json(),
            **({"heldout_replay": replay} if replay else {}),
            "timings_s": timer.seconds | {"total": time.perf_counter() - t_start},
        }
        asset = Asset(**{**asset.__dict__, "files": files, "provenance": provenance})
        write_asset(asset, tmp / "asset.json")
        from twin.report import write_report

        write_report(tmp / "report.html", asset_to_json(asset), loss_history, traces,
                     diagnosis.traces if diagnosis else None)
    log_summary(asset_to_json(asset), log)
    log(f"wrote {out}/ in {time.perf_counter() - t_start:.1f} s")
    return out


def weighed_where_prior(theta, weighed: tuple[float, float] | None):
    """A mass the recordings could not determine is the user's weighing, said so, rather than the prior's."""
    from assets import Estimate

    if weighed is None or theta.mass.source != "prior":
        return theta
    mass, std = weighed
    return replace(theta, mass=Estimate(mass, std, source="weighed", interval95=(mass - 1.96 * std, mass + 1.96 * std),
                                        prior=theta.mass.prior))


def log_summary(doc: dict, log) -> None:
    from twin.summary import summary_lines

    log("summary:")
    for line in summary_lines(doc):
        log(f"  {line}")


def _replay_free(timer, mjcf_path, asset, recording, X_tracked_body, window_s, diagnosis, log) -> dict:
    """The exported MJCF replaying the evaluation recording in MuJoCo beside Newton's replay of the fit, and
    both against the sensors' noise alone: the best any model could do on this recording."""
    from pipelines.validate import replay_held_mujoco

    mujoco = timer.run("replay (MuJoCo)", replay_held_mujoco, mjcf_path, asset, recording, X_tracked_body, window_s)
    newton = asset.fit.final.rmse_position_m
    floor = diagnosis.noise_floor.get("rmse_position_m") if diagnosis and diagnosis.noise_floor else None
    log(f"replay of {Path(recording.path).name}: MuJoCo "
        f"{1000 * mujoco['rmse_position_m']:.3f} mm, Newton {1000 * newton:.3f} mm"
        + (f", the sensors' noise alone {1000 * floor:.3f} mm" if floor else ""))
    return {"recording": str(recording.path), "mujoco": mujoco, "newton": {"rmse_position_m": newton},
            "mujoco_over_newton": mujoco["rmse_position_m"] / newton if newton > 0 else None,
            "noise_floor_m": floor, "mujoco_over_noise_floor": mujoco["rmse_position_m"] / floor if floor else None}


def _replay_pushed(timer, scene_path, asset, recording, window_s, sconfig, log) -> dict:
    """The exported MJCF in its scene (a plane carrying the identified friction) replaying the evaluation
    recording's pushes in MuJoCo, on the windows Newton's replay of the fit used."""
    from pipelines.validate import replay_pushed_mujoco

    mujoco = timer.run("replay (MuJoCo)", replay_pushed_mujoco, scene_path, asset, recording, window_s, sconfig)
    newton = asset.fit.final.rmse_position_m
    log(f"replay of {Path(recording.path).name}: MuJoCo {1000 * mujoco['rmse_position_m']:.3f} mm, "
        f"Newton {1000 * newton:.3f} mm")
    return {"recording": str(recording.path), "mujoco": mujoco, "newton": {"rmse_position_m": newton}}


@dataclass(frozen=True)
class MaterialChoice:
    """The library entry the prior starts from, and how the user's words led to it (asset.json `material`)."""

    entry: object | None
    """The `MaterialRange`, or None for the wide `unknown` prior."""
    text: str | None
    source: str
    """"named" (--material), "hint" (object.json), "unmatched" (a hint the library does not know), "vlm",
    or "library" (no words given)."""
    score: float | None

    def material(self, name: str, density: float, friction: float):
        from assets import Material

        return Material(name, density, friction, text=self.text, source=self.source, match_score=self.score)


def choose_material(named: str | None, hint: str | None, log) -> MaterialChoice:
    """--material must match the library (checked before the build starts); an object.json hint that matches
    nothing is a warning and the wide prior, never a failed build."""
    from assets.materials import MATCH_THRESHOLD, match_material, material_range, suggest_materials

    if named is not None:
        match = match_material(named)
        return MaterialChoice(material_range(named), named, "named", match.score if match.name else None)
    if hint is None:
        return MaterialChoice(None, None, "library", None)
    match = match_material(hint)
    if match.name is None or match.score < MATCH_THRESHOLD:
        log(f"warning: object.json material {hint!r} matches nothing in the library (nearest: "
            f"{', '.join(suggest_materials(hint))}); using the wide prior of an unknown material")
        return MaterialChoice(None, hint, "unmatched", 0.0)
    if match.how != "exact":
        log(f"material {hint!r} read as {match.name} ({match.how}, match {match.score:.2f})")
    return MaterialChoice(material_range(match.name), hint, "hint", match.score)


def _sliding_body(mesh_object, prior):
    """The pushed object as the sliding model sees it, and the prior's friction coefficient.

    The support face is the mesh's bounding box bottom (object frame, axes parallel to world at the scan);
    mass and I_zz spreads from the bounds C, taken as about +-2 std of the log.
    """
    from pipelines.identify.sliding import PlanarBody

    mass_rel = float(np.log(prior.upper[0] / prior.lower[0]) / 4)
    izz_rel = float(np.log(prior.upper[6] / prior.lower[6]) / 4)
    body = PlanarBody(tuple(0.5 * (mesh_object.bounds[1] - mesh_object.bounds[0])), float(prior.inertial.mass),
                      float(np.asarray(prior.inertial.inertia)[2, 2]), mass_rel_std=mass_rel, izz_rel_std=izz_rel)
    return body, float(prior.friction_kinetic[0])


def _sliding_result(pushed, refit, diagnosis, body, prior):
    """Theta, fit metrics, provenance, loss curve and traces of a pushed object.

    What the pushes leave undetermined keeps the prior's value and is marked "prior"; COM and the
    tilting moments always are, and so is I_zz where some window turns against its pushing moment (the
    fit's I_zz then stands in for what turns the object; `PushedIdentification.turns_explained`). With
    effects chosen by the diagnosis, its refit (mu and I_zz fitted with them) replaces the
    identification's, whose estimate lacked them, as for a free body.
    """
    from dataclasses import asdict

    from assets import Estimate, Fit, FitMetrics, Theta

    fit = refit if refit is not None else pushed.fit
    inertia0 = np.asarray(prior.inertial.inertia, dtype=float)
    mass0 = float(prior.inertial.mass)
    (_, mass, izz), (_, mass_std, izz_std) = fit.theta, fit.std
    friction, friction_from = _sliding_friction(fit, pushed.balance, prior)
    mass_known, izz_known = fit.determined[1], fit.determined[2] and pushed.turns_explained
    # one tensor scale keeps it physically consistent: Izz's if the pushes determined it, else the mass's
    scale = izz / inertia0[2, 2] if izz_known else (mass / mass0 if mass_known else 1.0)
    inertia = inertia0 * scale
    theta = Theta(
        mass=Estimate(float(mass) if mass_known else mass0, float(mass_std),
                      source="measured" if mass_known else "prior", prior=prior.provenance()),
        com=Estimate(tuple(prior.inertial.com), (0.0, 0.0, 0.0), source="prior"),
        inertia=Estimate(tuple(map(tuple, inertia)),
                         tuple(map(tuple, np.abs(inertia) * (izz_std / izz if izz_known else body.izz_rel_std))),
                         source="measured" if izz_known else "prior"),
        friction=friction,
    )
    # the replay before and after: the diagnosis's held-out windows when it chose effects, else the identification's
    baseline, final = ((diagnosis.fits["before"], diagnosis.fits["after"]) if refit is not None
                       else (FitMetrics(*pushed.baseline), FitMetrics(*pushed.final)))
    provenance = {"identify": pushed.provenance() | {"body": asdict(body), "friction_from": friction_from}
                  | ({"with_effects": refit.provenance()} if refit is not None else {}),
                  **({"diagnose": diagnosis.provenance()} if diagnosis else {})}
    return theta, Fit(baseline, final, pushed.config.window_s), provenance, fit.loss_history, pushed.traces


def _sliding_friction(fit, balance, prior):
    """The friction coefficient and what gave it (`measured_friction`); where neither the sliding fit nor the
    wrench balance measured it, the prior raised to the fit's bound, marked "prior" with the bound as its
    interval's low end."""
    from assets import Estimate
    from pipelines.identify.sliding import measured_friction

    measured = measured_friction(fit, balance)
    if measured is not None:
        mu, std, source = measured
        return Estimate(mu, std, interval95=(mu - 1.96 * std, mu + 1.96 * std)), source
    bound = float(fit.theta[0])
    central, _, high = map(float, prior.friction_kinetic)
    value = max(central, bound)
    return (Estimate(value, (max(high, value) - bound) / 4, source="prior", interval95=(bound, max(high, value))),
            "prior, above the sliding fit's bound")


def _log_diagnosis(diagnosis, log) -> None:
    for line in diagnosis.findings[:6]:
        log(f"  residual: {line}")
    fits = diagnosis.fits
    for e in diagnosis.effects:
        log(f"  effect {e.name}: {e.params}")
    floor = (f" (the sensors' noise alone: about {1000 * diagnosis.noise_floor['rmse_position_m']:.3f} mm)"
             if diagnosis.noise_floor else "")
    if diagnosis.effects:
        log(f"  held-out position RMSE {1000 * fits['before'].rmse_position_m:.3f} -> "
            f"{1000 * fits['after'].rmse_position_m:.3f} mm{floor}")
    else:
        log(f"  no effect improves the held-out prediction, {1000 * fits['after'].rmse_position_m:.3f} mm{floor}")
    for u in diagnosis.unexplained:
        log(f"  unexplained: {u['summary']}")
    if diagnosis.doubtful:
        log(f"  doubtful (a mismatch may have corrupted them): {', '.join(diagnosis.doubtful)}")


@dataclass(frozen=True)
class DiagnoseRunConfig:
    """`twin diagnose`: the diagnose stage alone on a built OUT and recordings."""

    output: Path
    logs: tuple[Path, ...]
    holdout: Path | None = None
    bootstraps: int = 40


def diagnose_output(config: DiagnoseRunConfig, log: Callable[[str], None] = print) -> Path:
    """Diagnose the asset in config.output against recordings; rewrite its asset.json and report.html.

    The identified parameters and exported files stay as built (`twin build` carries chosen effects into
    them); effects, unexplained and provenance.diagnose are replaced.
    """
    from assets import Inertial, Pose, asset_to_json, read_asset, write_asset
    from pipelines.diagnose import DiagnoseConfig, diagnose_held
    from twin.checks import check_recording_path
    from twin.report import write_report

    out = Path(config.output)
    if not (out / "asset.json").is_file():
        raise BuildError(f"{out}/asset.json: not found; run `twin build` into {out} first")
    if not config.logs:
        raise BuildError("--logs: no recording given; pass --logs TRIAL.mcap")
    for path in config.logs:
        check_recording_path(path)
    if config.holdout:
        check_recording_path(config.holdout, "--holdout")
    asset = read_asset(out / "asset.json")
    timer = StageTimer(log)
    provenance = asset.provenance
    # the recordings are read with the options the asset was built with (topics, frames, sensor rotation)
    built = provenance.get("config", {})
    reader = BuildConfig(source=out, logs=(), topics=tuple(map(tuple, built.get("topics", ()))),
                         frames=tuple(map(tuple, built.get("frames", ()))),
                         wrench_rotation_xyzw=built.get("wrench_rotation_xyzw"),
                         wrench_reaction=bool(built.get("wrench_reaction", False)))
    trials = [reader.read(p) for p in config.logs]
    holdout = reader.read(config.holdout) if config.holdout else None
    try:
        if asset.kind == "sliding":
            from pipelines.identify.sliding import PlanarBody, SlidingConfig

            identified = provenance["identify"]
            body = PlanarBody(**{k: tuple(v) if isinstance(v, list) else v for k, v in identified["body"].items()})
            sconfig = SlidingConfig(**{k: tuple(v) if isinstance(v, list) else v
                                       for k, v in identified["config"].items()})
            mu_prior = identified["prior_theta"][0]
        elif asset.joint is not None:
            from pipelines.diagnose import diagnose_jointed
            from pipelines.identify.jointed import JointedConfig
            from pipelines.identify.kind import detect_kind

            p = provenance["prior"]
            prior = Inertial(p["mass_kg"], tuple(p["com_m"]), np.asarray(p["inertia_kg_m2"]))
            jconfig = JointedConfig(**provenance["identify"]["config"])
        else:
            uniform = provenance["prior"]["uniform"]
            tracked = provenance["tracked_frame_in_object"]
    except KeyError as exc:
        raise BuildError(f"{out}/asset.json: provenance lacks {exc}; rebuild it with this version of twin") from exc
    if asset.kind == "sliding":
        from pipelines.diagnose import diagnose_pushed

        diagnosis, _ = timer.run("diagnose", diagnose_pushed, trials, [holdout] if holdout else [], body, mu_prior, sconfig,
                                       DiagnoseConfig(bootstraps=config.bootstraps))
    elif asset.joint is not None:
        joint = detect_kind(trials[0], asset.kind).joint
        diagnosis, _ = timer.run("diagnose", diagnose_jointed, trials, holdout, joint, asset.placement, prior, jconfig,
                                        DiagnoseConfig(bootstraps=config.bootstraps))
    else:
        prior = Inertial(uniform["mass_kg"], tuple(uniform["com_m"]), np.asarray(uniform["inertia_kg_m2"]))
        X_tracked_body = Pose(tuple(tracked["position"]), tuple(tracked["quaternion_xyzw"])).inverse()
        diagnosis = timer.run("diagnose", diagnose_held, trials, holdout, X_tracked_body, prior,
                                  DiagnoseConfig(bootstraps=config.bootstraps,
                                                 window_s=asset.fit.window_s if asset.fit else 0.1))
    _log_diagnosis(diagnosis, log)
    run = {"logs": [str(p) for p in config.logs], "holdout": str(config.holdout) if config.holdout else None}
    asset = replace(asset, effects=diagnosis.effects, unexplained=diagnosis.unexplained,
                          provenance={**provenance, "diagnose": diagnosis.provenance() | {"run": run}})
    # written beside and moved over: a reader, or an interrupt, sees the old files or the new ones
    with tempfile.TemporaryDirectory(prefix=".twin-", dir=out) as tmp:
        write_asset(asset, Path(tmp) / "asset.json")
        write_report(Path(tmp) / "report.html", asset_to_json(asset), (), None, diagnosis.traces)
        for name in ("asset.json", "report.html"):
            os.replace(Path(tmp) / name, out / name)
    log(f"updated {out}/asset.json and report.html")
    return out


def _read_source(config: BuildConfig):
    """The scan sessions (read and checked, not yet fused) or the mesh of SOURCE: quick, so a bad file
    fails before the recordings are classified and minutes before the reconstruction would."""
    from pipelines.scan import read_scan

    source = Path(config.source)
    if source.is_dir():
        return [read_scan(p) for p in (source, *config.scans)]
    from pipelines.meshes import read_mesh

    return read_mesh(source, config.mesh_units or "m")


def _object_mesh(config: BuildConfig, source):
    """The watertight object mesh in world at its placement, its name and stats."""
    from pipelines.reconstruct import ReconstructConfig, reconstruct

    if not isinstance(source, list):
        return source, Path(config.source).stem, {"mesh_file": str(config.source),
                                                  "mesh_units": config.mesh_units or "m"}
    if len(source) > 1:
        from pipelines.sessions import SessionsConfig, merge_sessions

        sessions_config = SessionsConfig()
        rec = merge_sessions(source, sessions_config)
        stats = {"config": asdict(sessions_config), "frames": sum(len(s.frames) for s in source),
                 "voxel_size_m": rec.voxel_size_m, **rec.stats}
        return rec.mesh, source[0].name, stats
    scan = source[0]
    reconstruct_config = ReconstructConfig()
    rec = reconstruct(scan, reconstruct_config)
    stats = {"config": asdict(reconstruct_config), "frames": len(scan.frames), "voxel_size_m": rec.voxel_size_m,
             **rec.stats}
    return rec.mesh, scan.name, stats


def _progress_logger(log):
    def progress(iteration: int, loss: float):
        # Levenberg-Marquardt takes a handful of iterations; the paper's optimizer takes hundreds of steps
        if iteration <= 10 or iteration % 25 == 0:
            log(f"  iteration {iteration}: loss {loss:.6g}")
    return progress


def _write_meshes(tmp: Path, mesh_object, parts) -> tuple[str, ...]:
    """meshes/visual.obj and meshes/collision_NNN.obj under `tmp`; returns the collision paths (relative)."""
    (tmp / "meshes").mkdir()
    mesh_object.export(tmp / "meshes" / "visual.obj")
    collision = []
    for k, part in enumerate(parts.parts):
        rel = f"meshes/collision_{k:03d}.obj"
        part.export(tmp / rel)
        collision.append(rel)
    return tuple(collision)
