"""`twin bench push` and `twin bench push-real`: surface friction of pushed objects.

push: synthetic pushes with known friction (pipelines/synth/push.py), one per
seed, each with its own mu, mass, push offset (so the block turns) and a sensor
bias; the prior's mass is 20 % off the truth, as a material-library density can be.

push-real: the 2015 MIT block bags (../shared/data/mit-push/ros2_mcap), read as
they were recorded: Vicon pose, un-zeroed ATI wrench in link_ft resolved
through the bag's /tf, and /tip_pose (a PoseStamped of link_ft in base_link,
header frame empty) as the contact point. Per trial: mu, and the quasi-static
estimate beside it; per block: the spread across trials. Then predictive
validity: identified on half of a block's trials, the other half's motion
predicted from its measured force and contact point, in windows started from
measured states, against the prior's friction.
"""

from __future__ import annotations

import tempfile
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

DATA = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mit-push").resolve()


def box_izz(mass_kg: float, half_extents_m) -> float:
    hx, hy, _ = half_extents_m
    return mass_kg * ((2 * hx) ** 2 + (2 * hy) ** 2) / 12.0


ENGINES = ("newton", "mujoco")
TRUTH_CONTACT = {"newton": "grid", "mujoco": "box"}
"""The truth model's support contact per engine: MuJoCo's box (its corners) made the MuJoCo recordings; the
Newton engine carries the block on an 8 x 8 grid of points, which `PushContact(shape="grid")` copies."""


def push_case(seed: int):
    """The push of one seed: its own mu, mass, push offset (so the block turns), start heading and sensor bias."""
    from pipelines.synth.push import PushConfig

    rng = np.random.default_rng(seed)
    return PushConfig(
        mu=float(rng.uniform(0.2, 0.6)), mass_kg=float(rng.uniform(0.4, 1.2)),
        offset_m=float(rng.uniform(-0.025, 0.025)), yaw0_rad=float(rng.uniform(-0.3, 0.3)),
        force_bias_n=tuple(rng.uniform(-0.5, 0.5, 3)), seed=seed,
    )


def _write(engine: str, path: Path, push, wrench_frame: str = "world"):
    if engine == "mujoco":
        from pipelines.synth.mujoco_push import write_pushed_mujoco

        return write_pushed_mujoco(path, push, wrench_frame=wrench_frame)
    from pipelines.synth.push import write_push

    return write_push(path, push)


def _identify_modes(engine: str, seed: int, tmp: Path, prior_mass_factor: float, mu_prior: float) -> list[dict]:
    """The identification alone, three ways ("m known", "m free", "slow"; bench_push), as a build without a
    held-out push: on the support model `choose_support` keeps from the trial's halves with the mass known, mu
    as `measured_friction` reports it (the sliding fit, else the wrench balance; "bound": neither measured it)."""
    from pipelines.identify.sliding import (
        PlanarBody, SlidingConfig, choose_support, estimate_force_bias, identify_sliding, measured_friction,
        push_windows, quasi_static_friction, wrench_balance_friction,
    )
    from pipelines.logs import read_recording

    config = SlidingConfig()
    push = push_case(seed)
    recordings = {}
    for name, variant in (("strokes", push), ("slow", replace(push, speed_m_s=0.03, stroke_s=5.0, push_s=2.9))):
        path = tmp / f"push_{engine}_{seed}_{name}.mcap"
        truth = _write(engine, path, variant)
        recordings[name] = read_recording(path)
    known = PlanarBody(push.half_extents_m, truth.mass_kg, box_izz(truth.mass_kg, push.half_extents_m))
    strokes = recordings["strokes"]
    found = choose_support(push_windows(strokes, known, config, estimate_force_bias(strokes, config)), None,
                           known, mu_prior, config)
    config = replace(config, support=found[0].support if found else config.support)
    rows = []
    for mode, mass, free, rec in (
            ("m known", truth.mass_kg, (True, False, True), recordings["strokes"]),
            ("m free", truth.mass_kg * prior_mass_factor, (True, True, True), recordings["strokes"]),
            ("slow", truth.mass_kg, (True, False, True), recordings["slow"])):
        t0 = time.perf_counter()
        body = PlanarBody(push.half_extents_m, mass, box_izz(mass, push.half_extents_m))
        bias = estimate_force_bias(rec, config)
        windows = push_windows(rec, body, config, bias)
        fit = identify_sliding(windows, body, config, mu_prior=mu_prior, free=free)
        balance = wrench_balance_friction(windows, body, config)
        mu, _, by = measured_friction(fit, balance) or (float(fit.theta[0]), 0.0, "bound")
        rows.append({
            "engine": engine, "seed": seed, "mode": mode, "support": config.support, "by": by,
            "mu_true": truth.mu, "mu": mu, "mu_err_pct": 100 * (mu / truth.mu - 1),
            "mu_m_err_pct": 100 * (mu * fit.theta[1] / (truth.mu * truth.mass_kg) - 1),
            "mass_err_pct": 100 * (fit.theta[1] / truth.mass_kg - 1),
            "izz_err_pct": 100 * (fit.theta[2] / truth.izz_kgm2 - 1),
            "determined": fit.determined, "turn_deg": net_yaw_deg(rec), "windows": fit.window_count,
            "mu_qs_true_mass": quasi_static_friction(rec, body, config, bias, truth.mass_kg),
            "bias_err_n": float(np.max(np.linalg.norm(bias.force_n - np.asarray(push.force_bias_n), axis=1))),
            "rmse_mm": 1e3 * fit.rmse_position_m, "seconds": time.perf_counter() - t0,
            "mu_wb_err_pct": 100 * (balance.mu / truth.mu - 1) if balance else float("nan"),
            "wb_windows": len(balance.per_window) if balance else 0,
        })
    return rows


