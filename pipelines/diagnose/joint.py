"""Diagnose a part on a joint (drawer, door): which passive joint force does the identified model lack?

The jointed base model is M q'' = tau + Q_g(q) - f_c tanh(q'/eps): its Coulomb
friction is always fitted (`theta.friction`), so `coulomb_friction` is no
candidate here (DESIGN.md). The candidates are passive joint forces the base
lacks, each a term of the joint's generalized force in the Featherstone
rollout (`passive_joint_force`, through `joint_f`):

  viscous_damping:   -b q'
  spring:            -k (q - q0)            (door closers, soft-close drawers)
  stribeck_friction: -(f_s - f_c) exp(-(q'/v_s)^2) tanh(q'/eps), breakaway above f_c

Screening regresses the joint effort on the base columns plus every candidate's
(the Stribeck speed searched on a grid) with backward elimination under the BIC
and bootstrap inclusion probabilities. Effort regression is weak evidence here:
q'' from tracked poses carries noise far above the F/T sensor's. So every
candidate, alone, is refitted with the body in Newton (`identify_jointed(...,
effects=...)`) and replayed on held-out data in windows from smoothed starts;
a candidate is chosen when it predicts the windows significantly better than
the base model, the pair of the two best when it beats the better of them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from assets import Effect, FitMetrics
from pipelines.identify import (
    JOINT_EFFECT_PARAMS, STRIBECK_SPEEDS, JointedConfig, equation_of_motion_rows, identify_jointed, joint_body,
    joint_effect_columns, moving_mask, predicts_better, q_and_position_rmse, replay_jointed,
)

from .residuals import analyse_joint_residual, describe, localise_joint_friction, unexplained
from .screening import Library, fit_subset, screen
from .config import DiagnoseConfig
from .select import Diagnosis

JOINT_CANDIDATES = tuple(JOINT_EFFECT_PARAMS)
"""Joint candidates in screening order."""


def joint_effect_params(name: str, identified) -> dict:
    """The DESIGN.md parameters of effect `name` from an identification that fitted it."""
    if name == "viscous_damping":
        return {"b": identified.value("damping")}
    if name == "spring":
        k = identified.value("stiffness")
        return {"k": k, "q0": identified.value("spring_force") / k if k != 0 else 0.0}
    f_c = identified.value("friction")
    return {"f_s": f_c + identified.value("stribeck"), "f_c": f_c, "v_s": identified.value("stribeck_speed")}


def _library(rows: list[dict], config: JointedConfig, stribeck_speed: float, noise: float) -> Library:
    """Base columns and every candidate's, thinned to the low-pass filter's Nyquist rate, in noise units."""
    Xs, ys, samples, offset, stride = [], [], [], 0, 1
    groups: dict[str, tuple[int, int]] = {}
    for r in rows:
        stride = max(1, int(r["rate_hz"] / (2 * config.smoothing_hz)))
        keep = np.arange(0, len(r["t_s"]), stride)
        cols = [r["columns"][keep]]
        start = r["columns"].shape[1]
        for name in JOINT_CANDIDATES:
            c = joint_effect_columns(name, r, config, stribeck_speed)[keep]
            groups[name] = (start, start + c.shape[1])
            start += c.shape[1]
            cols.append(c)
        Xs.append(np.concatenate(cols, 1) / noise)
        ys.append(r["tau"][keep] / noise)
        samples.append(keep + offset)
        offset += len(r["t_s"])
    return Library(np.vstack(Xs), np.concatenate(ys), groups, np.concatenate(samples), stride,
                   rows[0]["columns"].shape[1])


def _columns(lib: Library, names) -> np.ndarray:
    return lib.X[:, list(range(lib.base)) + [c for n in names for c in range(*lib.groups[n])]]


def _stribeck_speed(rows: list[dict], config: JointedConfig) -> float:
    """The v_s [m/s or rad/s] on the grid at which the full candidate library fits the trials best."""
    def rss(v_s):
        return fit_subset(_library(rows, config, v_s, 1.0), JOINT_CANDIDATES)[1]
    return float(min(STRIBECK_SPEEDS, key=rss))


def _time_blocks(recording, blocks: int = 2) -> list:
    """`recording` cut into `blocks` consecutive parts of equal duration (each a Recording)."""
    t0 = min(recording.pose.t_s[0], recording.wrench.t_s[0])
    edges = t0 + recording.duration_s * np.arange(blocks + 1) / blocks

    def cut(track, a, b, fields):
        if track is None:
            return None
        keep = (track.t_s >= a) & (track.t_s <= b)
        return replace(track, t_s=track.t_s[keep],
                       **{f: getattr(track, f)[keep] for f in fields if getattr(track, f) is not None})

    return [replace(recording, pose=cut(recording.pose, a, b, ("position", "quat_xyzw")),
                    wrench=cut(recording.wrench, a, b, ("force", "torque")),
                    wrench_raw=cut(recording.wrench_raw, a, b, ("force", "torque")),
                    contact=cut(recording.contact, a, b, ("position",)),
                    joints=cut(recording.joints, a, b, ("position", "velocity")), duration_s=float(b - a))
            for a, b in zip(edges[:-1], edges[1:])]


def _spring_stands_for_friction(identified, names, state, q: np.ndarray) -> bool:
    """Whether a chosen spring only stands in for a friction that depends on the direction of motion: such a
    friction is, while the part moves, a constant force on top of the Coulomb one, which a spring mimics with a
    stiffness of the wrong sign (pushing away from its rest position) or a rest position far outside the
    travel seen (k q0 the constant, k q small). A door closer or a soft-close spring does neither."""
    if "spring" not in names or not any("qd" in u["where"] for u in state):
        return False
    params = joint_effect_params("spring", identified)
    span = float(q.max() - q.min())
    outside = max(float(q.min()) - params["q0"], params["q0"] - float(q.max()), 0.0)
    return params["k"] <= 0 or outside > span


def _design(rows: dict, names: tuple, config: JointedConfig, stribeck_speed: float) -> np.ndarray:
    """The base model's effort columns of `rows` (`equation_of_motion_rows`) and those of the effects `names`."""
    return np.concatenate([rows["columns"]] + [joint_effect_columns(c, rows, config, stribeck_speed) for c in names], 1)


