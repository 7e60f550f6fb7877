"""`twin bench push-mit`: surface friction from the MIT pushing dataset's trials, mass known.

Every trial under ../shared/data/mit-push/mit_push_dataset (raw .h5 and .json,
read by pipelines/push_dataset.py as recorded) is fitted for mu alone, starting
from the quasi-static estimate: the
object's mass and yaw inertia are known (objects.json), so mu itself is
measured, not mu * m. Beside it, the quasi-static estimate (steady pushing
force over m g). Per object and surface: the spread across trials. Predictive
validity: for each trial of an object and surface, mu identified on the others
(leave one out: the set holds two or three trials per pair), its motion
predicted from its measured pusher force and contact point, in windows started
from measured states, against the prior's friction.

The pushes are slow (10 mm/s pusher, the object creeping at 1-3 mm/s), so the
simulation step is 0.1 ms: Newton's penalty friction sticks below mu g dt and
lets a stuck body creep at F dt / m, both of which must stay below the object's
speed for the fit to see Coulomb friction (sliding.py module docstring).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from twin.bench.push import DATA, net_yaw_deg

MIT_CONFIG = dict(dt_s=1e-4, moving_speed_m_s=1e-3)
"""SlidingConfig changes for the dataset's slow pushes: step [s] and the speed a window must exceed [m/s]."""


def _trial_files(root: Path) -> list[Path]:
    base = root / "mit_push_dataset"
    return sorted([*base.glob("h5_raw/*.h5"), *base.glob("json/*.json")])


def mit_body(root: Path, shape: str):
    """PlanarBody of a dataset object: its STL's footprint, objects.json's mass and planar inertia (both known).

    The STL's frame is the Vicon frame; for the symmetric shapes read here its
    origin is the centroid (mit-push README, section 3).
    """
    import trimesh

    from pipelines.identify.sliding import PlanarBody

    spec = json.loads((root / "objects.json").read_text())["objects"][shape]
    mesh = trimesh.load_mesh(root / spec["mesh_stl"])
    half = tuple(float(h) for h in mesh.extents / 2)
    return PlanarBody(half, spec["mass_kg"], spec["moment_of_inertia_kgm2"]), spec