def build_and_replay(engine: str, seed: int, tmp: Path, heldout_offset_m: float = -0.015) -> dict:
    """`twin build` of one seed's push as a user runs it (the block's mesh, the trial, --holdout, the weighed
    mass), then the held-out pushes replayed in MuJoCo by the exported scene.xml and by the truth model.

    The truth model is the MuJoCo model of the push without its pusher (`pushed_block_xml`): for MuJoCo-made
    recordings the model that made them, for Newton-made ones the true parameters on the Newton engine's
    support grid in MuJoCo (`TRUTH_CONTACT`; "truth_box_mm": on MuJoCo's box instead).
    Both replay the same windows the same way (`replay_pushed_model`); the ratio is the export's error over
    the truth's.
    """
    import json

    import mujoco

    from pipelines.identify.sliding import PlanarBody
    from pipelines.logs import read_recording
    from pipelines.synth.mujoco_push import (
        PushContact, PushedSampleConfig, make_pushed_sample, push_settings, pushed_block_xml,
    )
    from pipelines.validate import replay_pushed_model
    from twin.build import BuildConfig, build

    push = push_case(seed)
    sample = tmp / f"sample_{engine}_{seed}"
    make_pushed_sample(sample, PushedSampleConfig(push=push, heldout_offset_m=heldout_offset_m), engine=engine)
    t0 = time.perf_counter()
    out = build(BuildConfig(source=sample / "block.obj", logs=(sample / "trial.mcap",), holdout=sample / "heldout.mcap",
                            output=sample / "out", kind="sliding", material="steel",
                            mass_kg=(push.mass_kg, 0.005 * push.mass_kg)), log=lambda _: None)
    seconds = time.perf_counter() - t0
    asset = json.loads((Path(out) / "asset.json").read_text())
    exported = asset["provenance"]["heldout_replay"]["mujoco"]
    planar = PlanarBody(push.half_extents_m, push.mass_kg, box_izz(push.mass_kg, push.half_extents_m))
    heldout = read_recording(sample / "heldout.mcap")
    truth = {}
    for shape in ("box", "grid"):
        model = mujoco.MjModel.from_xml_string(pushed_block_xml(push, push_settings(), PushContact(shape=shape),
                                                                pusher=False))
        truth[shape] = replay_pushed_model(model, "block", planar, heldout, exported["window_s"])
    truth = truth[TRUTH_CONTACT[engine]] | {"box_rmse_position_m": truth["box"]["rmse_position_m"]}
    theta = asset["theta"]
    return {
        "engine": engine, "seed": seed, "mu_true": push.mu, "mu": theta["friction"]["value"],
        "mu_err_pct": 100 * (theta["friction"]["value"] / push.mu - 1),
        "mass_source": theta["mass"]["source"], "mass_err_pct": 100 * (theta["mass"]["value"] / push.mass_kg - 1),
        "izz_err_pct": 100 * (np.asarray(theta["inertia"]["value"])[2, 2] / box_izz(push.mass_kg, push.half_extents_m)
                              - 1),
        "effects": [e["name"] for e in asset["effects"]],
        "support": asset["provenance"]["identify"].get("support", {}).get("model", "?"),
        "export_mm": 1e3 * exported["rmse_position_m"], "truth_mm": 1e3 * truth["rmse_position_m"],
        "truth_box_mm": 1e3 * truth["box_rmse_position_m"],
        "ratio": exported["rmse_position_m"] / truth["rmse_position_m"],
        "export_deg": float(np.degrees(exported["rmse_heading_rad"])),
        "truth_deg": float(np.degrees(truth["rmse_heading_rad"])),
        "heading_ratio": exported["rmse_heading_rad"] / truth["rmse_heading_rad"],
        "windows": exported["windows"], "window_s": exported["window_s"], "seconds": seconds,
    }


