"""`twin build`: scan or mesh plus recordings in, identified and validated assets out.

The stages run in order; each is a function of typed inputs. The shared ones (the inputs, the kind, the
object mesh, its convex parts and the prior) make a `Prepared`; the kind's identification and diagnosis
(twin/held.py, twin/pushed.py, twin/jointed.py) turn it into an `Identified`, which the export, validation,
replay and writing stages take. Outputs go to a temporary directory beside OUT and replace it only when
everything is written and validated, so a failed build leaves a previous OUT untouched.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path
from typing import Callable

import numpy as np

from assets import Pose, asset_to_json
from exporters import export_all
from pipelines.decompose import decompose
from pipelines.meshes import read_mesh
from pipelines.reconstruct import reconstruct
from pipelines.scan import read_scan
from pipelines.sessions import SessionsConfig, merge_sessions
from twin.checks import check_build
from twin.diagnose import DiagnoseRunConfig, diagnose_output
from twin.held import held_asset
from twin.jointed import jointed_asset
from twin.output import staged_output
from twin.pushed import pushed_asset
from twin.stages import (
    BuildConfig, BuildError, Identified, MaterialChoice, Prepared, StageTimer, choose_material, kind_hint,
    quiet_warp, weighed_where_prior,
)
from twin.write import log_summary, output_files, write_meshes, write_results

__all__ = [
    "BuildConfig", "BuildError", "DiagnoseRunConfig", "MaterialChoice", "StageTimer", "build", "choose_material",
    "diagnose_output", "kind_hint", "log_summary", "quiet_warp", "staged_output", "weighed_where_prior",
]


def build(config: BuildConfig, log: Callable[[str], None] = print) -> Path:
    """Run every stage and write config.output atomically; returns the output directory."""
    check_build(config)  # within the first second, before the heavy imports
    quiet_warp()
    from pipelines.identify import detect_kind

    timer = StageTimer(log)
    # The inputs are read first: they are quick, and a bad file should fail before minutes of geometry.
    source = timer.run("scan" if Path(config.source).is_dir() else "mesh", _read_source, config)
    choice = choose_material(config.material, source[0].material_hint if isinstance(source, list) else None, log)
    trials = [timer.run(f"logs {p.name}", config.read, p) for p in config.logs]
    holdout = timer.run(f"logs {config.holdout.name}", config.read, config.holdout) if config.holdout else None
    detection = timer.run("kind", detect_kind, trials[0], config.kind)
    log(f"motion: {detection.kind}" + (" (--kind)" if detection.forced else f" (BIC {detection.bic})"))
    mesh_world, name, scan_stats = _reconstruct(config, source, timer, log)
    placement, mesh = _placed(mesh_world)
    parts = timer.run("decompose", decompose, mesh, config.decompose, cache_dir=Path(config.cache_dir) / "coacd")
    name = config.name or name
    prior, choice = _prior(config, mesh, name, choice, timer, log)
    prepared = Prepared(config, trials, holdout, detection, mesh, placement, parts, prior, choice, name, scan_stats,
                        timer, log)

    identified = _identify_for(detection)(prepared)

    out = Path(config.output)
    with staged_output(out, config.force) as tmp:
        write_meshes(tmp, mesh, parts, identified.base_mesh, config.mesh_units)
        paths = timer.run("export", export_all, identified.asset, tmp)
        files = output_files(paths, tmp, identified)
        validation = identified.validate(identified.asset, tmp, files)
        replay = identified.replay(identified.asset, tmp, files)
        asset = write_results(tmp, prepared, identified, files, validation, replay)
    log_summary(asset_to_json(asset), log)
    log(f"wrote {out}/{identified.note} in {timer.elapsed():.1f} s")
    return out


def _reconstruct(config: BuildConfig, source, timer: StageTimer, log):
    """The object mesh in world, its name and stats; each further scan session's registration logged."""
    mesh_world, name, scan_stats = timer.run("reconstruct", _object_mesh, config, source)
    for session in scan_stats.get("sessions", [])[1:]:
        r = session["registration"]
        log(f"session {session['root']}: registered with fitness {r['fitness']:.3f}, RMSE {1000 * r['rmse_m']:.2f} mm")
    return mesh_world, name, scan_stats


def _identify_for(detection) -> Callable[[Prepared], Identified]:
    """The kind's identification and diagnosis: a part on a joint, a pushed body, or a free one."""
    if detection.joint is not None:
        return jointed_asset
    return pushed_asset if detection.kind == "sliding" else held_asset


def _placed(mesh_world):
    """The object frame (at the mesh's centre of mass, axes of world) and the mesh in it."""
    placement = Pose(tuple(mesh_world.center_mass), (0.0, 0.0, 0.0, 1.0))
    mesh = mesh_world.copy()
    mesh.apply_translation(-np.asarray(placement.position))
    return placement, mesh


def _prior(config: BuildConfig, mesh, name: str, choice: MaterialChoice, timer: StageTimer, log):
    """The geometry prior from the material and, with --vlm, a vision-language model's guess; the choice
    says "vlm" where the model's material made the prior."""
    from pipelines.priors import VlmConfig, ask_vlm, describe_object, estimate_prior, scan_image

    named = choice.entry.name if choice.entry else None
    guess = None
    if config.vlm:  # any failure is a warning and None: the build goes on with the offline prior
        vlm = VlmConfig(url=config.vlm, model=config.vlm_model, cache_dir=Path(config.cache_dir) / "vlm")
        guess = timer.run("vlm", ask_vlm, vlm, scan_image(config.source), describe_object(mesh, name, named))
        log(f"VLM: {guess.material}, {guess.mass_kg} kg, confidence {guess.confidence}" if guess else
            "VLM: no usable answer; using the offline prior")
    prior = timer.run("priors", estimate_prior, mesh, choice.entry, guess, weighed=config.mass_kg)
    if choice.entry is None and prior.details["fusion"]["material_from"] == "vlm":
        choice = replace(choice, source="vlm")
    return prior, choice


def _read_source(config: BuildConfig):
    """The scan sessions (read and checked, not yet fused) or the mesh of SOURCE: quick, so a bad file
    fails before the recordings are classified and minutes before the reconstruction would."""
    source = Path(config.source)
    if source.is_dir():
        return [read_scan(p) for p in (source, *config.scans)]
    return read_mesh(source, config.mesh_units or "m")


def _object_mesh(config: BuildConfig, source):
    """The watertight object mesh in world at its placement, its name and stats."""
    if not isinstance(source, list):
        return source, Path(config.source).stem, {"mesh_file": str(config.source),
                                                  "mesh_units": config.mesh_units or "m"}
    if len(source) > 1:
        sessions_config = SessionsConfig()
        rec = merge_sessions(source, sessions_config)
        stats = {"config": asdict(sessions_config), "frames": sum(len(s.frames) for s in source),
                 "voxel_size_m": rec.voxel_size_m, **rec.stats}
        return rec.mesh, source[0].name, stats
    scan = source[0]
    rec = reconstruct(scan, config.reconstruct)
    stats = {"config": asdict(config.reconstruct), "frames": len(scan.frames), "voxel_size_m": rec.voxel_size_m,
             **rec.stats}
    return rec.mesh, scan.name, stats
