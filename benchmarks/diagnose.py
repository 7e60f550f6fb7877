"""`twin bench diagnose`: recordings with a concealed effect (or none), shuffled; is the right one found?

The cases and their recordings are made in `benchmarks.diagnose_cases` (by twin's own Newton code or by
MuJoCo, `--engine`); this module diagnoses each as a user's build would and prints one row per case: what
was concealed and what was found, the main parameter's error, the held-out replay before and after, the
truth model's own replay on the same recording, and the body's parameters after the diagnosis against the
truth (mass, COM, and on a joint the quantity its motion determines: a drawer's mass, a door's moment
about its hinge).

Each row also replays the model that made the recordings (the true body and the concealed effect) on the
held-out recording, as the diagnosis replays its own: the error that model leaves is the floor of the sensors'
noise integrated over a window, which no model is expected to beat, so it shows where halving the error is
possible at all.
"""

from __future__ import annotations

import base64
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.diagnose_cases import (  # noqa: F401  (some re-exported)
    EFFECTS, FREE_OBJECTS, JOINT_EFFECTS, JOINT_OBJECTS, OOV_EFFECTS, Case, case_kind, concealed_effect,
    concealed_joint_effect, determined_quantity, free_case_mesh, joint_effort_noise, make_cases, make_mujoco_cases,
    overlaps, record_case, record_joint_case, record_mujoco_case, record_mujoco_joint_case, record_push_case,
    true_body, true_joint_model_fit, true_model_fit, true_push_replays, true_state_range,
)


def truth_magnitude(effect) -> float:
    """The size of a concealed effect by the parameter its diagnosis is scored on (joint Stribeck: f_s - f_c)."""
    from pipelines.diagnose import main_magnitude

    params = effect.params
    if effect.name == "time_delay":
        return abs(params["seconds"])
    if effect.name == "spring":
        return params["k"]
    if effect.name == "stribeck_friction":
        return params["f_s"] - params["f_c"]
    if effect.name == "viscous_damping" and "b_angular" not in params:
        return params["b"]
    return main_magnitude(effect.name, params)


MAIN_STD_KEYS = {"sensor_bias": ("force",), "time_delay": ("seconds",), "viscous_damping": ("b", "damping"),
                 "quadratic_drag": ("c",), "nonuniform_density": ("com_shift",), "spring": ("stiffness",),
                 "stribeck_friction": ("stribeck",)}
"""Where an effect's evidence holds the standard deviation of its main parameter: free-body effects under the
parameter's own name, jointed ones under the identification's (stribeck: f_s - f_c)."""


def main_std(effect) -> float | None:
    """The reported standard deviation of an effect's main parameter as `truth_magnitude` measures it; a vector's
    norm through its direction, components taken as independent."""
    std = effect.evidence.get("std", {})
    for key in MAIN_STD_KEYS[effect.name]:
        if key in std:
            s = np.atleast_1d(np.asarray(std[key], dtype=float))
            if s.size == 1:
                return float(s[0])
            u = np.asarray(effect.params[key], dtype=float)
            return float(np.linalg.norm(u / np.linalg.norm(u) * s))
    return None