def friction_patterns(rows: dict, names: tuple, config: JointedConfig, stribeck_speed: float, noise: float,
                      stride: int, joint_type: str) -> tuple[dict, ...]:
    """Friction-like mismatches localised in q or in the direction of motion (`localise_joint_friction`), holding
    a tenth of the residual at least, in the effort residual of the least-squares model with effects `names`
    fitted to `rows` (`equation_of_motion_rows`) themselves.

    Fitted to the rows it is tested on, not carried over from the training recordings: a gravity moment off by
    1 % (an oven door's trial and held-out recording disagree by that much) leaves a torque of one sign along
    the travel, which times the direction of motion reads as a friction that depends on the direction, 1.4x
    the noise on a clean door, in Newton's recordings as in MuJoCo's."""
    X = _design(rows, names, config, stribeck_speed)
    coef, *_ = np.linalg.lstsq(X[::stride], rows["tau"][::stride], rcond=None)
    prismatic = joint_type == "prismatic"
    return tuple(u for u in localise_joint_friction(rows["q"], rows["qd"], (rows["tau"] - X @ coef) / noise,
                                                    stride=stride, unit="m/s" if prismatic else "rad/s",
                                                    q_unit="m" if prismatic else "rad")
                 if u["share"] >= 0.1)


def replay_fit(joint, q_sim: np.ndarray, windows) -> FitMetrics:
    """Replay error against the zero-phase smoothed q, as the free-body replay is scored against the smoothed
    track: the tracker's noise is a floor both models share and would hide how much of the motion each one
    predicts."""
    replay = q_and_position_rmse(joint, q_sim, windows.q_smoothed[1:])
    return FitMetrics(replay["rmse_position_m"], replay["rmse_q"] if joint.type == "revolute" else 0.0,
                      replay["rmse_q"])


def _window_mse(q_sim: np.ndarray, windows) -> np.ndarray:
    """Mean squared q error [m^2 or rad^2] per replayed window."""
    return np.mean((q_sim - windows.q[1:]) ** 2, axis=0)