def _bench_case(args) -> tuple[list[dict], dict]:
    engine, seed, prior_mass_factor, mu_prior, identification = args
    from twin.build import quiet_warp

    quiet_warp()
    with tempfile.TemporaryDirectory() as tmp:
        modes = _identify_modes(engine, seed, Path(tmp), prior_mass_factor, mu_prior) if identification else []
        return modes, build_and_replay(engine, seed, Path(tmp))


def bench_push(seeds: int = 5, prior_mass_factor: float = 1.2, mu_prior: float = 0.5, engine: str = "both",
               workers: int = 1, identification: bool = True) -> dict:
    """Print and return, per seed and engine, the identification's errors and the build's.

    engine: "newton" (pipelines/synth/push.py, twin's own model), "mujoco" (pipelines/synth/mujoco_push.py:
    MuJoCo's contact, a PD-servoed pusher, its force sensor) or "both", side by side; a target counts as met
    only where it holds on every engine run.

    Identification modes: "m known" fits mu and I_zz with the true mass (objects of known mass, as
    in the MIT dataset); "m free" fits mu, m and I_zz from a mass prior
    `prior_mass_factor` x the truth (what pushes alone can tell); "slow" is "m known" on a second
    recording of the same block pushed in one continuous stroke at 30 mm/s, where the quasi-static wrench
    balance ("wb") applies (the strokes of the others stop the block within most windows). Each on the support
    model and with mu as a build without a held-out push has them (`_identify_modes`).

    Build: `build_and_replay` (the user's `twin build` with a held-out push and the weighed mass): the
    friction it reports, the effects its diagnosis reports on these clean pushes, and the exported scene's
    MuJoCo replay of the held-out pushes against the truth model's. workers: seeds run in parallel processes;
    identification False: the builds alone.
    """
    if engine not in (*ENGINES, "both"):
        raise ValueError(f"engine: expected newton, mujoco or both, got {engine!r}")
    engines = ENGINES if engine == "both" else (engine,)
    cases = [(e, seed, prior_mass_factor, mu_prior, identification) for seed in range(seeds) for e in engines]
    if workers > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            results = list(pool.map(_bench_case, cases))
    else:
        results = [_bench_case(c) for c in cases]
    rows = [r for modes, _ in results for r in modes]
    builds = [b for _, b in results]
    if rows:
        _print_identification(rows, engines, seeds, prior_mass_factor, mu_prior)
    _print_builds(builds, engines)
    return {"identification": rows, "build": builds}