def _diagnose_case(case: Case, duration_s: float, config, with_holdout: bool = True, push_late_s: float = 0.0) -> dict:
    """Record `case`, diagnose it as a build would, and score what came out (one table row, less its index).

    `with_holdout` False: as a build without --holdout, the diagnosis choosing on the trial alone; the held-out
    recording then only scores the true model. push_late_s: a push's pose tracks start this much later [s]."""
    from pipelines.diagnose import diagnose_held, diagnose_jointed, diagnose_pushed
    from pipelines.identify import identify_jointed
    from pipelines.identify.posterior import Z95
    from pipelines.identify.sliding import SUPPORTS, SlidingConfig, identify_pushed

    kind = case_kind(case)
    mujoco = case.engine == "mujoco"
    joint = refit = kept = alone = push_truth = None
    with tempfile.TemporaryDirectory() as tmp:
        if kind == "joint":
            record = record_mujoco_joint_case if mujoco else record_joint_case
            trial, holdout, joint, placement, prior = record(case, Path(tmp))
            given = holdout if with_holdout else None
            diagnosis, refit = diagnose_jointed([trial], given, joint, placement, prior, config=config)
            # a build keeps the refit with the chosen effects, else its identification (twin/jointed.py)
            kept = refit or identify_jointed([trial], joint, placement, prior, given)
            # and a build without --holdout: the identification's own choice between its two estimates
            alone = identify_jointed([trial], joint, placement, prior, None) if with_holdout else None
            oov = case.effect is not None and case.effect.name in OOV_EFFECTS
            true_fit = (true_joint_model_fit(replace(case, effect=None) if oov else case, holdout, joint, placement,
                                             config.joint_window_s))
        elif kind == "push":
            trial, holdout, body, mu_prior = record_push_case(case, Path(tmp))
            trial, holdout = (pose_from(r, r.pose.t_s[0] + push_late_s) for r in (trial, holdout))
            given = holdout if with_holdout else None
            # the support the build would choose (`identify_pushed`), which the diagnosis then keeps
            support = identify_pushed([trial], given, body, mu_prior, SlidingConfig(), supports=SUPPORTS).config
            diagnosis, refit = diagnose_pushed([trial], [given] if given else [], body, mu_prior, support, config)
            true_fit, push_truth = None, true_push_replays(case, holdout, body, support.window_s)
        else:
            record = record_mujoco_case if mujoco else record_case
            trial, holdout, prior, X_tracked_body = record(case, Path(tmp), duration_s)
            given = holdout if with_holdout else None
            diagnosis = diagnose_held([trial], given, X_tracked_body, prior, config)
            true_fit = true_model_fit(case, holdout, X_tracked_body, prior, config.window_s)
            kept = diagnosis.posterior or kept_held_body(case, trial, given, X_tracked_body)
    top = diagnosis.effects[0] if diagnosis.effects else None
    truth = case.effect.name if case.effect else None
    error = std = None
    if top is not None and case.effect is not None and top.name == truth and truth not in OOV_EFFECTS:
        # a delay of the wrong sign counts as an error of more than 100 %
        found = (top.params["seconds"] * np.sign(case.effect.params["seconds"]) if truth == "time_delay"
                 else truth_magnitude(replace(case.effect, params=top.params)))
        error = 100 * abs(found - truth_magnitude(case.effect)) / truth_magnitude(case.effect)
        vector = {"sensor_bias": "force", "nonuniform_density": "com_shift"}.get(truth)
        if vector is not None:  # a vector by its difference, so a wrong direction or frame counts
            error = 100 * float(np.linalg.norm(np.subtract(top.params[vector], case.effect.params[vector]))
                                / np.linalg.norm(case.effect.params[vector]))
        reported = main_std(top)
        std = None if reported is None else 100 * reported / truth_magnitude(case.effect)
    row = {"engine": case.engine, "frame": case.wrench_frame, "object": case.shape, "kind": kind,
           "concealed": truth, "ratio": case.ratio, "found": top.name if top else None,
           "all_found": [e.name for e in diagnosis.effects], "main_error_pct": error, "main_std_pct": std,
           "rmse_before_m": diagnosis.fits["before"].rmse_position_m,
           "rmse_after_m": diagnosis.fits["after"].rmse_position_m,
           "rmse_true_m": None if true_fit is None else true_fit.rmse_position_m,
           "floor_m": diagnosis.noise_floor["rmse_position_m"] if diagnosis.noise_floor else None,
           "unexplained": [dict(u) for u in diagnosis.unexplained],
           # what a build flags: the diagnosis's doubtful values, and its identification's where that is kept
           "doubtful": sorted(set(diagnosis.doubtful) | set(getattr(kept, "doubtful", ()))),
           "mass_pct": None, "com_mm": None, "determined_pct": None, "oov_overlap": None, "push_truth": push_truth}
    # the body a build publishes: the refit with the chosen effects, else the identification (a held body's posterior)
    after = kept.inertial if kept is not None else None
    if kind in ("free", "joint") and after is not None:
        body = true_body(case)
        row["mass_pct"] = 100 * (after.mass - body.mass) / body.mass
        row["com_mm"] = 1000 * float(np.linalg.norm(np.asarray(after.com) - np.asarray(body.com)))
        if kind == "joint":
            d_true = determined_quantity(case, body)
            row["determined_pct"] = 100 * (determined_quantity(case, after) - d_true) / d_true
            row["alone"] = None if alone is None else {
                "selected": alone.selected, "doubtful": list(alone.doubtful),
                "determined_pct": 100 * (determined_quantity(case, alone.inertial) - d_true) / d_true}
        else:  # the inertia about the COM, relative Frobenius error
            row["determined_pct"] = 100 * float(np.linalg.norm(after.inertia_matrix() - body.inertia_matrix())
                                                / np.linalg.norm(body.inertia_matrix()))
            # the moments the kept body's posterior determines: its 95 % interval within 5 % (the cube's and
            # sphere's object axes are principal); the worst one's error, and whether each lies within 2 std
            moments, std = np.diag(after.inertia_matrix()), kept.std[4:7]
            true_moments = np.diag(body.inertia_matrix())
            determined = Z95 * std < 0.05 * np.abs(moments)
            row["moments_determined"] = int(determined.sum())
            row["moments_pct"] = (float(np.max(np.abs(100 * (moments / true_moments - 1))[determined]))
                                  if determined.any() else None)
            row["moments_covered"] = int(np.sum(np.abs(moments - true_moments) <= 2 * std))
    elif kind == "push" and refit is not None:
        row["determined_pct"] = 100 * (float(refit.theta[0]) - 0.3) / 0.3  # mu
    if kind == "joint" and truth in OOV_EFFECTS:
        where = true_state_range(case, joint)
        row["oov_truth"] = where
        row["oov_overlap"] = any(overlaps(u.get("where", {}), where) for u in diagnosis.unexplained)
    return row


