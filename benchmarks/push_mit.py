"""`twin bench push-mit`: surface friction from the MIT pushing dataset's trials, mass known.

Every trial under ../shared/data/mit-push/mit_push_dataset (raw .h5 and .json,
read by pipelines/push_dataset.py as recorded) is fitted for mu alone, starting
from the quasi-static estimate: the
object's mass and yaw inertia are known (objects.json), so mu itself is
measured, not mu * m. Beside it, the quasi-static wrench balance (which a
build reports where the fit's simulation sticks in every window, mu then only
bounded from below) and the lab's quasi-static estimate (steady pushing force
over m g). Per object and surface: the spread across trials. Predictive
validity: for each trial of an object and surface, mu identified on the others
(leave one out: the set holds two or three trials per pair), its motion
predicted from its measured pusher force and contact point, in windows started
from measured states, against the prior's friction.

The pushes are slow (10 mm/s pusher, the object sliding at 1-3 mm/s), so the
simulation step is 0.1 ms: Newton's penalty friction sticks below mu g dt and
lets a stuck body creep at F dt / m, both of which must stay below the object's
speed for the fit to see Coulomb friction (pipelines.identify.sliding docstring). Pushes
this slow are quasi-static: driven by the measured force, the simulated object
sticks or runs away, so the fit may only bound mu (`sliding_windows`), and the
wrench balance measures it.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from benchmarks.push import DATA, net_yaw_deg

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
        SlidingConfig, SlidingRollout, estimate_force_bias, identify_sliding, measured_friction, push_windows,
        quasi_static_friction, replay_errors, turn_check, wrench_balance_error, wrench_balance_friction,
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
        balance = wrench_balance_friction(windows, body, config)
        measured = measured_friction(fit, balance)  # as a build reports it
        chosen = measured[0] if measured is not None else float("nan")
        rows.append({**row, "mu": float(fit.theta[0]), "mu_std": float(fit.std[0]), "windows": fit.window_count,
                     "sliding": fit.sliding_windows, "determined": fit.determined[0],
                     "mu_wb": balance.mu if balance else float("nan"), "mu_wb_std": balance.std if balance else 0.0,
                     "wb_windows": len(balance.per_window) if balance else 0,
                     "wb_residual_n": balance.residual_n if balance else float("nan"), "mu_chosen": chosen,
                     "mu_qs": mu_qs, "against": int(turn_check(windows, body, config).drives_turn.sum()),
                     "rmse_mm": 1e3 * fit.rmse_position_m, "rmse_deg": float(np.degrees(fit.rmse_heading_rad)),
                     "seconds": time.perf_counter() - t0, "windows_data": windows, "body": body})

    fitted = [r for r in rows if "mu" in r]
    pairs = sorted({r["pair"] for r in fitted})
    summary, prediction = [], []
    for pair in pairs:
        group = [r for r in fitted if r["pair"] == pair]
        # a bound is not a measurement: the spread is over the trials that measured mu (either way)
        mus = np.array([r["mu_chosen"] for r in group if np.isfinite(r["mu_chosen"])])
        qs = np.array([r["mu_qs"] for r in group])
        cv = (lambda a: 100 * a.std(ddof=1) / a.mean() if len(a) > 1 else float("nan"))
        summary.append({"pair": pair, "trials": len(group), "measured": len(mus),
                        "mu_mean": mus.mean() if len(mus) else float("nan"), "mu_cv_pct": cv(mus),
                        "qs_mean": qs.mean(), "qs_cv_pct": cv(qs)})
        for r in group if len(mus) > 1 else []:
            mu_fit = float(np.median([o["mu_chosen"] for o in group if o is not r and np.isfinite(o["mu_chosen"])]))
            body = r["body"]
            rollout = SlidingRollout(r["windows_data"], body, config)
            p_fit, h_fit = replay_errors(rollout, (mu_fit, body.mass_kg, body.izz_kgm2))
            p_prior, h_prior = replay_errors(rollout, (mu_prior, body.mass_kg, body.izz_kgm2))
            f_fit, f_prior = (wrench_balance_error(r["windows_data"], body, config, mu) for mu in (mu_fit, mu_prior))
            prediction.append({
                "force_n": f_fit if f_fit is not None else float("nan"),
                "force_prior_n": f_prior if f_prior is not None else float("nan"),
                "block": pair, "trial": r["trial"], "mu_fit": mu_fit, "mu_prior": mu_prior,
                "pos_mm": 1e3 * p_fit, "pos_prior_mm": 1e3 * p_prior,
                "heading_deg": float(np.degrees(h_fit)), "heading_prior_deg": float(np.degrees(h_prior)),
                "traj_fit": rollout.trajectories((mu_fit, body.mass_kg, body.izz_kgm2)),
                "traj_prior": rollout.trajectories((mu_prior, body.mass_kg, body.izz_kgm2)),
                "measured": r["windows_data"].measured,
            })

    print(f"MIT pushing dataset ({root / 'mit_push_dataset'}): mu fitted with the mass and I_zz known "
          f"(objects.json), step {config.dt_s * 1e3:g} ms, prior mu {mu_prior} (stainless steel)")
    print("mu: the Newton sliding fit; 'slid': windows in which its simulation slides (with none it sticks "
          "throughout and mu is only a lower bound, '>='); mu wb: the quasi-static wrench balance over the 'st' "
          "steady windows, its residual 'wb res'; mu qs: steady force over m g; 'reported': what a build reports "
          "(the fit, or the balance where the fit is a bound); 'against': windows whose turn no mu explains "
          "(friction would have to drive it: `turn_check`)")
    print(f"{'trial':78} {'m kg':>6} {'mu':>7} {'mu std':>6} {'win':>3} {'slid':>4} {'mu wb':>6} {'wb std':>6} "
          f"{'st':>3} {'wb res N':>8} {'mu qs':>6} {'reported':>8} {'turn deg':>8} {'against':>7} {'bias N':>6} "
          f"{'rmse mm':>7} {'rmse deg':>8} {'s':>5}")
    for r in rows:
        if "skipped" in r:
            print(f"{r['trial']:78} {r['mass']:6.3f} skipped: {r['skipped']} (turn {r['turn_deg']:.1f} deg)")
            continue
        mu = f"{r['mu']:.3f}" if r["determined"] else f">={r['mu']:.3f}"
        print(f"{r['trial']:78} {r['mass']:6.3f} {mu:>7} {r['mu_std']:6.3f} {r['windows']:3d} {r['sliding']:4d} "
              f"{r['mu_wb']:6.3f} {r['mu_wb_std']:6.3f} {r['wb_windows']:3d} {r['wb_residual_n']:8.3f} "
              f"{r['mu_qs']:6.3f} {r['mu_chosen']:8.3f} {r['turn_deg']:8.1f} {r['against']:7d} {r['bias_n']:6.3f} "
              f"{r['rmse_mm']:7.2f} "
              f"{r['rmse_deg']:8.2f} {r['seconds']:5.1f}")
    print("\nper object / surface:")
    print(f"{'pair':16} {'trials':>6} {'measured':>8} {'mu mean':>7} {'mu CV %':>7} {'qs mean':>7} {'qs CV %':>7}"
          "   (mu: as reported)")
    for s in summary:
        print(f"{s['pair']:16} {s['trials']:6d} {s['measured']:8d} {s['mu_mean']:7.3f} {s['mu_cv_pct']:7.2f} "
              f"{s['qs_mean']:7.3f} {s['qs_cv_pct']:7.2f}")
    if prediction:
        from benchmarks.push import plot_prediction

        print(f"\npredictive validity, leave one out: the motion replayed in {config.window_s} s windows from "
              "measured states, measured force and contact (pos, head), and the pushing wrench predicted from the "
              "measured motion by the wrench balance (force N: RMS miss over the steady windows), at the others' "
              "mu and at the prior's:")
        print(f"{'pair':16} {'trial':78} {'mu fit':>6} {'pos mm':>7} {'prior mm':>8} {'head deg':>8} {'prior deg':>9} "
              f"{'force N':>7} {'prior N':>7}")
        for p in prediction:
            print(f"{p['block']:16} {p['trial']:78} {p['mu_fit']:6.3f} {p['pos_mm']:7.2f} {p['pos_prior_mm']:8.2f} "
                  f"{p['heading_deg']:8.2f} {p['heading_prior_deg']:9.2f} {p['force_n']:7.3f} "
                  f"{p['force_prior_n']:7.3f}")
        plot_prediction(prediction, figure, "Held-out MIT pushing-dataset trials: object motion predicted from "
                        "measured pusher force and contact point")
        print(f"\nfigure: {figure}")
    return {"trials": rows, "summary": summary, "prediction": prediction}