def _print_identification(rows, engines, seeds, prior_mass_factor, mu_prior) -> None:
    print(f"identification alone: prior mu = {mu_prior}; 'm free' starts from a mass prior = truth x "
          f"{prior_mass_factor}; 'data' marks the parameters (mu, m, Izz) the pushes determined; support: the "
          f"model chosen from the trial's halves with the mass known")
    print(f"{'engine':6} {'seed':>4} {'mode':7} {'mu true':>7} {'mu':>6} {'mu err %':>8} {'mu*m err %':>10} "
          f"{'m err %':>7} {'Izz err %':>9} {'data':>4} {'turn deg':>8} {'win':>3} {'mu qs':>6} {'bias err N':>10} "
          f"{'rmse mm':>7} {'wb err %':>8} {'st':>3} {'s':>5} support mu by")
    for r in rows:
        flags = "".join("y" if d else "n" for d in r["determined"])
        print(f"{r['engine']:6} {r['seed']:4d} {r['mode']:7} {r['mu_true']:7.3f} {r['mu']:6.3f} "
              f"{r['mu_err_pct']:+8.2f} {r['mu_m_err_pct']:+10.2f} {r['mass_err_pct']:+7.2f} {r['izz_err_pct']:+9.2f} "
              f"{flags:>4} {r['turn_deg']:8.1f} {r['windows']:3d} {r['mu_qs_true_mass']:6.3f} {r['bias_err_n']:10.3f} "
              f"{r['rmse_mm']:7.3f} {r['mu_wb_err_pct']:+8.2f} {r['wb_windows']:3d} {r['seconds']:5.1f} {r['support']} {r['by']}")
    print("wb: the quasi-static wrench balance over its 'st' steady windows (none: the strokes stop the block)")
    for engine in engines:
        for mode in ("m known", "m free", "slow"):
            got = [r for r in rows if r["mode"] == mode and r["engine"] == engine]
            worst = max(abs(r["mu_err_pct"]) for r in got)
            worst_mm = max(abs(r["mu_m_err_pct"]) for r in got)
            wb = [abs(r["mu_wb_err_pct"]) for r in got if r["wb_windows"]]
            print(f"{engine} {mode}: worst |mu error| {worst:.2f} %, worst |mu*m error| {worst_mm:.2f} % over "
                  f"{seeds} seeds (target: mu within 5 %)"
                  + (f"; wrench balance worst {max(wb):.2f} % over {len(wb)}" if wb else ""))


def _print_builds(builds, engines) -> None:
    print("\nbuild (`twin build` with --holdout and the weighed mass): friction, the support model it kept, effects "
          "reported on these clean "
          "pushes, and the held-out pushes replayed in MuJoCo, position RMSE of the exported scene.xml against the "
          "truth model's (the MuJoCo model that made the recording; for Newton-made ones the true parameters on "
          "the Newton engine's 8 x 8 support grid in MuJoCo; 'box mm': on MuJoCo's box)")
    cells = ["mu err %", "Izz err %", "support", "effects", "export mm", "truth mm", "ratio", "head ratio", "box mm"]
    width = [8, 9, 7, 16, 9, 8, 6, 10, 6]
    print(f"{'seed':>4} " + " | ".join(" ".join(f"{c:>{w}}" for c, w in zip(cells, width)) for _ in engines))
    print(f"{'':>4} " + " | ".join(f"{e:^{sum(width) + len(width) - 1}}" for e in engines))
    for seed in sorted({b["seed"] for b in builds}):
        parts = []
        for engine in engines:
            b = next(x for x in builds if x["seed"] == seed and x["engine"] == engine)
            effects = ",".join(b["effects"]) or "none"
            parts.append(f"{b['mu_err_pct']:+8.2f} {b['izz_err_pct']:+9.1f} {b['support']:>7} {effects[:16]:>16} "
                         f"{b['export_mm']:9.3f} "
                         f"{b['truth_mm']:8.3f} {b['ratio']:6.2f} {b['heading_ratio']:10.2f} {b['truth_box_mm']:6.3f}")
        print(f"{seed:4d} " + " | ".join(parts))
    for engine in engines:
        got = [b for b in builds if b["engine"] == engine]
        mu_ok = max(abs(b["mu_err_pct"]) for b in got)
        ratio = max(b["ratio"] for b in got)
        clean = sum(not b["effects"] for b in got)
        print(f"{engine}: worst |mu error| {mu_ok:.2f} % (target 5 %: {'met' if mu_ok <= 5 else 'MISSED'}); "
              f"worst replay ratio {ratio:.2f} (target 1.5: {'met' if ratio <= 1.5 else 'MISSED'}); "
              f"nothing reported on {clean}/{len(got)} clean pushes "
              f"({'met' if clean == len(got) else 'MISSED'}); "
              f"median build {np.median([b['seconds'] for b in got]):.0f} s")


def net_yaw_deg(rec) -> float:
    from scipy.spatial.transform import Rotation

    x = Rotation.from_quat(rec.pose.quat_xyzw).apply([1.0, 0.0, 0.0])
    yaw = np.unwrap(np.arctan2(x[:, 1], x[:, 0]))
    return float(np.degrees(yaw[-1] - yaw[0]))


@dataclass(frozen=True)
class Block:
    """A 2015 block set: its folder, Vicon topic, what is assumed of its size and material.

    None of the blocks' masses is known (mit-push README); sizes other than the
    steel block's mesh are inferred from marker positions.
    """

    folder: str
    vicon_topic: str
    half_extents_m: tuple[float, float, float]
    material: str
    size_source: str