def bench_push_mit(root: Path = DATA, figure: Path = Path("docs/push_prediction_mit.png")) -> dict:
    """Print per-trial mu (mass known), the quasi-static estimate, the spread per object and surface,
    and leave-one-out predictive validity; save the figure."""
    from assets.materials import material_range
    from pipelines.identify.sliding import (
        SlidingConfig, SlidingRollout, estimate_force_bias, identify_sliding, push_windows, quasi_static_friction,
        replay_errors,
    )
    from pipelines.push_dataset import PushTrialName, read_push_trial

    files = _trial_files(root)
    if not files:
        raise RuntimeError(f"{root / 'mit_push_dataset'}: no pushing-dataset trials (.h5 or .json) there")
    config = SlidingConfig(**MIT_CONFIG)
    mu_prior = material_range("stainless_steel").kinetic()[0]
    rows = []
    for path in files:
        t0 = time.perf_counter()
        name = PushTrialName.parse(path)
        body, _ = mit_body(root, name.shape)
        rec = read_push_trial(path)
        bias = estimate_force_bias(rec, config)
        row = {"trial": path.name, "pair": f"{name.shape}/{name.surface}", "name": name, "mass": body.mass_kg,
               "turn_deg": net_yaw_deg(rec),
               "bias_n": float(np.max(np.linalg.norm(bias.force_n[:, :2], axis=1), initial=0.0)),
               "bias_source": bias.source}
        try:
            windows = push_windows(rec, body, config, bias)
        except ValueError as exc:
            rows.append({**row, "skipped": str(exc).split(": ", 1)[1]})
            continue
        # the fit starts from the quasi-static estimate: from above the force balance the simulated
        # object sticks, where the gradient in mu is zero (newton.md), and a slow push never leaves it
        mu_qs = quasi_static_friction(rec, body, config, bias, body.mass_kg)
        fit = identify_sliding(windows, body, config, mu_prior=mu_qs, free=(True, False, False))
        rows.append({**row, "mu": float(fit.theta[0]), "mu_std": float(fit.std[0]), "windows": fit.window_count,
                     "mu_qs": mu_qs,
                     "rmse_mm": 1e3 * fit.rmse_position_m, "rmse_deg": float(np.degrees(fit.rmse_heading_rad)),
                     "seconds": time.perf_counter() - t0, "windows_data": windows, "body": body})

    fitted = [r for r in rows if "mu" in r]
    pairs = sorted({r["pair"] for r in fitted})
    summary, prediction = [], []
    for pair in pairs:
        group = [r for r in fitted if r["pair"] == pair]
        mus = np.array([r["mu"] for r in group])
        qs = np.array([r["mu_qs"] for r in group])
        cv = (lambda a: 100 * a.std(ddof=1) / a.mean() if len(a) > 1 else float("nan"))
        summary.append({"pair": pair, "trials": len(group), "mu_mean": mus.mean(), "mu_cv_pct": cv(mus),
                        "qs_mean": qs.mean(), "qs_cv_pct": cv(qs)})
        for r in group if len(group) > 1 else []:
            mu_fit = float(np.median([o["mu"] for o in group if o is not r]))
            body = r["body"]
            rollout = SlidingRollout(r["windows_data"], body, config)
            p_fit, h_fit = replay_errors(rollout, (mu_fit, body.mass_kg, body.izz_kgm2))
            p_prior, h_prior = replay_errors(rollout, (mu_prior, body.mass_kg, body.izz_kgm2))
            prediction.append({
                "block": pair, "trial": r["trial"], "mu_fit": mu_fit, "mu_prior": mu_prior,
                "pos_mm": 1e3 * p_fit, "pos_prior_mm": 1e3 * p_prior,
                "heading_deg": float(np.degrees(h_fit)), "heading_prior_deg": float(np.degrees(h_prior)),
                "traj_fit": rollout.trajectories((mu_fit, body.mass_kg, body.izz_kgm2)),
                "traj_prior": rollout.trajectories((mu_prior, body.mass_kg, body.izz_kgm2)),
                "measured": r["windows_data"].measured,
            })

    print(f"MIT pushing dataset ({root / 'mit_push_dataset'}): mu fitted with the mass and I_zz known "
          f"(objects.json), step {config.dt_s * 1e3:g} ms, prior mu {mu_prior} (stainless steel)")
    print(f"{'trial':78} {'m kg':>6} {'mu':>6} {'mu std':>6} {'mu qs':>6} {'win':>3} {'turn deg':>8} "
          f"{'bias N':>6} {'rmse mm':>7} {'rmse deg':>8} {'s':>5}")
    for r in rows:
        if "skipped" in r:
            print(f"{r['trial']:78} {r['mass']:6.3f} skipped: {r['skipped']} (turn {r['turn_deg']:.1f} deg)")
            continue
        print(f"{r['trial']:78} {r['mass']:6.3f} {r['mu']:6.3f} {r['mu_std']:6.3f} {r['mu_qs']:6.3f} "
              f"{r['windows']:3d} {r['turn_deg']:8.1f} {r['bias_n']:6.3f} {r['rmse_mm']:7.2f} {r['rmse_deg']:8.2f} "
              f"{r['seconds']:5.1f}")
    print("\nper object / surface:")
    print(f"{'pair':16} {'trials':>6} {'mu mean':>7} {'mu CV %':>7} {'qs mean':>7} {'qs CV %':>7}")
    for s in summary:
        print(f"{s['pair']:16} {s['trials']:6d} {s['mu_mean']:7.3f} {s['mu_cv_pct']:7.2f} {s['qs_mean']:7.3f} "
              f"{s['qs_cv_pct']:7.2f}")
    if prediction:
        from twin.bench.push import _plot_prediction

        print(f"\npredictive validity, leave one out ({config.window_s} s windows from measured states, "
              "measured force and contact):")
        print(f"{'pair':16} {'trial':78} {'mu fit':>6} {'pos mm':>7} {'prior mm':>8} {'head deg':>8} {'prior deg':>9}")
        for p in prediction:
            print(f"{p['block']:16} {p['trial']:78} {p['mu_fit']:6.3f} {p['pos_mm']:7.2f} {p['pos_prior_mm']:8.2f} "
                  f"{p['heading_deg']:8.2f} {p['heading_prior_deg']:9.2f}")
        _plot_prediction(prediction, figure, "Held-out MIT pushing-dataset trials: object motion predicted from "
                         "measured pusher force and contact point")
        print(f"\nfigure: {figure}")
    return {"trials": rows, "summary": summary, "prediction": prediction}
