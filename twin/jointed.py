"""`twin build` for drawers and doors: the part on the joint its motion shows, a fixed base, joint physics."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from assets import COM, MASS, MOMENTS, Asset, Estimate, Fit, FitMetrics, Joint, Theta
from pipelines.validate import replay_jointed_mujoco, validate_jointed_exports
from twin.stages import Identified, Prepared, kind_hint, log_diagnosis, weighed_where_prior
from twin.summary import bounds_flags, disagreement_flags, doubtful_flags, extent_flags
from twin.write import mesh_geometry

LIMIT_MARGIN = 0.1
"""Joint limits: the observed travel widened by this share of it on each side (plus 5 mm or 0.05 rad)."""


def joint_limits(joint_type: str, q_observed: np.ndarray) -> tuple[float, float]:
    lo, hi = float(np.min(q_observed)), float(np.max(q_observed))
    pad = LIMIT_MARGIN * (hi - lo) + (0.005 if joint_type == "prismatic" else 0.05)
    return lo - pad, hi + pad


def _prior_estimate(value, lower, upper, prior_doc=None):
    """A quantity taken from the prior: its 95 % interval is the prior's bounds C."""
    if np.ndim(value) == 0:
        return Estimate(float(value), float((upper - lower) / 4), source="prior",
                        interval95=(float(lower), float(upper)), prior=prior_doc)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    return Estimate(value, (upper - lower) / 4, source="prior", interval95=(lower, upper), prior=prior_doc)


def jointed_theta(identified, prior, joint_type: str):
    """theta of the part: measured where the joint's motion determines it, prior elsewhere."""
    inertial = identified.inertial
    lo, hi = np.asarray(prior.lower), np.asarray(prior.upper)
    ci = lambda v, s: (float(v - 1.96 * s), float(v + 1.96 * s))  # noqa: E731
    friction = Estimate(identified.value("friction"), identified.std("friction"),
                        interval95=ci(identified.value("friction"), identified.std("friction")))
    # the tensor is the prior's, scaled by what was measured (mass, or the moment about the axis)
    scale = inertial.inertia_matrix()[0, 0] / prior.inertial.inertia_matrix()[0, 0]
    inertia = _prior_estimate(inertial.inertia, np.diag(lo[MOMENTS] * scale), np.diag(hi[MOMENTS] * scale))
    if joint_type == "prismatic":
        m, s = identified.value("mass"), identified.std("mass")
        return Theta(Estimate(m, s, interval95=ci(m, s), prior=prior.provenance()),
                     _prior_estimate(inertial.com, lo[COM], hi[COM]), inertia, friction)
    determined = [("axis_inertia", Estimate(identified.value("axis_inertia"), identified.std("axis_inertia"),
                                            interval95=ci(identified.value("axis_inertia"),
                                                          identified.std("axis_inertia"))))]
    if "gravity_moment_e1" in identified.names:
        i = [identified.names.index("gravity_moment_e1"), identified.names.index("gravity_moment_e2")]
        md = identified.values[i]
        g = np.linalg.norm(md)
        s = float(np.sqrt(md @ identified.covariance[np.ix_(i, i)] @ md) / max(g, 1e-12))
        determined.append(("gravity_moment", Estimate(g, s, interval95=ci(g, s))))
    mass = _prior_estimate(prior.inertial.mass, lo[MASS], hi[MASS], prior.provenance())
    return Theta(mass, _prior_estimate(inertial.com, lo[COM], hi[COM]), inertia, friction, tuple(determined))


