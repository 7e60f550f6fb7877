"""`twin build` for drawers and doors: the part on the joint its motion shows, a fixed base, joint physics."""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

LIMIT_MARGIN = 0.1
"""Joint limits: the observed travel widened by this share of it on each side (plus 5 mm or 0.05 rad)."""


def joint_limits(joint_type: str, q_observed: np.ndarray) -> tuple[float, float]:
    lo, hi = float(np.min(q_observed)), float(np.max(q_observed))
    pad = LIMIT_MARGIN * (hi - lo) + (0.005 if joint_type == "prismatic" else 0.05)
    return lo - pad, hi + pad


def _prior_estimate(value, lower, upper, prior_doc=None):
    """A quantity taken from the prior: its 95 % interval is the prior's bounds C."""
    from assets import Estimate

    if np.ndim(value) == 0:
        return Estimate(float(value), float((upper - lower) / 4), source="prior",
                        interval95=(float(lower), float(upper)), prior=prior_doc)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    return Estimate(value, (upper - lower) / 4, source="prior", interval95=(lower, upper), prior=prior_doc)


def jointed_theta(identified, prior, joint_type: str):
    """theta of the part: measured where the joint's motion determines it, prior elsewhere."""
    from assets import Estimate, Theta

    inertial = identified.inertial
    lo, hi = np.asarray(prior.lower), np.asarray(prior.upper)
    ci = lambda v, s: (float(v - 1.96 * s), float(v + 1.96 * s))  # noqa: E731
    friction = Estimate(identified.value("friction"), identified.std("friction"),
                        interval95=ci(identified.value("friction"), identified.std("friction")))
    # the tensor is the prior's, scaled by what was measured (mass, or the moment about the axis)
    scale = inertial.inertia_matrix()[0, 0] / prior.inertial.inertia_matrix()[0, 0]
    inertia = _prior_estimate(inertial.inertia, np.diag(lo[4:7] * scale), np.diag(hi[4:7] * scale))
    if joint_type == "prismatic":
        m, s = identified.value("mass"), identified.std("mass")
        return Theta(Estimate(m, s, interval95=ci(m, s), prior=prior.provenance()),
                     _prior_estimate(inertial.com, lo[1:4], hi[1:4]), inertia, friction)
    determined = [("axis_inertia", Estimate(identified.value("axis_inertia"), identified.std("axis_inertia"),
                                            interval95=ci(identified.value("axis_inertia"),
                                                          identified.std("axis_inertia"))))]
    if "gravity_moment_e1" in identified.names:
        i = [identified.names.index("gravity_moment_e1"), identified.names.index("gravity_moment_e2")]
        md = identified.values[i]
        g = np.linalg.norm(md)
        s = float(np.sqrt(md @ identified.covariance[np.ix_(i, i)] @ md) / max(g, 1e-12))
        determined.append(("gravity_moment", Estimate(g, s, interval95=ci(g, s))))
    mass = _prior_estimate(prior.inertial.mass, lo[0], hi[0], prior.provenance())
    return Theta(mass, _prior_estimate(inertial.com, lo[1:4], hi[1:4]), inertia, friction, tuple(determined))