BLOCKS = (
    Block("St_block", "/vicon/SteelBlock/SteelBlock", (0.049475, 0.049475, 0.004735), "steel",
          "meshes/pnpush_blocks/SteelBlock.stl"),
    Block("Al_block", "/vicon/MetalSquare/MetalSquare", (0.049475, 0.049475, 0.004735), "aluminium",
          "inferred: a plate like the steel one (markers at +-35 mm)"),
    Block("Plastic_block", "/vicon/SquareBlock/SquareBlock", (0.0375, 0.0375, 0.025), "abs",
          "inferred: markers span 72 x 74 mm, 61 mm high"),
)


def read_block_trial(path: Path, block: Block):
    """One bag as recorded: pose from Vicon, raw /netft_data through /tf (a reaction), /tip_pose as the contact."""
    from pipelines.logs import read_recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # per-bag notes (dropouts, held transforms) are not the point here
        return read_recording(
            path, {"pose": block.vicon_topic, "wrench": "/netft_data", "contact": "/tip_pose"},
            {"contact": "base_link"},
            wrench_reaction=True,  # the ATI sensor reads the block's push back on the probe
        )


def block_prior(block: Block):
    from assets.materials import material_range
    from pipelines.identify.sliding import PlanarBody

    material = material_range(block.material)
    hx, hy, hz = block.half_extents_m
    mass = material.density * 8 * hx * hy * hz
    return PlanarBody(block.half_extents_m, mass, box_izz(mass, block.half_extents_m)), material.kinetic()[0]


FREE = (True, False, True)
"""Real blocks: mu and I_zz fitted, the mass from the prior (unknown for every block; see bench push)."""


