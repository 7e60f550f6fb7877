"""`twin build` for a pushed body: an object slid over a table, its friction (and what the pushes determine of
its mass and I_zz) identified, its missing physics looked for, and the pushes replayed in the exported scene."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from assets import FLAT_INERTIAL, MASS, Estimate, Fit, FitMetrics, Theta
from pipelines.validate import replay_pushed_mujoco, validate_exports
from twin.stages import Identified, Prepared, body_asset, kind_hint, log_diagnosis, weighed_where_prior


def pushed_asset(p: Prepared) -> Identified:
    """Identify the pushed object on the support its pushes choose, diagnose what the model lacks (the refit
    with it kept), and combine a weighed mass where the pushes left the mass to the prior."""
    from pipelines.diagnose import diagnose
    from pipelines.identify import SUPPORTS, PushedBody, SlidingConfig, identify_pushed

    config, timer, log = p.config, p.timer, p.log
    body, mu_prior = sliding_body(p.mesh, p.prior)
    with kind_hint(p.detection, p.trials[0]):
        pushed = timer.run("identify", identify_pushed, p.trials, p.holdout, body, mu_prior,
                           SlidingConfig(moving_speed_m_s=config.push_min_speed_m_s), supports=SUPPORTS)
    # the support the pushes chose: the diagnosis, the replay and the export use it too
    sconfig = pushed.config
    subject = PushedBody(body, mu_prior, sconfig)
    if pushed.support is not None:
        log(f"  {pushed.support.words}")
    diagnosis, refit = None, None
    if config.diagnose:
        diagnosis, refit = timer.run("diagnose", diagnose, subject, p.trials, p.holdout, config.diagnosis)
        log_diagnosis(diagnosis, log)
    theta, fit, provenance, loss_history, traces = sliding_result(pushed, refit, diagnosis, body, p.prior)
    provenance["subject"] = subject.to_json()
    theta = weighed_where_prior(theta, config.mass_kg)
    log(f"  friction {theta.friction.value:.3f} +- {theta.friction.std:.3f} "
        f"({provenance['identify']['friction_from']})")
    recording = p.holdout or p.trials[0]

    def replay(asset, tmp: Path, files: dict) -> dict:
        return replay_pushed(p, tmp / files["scene"], asset, recording, fit.window_s, sconfig)

    return Identified(
        asset=body_asset(p, theta, fit, diagnosis, set(), provenance),
        provenance=provenance,
        decompose=p.parts.stats | {"volume_union_m3": p.parts.volume_union_m3,
                                   "volume_mesh_m3": p.parts.volume_mesh_m3},
        validate=lambda asset, tmp, files: timer.run("validate", validate_exports, asset, tmp, files).to_json(),
        replay=replay,
        report=(loss_history, traces, diagnosis.traces if diagnosis else None),
    )


def sliding_body(mesh_object, prior):
    """The pushed object as the sliding model sees it, and the prior's friction coefficient.

    The support face is the mesh's bounding box bottom (object frame, axes parallel to world at the scan);
    mass and I_zz spreads from the bounds C, taken as about +-2 std of the log.
    """
    from pipelines.identify import PlanarBody

    izz = FLAT_INERTIAL.index("Izz")
    mass_rel = float(np.log(prior.upper[MASS] / prior.lower[MASS]) / 4)
    izz_rel = float(np.log(prior.upper[izz] / prior.lower[izz]) / 4)
    body = PlanarBody(tuple(0.5 * (mesh_object.bounds[1] - mesh_object.bounds[0])), float(prior.inertial.mass),
                      float(np.asarray(prior.inertial.inertia)[2, 2]), mass_rel_std=mass_rel, izz_rel_std=izz_rel)
    return body, float(prior.friction_kinetic[0])


def sliding_result(pushed, refit, diagnosis, body, prior):
    """Theta, fit metrics, provenance, loss curve and traces of a pushed object.

    What the pushes leave undetermined keeps the prior's value and is marked "prior"; COM and the
    tilting moments always are, and so is I_zz where some window turns against its pushing moment (the
    fit's I_zz then stands in for what turns the object; `PushedIdentification.turns_explained`). With
    effects chosen by the diagnosis, its refit (mu and I_zz fitted with them) replaces the
    identification's, whose estimate lacked them, as for a free body.
    """
    fit = refit if refit is not None else pushed.fit
    inertia0 = np.asarray(prior.inertial.inertia, dtype=float)
    mass0 = float(prior.inertial.mass)
    (_, mass, izz), (_, mass_std, izz_std) = fit.theta, fit.std
    friction, friction_from = sliding_friction(fit, pushed.balance, prior)
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


def sliding_friction(fit, balance, prior):
    """The friction coefficient and what gave it (`measured_friction`); where neither the sliding fit nor the
    wrench balance measured it, the prior raised to the fit's bound, marked "prior" with the bound as its
    interval's low end."""
    from pipelines.identify import measured_friction

    measured = measured_friction(fit, balance)
    if measured is not None:
        mu, std, source = measured
        return Estimate(mu, std, interval95=(mu - 1.96 * std, mu + 1.96 * std)), source
    bound = float(fit.theta[0])
    central, _, high = map(float, prior.friction_kinetic)
    value = max(central, bound)
    return (Estimate(value, (max(high, value) - bound) / 4, source="prior", interval95=(bound, max(high, value))),
            "prior, above the sliding fit's bound")


def replay_pushed(p: Prepared, scene_path, asset, recording, window_s, sconfig) -> dict:
    """The exported MJCF in its scene (a plane carrying the identified friction) replaying the evaluation
    recording's pushes in MuJoCo, on the windows Newton's replay of the fit used."""
    mujoco = p.timer.run("replay (MuJoCo)", replay_pushed_mujoco, scene_path, asset, recording, window_s, sconfig)
    newton = asset.fit.final.rmse_position_m
    floor = mujoco["noise_floor_m"]
    p.log(f"replay of {Path(recording.path).name}: MuJoCo {1000 * mujoco['rmse_position_m']:.3f} mm, "
          f"Newton {1000 * newton:.3f} mm, the tracker's noise alone {1000 * floor:.3f} mm")
    return {"recording": str(recording.path), "mujoco": mujoco, "newton": {"rmse_position_m": newton},
            "noise_floor_m": floor, "mujoco_over_noise_floor": mujoco["rmse_position_m"] / floor if floor else None}