def pose_from(recording, t_s: float):
    """`recording` with its pose track from t_s [s] on (the other streams kept)."""
    pose = recording.pose
    keep = pose.t_s >= t_s
    return replace(recording, pose=replace(pose, t_s=pose.t_s[keep], position=pose.position[keep],
                                           quat_xyzw=pose.quat_xyzw[keep]))


def kept_held_body(case: Case, trial, holdout, X_tracked_body):
    """The body a build keeps where the diagnosis chose no effect: `identify_held`'s posterior, its prior from
    the mesh and an unnamed material as a build's (`twin build` would keep its Newton fit instead only where
    that predicts the held-out recording better, which it does on none of `twin bench paper`'s rows)."""
    from assets.materials import material_range
    from pipelines.identify import IdentifyConfig, InertialBounds, identify_held
    from pipelines.priors import uniform_density_prior

    prior = uniform_density_prior(free_case_mesh(case)[1], material_range(None))
    return identify_held([trial], holdout, X_tracked_body, prior.inertial, InertialBounds(prior.lower, prior.upper),
                         IdentifyConfig(), "ls").posterior


def _fmt(value, spec: str, width: int) -> str:
    return f"{'' if value is None else format(value, spec):>{width}}"


def bench_diagnose(concealed: int = 40, clean: int = 10, duration_s: float = 3.0, seed: int = 0,
                   bootstraps: int = 40, cases: tuple[int, ...] = (), engine: str = "newton",
                   with_holdout: bool = True, push_late_s: float = 0.0) -> list[dict]:
    """Run every case (or only the indices `cases` of each engine's shuffled list, the same recordings as in the
    full run) on recordings made by `engine` ("newton", "mujoco" or "both"), print the table and the summary
    per engine; returns the rows. `with_holdout` False diagnoses as a build without --holdout does; push_late_s
    starts each push's pose tracks that much later [s]."""
    from pipelines.diagnose import DiagnoseConfig

    if engine not in ("newton", "mujoco", "both"):
        raise ValueError(f"bench diagnose --engine: expected newton, mujoco or both, got {engine!r}")
    engines = ("newton", "mujoco") if engine == "both" else (engine,)
    header = (f"{'#':>3} {'engine':<6} {'frame':<7} {'object':<12} {'concealed':<20} {'ratio':>6} "
              f"{'found (top-1)':<20} {'main err %':>10} {'std %':>6} {'rmse before mm':>14} {'after mm':>9} "
              f"{'truth mm':>9} {'floor mm':>9} {'mass %':>7} {'COM mm':>7} {'det %':>7} {'unexpl':>6} {'s':>5}")
    print(header)
    print("-" * len(header))
    rows = []
    for name in engines:
        made = make_cases(concealed, clean, seed) if name == "newton" else make_mujoco_cases(concealed, clean, seed)
        for k, case in enumerate(made):
            if cases and k not in cases:
                continue
            t0 = time.perf_counter()
            row = _diagnose_case(case, duration_s, DiagnoseConfig(bootstraps=bootstraps, seed=case.seed), with_holdout,
                                 push_late_s)
            row.update(index=k, seconds=time.perf_counter() - t0)
            rows.append(row)
            mm = lambda v: None if v is None else 1000 * v  # noqa: E731
            unexplained = (("hit" if row["oov_overlap"] else "miss") if row["oov_overlap"] is not None
                           else str(len(row["unexplained"])))
            print(f"{k:>3} {name:<6} {case.wrench_frame:<7} {case.shape:<12} {row['concealed'] or 'none':<20} "
                  f"{case.ratio:>6.2f} {row['found'] or 'none':<20} {_fmt(row['main_error_pct'], '.1f', 10)} "
                  f"{_fmt(row['main_std_pct'], '.1f', 6)} {_fmt(mm(row['rmse_before_m']), '.3f', 14)} "
                  f"{_fmt(mm(row['rmse_after_m']), '.3f', 9)} {_fmt(mm(row['rmse_true_m']), '.3f', 9)} "
                  f"{_fmt(mm(row['floor_m']), '.3f', 9)} {_fmt(row['mass_pct'], '+.1f', 7)} "
                  f"{_fmt(row['com_mm'], '.2f', 7)} {_fmt(row['determined_pct'], '+.1f', 7)} {unexplained:>6} "
                  f"{row['seconds']:>5.1f}", flush=True)
            for u in row["unexplained"]:
                print(f"      unexplained: {u['summary']}")
            if row["doubtful"]:
                print(f"      doubtful: {', '.join(row['doubtful'])}")
            if row.get("alone"):
                a = row["alone"]
                print(f"      without --holdout: {a['selected']} kept, the determined quantity {a['determined_pct']:+.1f} %"
                      + (f", doubtful: {', '.join(a['doubtful'])}" if a["doubtful"] else ""))
    for name in engines:
        print(f"\n== {name} ==")
        _summary([r for r in rows if r["engine"] == name])
    return rows