def jointed_asset(p: Prepared) -> Identified:
    """Identify the part on its joint, look for missing passive joint forces; the asset exports base + part +
    joint, its validation reloads them, its replay runs the held-out trial in MuJoCo."""
    from pipelines.identify import (
        JointedConfig, JointedPart, identify_jointed, joint_body, joint_coordinates, joint_windows,
        q_and_position_rmse, replay_jointed,
    )

    config, prior, timer, log, holdout = p.config, p.prior, p.timer, p.log, p.holdout
    fit = p.detection.joint
    jconfig = JointedConfig()
    subject = JointedPart(fit, p.placement, prior.inertial, jconfig)
    with kind_hint(p.detection, p.trials[0]):
        identified = timer.run("identify (Featherstone)", identify_jointed, p.trials, fit, p.placement,
                               prior.inertial, holdout, jconfig)
    diagnosis, kept, diagnosis_skipped = None, identified, None
    if config.diagnose:
        from pipelines.diagnose import diagnose

        try:
            diagnosis, refit = timer.run("diagnose", diagnose, subject, p.trials, holdout, config.diagnosis)
        except ValueError as exc:  # e.g. trial halves too short for one window each: the identified build stands
            log(f"diagnose skipped: {exc}")
            diagnosis_skipped = str(exc)
        else:
            log_diagnosis(diagnosis, log)
            # the identification lacked the effect, so its estimate is biased: the refit with it is kept
            kept = refit or identified
    found = {e.name: e.params for e in diagnosis.effects} if diagnosis else {}
    # every recording shows travel the part can make, the held-out one too
    q_all = np.concatenate([joint_coordinates(fit, t.pose) for t in (*p.trials, *filter(None, [holdout]))])
    lower, upper = joint_limits(fit.type, q_all)
    spring = found.get("spring", {"k": 0.0, "q0": 0.0})
    joint = Joint(fit.type, tuple(fit.axis), tuple(fit.origin), lower, upper,
                  damping=found.get("viscous_damping", {"b": 0.0})["b"], stiffness=spring["k"], spring_ref=spring["q0"],
                  axis_std_rad=fit.axis_std_rad, origin_std_m=tuple(fit.origin_std_m),
                  friction_grip_s=kept.friction_grip_s())
    theta = weighed_where_prior(jointed_theta(kept, prior, fit.type), config.mass_kg)
    held = identified.fits.get("holdout", {})
    if held:
        kept_replay = held[identified.selected]
        if kept is not identified:
            # the refit replayed as the identification replays its own (its windows, measured starts): beside
            # the MuJoCo replay and a build without an effect, like for like
            body = joint_body(fit, p.placement, prior.inertial, jconfig, tuple(found))
            kept_replay = replay_jointed(holdout, fit, p.placement, prior.inertial, body, kept.values, jconfig)[0]
        held = {**held, "kept": kept_replay}
    metrics = lambda d: FitMetrics(d["rmse_position_m"], d["rmse_q"] if fit.type == "revolute" else 0.0,  # noqa: E731
                                   d["rmse_q"])
    asset = Asset(
        name=p.name, kind=fit.type, placement=p.placement, theta=theta,
        geometry=mesh_geometry(p.parts, p.scan_stats.get("extent"), config.base_mesh),
        material=p.choice.material(prior.material.name, float(theta.mass.value / p.mesh.volume), prior.friction[0]),
        joint=joint,
        fit=Fit(metrics(held["prior"]), metrics(held["kept"]), jconfig.window_s) if held else None,
        effects=diagnosis.effects if diagnosis else (),
        unexplained=diagnosis.unexplained if diagnosis else (),
        flags=(bounds_flags(theta, prior.lower, prior.upper) + extent_flags(p.scan_stats.get("extent"))
               + doubtful_flags(diagnosis.doubtful if diagnosis else ())
               + disagreement_flags(kept.doubtful, kept.disagreement)),
    )

    def replay(asset, tmp: Path, files: dict) -> dict:
        if holdout is None:
            return {}
        mujoco = timer.run("replay (MuJoCo)", replay_jointed_mujoco, tmp / files["mjcf"], asset, holdout, fit,
                           jconfig)
        # the tracker's noise about the smoothed track: what no model's replay of it can go below
        w = joint_windows(holdout, fit, jconfig)
        floor = q_and_position_rmse(fit, w.q_smoothed[1:], w.q[1:])["rmse_position_m"]
        result = {"mujoco": mujoco, "newton": held["kept"], "noise_floor_m": floor,
                  "mujoco_over_noise_floor": mujoco["rmse_position_m"] / floor}
        log(f"held-out replay: MuJoCo {1000 * mujoco['rmse_position_m']:.3f} mm, Newton "
            f"{1000 * result['newton']['rmse_position_m']:.3f} mm, the tracker's noise alone {1000 * floor:.3f} mm")
        return result

    report = None
    if identified.traces:
        tr = identified.traces
        report = (identified.loss_history, {
            "t_s": tr["t_s"].reshape(-1), "window_s": jconfig.window_s,
            "measured_position": fit.tracked_position(tr["measured"]).reshape(-1, 3),
            "baseline_position": fit.tracked_position(tr["prior"]).reshape(-1, 3),
            "final_position": fit.tracked_position(tr["kept"]).reshape(-1, 3),
        }, diagnosis.traces if diagnosis else None)
    return Identified(
        asset=asset,
        provenance={
            "identify": {"method": "featherstone", "config": asdict(jconfig), **identified.provenance()},
            "subject": subject.to_json(),
            **({"diagnose": diagnosis.provenance() | {"refit": kept.provenance()}} if kept is not identified else
               {"diagnose": diagnosis.provenance()} if diagnosis else
               {"diagnose": {"skipped": diagnosis_skipped}} if diagnosis_skipped else {}),
        },
        decompose=p.parts.stats,
        validate=lambda asset, tmp, files: timer.run("validate", validate_jointed_exports, asset, tmp, files),
        replay=replay,
        report=report,
        base_mesh=config.base_mesh,
        note=f" ({fit.type} joint)",
    )
