"""`twin build` for a free body: the object held and moved by hand or by a robot, its inertia identified
from the motion and the wrench, its missing physics looked for, and the held-out recording replayed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from assets import COM, FLAT_INERTIAL, MASS, MOMENTS, Estimate, Fit, Theta, symmetric_from_flat
from pipelines.validate import replay_held_mujoco, validate_exports
from twin.stages import Identified, Prepared, body_asset, kind_hint, log_diagnosis


def held_asset(p: Prepared) -> Identified:
    """Identify the held object's inertia, diagnose what the model lacks (the refit with it kept), and
    combine a weighed mass."""
    from pipelines.diagnose import diagnose
    from pipelines.identify import (
        HeldBody, IdentifyConfig, InertialBounds, identify_held, tracked_to_object, with_weighed_mass,
    )
    from pipelines.priors import part_pseudo_inertias

    config, prior, timer, log = p.config, p.prior, p.timer, p.log
    X_tracked_body = tracked_to_object(p.trials[0], p.placement)
    id_config = IdentifyConfig(window_s=config.window_s, max_iterations=config.max_iterations,
                               optimizer=config.optimizer)
    with kind_hint(p.detection, p.trials[0]):
        held = timer.run(
            "identify", identify_held, p.trials, p.holdout, X_tracked_body, prior.inertial,
            InertialBounds(prior.lower, prior.upper), id_config, config.method, _progress_logger(log),
            parts=part_pseudo_inertias(p.parts.parts),
        )
    log(f"  kept the {held.choice}")
    inertial, covariance = held.inertial, held.covariance
    dominated = set(held.prior_dominated)
    fit_baseline, fit_final = held.fits["baseline"], held.fits[held.selected]
    subject = HeldBody(X_tracked_body, prior.uniform, config.window_s)
    diagnosis = None
    if config.diagnose:
        diagnosis, refit = timer.run("diagnose", diagnose, subject, p.trials, p.holdout, config.diagnosis)
        log_diagnosis(diagnosis, log)
        if refit is not None:
            # the identification lacked the effect, so its estimate is biased: the refit with it is kept
            inertial, covariance, dominated = refit.inertial, refit.covariance, set(refit.prior_dominated)
            fit_final = diagnosis.fits["after_unsmoothed"]  # measured as the identification's replays

    if config.mass_kg is not None:
        inertial, covariance = with_weighed_mass(inertial, covariance, *config.mass_kg)
        log(f"  with the weighed {config.mass_kg[0]:.4g} kg: mass {inertial.mass:.4g} kg")
    theta = _held_theta(inertial, covariance, dominated, prior)
    fit = Fit(fit_baseline, fit_final, id_config.window_s)
    provenance = {
        "identify": {"method": config.method, **held.provenance()},
        **({"diagnose": diagnosis.provenance()} if diagnosis else {}),
        "subject": subject.to_json(),
    }
    recording = p.holdout or p.trials[0]

    def replay(asset, tmp: Path, files: dict) -> dict:
        return replay_free(p, tmp / files["mjcf"], asset, recording, X_tracked_body, fit.window_s, diagnosis)

    return Identified(
        asset=body_asset(p, theta, fit, diagnosis, dominated, provenance),
        provenance=provenance,
        decompose=p.parts.stats | {"volume_union_m3": p.parts.volume_union_m3,
                                   "volume_mesh_m3": p.parts.volume_mesh_m3},
        validate=lambda asset, tmp, files: timer.run("validate", validate_exports, asset, tmp, files).to_json(),
        replay=replay,
        report=(held.loss_history, held.traces, diagnosis.traces if diagnosis else None),
    )


def _held_theta(inertial, covariance, dominated: set, prior) -> Theta:
    """theta with its standard deviations and 95 % intervals; friction is the prior's (a held object never
    slides). A quantity whose every component the recordings left to the geometry prior is the prior's."""
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    inertia_std = symmetric_from_flat(std)
    ci = lambda v, s: (np.asarray(v) - 1.96 * np.asarray(s), np.asarray(v) + 1.96 * np.asarray(s))  # noqa: E731
    source = lambda names: "prior" if dominated >= set(names) else "measured"  # noqa: E731
    return Theta(
        mass=Estimate(inertial.mass, std[MASS], source=source(FLAT_INERTIAL[:1]),
                      interval95=ci(inertial.mass, std[MASS]), prior=prior.provenance()),
        com=Estimate(inertial.com, tuple(std[COM]), source=source(FLAT_INERTIAL[COM]),
                     interval95=ci(inertial.com, std[COM])),
        inertia=Estimate(inertial.inertia, inertia_std, source=source(FLAT_INERTIAL[MOMENTS.start:]),
                         interval95=ci(inertial.inertia, inertia_std)),
        friction=Estimate(
            prior.friction[0], (prior.friction[2] - prior.friction[1]) / 4, source="prior",
            interval95=(prior.friction[1], prior.friction[2]),
        ),
    )


def replay_free(p: Prepared, mjcf_path, asset, recording, X_tracked_body, window_s, diagnosis) -> dict:
    """The exported MJCF replaying the evaluation recording in MuJoCo beside Newton's replay of the fit, and
    both against the sensors' noise alone: the best any model could do on this recording."""
    from pipelines.diagnose import without_recording_effects

    # the recording's own effects are taken off it, as the Newton replay of the fit does
    recording = without_recording_effects(recording, [(e.name, e.params) for e in asset.effects])
    mujoco = p.timer.run("replay (MuJoCo)", replay_held_mujoco, mjcf_path, asset, recording, X_tracked_body, window_s)
    newton = asset.fit.final.rmse_position_m
    floor = diagnosis.noise_floor["unsmoothed"]["rmse_position_m"] if diagnosis and diagnosis.noise_floor else None
    p.log(f"replay of {Path(recording.path).name}: MuJoCo "
          f"{1000 * mujoco['rmse_position_m']:.3f} mm, Newton {1000 * newton:.3f} mm"
          + (f", the sensors' noise alone {1000 * floor:.3f} mm" if floor else ""))
    return {"recording": str(recording.path), "mujoco": mujoco, "newton": {"rmse_position_m": newton},
            "mujoco_over_newton": mujoco["rmse_position_m"] / newton if newton > 0 else None,
            "noise_floor_m": floor, "mujoco_over_noise_floor": mujoco["rmse_position_m"] / floor if floor else None}


def _progress_logger(log):
    def progress(iteration: int, loss: float):
        # Levenberg-Marquardt takes a handful of iterations; the paper's optimizer takes hundreds of steps
        if iteration <= 10 or iteration % 25 == 0:
            log(f"  iteration {iteration}: loss {loss:.6g}")
    return progress