def _summary(rows: list[dict]) -> None:
    concealed = [r for r in rows if r["concealed"] and r["concealed"] not in OOV_EFFECTS]
    oov = [r for r in rows if r["concealed"] in OOV_EFFECTS]
    clean = [r for r in rows if not r["concealed"]]
    right = [r for r in concealed if r["found"] == r["concealed"]]
    within = [r for r in right if r["main_error_pct"] is not None and r["main_error_pct"] <= 15]
    reported = [r for r in rows if r["found"] and r["rmse_true_m"] is not None]
    halved = [r for r in reported if r["rmse_after_m"] <= 0.5 * r["rmse_before_m"]]
    print(f"top-1 right: {len(right)}/{len(concealed)} concealed ({100 * len(right) / max(len(concealed), 1):.0f} %)")
    # a concealed effect that even the model that made the recording does not replay better than the base fit
    # (another simulator's joint friction, an effect at the noise) is beyond what the held-out recording tells
    groups = {"where the true model replays the held-out recording better than the base fit":
              lambda r: r["rmse_true_m"] is not None and r["rmse_true_m"] < r["rmse_before_m"],
              "where it does not": lambda r: r["rmse_true_m"] is not None and r["rmse_true_m"] >= r["rmse_before_m"],
              "pushes (their truth is MuJoCo's: below)": lambda r: r["rmse_true_m"] is None}
    print("  " + "; ".join(f"{label}: {sum(r['found'] == r['concealed'] for r in concealed if of(r))}/"
                           f"{sum(of(r) for r in concealed)}" for label, of in groups.items()))
    pushes = [r for r in concealed if r["push_truth"] is not None]
    if pushes:
        told = [r for r in pushes if r["push_truth"]["tells"]]
        print(f"  pushes the model that made them (MuJoCo) replays better with their effect than "
              f"without: {len(told)}/{len(pushes)}; right in {sum(r['found'] == r['concealed'] for r in told)} of "
              f"those (with / without, mm: " + ", ".join(
                  f"{1e3 * r['push_truth']['with_m']:.3f} / {1e3 * r['push_truth']['without_m']:.3f}"
                  for r in pushes) + ")")
    for kind in ("free", "joint", "push"):
        for name in sorted({r["concealed"] for r in concealed if r["kind"] == kind}):
            of = [r for r in concealed if r["concealed"] == name and r["kind"] == kind]
            ok = [r for r in of if r["found"] == name]
            errs = [r["main_error_pct"] for r in ok if r["main_error_pct"] is not None]
            frames = ", ".join(f"{f} {sum(r['found'] == name for r in of if r['frame'] == f)}/"
                               f"{sum(r['frame'] == f for r in of)}" for f in sorted({r['frame'] for r in of}))
            print(f"  {kind:<5} {name:<18} {len(ok)}/{len(of)} right ({frames}), main parameter error median "
                  f"{np.median(errs) if errs else float('nan'):.1f} %, max {max(errs) if errs else float('nan'):.1f} %")
    for kind in ("free", "joint", "push"):
        of = [r for r in clean if r["kind"] == kind]
        if of:
            print(f"nothing reported on clean ({kind}): {sum(not r['found'] for r in of)}/{len(of)} no effect, "
                  f"{sum(not r['found'] and not r['unexplained'] for r in of)}/{len(of)} no effect and no unexplained")
    print(f"nothing reported on clean: {sum(not r['found'] for r in clean)}/{len(clean)} no effect; "
          f"{sum(not r['found'] and not r['unexplained'] for r in clean)}/{len(clean)} no effect and no unexplained")
    if oov:
        hit = [r for r in oov if r["oov_overlap"]]
        print(f"out of vocabulary: an unexplained entry overlapping the true range in {len(hit)}/{len(oov)}; "
              f"an effect named anyway in {sum(bool(r['found']) for r in oov)}/{len(oov)}; "
              f"parameters flagged doubtful in {sum(bool(r['doubtful']) for r in oov)}/{len(oov)}")
    print(f"main parameter within 15 %: {len(within)}/{len(right)} of the right ones")
    covered = [r for r in right if r["main_std_pct"] and r["main_error_pct"] <= 2 * r["main_std_pct"]]
    print(f"main parameter within 2 reported standard deviations: {len(covered)}/{len(right)} of the right ones")
    # the body after the diagnosis: mass within 3 %, the determined quantity (joint: drawer mass, door moment
    # about the hinge; free: the inertia, Frobenius) within 5 %, where the truth model replays the held-out
    # recording under twice the noise floor (free rows; joint rows have no floor estimate: every in-vocabulary one)
    bodies = [r for r in rows if r["mass_pct"] is not None and r["concealed"] not in OOV_EFFECTS
              and (r["floor_m"] is None or r["rmse_true_m"] < 2 * r["floor_m"])]
    for kind in ("free", "joint"):
        of = [r for r in bodies if r["kind"] == kind]
        if of:
            # a hinge's motion does not determine the door's mass, only its moment about the hinge
            weighed = [r for r in of if r["object"] not in ("cabinet_door", "oven_door")]
            mass = sum(abs(r["mass_pct"]) <= 3 for r in weighed)
            det = sum(abs(r["determined_pct"]) <= 5 for r in of)
            what = "the quantity the joint determines (drawer mass, door moment)" if kind == "joint" else "inertia"
            print(f"body after the diagnosis ({kind}, {len(of)} rows whose truth replays under twice the floor): "
                  f"mass within 3 % in {mass}/{len(weighed)}, {what} within 5 % in {det}/{len(of)}; "
                  f"COM error median {np.median([r['com_mm'] for r in of]):.2f} mm")
            if kind == "free":
                some = [r for r in of if r["moments_determined"]]
                print(f"  free: the principal moments the kept body's posterior determines (95 % within 5 %): "
                      f"{sum(r['moments_determined'] for r in of)} of {3 * len(of)} in {len(some)} rows, all within "
                      f"5 % in {sum(r['moments_pct'] <= 5 for r in some)}/{len(some)}; every moment within 2 std in "
                      f"{sum(r['moments_covered'] for r in of)}/{3 * len(of)}")
    alone = [r for r in rows if r.get("alone")]
    if alone:
        off = [r for r in alone if abs(r["alone"]["determined_pct"]) > 5]
        ok = [r for r in alone if r not in off]
        print(f"the identification without a held-out recording (joint): the quantity the joint determines within 5 % "
              f"in {len(ok)}/{len(alone)}; flagged doubtful in {sum(bool(r['alone']['doubtful']) for r in off)}/"
              f"{len(off)} of the others, in {sum(bool(r['alone']['doubtful']) for r in ok)}/{len(ok)} of those within")
    print(f"held-out position RMSE at least halved: {len(halved)}/{len(reported)} where an effect is reported")
    halvable = [r for r in reported if r["rmse_true_m"] <= 0.5 * r["rmse_before_m"]]
    print(f"  the true model halves it in {len(halvable)}/{len(reported)}; ours halves it in "
          f"{sum(r in halved for r in halvable)} of those {len(halvable)}")
    ratios = [r["rmse_after_m"] / r["rmse_true_m"] for r in reported]
    if ratios:
        print(f"  held-out RMSE after / the true model's: median {np.median(ratios):.2f}, max {max(ratios):.2f}; "
              f"within 10 %: {sum(x <= 1.1 for x in ratios)}/{len(ratios)}")
        # the error the sensors' noise leaves is in before, after and the truth alike; what a model can remove is
        # the rest, sqrt(rmse^2 - truth^2) (independent errors add in squares)
        excess = [(np.sqrt(max(r["rmse_before_m"] ** 2 - r["rmse_true_m"] ** 2, 0.0)),
                   np.sqrt(max(r["rmse_after_m"] ** 2 - r["rmse_true_m"] ** 2, 0.0))) for r in reported]
        print(f"  error above the true model's, sqrt(rmse^2 - truth^2), at least halved: "
              f"{sum(after <= 0.5 * before for before, after in excess)}/{len(excess)}")
    with_floor = [r for r in reported if r["floor_m"] is not None]  # held bodies
    possible = [r for r in with_floor if r["rmse_before_m"] >= 2 * r["floor_m"]]
    print(f"  error before at least twice the estimated noise floor in {len(possible)}/{len(with_floor)} (free); "
          f"ours halves it in {sum(r in halved for r in possible)} of those {len(possible)}")
    floors = [r["floor_m"] / r["rmse_true_m"] for r in rows if r["floor_m"] is not None and r["rmse_true_m"]]
    if floors:
        print(f"estimated noise floor / the true model's error, free rows: median {np.median(floors):.2f}, "
              f"range {min(floors):.2f}-{max(floors):.2f}")