def bench_push_real(root: Path = DATA, blocks: tuple[str, ...] = ()) -> dict:
    """Print per-trial friction, per-block spread, and predictive validity; save the figure
    (docs/push_prediction.png, or docs/push_prediction_<blocks>.png for some of the blocks).

    Beside each trial's quasi-static estimate, the same with the force offset
    taken where it was before it came from pusher-away stretches: the median
    force before the block first moves, with the pusher already resting on it.
    """
    from pipelines.identify.sliding import (
        ForceBias, SlidingConfig, SlidingRollout, estimate_force_bias, identify_sliding, push_windows,
        quasi_static_friction, replay_errors, turn_check, wrench_balance_friction,
    )

    known = tuple(b.folder for b in BLOCKS)
    unknown = sorted(set(blocks) - set(known))
    if unknown:
        raise ValueError(f"push-real: unknown block(s) {unknown}, expected some of {list(known)}")
    figure = Path("docs/push_prediction.png" if not blocks else f"docs/push_prediction_{'_'.join(blocks)}.png")
    blocks = blocks or known
    bags = root / "ros2_mcap"
    if not bags.exists():
        raise RuntimeError(f"{bags}: the MIT pushing bags are not there")
    config = SlidingConfig()
    trials, summary, prediction = [], [], []
    for block in (b for b in BLOCKS if b.folder in blocks):
        body, mu_prior = block_prior(block)
        resting = replace(config, pusher_clear_m=np.inf, lift_m=np.inf)  # the pusher is never away
        preloaded = replace(config, preload_fraction=-np.inf)  # a resting pusher always preloads
        per_block = []
        for trial_dir in sorted((bags / block.folder).iterdir(), key=lambda p: int(p.name.rsplit("_", 1)[1])):
            t0 = time.perf_counter()
            rec = read_block_trial(trial_dir, block)
            bias = estimate_force_bias(rec, config)
            rest = estimate_force_bias(rec, resting)
            away = estimate_force_bias(rec, preloaded)
            drift = ForceBias(np.r_[rest.t_s, away.t_s], np.r_[rest.force_n, away.force_n], "linear, rest to away")
            try:
                windows = push_windows(rec, body, config, bias)
            except ValueError as exc:
                trials.append({"block": block.folder, "trial": trial_dir.name, "skipped": str(exc)})
                continue
            fit = identify_sliding(windows, body, config, mu_prior=mu_prior, free=FREE)
            balance = wrench_balance_friction(windows, body, config)
            row = {
                "sliding": fit.sliding_windows, "mu_wb": balance.mu if balance else float("nan"),
                "wb_windows": len(balance.per_window) if balance else 0,
                "against": int(turn_check(windows, body, config).drives_turn.sum()),
                "block": block.folder, "trial": trial_dir.name, "mu": float(fit.theta[0]),
                "mass": float(fit.theta[1]), "mu_m": float(fit.theta[0] * fit.theta[1]),
                "determined": fit.determined, "windows": fit.window_count,
                "mu_qs_prior_mass": quasi_static_friction(rec, body, config, bias, body.mass_kg),
                "mu_qs_resting_zero": quasi_static_friction(rec, body, config, rest, body.mass_kg),
                "mu_qs_drift": quasi_static_friction(rec, body, config, drift, body.mass_kg),
                "bias": bias, "rest_n": rest.force_n[0, :2], "away_n": away.force_n[-1, :2],
                "rmse_mm": 1e3 * fit.rmse_position_m,
                "rmse_heading_deg": float(np.degrees(fit.rmse_heading_rad)), "turn_deg": net_yaw_deg(rec),
                "seconds": time.perf_counter() - t0, "windows_data": windows, "theta": fit.theta,
            }
            trials.append(row)
            per_block.append(row)
        mus = np.array([r["mu"] for r in per_block])
        mums = np.array([r["mu_m"] for r in per_block])
        qs = np.array([r["mu_qs_prior_mass"] for r in per_block])
        qs_resting = np.array([r["mu_qs_resting_zero"] for r in per_block])
        qs_drift = np.array([r["mu_qs_drift"] for r in per_block])
        wb = np.array([r["mu_wb"] for r in per_block if np.isfinite(r["mu_wb"])])
        summary.append({
            "against": sum(r["against"] for r in per_block), "windows": sum(r["windows"] for r in per_block),
            "wb_trials": len(wb), "wb_mean": wb.mean() if len(wb) else float("nan"),
            "wb_cv_pct": 100 * wb.std(ddof=1) / wb.mean() if len(wb) > 1 else float("nan"),
            "block": block.folder, "trials": len(per_block), "mu_mean": mus.mean(),
            "mu_cv_pct": 100 * mus.std(ddof=1) / mus.mean(),
            "mu_m_cv_pct": 100 * mums.std(ddof=1) / mums.mean(), "qs_mean": qs.mean(),
            "qs_cv_pct": 100 * qs.std(ddof=1) / qs.mean(), "prior_mass": body.mass_kg, "mu_prior": mu_prior,
            "qs_resting_mean": qs_resting.mean(), "qs_resting_cv_pct": 100 * qs_resting.std(ddof=1) / qs_resting.mean(),
            "qs_drift_mean": qs_drift.mean(), "qs_drift_cv_pct": 100 * qs_drift.std(ddof=1) / qs_drift.mean(),
        })

        # predictive validity: identified on the odd-numbered trials (the median of their estimates),
        # the even-numbered ones predicted
        fit_rows, test_rows = per_block[0::2], per_block[1::2]
        identified = np.median([r["theta"] for r in fit_rows], axis=0)
        prior_theta = np.array([mu_prior, body.mass_kg, body.izz_kgm2])
        for r in test_rows:
            rollout = SlidingRollout(r["windows_data"], body, config)
            p_fit, h_fit = replay_errors(rollout, identified)
            p_prior, h_prior = replay_errors(rollout, prior_theta)
            prediction.append({
                "block": block.folder, "trial": r["trial"], "mu_fit": float(identified[0]),
                "izz_fit": float(identified[2]), "mu_prior": mu_prior,
                "pos_mm": 1e3 * p_fit, "pos_prior_mm": 1e3 * p_prior,
                "heading_deg": float(np.degrees(h_fit)), "heading_prior_deg": float(np.degrees(h_prior)),
                "traj_fit": rollout.trajectories(identified), "traj_prior": rollout.trajectories(prior_theta),
                "measured": r["windows_data"].measured,
            })

    print("per trial (mass from the prior's material density unless 'data' says the pushes determined it):")
    print(f"{'block':14} {'trial':20} {'mu':>6} {'m kg':>6} {'mu*m':>6} {'data':>4} {'win':>3} {'slid':>4} "
          f"{'mu wb':>6} {'st':>3} {'mu qs':>6} {'qs rest':>7} {'qs drift':>8} {'zeros':>5} {'drift N':>7} "
          f"{'turn deg':>8} {'against':>7} {'rmse mm':>7} {'rmse deg':>8} {'s':>5}")
    for r in trials:
        if "skipped" in r:
            print(f"{r['block']:14} {r['trial']:20} skipped: {r['skipped']}")
            continue
        flags = "".join("y" if d else "n" for d in r["determined"])
        b = r["bias"]
        drift = float(np.linalg.norm(r["rest_n"] - r["away_n"]))
        zeros = f"{len(b.t_s)}{'r' if b.source.startswith('pusher resting') else 'a'}"
        print(f"{r['block']:14} {r['trial']:20} {r['mu']:6.3f} {r['mass']:6.3f} {r['mu_m']:6.3f} {flags:>4} "
              f"{r['windows']:3d} {r['sliding']:4d} {r['mu_wb']:6.3f} {r['wb_windows']:3d} "
              f"{r['mu_qs_prior_mass']:6.3f} {r['mu_qs_resting_zero']:7.3f} "
              f"{r['mu_qs_drift']:8.3f} {zeros:>5} "
              f"{drift:7.3f} {r['turn_deg']:8.1f} {r['against']:7d} {r['rmse_mm']:7.2f} {r['rmse_heading_deg']:8.2f} "
              f"{r['seconds']:5.1f}")
    print("slid: windows in which the fit's simulation slides (none: mu only bounded from below); mu wb: the "
          "quasi-static wrench balance over its 'st' steady windows; against: windows whose turn no mu explains at "
          "the prior's I_zz (friction would have to drive it: turn_check)")
    print("zeros: how many force-offset zeros the fit used, 'a' with the pusher away, 'r' resting on the block before "
          "the push; qs rest: the quasi-static mu with the resting offset; qs drift: linear from that to the "
          "pusher-away zero after the push; drift N: their difference")
    print("\nper block:")
    print(f"{'block':14} {'trials':>6} {'prior m kg':>10} {'mu prior':>8} {'mu mean':>7} {'mu CV %':>7} "
          f"{'mu*m CV %':>9} {'wb trials':>9} {'wb mean':>7} {'wb CV %':>7} {'qs mean':>7} {'qs CV %':>7} "
          f"{'qs rest mean':>12} {'qs rest CV %':>12} {'qs drift mean':>13} {'qs drift CV %':>13} {'against':>9}")
    for s in summary:
        print(f"{s['block']:14} {s['trials']:6d} {s['prior_mass']:10.3f} {s['mu_prior']:8.3f} {s['mu_mean']:7.3f} "
              f"{s['mu_cv_pct']:7.2f} {s['mu_m_cv_pct']:9.2f} {s['wb_trials']:9d} {s['wb_mean']:7.3f} "
              f"{s['wb_cv_pct']:7.2f} {s['qs_mean']:7.3f} {s['qs_cv_pct']:7.2f} "
              f"{s['qs_resting_mean']:12.3f} {s['qs_resting_cv_pct']:12.2f} {s['qs_drift_mean']:13.3f} "
              f"{s['qs_drift_cv_pct']:13.2f} {s['against']:>4d}/{s['windows']:<4d}")
    print("\npredictive validity: fitted on odd-numbered trials, predicting the others "
          f"({config.window_s} s windows from measured states, measured force and contact):")
    print(f"{'block':14} {'trial':20} {'mu fit':>6} {'pos mm':>7} {'prior mm':>8} {'head deg':>8} {'prior deg':>9}")
    for p in prediction:
        print(f"{p['block']:14} {p['trial']:20} {p['mu_fit']:6.3f} {p['pos_mm']:7.2f} {p['pos_prior_mm']:8.2f} "
              f"{p['heading_deg']:8.2f} {p['heading_prior_deg']:9.2f}")
    plot_prediction(prediction, figure)
    print(f"\nfigure: {figure}")
    return {"trials": trials, "summary": summary, "prediction": prediction}


