"""`twin build`: scan or mesh plus recordings in, identified and validated assets out.

The stages run in order; each is a function of typed inputs. Outputs go to a
temporary directory beside OUT and replace it only when everything is written
and validated, so a failed build leaves a previous OUT untouched.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Literal

import numpy as np

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb")


class BuildError(RuntimeError):
    """A build failed for a reason the user can act on; the message names the file."""


@dataclass(frozen=True)
class BuildConfig:
    """Everything a build depends on; printed into asset.json provenance."""

    source: Path
    logs: tuple[Path, ...]
    output: Path = Path("out")
    holdout: Path | None = None
    material: str | None = None
    name: str | None = None
    method: Literal["newton", "ls"] = "newton"
    window_s: float = 0.1
    max_iterations: int = 30
    cache_dir: Path = Path.home() / ".cache" / "twin"


@dataclass
class StageTimer:
    """Wall time per stage, reported live through `log`."""

    log: Callable[[str], None]
    seconds: dict = field(default_factory=dict)

    def run(self, name: str, fn, *args, **kwargs):
        self.log(f"{name} ...")
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        self.seconds[name] = time.perf_counter() - t0
        self.log(f"{name} done in {self.seconds[name]:.1f} s")
        return out


def build(config: BuildConfig, log: Callable[[str], None] = print) -> Path:
    """Run every stage and write config.output atomically; returns the output directory."""
    from assets import (
        Asset, Estimate, Fit, Geometry, Material, Pose, Theta, asset_to_json, write_asset,
    )
    from assets.materials import material_range
    from exporters import export_all
    from pipelines.decompose import DecomposeConfig, decompose
    from pipelines.identify import IdentifyConfig, InertialBounds, identify_free_body, identify_least_squares
    from pipelines.logs import read_recording
    from pipelines.priors import uniform_density_prior
    from pipelines.validate import validate_exports

    t_start = time.perf_counter()
    timer = StageTimer(log)
    if not config.logs:
        raise BuildError("no recording given: pass --logs TRIAL.mcap")
    for path in (*config.logs, *((config.holdout,) if config.holdout else ())):
        if not Path(path).is_file():
            raise BuildError(f"{path}: recording not found")

    # Recordings are read first: they are quick, and a bad file should fail before minutes of geometry.
    trials = [timer.run(f"logs {p.name}", read_recording, p) for p in config.logs]
    holdout = timer.run(f"logs {config.holdout.name}", read_recording, config.holdout) if config.holdout else None
    mesh_world, name, hint, scan_stats = timer.run("scan + reconstruct", _object_mesh, config)
    name = config.name or name
    placement = Pose(tuple(mesh_world.center_mass), (0.0, 0.0, 0.0, 1.0))
    mesh_object = mesh_world.copy()
    mesh_object.apply_translation(-np.asarray(placement.position))

    parts = timer.run(
        "decompose", decompose, mesh_object, DecomposeConfig(), cache_dir=Path(config.cache_dir) / "coacd"
    )
    material = material_range(config.material or hint)
    prior = timer.run("priors", uniform_density_prior, mesh_object, material)

    X_tracked_body = tracked_to_object(trials[0], placement)

    bounds = InertialBounds(prior.lower, prior.upper)
    ls = timer.run("identify (least squares)", _least_squares, trials, X_tracked_body, identify_least_squares)
    start = _clip_into_bounds(ls.inertial, prior, bounds)
    id_config = IdentifyConfig(window_s=config.window_s, max_iterations=config.max_iterations)
    if config.method == "newton":
        windows = _windows(trials, id_config)
        progress = _progress_logger(log)
        result = timer.run(
            "identify (Newton)", identify_free_body, windows, X_tracked_body, start, bounds, id_config, progress
        )
        inertial, covariance, loss_history = result.inertial, result.covariance, result.loss_history
        method_info = result.provenance()
    else:
        inertial, covariance, loss_history = ls.inertial, ls.covariance, ()
        method_info = {"cutoff_hz": ls.cutoff_hz, "samples": ls.sample_count}

    # With a held-out recording, least squares and the Newton fit compete on predicting it.
    evaluation = holdout or trials[0]
    candidates = {"baseline": prior.inertial, "least_squares": ls.inertial}
    if config.method == "newton":
        candidates["newton"] = inertial
    fits, impulse, traces = timer.run("fit quality", _fit_quality, evaluation, X_tracked_body, candidates, id_config)
    selected = config.method if config.method == "newton" else "least_squares"
    if holdout is not None and config.method == "newton" and _impulse_score(impulse, "least_squares") < \
            _impulse_score(impulse, "newton"):
        selected = "least_squares"
        inertial, covariance = ls.inertial, ls.covariance
        log("least squares predicts the held-out recording's impulses better than the Newton fit: keeping it")
    method_info["selected"] = selected
    method_info["candidates"] = {
        k: {"mass": v.mass, "com": list(v.com), "inertia": [list(r) for r in v.inertia]} for k, v in candidates.items()
    }
    method_info["heldout_fits"] = {k: asdict(v) | {"impulse_rms": impulse[k]} for k, v in fits.items()} \
        if holdout is not None else None
    fit_baseline, fit_final = fits["baseline"], fits[selected]
    traces = {"t_s": traces["t_s"], "measured_position": traces["measured_position"], "window_s": traces["window_s"],
              "baseline_position": traces["baseline_position"], "final_position": traces[f"{selected}_position"]}

    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    inertia_std = np.array([[std[4], std[7], std[8]], [std[7], std[5], std[9]], [std[8], std[9], std[6]]])
    ci = lambda v, s: (np.asarray(v) - 1.96 * np.asarray(s), np.asarray(v) + 1.96 * np.asarray(s))  # noqa: E731
    theta = Theta(
        mass=Estimate(inertial.mass, std[0], interval95=ci(inertial.mass, std[0]), prior=prior.provenance()),
        com=Estimate(inertial.com, tuple(std[1:4]), interval95=ci(inertial.com, std[1:4])),
        inertia=Estimate(inertial.inertia, inertia_std, interval95=ci(inertial.inertia, inertia_std)),
        friction=Estimate(
            material.friction, (material.friction_high - material.friction_low) / 4, source="prior",
            interval95=(material.friction_low, material.friction_high),
        ),
    )

    out = Path(config.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        (tmp / "meshes").mkdir()
        mesh_object.export(tmp / "meshes" / "visual.obj")
        collision = []
        for k, part in enumerate(parts.parts):
            rel = f"meshes/collision_{k:03d}.obj"
            part.export(tmp / rel)
            collision.append(rel)
        asset = Asset(
            name=name,
            kind="free",
            placement=placement,
            theta=theta,
            geometry=Geometry("meshes/visual.obj", tuple(collision)),
            material=Material(material.name, float(inertial.mass / mesh_object.volume), material.friction),
            fit=Fit(fit_baseline, fit_final, id_config.window_s),
        )
        paths = timer.run("export", export_all, asset, tmp)
        files = {**paths.to_json(relative_to=tmp), "report": "report.html"}
        validation = timer.run("validate", validate_exports, asset, tmp, files)
        provenance = {
            "config": json.loads(json.dumps(asdict(config), default=str)),
            "scan": scan_stats,
            "decompose": parts.stats | {"volume_union_m3": parts.volume_union_m3, "volume_mesh_m3": parts.volume_mesh_m3},
            "prior": prior.provenance(),
            "identify": {"method": config.method, **method_info},
            "tracked_frame_in_object": {"position": list(X_tracked_body.inverse().position),
                                        "quaternion_xyzw": list(X_tracked_body.inverse().quaternion_xyzw)},
            "validation": validation.to_json(),
            "timings_s": timer.seconds | {"total": time.perf_counter() - t_start},
        }
        asset = Asset(**{**asset.__dict__, "files": files, "provenance": provenance})
        write_asset(asset, tmp / "asset.json")
        from twin.report import write_report

        write_report(tmp / "report.html", asset_to_json(asset), loss_history, traces)
        _replace_dir(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    log(f"wrote {out}/ in {time.perf_counter() - t_start:.1f} s")
    return out


def _object_mesh(config: BuildConfig):
    """The watertight object mesh in world at its placement, its name, a material hint, stats."""
    import trimesh

    from pipelines.reconstruct import reconstruct
    from pipelines.scan import read_scan

    source = Path(config.source)
    if source.is_dir():
        scan = read_scan(source)
        rec = reconstruct(scan)
        stats = {"frames": len(scan.frames), "voxel_size_m": rec.voxel_size_m, **rec.stats}
        return rec.mesh, scan.name, scan.material_hint, stats
    if source.suffix.lower() in MESH_SUFFIXES and source.is_file():
        try:
            mesh = trimesh.load(source, force="mesh")
        except Exception as exc:  # trimesh raises many types for bad files
            raise BuildError(f"{source}: cannot read mesh ({exc})") from exc
        if not mesh.is_volume:
            raise BuildError(f"{source}: mesh is not watertight with consistent normals")
        return mesh, source.stem, None, {"mesh_file": str(source)}
    raise BuildError(f"{source}: not a scan directory or a mesh file ({', '.join(MESH_SUFFIXES)})")


def tracked_to_object(recording, placement):
    """The object frame in the tracked frame, from the scan placement and the first still poses.

    The object sits at its placement when the recording starts; poses in the
    first 0.1 s are averaged when they are still (spread under 1 mm), which
    beats the tracker's noise.
    """
    from scipy.spatial.transform import Rotation

    from assets import Pose

    pose = recording.pose
    first = pose.t_s <= pose.t_s[0] + 0.1
    if np.ptp(pose.position[first], axis=0).max() > 1e-3:
        first = np.zeros(len(pose.t_s), bool)
        first[0] = True
    position = pose.position[first].mean(axis=0)
    rotation = Rotation.from_quat(pose.quat_xyzw[first]).mean()
    T_world_tracked = Pose(tuple(position), tuple(rotation.as_quat()))
    return T_world_tracked.inverse() @ placement


def _least_squares(trials, X_tracked_body, identify_least_squares):
    rec = trials[0]
    return identify_least_squares(
        rec.pose.t_s, rec.pose.position, rec.pose.quat_xyzw, rec.wrench.t_s, rec.wrench.force, rec.wrench.torque,
        X_tracked_body,
    )


def _windows(recordings, id_config):
    from pipelines.identify import concat_windows, make_windows

    return concat_windows(
        [
            make_windows(r.pose.t_s, r.pose.position, r.pose.quat_xyzw, r.wrench.t_s, r.wrench.force,
                         r.wrench.torque, window_s=id_config.window_s, substeps=id_config.substeps)
            for r in recordings
        ]
    )


def _clip_into_bounds(inertial, prior, bounds):
    """The least-squares start moved inside C and made physical, or the prior if it cannot be."""
    from assets import Inertial

    m = float(np.clip(inertial.mass, bounds.lower[0], bounds.upper[0]))
    c = np.clip(inertial.com, bounds.lower[1:4], bounds.upper[1:4])
    I = np.asarray(inertial.inertia) * (m / inertial.mass)
    candidate = Inertial(m, c, I)
    d, _ = candidate.principal()
    if candidate.physical_violation() is not None or d[0] < 1e-3 * d[2]:
        return prior.inertial
    return candidate


def _fit_quality(recording, X_tracked_body, candidates: dict, id_config):
    """Windowed replay from measured states for each candidate body.

    Returns FitMetrics per candidate, its momentum-scaled RMS (position, rotation), and position traces.
    """
    from assets import FitMetrics
    from pipelines.identify.inertia import theta_from_physical
    from pipelines.identify.rollout import FreeBodyRollout

    windows = _windows([recording], id_config)
    rollout = FreeBodyRollout(windows, X_tracked_body)
    t = windows.t_start_s[None, :] + windows.dt_s * windows.substeps * np.arange(1, windows.sample_count + 1)[:, None]
    measured = windows.measured_position[1:]
    traces = {"t_s": t.T.reshape(-1).tolist(), "measured_position": measured.transpose(1, 0, 2).reshape(-1, 3).tolist(),
              "window_s": windows.window_s}
    fits, impulse = {}, {}
    for label, inertial in candidates.items():
        theta = theta_from_physical(inertial.mass, inertial.com, inertial.inertia_matrix())
        scaled = rollout.residuals(theta, momentum_scaled=True)
        impulse[label] = [float(np.sqrt(np.mean(np.sum(scaled[..., :3] ** 2, -1)))),
                          float(np.sqrt(np.mean(np.sum(scaled[..., 3:] ** 2, -1))))]
        r = rollout.residuals(theta, momentum_scaled=False)
        rp, rr = r[..., :3], r[..., 3:]
        fits[label] = FitMetrics(
            rmse_position_m=float(np.sqrt(np.mean(np.sum(rp**2, -1)))),
            rmse_rotation_rad=float(np.sqrt(np.mean(np.sum(rr**2, -1)))),
            loss=float(np.mean(np.sum(rp**2, -1) + np.sum(rr**2, -1))),
        )
        traces[f"{label}_position"] = (measured + rp).transpose(1, 0, 2).reshape(-1, 3).tolist()
    return fits, impulse, traces


def _impulse_score(impulse: dict, label: str) -> float:
    """Held-out error in momentum-scaled units (see eval_tracked_pose_error), relative to least squares.

    The plain pose error favours too-large inertia when the wrench is noisy;
    scaled by each candidate's own mass and inertia it ranks them without that bias.
    """
    ref = impulse["least_squares"]
    return sum((x / max(r, 1e-30)) ** 2 for x, r in zip(impulse[label], ref))


def _progress_logger(log):
    def progress(evaluation: int, loss: float):
        if evaluation == 1 or evaluation % 25 == 0:
            log(f"  evaluation {evaluation}: loss {loss:.6g}")
    return progress


def _replace_dir(new: Path, out: Path) -> None:
    """Move `new` to `out`; an existing `out` is swapped aside first and removed last."""
    old = None
    if out.exists():
        old = out.with_name(f".{out.name}.old-{time.time_ns()}")
        out.rename(old)
    new.rename(out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