from benchmarks.workshop import MIRROR, WORKSHOP_TOOLS, workshop_recording  # noqa: E402


def bench_diagnose_workshop(seed: int = 0) -> list[dict]:
    """Diagnose each workshop tool (time-blocked cross-validation); print what it finds against the truth."""
    from pipelines.diagnose import DiagnoseConfig, diagnose_held

    rng = np.random.default_rng(seed)
    header = (f"{'tool':<19} {'found':<34} {'true COM shift mm':<22} {'found COM shift mm':<22} "
              f"{'rmse before mm':>14} {'after mm':>9}")
    print(header)
    print("-" * len(header))
    rows = []
    for tool in WORKSHOP_TOOLS:
        with tempfile.TemporaryDirectory() as tmp:
            recording, prior, X_tracked_body, shift = workshop_recording(tool, Path(tmp), rng)
        diagnosis = diagnose_held([recording], None, X_tracked_body, prior, DiagnoseConfig(seed=seed))
        found = {e.name: e.params for e in diagnosis.effects}
        found_shift = found.get("nonuniform_density", {}).get("com_shift")
        # back to the dataset's (unmirrored) mesh frame for the table
        fmt = lambda v: "-" if v is None else "(" + ", ".join(f"{1000 * x:.1f}" for x in MIRROR @ v) + ")"  # noqa: E731
        row = {"tool": tool, "found": list(found), "true_shift_m": (MIRROR @ shift).tolist(),
               "found_shift_m": None if found_shift is None else (MIRROR @ np.asarray(found_shift)).tolist(),
               "rmse_before_m": diagnosis.fits["before"].rmse_position_m,
               "rmse_after_m": diagnosis.fits["after"].rmse_position_m,
               "unexplained": [u["summary"] for u in diagnosis.unexplained]}
        rows.append(row)
        print(f"{tool:<19} {', '.join(found) or 'none':<34} {fmt(shift):<22} "
              f"{fmt(None if found_shift is None else np.asarray(found_shift)):<22} "
              f"{1000 * row['rmse_before_m']:>14.3f} {1000 * row['rmse_after_m']:>9.3f}", flush=True)
        for u in row["unexplained"]:
            print(f"    unexplained: {u}")
    return rows