def bench_push_offsets(root: Path = DATA) -> list[dict]:
    """Quasi-static friction of every block bag under three force-offset models, without the Newton fits.

    resting: the median force before the block first moves, the pusher resting on
    it (a preload, if any, counts as offset); away: the zero after the push, the
    pusher lifted; drift: linear in time from the resting zero to the away zero.
    The last column names the one the fits use (estimate_force_bias). A spread that falls from one model to another
    points at the offset, not the friction, as what varies between trials.
    """
    from pipelines.identify.sliding import ForceBias, SlidingConfig, estimate_force_bias, quasi_static_friction

    config = SlidingConfig()
    resting_config = replace(config, pusher_clear_m=np.inf, lift_m=np.inf)  # the pusher is never away
    away_config = replace(config, preload_fraction=-np.inf)  # a resting pusher always preloads
    rows = []
    for block in BLOCKS:
        body, _ = block_prior(block)
        for trial_dir in sorted((root / "ros2_mcap" / block.folder).iterdir(),
                                key=lambda p: int(p.name.rsplit("_", 1)[1])):
            rec = read_block_trial(trial_dir, block)
            chosen = estimate_force_bias(rec, config)
            away = estimate_force_bias(rec, away_config)
            rest = estimate_force_bias(rec, resting_config)
            models = {"resting": rest, "away": away,
                      "drift": ForceBias(np.r_[rest.t_s, away.t_s], np.r_[rest.force_n, away.force_n], "drift")}
            row = {"block": block.folder, "trial": trial_dir.name, "zeros": chosen.source,
                   "offset_change_n": (away.force_n[-1, :2] - rest.force_n[0, :2]).tolist()}
            try:
                row.update({k: quasi_static_friction(rec, body, config, b, body.mass_kg) for k, b in models.items()})
            except ValueError as exc:
                row["skipped"] = str(exc).split(": ", 1)[1]
            rows.append(row)
    print("quasi-static mu (median pushing force over m g, prior mass) under three force-offset models:")
    print(f"{'block':14} {'trial':20} {'resting':>7} {'away':>7} {'drift':>7}  offset away - resting, world x y [N]; "
          "the offset the fit uses (estimate_force_bias)")
    for r in rows:
        change = "({:+.3f}, {:+.3f})".format(*r["offset_change_n"])
        if "skipped" in r:
            print(f"{r['block']:14} {r['trial']:20} skipped: {r['skipped']}  {change}")
            continue
        print(f"{r['block']:14} {r['trial']:20} {r['resting']:7.3f} {r['away']:7.3f} {r['drift']:7.3f}  {change}; "
              f"{r['zeros']}")
    print(f"\n{'block':14} {'trials':>6} " + " ".join(f"{m + ' mean':>12} {m + ' CV %':>12}"
                                                       for m in ("resting", "away", "drift")))
    for block in BLOCKS:
        got = [r for r in rows if r["block"] == block.folder and "skipped" not in r]
        cells = []
        for m in ("resting", "away", "drift"):
            v = np.array([r[m] for r in got])
            cells.append(f"{v.mean():12.3f} {100 * v.std(ddof=1) / v.mean():12.2f}")
        print(f"{block.folder:14} {len(got):6d} " + " ".join(cells))
    return rows