def diagnose_jointed(trials: list, holdout, joint, placement, prior, jconfig: JointedConfig = JointedConfig(),
                     config: DiagnoseConfig = DiagnoseConfig()):
    """Diagnose a part on `joint` from `trials`; `holdout` (a Recording or None) chooses and validates.

    prior: the part's prior body (object frame). Every candidate set is refitted with the body in Newton on
    the training recordings and replayed, in windows from smoothed starts, on the evaluation recordings
    (the held-out one by a fit on the trials and each trial by a fit on the held-out one; without it, each
    half of the trial fitted on the other). A candidate is kept when it predicts the windows significantly
    better than the base model (`predicts_better`), a pair when it beats its better member too.

    Returns (Diagnosis, the identification on all trials with the chosen effects, or None if none is chosen).
    """
    rng = np.random.default_rng(config.seed)
    # candidates compared with a rigid grip: a fitted grip let a damping stand in for the load MuJoCo's soft
    # frictionloss leaks while it holds, and named it on a clean cabinet door. Each fit is compared by its Newton
    # fit, never swapped for least squares (which lacks the candidate): no disagreement marks it doubtful here.
    identification = replace(jconfig, fit_grip=False, disagreement_share=np.inf)
    jconfig = replace(identification, window_s=config.joint_window_s)

    def fit_config(names: tuple) -> JointedConfig:
        """A breakaway acts at reversals only: over 0.6 s windows the start-state error grows around it and
        (f_s - f_c, v_s) falls into another minimum (a door's came back 28 % low, 2 % in 0.3 s windows), so
        a set with Stribeck friction is fitted in the identification's windows; every set is replayed in
        `jconfig`'s."""
        return identification if "stribeck_friction" in names else jconfig

    body = joint_body(joint, placement, prior, jconfig)
    rows = [equation_of_motion_rows(r, joint, body, jconfig) for r in trials]
    v_s = _stribeck_speed(rows, jconfig)
    full = _library(rows, jconfig, v_s, 1.0)
    _, rss, n = fit_subset(full, JOINT_CANDIDATES)
    noise = float(np.sqrt(rss / max(n - full.X.shape[1], 1)))
    lib = _library(rows, jconfig, v_s, noise)
    screening = screen(lib, rng, config.bootstraps)

    if holdout is not None:
        # the held-out recording evaluates a fit on the trials and each trial one on it: twice the windows,
        # each predicted by a fit that never saw it (13 windows alone left a door's damping at 1.8 standard errors)
        folds = [(trials, holdout)] + [([holdout], r) for r in trials]
    else:
        halves = [_time_blocks(r) for r in trials]
        first, second = [h[0] for h in halves], [h[1] for h in halves]
        folds = [(first, r) for r in second] + [(second, r) for r in first]
    refits: dict[tuple, dict] = {}
    base_fits: dict[JointedConfig, list] = {}

    def fold_bases(cfg: JointedConfig) -> list:
        """The base model fitted in `cfg`'s windows on each fold's training part."""
        if cfg not in base_fits:
            base_fits[cfg] = ([r[3] for r in evaluate(())["replays"]] if cfg == jconfig else
                              [identify_jointed(list(train), joint, placement, prior, None, cfg) for train, _ in folds])
        return base_fits[cfg]

    def evaluate(names: tuple) -> dict:
        """Newton refit of the body with `names` on each fold's training part (started from the base fit too, which
        it nests), replayed on its evaluation part."""
        if names not in refits:
            mse, replays = [], []
            nested = fold_bases(fit_config(names)) if names else [None] * len(folds)
            for (train, test), base in zip(folds, nested):
                ident = identify_jointed(list(train), joint, placement, prior, None, fit_config(names), effects=names,
                                         nests=base)
                b = joint_body(joint, placement, prior, jconfig, names)
                replay, q_sim, w = replay_jointed(test, joint, placement, prior, b, ident.values, jconfig)
                mse.append(_window_mse(q_sim, w))
                replays.append((replay, q_sim, w, ident))
            refits[names] = {"mse": np.concatenate(mse), "replays": replays}
        return refits[names]

    def fits_better(names: tuple) -> bool:
        """Whether the set's fit lowers every fold's training loss below the base model's in the same windows.
        The base is nested in every set, so a fit that does not is not a better explanation of the data,
        whatever its replay does: on an oven door, whose windows diverge like an inverted pendulum's, a
        fitted spring of 7e-4 N m/rad with a higher training loss replayed the clean held-out trial 3 % better."""
        return all(r[3].loss_history[-1] < b.loss_history[-1]
                   for r, b in zip(evaluate(names)["replays"], fold_bases(fit_config(names))))

    base = evaluate(())
    passing = sorted((c for c in JOINT_CANDIDATES
                      if predicts_better(evaluate((c,))["mse"], base["mse"]) and fits_better((c,))),
                     key=lambda c: refits[(c,)]["mse"].sum())
    best: tuple = (passing[0],) if passing else ()
    if len(passing) >= 2:
        pair = tuple(c for c in JOINT_CANDIDATES if c in passing[:2])
        if predicts_better(evaluate(pair)["mse"], refits[best]["mse"]):
            best = pair
    scores = {"+".join(k) or "none": float(v["mse"].mean()) for k, v in refits.items()}

    evaluation = holdout if holdout is not None else trials[0]
    if holdout is not None:
        _, q_before, windows, base_fit = refits[()]["replays"][0]
        _, q_after, _, final = refits[best]["replays"][0]
    else:  # the reported replay: the trial, by models fitted on all of it
        def fitted(names, nests=None):
            ident = identify_jointed(trials, joint, placement, prior, None, fit_config(names), effects=names,
                                     nests=nests)
            b = joint_body(joint, placement, prior, jconfig, names)
            return (*replay_jointed(evaluation, joint, placement, prior, b, ident.values, jconfig), ident)

        _, q_before, windows, base_fit = fitted(())
        _, q_after, _, final = fitted(best, base_fit) if best else (None, q_before, windows, base_fit)
    fits = {"before": replay_fit(joint, q_before, windows), "after": replay_fit(joint, q_after, windows)}

    effects = []
    for name in sorted(best, key=lambda c: refits[(c,)]["mse"].sum()):
        effects.append(Effect(name, joint_effect_params(name, final), {
            "inclusion_probability": screening.inclusion[name], "belongs": "object",
            "heldout_mse_q": {"none": scores["none"], name: scores[name], "chosen": scores["+".join(best)]},
            "std": {p: final.std(p) for p in JOINT_EFFECT_PARAMS[name]},
            "heldout_rmse_position_before_m": fits["before"].rmse_position_m,
            "heldout_rmse_position_after_m": fits["after"].rmse_position_m,
        }))

    eval_rows = equation_of_motion_rows(evaluation, joint, body, jconfig)
    stride = lib.stride

    def residual(names):
        """Effort residual [noise units] of the least-squares model with `names` on the evaluation rows."""
        coef, *_ = np.linalg.lstsq(_columns(lib, names), lib.y, rcond=None)
        return eval_rows["tau"] / noise - _design(eval_rows, names, jconfig, v_s) / noise @ coef

    unit = "m/s" if joint.type == "prismatic" else "rad/s"
    # on the rows where the part moves, as its least squares: where it sticks (a hold, a reversal) the friction
    # is whatever holds it, not the smooth tanh, and the effort left there reads as a force no model explains
    # (on clean Newton-made parts a hold kept 67 % of the residual in 0.4 s, a reversal 20 %)
    moves = moving_mask(eval_rows, jconfig.least_squares_min_speed)

    def analyse(r: np.ndarray):
        return analyse_joint_residual(*(eval_rows[k][moves] for k in ("t_s", "q", "qd", "tau")), r[moves],
                                      stride=stride, unit=unit)

    r_before, r_after = residual(()), residual(best)

    # a friction that depends on position or direction is no candidate: when the base model's residual shows
    # one and the chosen effect leaves it there, or is a spring that only stands in for it (a runner that
    # catches one way), the effect only bent itself to it: no effect is reported, the mismatch goes to
    # unexplained and the body's values it corrupts are flagged
    state = friction_patterns(eval_rows, (), jconfig, v_s, noise, stride, joint.type)
    if best:
        after_state = friction_patterns(eval_rows, best, jconfig, v_s, noise, stride, joint.type)
        if state and (after_state or _spring_stands_for_friction(final, best, state, eval_rows["q"])):
            best, state, effects = (), after_state or state, []
            q_after, final, r_after = q_before, base_fit, r_before
            fits = {"before": fits["before"], "after": fits["before"]}
        else:
            state = after_state
    residuals = {"before": analyse(r_before), "after": analyse(r_after)}
    left = state or unexplained(residuals["after"], config.unexplained_share, config.unexplained_chance)
    doubtful = []
    if state:
        doubtful += ["friction", "mass" if joint.type == "prismatic" else "inertia"]
    if not prior.mass / config.prior_mass_factor <= final.inertial.mass <= prior.mass * config.prior_mass_factor \
            and "mass" not in doubtful:
        doubtful.append("mass")  # far outside what the geometry and any material allow
    traces = {"t_s": windows.t_s.reshape(-1).tolist(),
              "measured_position": joint.tracked_position(windows.q[1:]).reshape(-1, 3).tolist(),
              "before_position": joint.tracked_position(q_before).reshape(-1, 3).tolist(),
              "after_position": joint.tracked_position(q_after).reshape(-1, 3).tolist(),
              "window_s": jconfig.window_s, "residual_t_s": eval_rows["t_s"].tolist(),
              "residual_before": r_before[:, None].tolist(), "residual_after": r_after[:, None].tolist()}
    diagnosis = Diagnosis(
        effects=tuple(effects), unexplained=left, screening=screening, scores=scores,
        fits=fits,
        residuals=residuals, findings=tuple(describe(residuals["before"])),
        inertial={"before": base_fit.inertial, "after": final.inertial},
        heldout=holdout is not None, traces=traces, doubtful=tuple(doubtful),
    )
    return diagnosis, final if best else None