def bench_diagnose_push_real(blocks: tuple[str, ...] = (), seed: int = 0) -> list[dict]:
    """Diagnose the 2015 MIT block pushes (../shared/data/mit-push/ros2_mcap): per block, the odd-numbered
    trials fitted and the even-numbered ones held out, the tool not told what to look for; print what it finds
    and the held-out replay error before and after."""
    from pipelines.diagnose import DiagnoseConfig, diagnose_pushed
    from pipelines.identify.sliding import SlidingConfig, estimate_force_bias, push_windows
    from benchmarks.push import BLOCKS, DATA, FREE, block_prior, read_block_trial
    from twin.report import diagnosis_plots

    known = tuple(b.folder for b in BLOCKS)
    unknown = sorted(set(blocks) - set(known))
    if unknown:
        raise ValueError(f"diagnose --push-real: unknown block(s) {unknown}, expected some of {list(known)}")
    bags = DATA / "ros2_mcap"
    if not bags.exists():
        raise FileNotFoundError(f"{bags}: the MIT pushing bags are not there")
    sconfig = SlidingConfig()
    rows = []
    Path("docs").mkdir(exist_ok=True)
    for block in (b for b in BLOCKS if b.folder in (blocks or known)):
        body, mu_prior = block_prior(block)
        usable, skipped = [], []
        for trial_dir in sorted((bags / block.folder).iterdir(), key=lambda p: int(p.name.rsplit("_", 1)[1])):
            rec = read_block_trial(trial_dir, block)
            try:  # a bag with no window of a sliding block under the pusher says nothing about the model
                push_windows(rec, body, sconfig, estimate_force_bias(rec, sconfig))
            except ValueError:
                skipped.append(trial_dir.name)
                continue
            usable.append((trial_dir.name, rec))
        fit_part, held_part = usable[0::2], usable[1::2]
        t0 = time.perf_counter()
        diagnosis, refit = diagnose_pushed([r for _, r in fit_part], [r for _, r in held_part], body, mu_prior,
                                           sconfig, DiagnoseConfig(seed=seed), free=FREE)
        before, after = diagnosis.fits["before"], diagnosis.fits["after"]
        row = {"block": block.folder, "fitted": [n for n, _ in fit_part], "held_out": [n for n, _ in held_part],
               "skipped": skipped, "effects": {e.name: e.params for e in diagnosis.effects},
               "evidence": {e.name: e.evidence for e in diagnosis.effects},
               "inclusion": diagnosis.screening.inclusion, "scores": diagnosis.scores,
               "candidates": diagnosis.screening.coefficients,
               "mu_with_effects": float(refit.theta[0]) if refit is not None else None,
               "rmse_before_mm": 1e3 * before.rmse_position_m, "rmse_after_mm": 1e3 * after.rmse_position_m,
               "heading_before_deg": float(np.degrees(before.rmse_rotation_rad)),
               "heading_after_deg": float(np.degrees(after.rmse_rotation_rad)),
               "findings": list(diagnosis.findings), "unexplained": [u["summary"] for u in diagnosis.unexplained],
               "seconds": time.perf_counter() - t0}
        rows.append(row)
        figure = Path(f"docs/diagnose_push_{block.folder}.png")
        figure.write_bytes(base64.b64decode(diagnosis_plots(diagnosis.traces)))
        print(f"{block.folder}: fitted {', '.join(row['fitted'])}; held out {', '.join(row['held_out'])}"
              + (f"; skipped (no sliding window) {', '.join(skipped)}" if skipped else ""), flush=True)
        world = {n: e["force_world_n"] for n, e in row["evidence"].items() if "force_world_n" in e}
        print(f"  found: {_format_effects(row['effects']) or 'none'}"
              + "".join(f" ({n} in world axes: ({w[0]:.4g}, {w[1]:.4g}) N)" for n, w in world.items()))
        print(f"  each candidate refitted alone: {_format_effects(row['candidates'])}")
        print("  inclusion: " + ", ".join(f"{k} {v:.2f}" for k, v in row["inclusion"].items())
              + "; held-out mean squared error per candidate set [mm^2]: "
              + ", ".join(f"{k} {1e6 * v:.3f}" for k, v in row["scores"].items()))
        print(f"  held-out replay: position {row['rmse_before_mm']:.2f} -> {row['rmse_after_mm']:.2f} mm, "
              f"heading {row['heading_before_deg']:.2f} -> {row['heading_after_deg']:.2f} deg "
              f"({row['seconds']:.0f} s)")
        for line in row["findings"]:
            print(f"  residual: {line}")
        for line in row["unexplained"]:
            print(f"  unexplained: {line}")
        print(f"  figure: {figure}")
    return rows