def plot_prediction(prediction: list[dict], figure: Path,
                    title: str = "Held-out MIT block pushes: object motion predicted from measured pusher force "
                                 "and contact point") -> None:
    """Bars of position and heading RMSE (identified vs prior friction) and one trial's windows overlaid."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    labels = [f"{p['block'].split('_')[0]} {p['trial'].rsplit('_', 1)[1]}" for p in prediction]
    x = np.arange(len(prediction))
    for ax, key, unit in ((axes[0], "pos", "mm"), (axes[1], "heading", "deg")):
        fit = [p[f"{key}_mm" if key == "pos" else "heading_deg"] for p in prediction]
        prior = [p[f"{key}_prior_mm" if key == "pos" else "heading_prior_deg"] for p in prediction]
        ax.bar(x - 0.2, prior, 0.4, label="prior friction", color="0.6")
        ax.bar(x + 0.2, fit, 0.4, label="identified on the other trials", color="tab:blue")
        ax.set_xticks(x, labels, rotation=60, fontsize=7)
        ax.set_ylabel(f"{'position' if key == 'pos' else 'heading'} RMSE [{unit}]")
        ax.legend(fontsize=8)
    best = max(prediction, key=lambda p: p["measured"].shape[1])
    ax = axes[2]
    for w in range(best["measured"].shape[1]):
        ax.plot(*best["measured"][:, w, :2].T * 1e3, "k-", lw=2, label="measured" if w == 0 else None)
        ax.plot(*best["traj_prior"][:, w, :2].T * 1e3, "-", color="0.6", label="prior friction" if w == 0 else None)
        ax.plot(*best["traj_fit"][:, w, :2].T * 1e3, "-", color="tab:blue", label="identified" if w == 0 else None)
    ax.set_title(f"{best['block']} {best['trial']}: {best['traj_fit'].shape[0] - 1}-sample windows", fontsize=9)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.axis("equal")
    ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(figure, dpi=110)
    plt.close(fig)