def build_jointed(config, trials, holdout, detection, mesh_object, placement, parts, prior, choice, name,
                  scan_stats, timer, log, t_start) -> Path:
    """Identify the part on its joint, look for missing passive joint forces, export base + part + joint,
    validate, replay the held-out trial in MuJoCo."""
    from assets import Asset, Fit, FitMetrics, Geometry, Joint, asset_to_json, write_asset
    from exporters import export_all
    from pipelines.identify.jointed import JointedConfig, identify_jointed, joint_windows, q_and_position_rmse
    from pipelines.identify.kind import joint_coordinates
    from pipelines.meshes import read_mesh
    from pipelines.validate import replay_jointed_mujoco, validate_jointed_exports

    from .build import _log_diagnosis, _write_meshes, kind_hint, log_summary, weighed_where_prior
    from .summary import bounds_flags, doubtful_flags, extent_flags
    from .output import staged_output

    fit = detection.joint
    jconfig = JointedConfig()
    with kind_hint(detection, trials[0]):
        identified = timer.run("identify (Featherstone)", identify_jointed, trials, fit, placement, prior.inertial,
                               holdout, jconfig)
    diagnosis, kept, diagnosis_skipped = None, identified, None
    if config.diagnose:
        from pipelines.diagnose import DiagnoseConfig, diagnose_jointed

        try:
            diagnosis, refit = timer.run("diagnose", diagnose_jointed, trials, holdout, fit, placement,
                                         prior.inertial, jconfig, DiagnoseConfig())
        except ValueError as exc:  # e.g. trial halves too short for one window each: the identified build stands
            log(f"diagnose skipped: {exc}")
            diagnosis_skipped = str(exc)
        else:
            _log_diagnosis(diagnosis, log)
            # the identification lacked the effect, so its estimate is biased: the refit with it is kept
            kept = refit or identified
    found = {e.name: e.params for e in diagnosis.effects} if diagnosis else {}
    # every recording shows travel the part can make, the held-out one too
    q_all = np.concatenate([joint_coordinates(fit, t.pose) for t in (*trials, *filter(None, [holdout]))])
    lower, upper = joint_limits(fit.type, q_all)
    spring = found.get("spring", {"k": 0.0, "q0": 0.0})
    joint = Joint(fit.type, tuple(fit.axis), tuple(fit.origin), lower, upper,
                  damping=found.get("viscous_damping", {"b": 0.0})["b"], stiffness=spring["k"], spring_ref=spring["q0"],
                  axis_std_rad=fit.axis_std_rad, origin_std_m=tuple(fit.origin_std_m))
    theta = weighed_where_prior(jointed_theta(kept, prior, fit.type), config.mass_kg)
    held = identified.fits.get("holdout", {})
    metrics = lambda d: FitMetrics(d["rmse_position_m"], d["rmse_q"] if fit.type == "revolute" else 0.0,  # noqa: E731
                                   d["rmse_q"])
    out = Path(config.output)
    with staged_output(out, config.force) as tmp:
        collision = _write_meshes(tmp, mesh_object, parts)
        base = None
        if config.base_mesh:
            read_mesh(config.base_mesh, config.mesh_units or "m", solid=False).export(tmp / "meshes" / "base.obj")
            base = "meshes/base.obj"
        asset = Asset(
            name=name, kind=fit.type, placement=placement, theta=theta,
            geometry=Geometry("meshes/visual.obj", collision, base, scan_stats.get("extent")),
            material=choice.material(prior.material.name, float(theta.mass.value / mesh_object.volume),
                                     prior.friction[0]),
            joint=joint,
            fit=Fit(metrics(held["prior"]), diagnosis.fits["after"] if kept is not identified else
                    metrics(held[identified.selected]), jconfig.window_s) if held else None,
            effects=diagnosis.effects if diagnosis else (),
            unexplained=diagnosis.unexplained if diagnosis else (),
            flags=(bounds_flags(theta, prior.lower, prior.upper) + extent_flags(scan_stats.get("extent"))
                   + doubtful_flags(diagnosis.doubtful if diagnosis else ())),
        )
        paths = timer.run("export", export_all, asset, tmp)
        files = {**paths.to_json(relative_to=tmp), **({"report": "report.html"} if identified.traces else {})}
        validation = timer.run("validate", validate_jointed_exports, asset, tmp, files)
        replay = {}
        if holdout is not None:
            mujoco = timer.run("replay (MuJoCo)", replay_jointed_mujoco, paths.mjcf, asset, holdout, fit, jconfig)
            # the tracker's noise about the smoothed track: what no model's replay of it can go below
            w = joint_windows(holdout, fit, jconfig)
            floor = q_and_position_rmse(fit, w.q_smoothed[1:], w.q[1:])["rmse_position_m"]
            replay = {"mujoco": mujoco,
                      "newton": held[identified.selected] if kept is identified else
                      {"rmse_q": diagnosis.fits["after"].loss,
                       "rmse_position_m": diagnosis.fits["after"].rmse_position_m},
                      "noise_floor_m": floor, "mujoco_over_noise_floor": mujoco["rmse_position_m"] / floor}
            log(f"held-out replay: MuJoCo {1000 * mujoco['rmse_position_m']:.3f} mm, Newton "
                f"{1000 * replay['newton']['rmse_position_m']:.3f} mm, the tracker's noise alone {1000 * floor:.3f} mm")
        provenance = {
            "config": json.loads(json.dumps(asdict(config), default=str)),
            "scan": scan_stats,
            "decompose": parts.stats,
            "prior": prior.provenance(),
            "kind": detection.to_json(),
            "identify": {"method": "featherstone", "config": asdict(jconfig), **identified.provenance()},
            **({"diagnose": diagnosis.provenance() | {"refit": kept.provenance()}} if kept is not identified else
               {"diagnose": diagnosis.provenance()} if diagnosis else
               {"diagnose": {"skipped": diagnosis_skipped}} if diagnosis_skipped else {}),
            "validation": validation,
            "heldout_replay": replay,
            "timings_s": timer.seconds | {"total": time.perf_counter() - t_start},
        }
        asset = Asset(**{**asset.__dict__, "files": files, "provenance": provenance})
        write_asset(asset, tmp / "asset.json")
        if identified.traces:
            from twin.report import write_report

            tr = identified.traces
            write_report(tmp / "report.html", asset_to_json(asset), identified.loss_history, {
                "t_s": tr["t_s"].reshape(-1), "window_s": jconfig.window_s,
                "measured_position": fit.tracked_position(tr["measured"]).reshape(-1, 3),
                "baseline_position": fit.tracked_position(tr["prior"]).reshape(-1, 3),
                "final_position": fit.tracked_position(tr["kept"]).reshape(-1, 3),
            }, diagnosis.traces if diagnosis else None)
    log_summary(asset_to_json(asset), log)
    log(f"wrote {out}/ ({fit.type} joint) in {time.perf_counter() - t_start:.1f} s")
    return out