PUSH_SYNTH_EFFECTS = ("viscous_damping", "time_delay", None)
"""Concealed in the synthetic pushes, in turn (None: clean)."""


def bench_diagnose_push_synth(seeds: int = 3) -> list[dict]:
    """Synthetic pushes (pipelines/synth/push.py: a 10 x 10 x 1 cm, 0.75 kg block, mu 0.3, pushed off its centre
    line so it turns) with a concealed drag, a concealed delay or nothing, one trial and one held-out push per
    case, the tool told nothing; prints what it finds against the truth."""
    from pipelines.diagnose import DiagnoseConfig, diagnose_pushed
    from pipelines.identify.sliding import PlanarBody, SlidingConfig
    from pipelines.logs import read_recording
    from pipelines.synth.push import PushConfig, write_push
    from benchmarks.push import box_izz

    half, mass = (0.05, 0.05, 0.005), 0.75
    body = PlanarBody(half, mass, box_izz(mass, half))
    rows = []
    header = (f"{'seed':>4} {'concealed':<16} {'truth':>10} {'found (top-1)':<16} {'value':>10} {'err %':>7} "
              f"{'rmse before mm':>14} {'after mm':>9} {'s':>5}")
    print(header)
    print("-" * len(header))
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        for name in PUSH_SYNTH_EFFECTS:
            concealed, key, truth = {}, None, None
            if name == "viscous_damping":
                truth = float(rng.uniform(1.0, 5.0))
                concealed, key = {"damping_n_s_m": truth}, "b"
            elif name == "time_delay":
                truth = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.005, 0.03))
                concealed, key = {"delay_s": truth}, "seconds"
            t0 = time.perf_counter()
            with tempfile.TemporaryDirectory() as tmp:
                recordings = []
                for k in range(2):  # the trial and the held-out push
                    path = Path(tmp) / f"push_{k}.mcap"
                    write_push(path, PushConfig(half_extents_m=half, mass_kg=mass, mu=0.3,
                                                offset_m=float(rng.uniform(0.01, 0.02)), seed=seed * 2 + k,
                                                **concealed))
                    recordings.append(read_recording(path))
            diagnosis, _ = diagnose_pushed(recordings[:1], recordings[1:], body, 0.5, SlidingConfig(),
                                           DiagnoseConfig(seed=seed))
            top = diagnosis.effects[0] if diagnosis.effects else None
            value = top.params[key] if top is not None and top.name == name else None
            error = None if value is None else 100 * (value - truth) / abs(truth)
            row = {"seed": seed, "concealed": name, "truth": truth, "found": top.name if top else None,
                   "all_found": [e.name for e in diagnosis.effects], "value": value, "error_pct": error,
                   "rmse_before_m": diagnosis.fits["before"].rmse_position_m,
                   "rmse_after_m": diagnosis.fits["after"].rmse_position_m, "seconds": time.perf_counter() - t0}
            rows.append(row)
            print(f"{seed:>4} {name or 'none':<16} {'' if truth is None else f'{truth:.4g}':>10} "
                  f"{row['found'] or 'none':<16} {'' if value is None else f'{value:.4g}':>10} "
                  f"{'' if error is None else f'{error:+.1f}':>7} {1000 * row['rmse_before_m']:>14.3f} "
                  f"{1000 * row['rmse_after_m']:>9.3f} {row['seconds']:>5.1f}", flush=True)
    concealed = [r for r in rows if r["concealed"]]
    clean = [r for r in rows if not r["concealed"]]
    print(f"top-1 right: {sum(r['found'] == r['concealed'] for r in concealed)}/{len(concealed)} concealed; "
          f"nothing reported on clean: {sum(not r['all_found'] for r in clean)}/{len(clean)}")
    return rows


def _format_effects(effects: dict) -> str:
    def fmt(v):
        if isinstance(v, (list, tuple)):
            return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
        return f"{v:.4g}"

    return "; ".join(f"{name} " + ", ".join(f"{k}={fmt(v)}" for k, v in params.items())
                     for name, params in effects.items())
