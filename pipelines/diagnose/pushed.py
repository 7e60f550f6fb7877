"""Diagnose a pushed object: what does the sliding model leave out?

The sliding base model (pipelines/identify/sliding/) is Coulomb friction of the
support face, loaded as `SlidingConfig.support` says (uniformly, or at its
corners: the build passes the support the identification chose from the pushes,
so that a corner-carried object's extra turning resistance is not read as
turning damping), driven by the measured pusher force (less the offset measured
at the recording's zeros) at the measured contact point. Its candidates, each a
term of the same Newton rollout:

  sensor_bias:     a force offset still in the reading after the zeros
                   (a drift, a load that depends on the arm's pose), world x, y
  viscous_damping: -b v and -b_angular omega_z on the body: friction that grows
                   with speed (velocity-strengthening surfaces, a dragged cable)
  time_delay:      the wrench's clock against the poses' (separate clocks), the force
                   read between steps so that the delay has a gradient
  contact_offset:  the force acting a fixed offset from the measured contact
                   point, world x, y (a tracked tip's calibration; not in
                   DESIGN.md's vocabulary)

With four candidates there is no regression screen: each, alone, is refitted
with mu and I_zz (and the windows' start velocities) on the training windows and
replayed on the evaluation windows from measured starts, the held-out
recordings' (or, without them, each half of every trial fitted on the other
half), cut at `PHASES` tilings: a unit of evaluation is a recording's windows
of every tiling that start in one window of the first, so that the choice does
not rest on which samples happen to share a window. A candidate is chosen when
it predicts those units significantly better than the base model
(`predicts_better`, per-unit log error), the pair
of the two best when it beats the better alone. A contact offset moves the
force's line against the COM exactly as a COM shift the other way would, so it
is a candidate only where it stands out of the reconstructed mesh's own COM
uncertainty as nonuniform_density must (`offset_resolved`). The choice must also predict
better than the other support model's (`SUPPORTS`) own best explanation, or it
stands in for how the face bears its load and is not reported. Inclusion
probabilities are the share of bootstrap resamples of the evaluation units in
which a candidate predicts better.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from assets import Effect, FitMetrics, Inertial
from pipelines.identify import (
    EFFECT_SLOTS, SUPPORTS, PlanarBody, PushWindows, SlidingConfig, SlidingFit, SlidingRollout, concat_push_windows,
    estimate_force_bias, estimate_noise_levels, identify_sliding, predicts_better, push_windows, turn_check,
)

from .residuals import analyse_planar_residual, describe, unexplained
from .screening import Screening
from .config import DiagnoseConfig
from .select import Diagnosis, com_shift_stands_out, mesh_com_std

PUSHED_CANDIDATES = ("sensor_bias", "viscous_damping", "time_delay", "contact_offset")
"""Candidates of the sliding kind, in the order they are tried."""


PHASES = 3
"""Tilings the evaluation windows are cut at, each a window's length / PHASES after the last: which samples share
a window changes the choice (docs/pushes.md, "Where the windows fall"), so it is made on all of them."""


@dataclass(frozen=True)
class _Tiles:
    """A recording's windows at every tiling: windows; phase [W]: the tiling's index (0: the windows the fits
    train on); tile [W]: the window of tiling 0 each starts in, which with the recording is its unit of
    evaluation (overlapping windows are not independent)."""

    windows: PushWindows
    phase: np.ndarray
    tile: np.ndarray


@dataclass(frozen=True)
class _Fold:
    """Which windows train and which evaluate: per recording, a boolean mask over its windows of tiling 0
    (train) and of every tiling (test, `_Tiles`)."""

    train: tuple[tuple[int, np.ndarray], ...]
    test: tuple[tuple[int, np.ndarray], ...]


@dataclass(frozen=True)
class _Refit:
    """A candidate set refitted on one fold: the fit and its replay of the evaluation windows from measured
    starts (residuals [S, W, 3]: x, y [m], heading x yaw length [m]; recording, phase, tile [W]: each window's
    recording and its `_Tiles` entries)."""

    fit: SlidingFit
    test: PushWindows
    residual: np.ndarray
    recording: np.ndarray
    phase: np.ndarray
    tile: np.ndarray


def _take(w: PushWindows, mask: np.ndarray) -> PushWindows:
    return replace(w, t_start_s=w.t_start_s[mask], start=w.start[mask], force=w.force[:, mask],
                   contact=w.contact[:, mask], measured=w.measured[:, mask])


def _select(parts: list[PushWindows], picks) -> PushWindows:
    return concat_push_windows([_take(parts[i], mask) for i, mask in picks if mask.any()])


def _tiles(recording, first: PushWindows, body: PlanarBody, sconfig: SlidingConfig, bias, t0_s: float) -> _Tiles:
    """`recording`'s windows at every tiling, `first` (tiling 0, timed from t0_s) among them, timed from t0_s."""
    samples = first.sample_count
    parts, phase = [first], [np.zeros(first.window_count, int)]
    for k in range(1, PHASES):
        try:
            w = push_windows(recording, body, sconfig, bias, phase=k * samples // PHASES)
        except ValueError:  # no window of this tiling where the pusher touches a sliding object
            continue
        parts.append(replace(w, t_start_s=w.t_start_s - t0_s))
        phase.append(np.full(w.window_count, k))
    windows = concat_push_windows(parts)
    tile = np.floor((windows.t_start_s - first.t_start_s[0]) / first.span_s + 1e-6).astype(int)
    return _Tiles(windows, np.concatenate(phase), tile)


def _folds(parts: list[PushWindows], tiles: list[_Tiles], trials: int) -> list[_Fold] | None:
    """The held-out recordings (indices from `trials` on) evaluate a fit on every trial; without them, the
    first half of each trial's windows (in time) and the second half evaluate each other, each on the windows of
    every tiling that lie within its span. None when the trials hold a single window and there is no held-out
    recording: nothing can be held out."""
    if len(parts) > trials:
        return [_Fold(tuple((i, np.ones(parts[i].window_count, bool)) for i in range(trials)),
                      tuple((i, np.ones(tiles[i].windows.window_count, bool)) for i in range(trials, len(parts))))]
    first = tuple((i, np.arange(parts[i].window_count) < parts[i].window_count / 2) for i in range(trials))
    second = tuple((i, ~mask) for i, mask in first)
    if not any(m.any() for _, m in first) or not any(m.any() for _, m in second):
        return None

    def within(half):
        out = []
        for i, mask in half:
            starts, t = parts[i].t_start_s[mask], tiles[i].windows.t_start_s
            inside = np.zeros(len(t), bool)
            if mask.any():
                inside = (t >= starts.min() - 1e-9) & (t <= starts.max() + 1e-9)  # none across the halves' border
            out.append((i, inside))
        return tuple(out)

    return [_Fold(first, within(second)), _Fold(second, within(first))]


def _first_tiling(refit: _Refit) -> _Refit:
    """`refit`'s evaluation windows of tiling 0 alone, back to back: the replay reported and plotted."""
    keep = refit.phase == 0
    return _Refit(refit.fit, _take(refit.test, keep), refit.residual[:, keep], refit.recording[keep],
                  refit.phase[keep], refit.tile[keep])


def _window_mse(residual: np.ndarray) -> np.ndarray:
    """Mean squared replay error per window [m^2] (position and heading arc)."""
    return np.mean(np.sum(residual**2, axis=-1), axis=0)


def _unit_mse(refit: _Refit) -> np.ndarray:
    """Mean squared replay error per unit of evaluation [m^2]: a recording's windows of every tiling that start
    in one window of tiling 0."""
    _, unit = np.unique(np.c_[refit.recording, refit.tile], axis=0, return_inverse=True)
    unit = unit.ravel()
    return np.bincount(unit, _window_mse(refit.residual)) / np.bincount(unit)


def diagnose_pushed(trials: list, holdouts: list, body: PlanarBody, mu_prior: float,
                    sconfig: SlidingConfig = SlidingConfig(), config: DiagnoseConfig = DiagnoseConfig(),
                    free: tuple[bool, bool, bool] = (True, False, True)) -> tuple[Diagnosis, SlidingFit | None]:
    """Diagnose a pushed object from `trials`; `holdouts` (recordings, possibly none) choose and validate.

    body, mu_prior: the sliding model's prior (as in identify_pushed); free: which of (mu, m, I_zz) every
    refit frees (the mass keeps its prior by default, see SlidingConfig.fit_mass). Times in the analysis
    are from each recording's first pose.

    Returns (Diagnosis, the sliding fit on all trials with the chosen effects, or None if none is chosen).
    """
    rng = np.random.default_rng(config.seed)
    recordings = [*trials, *holdouts]
    biases = [estimate_force_bias(r, sconfig) for r in recordings]
    sconfig = replace(sconfig, max_delay_s=config.max_delay_s)
    # each recording's windows, timed from its first pose
    parts = [replace(w, t_start_s=w.t_start_s - r.pose.t_s[0])
             for r, b in zip(recordings, biases) for w in [push_windows(r, body, sconfig, b)]]
    tiles = [_tiles(r, p, body, sconfig, b, r.pose.t_s[0]) for r, p, b in zip(recordings, parts, biases)]
    folds = _folds(parts, tiles, len(trials))
    testable = folds is not None
    if not testable:  # one window, no held-out recording: its replay and residuals alone, no candidate tried
        everything = tuple((i, np.ones(p.window_count, bool)) for i, p in enumerate(parts))
        folds = [_Fold(everything, tuple((i, t.phase == 0) for i, t in enumerate(tiles)))]

    def fit(names: tuple, train, support: str = sconfig.support) -> SlidingFit:
        return identify_sliding(_select(parts, train), body, replace(sconfig, support=support), mu_prior=mu_prior,
                                free=free, effects=names)

    length = sconfig.yaw_length_m or float(np.hypot(*body.half_extents_m[:2]))
    refits: dict[tuple, list[_Refit]] = {}  # under sconfig's support
    other_refits: dict[tuple, list[_Refit]] = {}  # under the other support model

    def refits_under(support: str) -> dict[tuple, list[_Refit]]:
        return refits if support == sconfig.support else other_refits

    def evaluate(names: tuple, support: str = sconfig.support) -> np.ndarray:
        """Held-out errors per unit of evaluation (`_unit_mse`) of `names` refitted on each fold's training
        windows."""
        cache = refits_under(support)
        if names not in cache:
            out = []
            for fold in folds:
                f = fit(names, fold.train, support)
                test = _select([t.windows for t in tiles], fold.test)
                residual = SlidingRollout(test, body, replace(sconfig, support=support)).residuals(f.theta, None,
                                                                                                 f.effect)
                picked = [(i, mask) for i, mask in fold.test if mask.any()]
                source, phase, tile = (np.concatenate(c) for c in zip(*[
                    (np.full(mask.sum(), i), tiles[i].phase[mask], tiles[i].tile[mask]) for i, mask in picked]))
                out.append(_Refit(f, test, residual, source, phase, tile))
            cache[names] = out
        return np.concatenate([_unit_mse(r) for r in cache[names]])

    base = evaluate(())
    tried = PUSHED_CANDIDATES if testable else ()

    def choose(support: str) -> tuple[list, tuple]:
        """The candidates that predict better under `support`, best first, and the set chosen."""
        none = evaluate((), support)
        passing = sorted((c for c in tried if predicts_better(evaluate((c,), support), none)
                          and (c != "contact_offset"
                               or all(offset_resolved(r.fit, body, config) for r in refits_under(support)[(c,)]))),
                         key=lambda c: evaluate((c,), support).sum())
        best: tuple = (passing[0],) if passing else ()
        if len(passing) >= 2:
            pair = tuple(c for c in PUSHED_CANDIDATES if c in passing[:2])
            if predicts_better(evaluate(pair, support), evaluate(best, support)):
                best = pair
        return passing, best

    passing, best = choose(sconfig.support)
    # where the support face bears its load is the contact's least certain part (another simulator's contacts,
    # a table's flatness), and a delay or a damping can stand in for it: a clean MuJoCo push chose a 2.5 ms
    # delay with its corners loaded and damping with its face loaded uniformly, each as good as the other.
    # The effects are kept only when they predict better than the other support model's own best explanation
    other = next(s for s in SUPPORTS if s != sconfig.support)
    rival = choose(other)[1] if best else ()
    stand_ins = ()
    if best and set(rival) != set(best) and not predicts_better(evaluate(best), evaluate(rival, other)):
        stand_ins, best = best, ()
    scores = {"+".join(k) or "none": float(evaluate(k).mean()) for k in refits}

    # inclusion: the share of bootstrap resamples of the evaluation units a candidate predicts better in
    gains = {c: np.log(np.maximum(evaluate((c,)), 1e-300)) - np.log(np.maximum(base, 1e-300)) for c in tried}
    picks = rng.integers(0, len(base), (config.bootstraps, len(base)))
    inclusion = {c: float(np.mean(g[picks].mean(axis=1) < 0)) for c, g in gains.items()}

    final = fit(best, tuple((i, np.ones(p.window_count, bool)) for i, p in enumerate(parts[:len(trials)]))) \
        if best else None
    effects = []
    for name in sorted(best, key=lambda c: evaluate((c,)).sum()):  # most certain first
        params, evidence = _effect_params(name, final, trials[0])
        effects.append(Effect(name, params, {
            **evidence, "inclusion_probability": inclusion[name],
            "belongs": "recording" if name in ("sensor_bias", "time_delay", "contact_offset") else "object",
            "heldout_mse_m2": {"none": scores["none"], name: scores[name], "chosen": scores["+".join(best)]},
        }))

    before, after = ([_first_tiling(r) for r in refits[k]] for k in ((), best))
    fits = {"before": _metrics(before, length), "after": _metrics(after, length)}
    for e in effects:
        e.evidence.update({"heldout_rmse_position_before_m": fits["before"].rmse_position_m,
                           "heldout_rmse_position_after_m": fits["after"].rmse_position_m})
    # the evaluation recordings share one tracker: the last one's noise sets the unit
    noise = estimate_noise_levels(recordings[-1].pose.t_s, recordings[-1].pose.position,
                                  recordings[-1].pose.quat_xyzw, recordings[-1].wrench.t_s,
                                  recordings[-1].wrench.force, recordings[-1].wrench.torque).position_m
    names = np.array([Path(r.path).name for r in recordings])
    series = {k: _series(v, sconfig) for k, v in (("before", before), ("after", after))}
    residuals = {k: analyse_planar_residual(s["t_s"], s["velocity"], s["force"], s["residual"] / noise,
                                            window_samples=before[0].test.sample_count,
                                            recordings=names[s["recording"]])
                 for k, s in series.items()}
    t_after = series["after"]["t_s"]
    left = (*unexplained(residuals["after"], config.unexplained_share, config.unexplained_chance,
                         (t_after.min(), t_after.max()), series["after"]["residual"]),
            *_turns_against_friction(parts, names, body, sconfig, series["after"],
                                     final.effect[list(EFFECT_SLOTS["contact_offset"])]
                                     if "contact_offset" in best else np.zeros(2)))
    traces = {"t_s": series["before"]["t_s"].tolist(),
              "measured_position": series["before"]["measured"].tolist(),
              "before_position": (series["before"]["measured"] + series["before"]["position_error"]).tolist(),
              "after_position": (series["after"]["measured"] + series["after"]["position_error"]).tolist(),
              "window_s": before[0].test.sample_count * sconfig.sample_period_s,
              "residual_t_s": series["before"]["t_s"].tolist(),
              "residual_before": (series["before"]["residual"] / noise).tolist(),
              "residual_after": (series["after"]["residual"] / noise).tolist()}
    screening = Screening(inclusion, tuple(passing),
                          {n: _effect_params(n, refits[(n,)][0].fit, trials[0])[0] for n in tried},
                          config.bootstraps)
    diagnosis = Diagnosis(
        effects=tuple(effects), unexplained=left, screening=screening, scores=scores, fits=fits,
        residuals=residuals, inertial={},
        findings=(*(() if testable else ("a single push window and no held-out recording: no candidate effect can "
                                         "be tested (give --holdout); the window's own replay is analysed",)),
                  *((f"{' and '.join(stand_ins)} predicted the held-out windows better with the support loaded "
                     f"as {sconfig.support!r}, but no better than {' and '.join(rival) or 'no effect'} with it "
                     f"loaded as {other!r}: a stand-in for the contact model, not reported",) if stand_ins else ()),
                  *describe(residuals["before"])),
        heldout=bool(holdouts), traces=traces,
    )
    return diagnosis, final


def offset_resolved(fit: SlidingFit, body: PlanarBody, config: DiagnoseConfig) -> bool:
    """Whether `fit`'s contact offset is one the push can tell from the mesh's own COM error, by the test a
    held body's COM shift meets (`com_shift_stands_out`, the mesh's COM uncertainty that of the body's box). On a
    clean Newton-made push a 0.44 mm offset with a standard deviation of 0.10 mm predicted the held-out push
    better, by 1 % of its error."""
    slots = list(EFFECT_SLOTS["contact_offset"])
    hx, hy, hz = np.square(body.half_extents_m)
    box = Inertial(body.mass_kg, (0.0, 0.0, 0.0), np.diag([hy + hz, hx + hz, hx + hy]) * body.mass_kg / 3.0)
    return com_shift_stands_out(fit.effect[slots], np.diag(fit.effect_std[slots] ** 2),
                                mesh_com_std(box, config)[:2], config)[1]


def _effect_params(name: str, fit: SlidingFit, recording) -> tuple[dict, dict]:
    """DESIGN.md parameters of `name` from a fit that carried it, and evidence (standard deviations, frames)."""
    if name == "time_delay":
        (k,) = EFFECT_SLOTS[name]
        return {"seconds": float(fit.effect[k])}, {"std": {"seconds": float(fit.effect_std[k])}}
    x, y = EFFECT_SLOTS[name]
    if name == "contact_offset":  # not in DESIGN.md's vocabulary: the force acts at the measured point plus it
        return ({"offset_m": [float(fit.effect[x]), float(fit.effect[y]), 0.0]},
                {"frame": "world", "std_m": [float(fit.effect_std[x]), float(fit.effect_std[y])]})
    if name == "viscous_damping":
        return ({"b": float(fit.effect[x]), "b_angular": float(fit.effect[y])},
                {"std": {"b": float(fit.effect_std[x]), "b_angular": float(fit.effect_std[y])}})
    world = np.array([fit.effect[x], fit.effect[y], 0.0])
    # DESIGN.md: a sensor bias is in the wrench message's frame. The sensor-to-world map is fitted over the
    # recording (the reading's sign included, e.g. a reaction); it holds where the sensor does not turn.
    raw, resolved = recording.wrench_raw.force, recording.wrench.force
    M, *_ = np.linalg.lstsq(raw, resolved, rcond=None)
    frame = recording.wrench_raw.frame_id or "world"
    fixed = float(np.sqrt(np.mean((raw @ M - resolved) ** 2))) < 0.05 * float(np.std(resolved)) + 1e-9
    # least squares, not solve: a reading with an axis that never varies (the MIT dataset's h5 trials
    # carry no vertical force) leaves that axis of the map, and of the bias, undetermined
    force = np.linalg.lstsq(M.T, world, rcond=None)[0] if fixed else world
    return ({"force": force.tolist(), "torque": [0.0, 0.0, 0.0]},
            {"frame": frame if fixed else "world", "force_world_n": world.tolist(),
             "std_world_n": [float(fit.effect_std[x]), float(fit.effect_std[y])],
             "note": "the offset left after the zeros' (provenance identify.force_bias_world); the vertical "
                     "part and the torque are not seen by a planar push"})


def _metrics(refits: list[_Refit], length: float) -> FitMetrics:
    r = np.concatenate([x.residual for x in refits], axis=1)
    return FitMetrics(rmse_position_m=float(np.sqrt(np.mean(np.sum(r[..., :2] ** 2, -1)))),
                      rmse_rotation_rad=float(np.sqrt(np.mean(r[..., 2] ** 2)) / length),
                      loss=float(np.mean(np.sum(r**2, -1))))


def _turns_against_friction(parts: list, names: np.ndarray, body, sconfig: SlidingConfig, after: dict,
                            contact_offset_m: np.ndarray) -> tuple:
    """DESIGN.md `unexplained` entries for the windows whose turn no friction coefficient explains (`turn_check`,
    with the chosen model's contact offset, world x, y [m]), consecutive windows of a recording as one stretch,
    with the share of the chosen model's evaluation residual in it."""
    def span(values: np.ndarray, fmt: str) -> str:
        return f"{values.min():{fmt}} to {values.max():{fmt}}" if len(values) > 1 else f"{values[0]:{fmt}}"

    energy = float(np.sum(after["residual"] ** 2))
    out = []
    for index, (part, name) in enumerate(zip(parts, names)):
        check = turn_check(replace(part, contact=part.contact + contact_offset_m), body, sconfig)
        flagged = np.flatnonzero(check.drives_turn)
        span_s = part.sample_count * sconfig.sample_period_s  # the clock `_series` times the samples by
        runs = np.split(flagged, np.flatnonzero(np.diff(part.t_start_s[flagged]) > 1.5 * span_s) + 1)
        for run in (r for r in runs if len(r)):
            a, b = float(part.t_start_s[run[0]]), float(part.t_start_s[run[-1]] + span_s)
            inside = (after["recording"] == index) & (after["t_s"] > a) & (after["t_s"] <= b)
            turn, pushing, friction = (np.degrees(check.turn_rad[run]), check.pushing_nm[run], check.friction_nm[run])
            ratio = check.izz_balance_kgm2[run] / body.izz_kgm2
            izz = ("" if not np.all(np.isfinite(ratio)) or len({bool(r > 1) for r in ratio}) > 1 else
                   f", or I_zz is {ratio.max() if ratio[0] > 1 else ratio.min():.2f}x the prior's or "
                   f"{'more' if ratio[0] > 1 else 'less'}")
            out.append({
                "summary": f"t = {a:.2f}-{b:.2f} s of {name}: in {len(run)} window(s) the object turns "
                           f"{span(turn, '+.1f')} deg while the pushing moment ({span(pushing, '+.4f')} N m) and "
                           f"its angular momentum leave a friction moment ({span(friction, '+.4f')} N m) that drives "
                           "the turn: no friction coefficient explains it at the prior's I_zz (the contact point, "
                           f"the force direction, the COM or the support pressure's symmetry is off{izz})",
                "where": {"t_s": [a, b]},
                "share": float(np.sum(after["residual"][inside] ** 2) / energy) if energy > 0 else 0.0})
    return tuple(out)


def _series(refits: list[_Refit], sconfig: SlidingConfig) -> dict:
    """The replay of the evaluation windows as time series, window after window: t [s] (each recording's own
    time), measured position (x, y, 0), position error, the planar residual [x, y, heading arc] [m], the
    object's velocity (vx, vy [m/s], yaw rate [rad/s]), the pusher force (x, y [N]) and the recording's
    index at each sample."""
    rows = []
    for x in refits:
        w, r = x.test, x.residual
        S = w.sample_count
        t = w.t_start_s[None, :] + sconfig.sample_period_s * np.arange(1, S + 1)[:, None]
        rate = np.gradient(w.measured, sconfig.sample_period_s, axis=0)[1:]
        force = w.window_force[w.substeps - 1::w.substeps][:S]
        rows.append((t.T.ravel(), w.measured[1:].transpose(1, 0, 2).reshape(-1, 3),
                     r.transpose(1, 0, 2).reshape(-1, 3), rate.transpose(1, 0, 2).reshape(-1, 3),
                     force.transpose(1, 0, 2).reshape(-1, 2), np.repeat(x.recording, S)))
    t, measured, residual, velocity, force, recording = (np.concatenate(c) for c in zip(*rows))
    return {"t_s": t, "measured": np.c_[measured[:, :2], np.zeros(len(t))],
            "position_error": np.c_[residual[:, :2], np.zeros(len(t))], "residual": residual,
            "velocity": velocity, "force": force, "recording": recording}
