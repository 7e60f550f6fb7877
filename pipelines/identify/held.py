"""The identify stage for a held object: the posterior (least squares' likelihood fused with the geometry
prior, posterior.py), the Newton fit from it, and held-out selection.

Inputs are recordings as `pipelines.logs` reads them (wrench in world axes
about the tracked origin), the scan placement and the prior. The rule that
picks the kept estimate: the posterior is kept, unless the Newton fit started
from it predicts the held-out recording better by more than twice the standard
error of the paired window differences (`_predicts_better`). Without a held-out
recording the posterior is kept: the Newton fit is driven by the noisy wrench
(biased, efficiency 0.13-0.88 in `twin bench crlb`) and ignores the prior but
for its bounds. The choice is said in words (`HeldIdentification.choice`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Callable, Literal

import numpy as np

from assets import COM, MASS, FitMetrics, Inertial, Pose, flat_inertial, symmetric_from_flat

from .free_body import Identification, IdentifyConfig, InertialBounds, identify_free_body, prior_starts
from .inertia import nearest_physical_inertia, theta_from_physical
from .least_squares import LeastSquaresResult, identify_least_squares
from .posterior import PosteriorConfig, PosteriorResult, data_term_from_least_squares, identify_posterior
from .rollout import FreeBodyRollout
from .windows import ShootingWindows, concat_windows, make_windows

Method = Literal["newton", "ls"]


@dataclass(frozen=True)
class HeldIdentification:
    """The kept estimate, its covariance over (mass, com xyz, Ixx Iyy Izz Ixy Ixz Iyz), and the evidence.

    candidates: each estimate by name ("baseline" is the prior); fits: windowed
    replay of the evaluation recording (held-out if given) per candidate;
    impulse_rms: the same replay's momentum-scaled RMS (position, rotation);
    traces: positions for the report.
    """

    inertial: Inertial
    covariance: np.ndarray
    selected: str
    candidates: dict
    fits: dict
    impulse_rms: dict
    traces: dict
    loss_history: tuple[float, ...]
    least_squares: LeastSquaresResult
    newton: Identification | None
    heldout: bool
    posterior: PosteriorResult | None = None
    choice: str = ""
    """Which estimate was kept and why, in words."""
    prior_dominated: tuple[str, ...] = ()
    """Flat parameters (`assets.FLAT_INERTIAL`) the recordings could not determine: the kept value is mostly
    the prior's."""

    def provenance(self) -> dict:
        out = {
            "selected": self.selected,
            "choice": self.choice,
            "prior_dominated": list(self.prior_dominated),
            "posterior": self.posterior.provenance() if self.posterior else None,
            "candidates": {k: {"mass": v.mass, "com": list(v.com), "inertia": [list(r) for r in v.inertia]}
                           for k, v in self.candidates.items()},
            "least_squares": {"cutoff_hz": self.least_squares.cutoff_hz, "samples": self.least_squares.sample_count},
            "newton": self.newton.provenance() if self.newton else None,
        }
        fits = {k: asdict(v) | {"impulse_rms": self.impulse_rms[k]} for k, v in self.fits.items()}
        out["heldout_fits" if self.heldout else "trial_fits"] = fits
        return out


def tracked_to_object(recording, placement: Pose) -> Pose:
    """The object frame in the tracked frame, from the scan placement and the still poses it starts with.

    The object sits at its placement when the recording starts. The still
    stretch ends where the 0.1 s running mean of the tracked position leaves
    the first 0.1 s's mean by more than four standard errors of the tracker's
    noise (measured on the recording); averaging the whole stretch beats the
    noise of any one sample (0.2 mm on a tracker of the sample recordings).
    """
    from scipy.spatial.transform import Rotation

    from .noise import recording_noise_levels

    pose = recording.pose
    noise = recording_noise_levels(recording)
    n = max(1, int(np.sum(pose.t_s <= pose.t_s[0] + 0.1)))
    running = np.cumsum(np.vstack([np.zeros(3), pose.position]), axis=0)
    running = (running[n:] - running[:-n]) / n  # mean of samples i .. i+n-1
    drift = np.abs(running - running[0]).max(axis=1)
    moved = np.flatnonzero(drift > 4 * np.sqrt(2.0 / n) * noise.position_m)
    still = int(moved[0]) if len(moved) else len(pose.t_s)
    rotation = Rotation.from_quat(pose.quat_xyzw[:still]).mean()
    T_world_tracked = Pose(tuple(pose.position[:still].mean(axis=0)), tuple(rotation.as_quat()))
    return T_world_tracked.inverse() @ placement


def identify_held(
    trials: list,
    holdout,
    X_tracked_body: Pose,
    prior: Inertial,
    bounds: InertialBounds,
    config: IdentifyConfig,
    method: Method = "newton",
    progress: Callable[[int, float], None] | None = None,
    *,
    parts: np.ndarray | None = None,
    posterior_config: PosteriorConfig = PosteriorConfig(),
) -> HeldIdentification:
    """Identify the held body from `trials` (Recordings); `holdout` (a Recording or None) selects and validates.

    The posterior fuses every trial's least-squares likelihood with the prior (uniform density at the
    prior's mass; per-part densities when `parts` [K, 4, 4], pseudo-inertias per unit density in the
    object frame, are given). method "newton" also runs the Newton fit from the posterior (and the prior's
    spread, `config.starts`); "ls" skips it. The module docstring states the rule that picks the kept one.
    """
    fits_ls = [identify_least_squares(r.pose.t_s, r.pose.position, r.pose.quat_xyzw, r.wrench.t_s, r.wrench.force,
                                      r.wrench.torque, X_tracked_body) for r in trials]
    ls = fits_ls[0]
    notes = []
    ls_body = _physical_or_none(ls.inertial) if ls.pi is None or ls.pi[0] > 0 else None
    if ls_body is None:
        notes.append("least squares is not a physical body (not replayed)")
    posterior = identify_posterior([data_term_from_least_squares(f.pi, f.normal, f.meat) for f in fits_ls],
                                   X_tracked_body, prior, (bounds.lower[MASS], bounds.upper[MASS]), parts,
                                   posterior_config, extra_starts={"least_squares": ls_body})
    candidates = {"baseline": prior}
    if ls_body is not None:
        candidates["least_squares"] = ls_body
    candidates["posterior"] = posterior.inertial
    newton = None
    if method == "newton":
        starts = [posterior.inertial] + prior_starts(prior, bounds, config.starts - 1, config.seed)
        try:
            newton = identify_free_body(windows_from_recordings(trials, config), X_tracked_body, starts, bounds,
                                        config, progress)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
            notes.append(f"the Newton fit failed ({exc})")
        if newton is not None:
            candidates["newton"] = newton.inertial

    thetas = {"posterior": posterior.theta, **({"newton": newton.theta} if newton is not None else {})}
    fits, window_impulse, traces = _replay(holdout or trials[0], X_tracked_body, candidates, config, thetas)
    for label in [k for k in candidates if k not in fits]:
        notes.append(f"{label} is not a body that can be replayed (left out)")
        del candidates[label]
    impulse = {k: np.sqrt(v.mean(axis=0)).tolist() for k, v in window_impulse.items()}
    selected = "posterior"
    if "newton" not in candidates:
        choice = ("posterior: the recordings' least-squares likelihood fused with the geometry prior"
                  + ("" if method == "newton" else " (the Newton fit was not asked for)"))
    elif holdout is None:
        choice = ("posterior: without a held-out recording the Newton fit, driven by the noisy wrench, cannot show "
                  "that it predicts better")
    elif _predicts_better(window_impulse, "newton", "posterior"):
        selected = "newton"
        choice = ("Newton fit: it predicts the held-out recording better than the posterior by more than twice "
                  "the standard error of the paired window differences")
    else:
        choice = ("posterior: the Newton fit from it does not predict the held-out recording significantly "
                  "better")
    if not posterior.moved:
        choice += f"; the posterior solver did not move from its start ({posterior.start}): {posterior.message}"
    if notes:
        choice += "; " + "; ".join(notes)
    inertial, covariance = ((newton.inertial, newton.covariance) if selected == "newton"
                            else (posterior.inertial, posterior.covariance))
    traces = {"t_s": traces["t_s"], "measured_position": traces["measured_position"], "window_s": traces["window_s"],
              "baseline_position": traces.get("baseline_position", traces[f"{selected}_position"]),
              "final_position": traces[f"{selected}_position"]}
    return HeldIdentification(
        inertial=inertial, covariance=covariance, selected=selected, candidates=candidates, fits=fits,
        impulse_rms=impulse, traces=traces, loss_history=newton.loss_history if newton else (), least_squares=ls,
        newton=newton, heldout=holdout is not None, posterior=posterior, choice=choice,
        prior_dominated=posterior.prior_dominated if selected == "posterior" else (),
    )


def _physical_or_none(body: Inertial | None) -> Inertial | None:
    """`body` with its inertia moved to the nearest physical one (the replay needs a log-Cholesky theta), or
    None when no such body exists (a mass that is not positive and finite)."""
    if body is None or not np.isfinite(body.mass) or body.mass <= 0:
        return None
    try:
        fixed = Inertial(body.mass, body.com, nearest_physical_inertia(body.mass, body.inertia))
        theta_from_physical(fixed.mass, fixed.com, fixed.inertia_matrix())
    except (ValueError, np.linalg.LinAlgError):
        return None
    return fixed if np.all(np.isfinite(fixed.inertia_matrix())) and np.all(np.isfinite(fixed.com)) else None


def with_weighed_mass(body: Inertial, covariance: np.ndarray, mass_kg: float,
                      std_kg: float) -> tuple[Inertial, np.ndarray]:
    """An estimate and its covariance conditioned on a weighing, a Gaussian measurement of the mass.

    The flat parameters (mass, COM xyz, Ixx Iyy Izz Ixy Ixz Iyz) take the linear (Kalman) update
    through their covariance, so COM and inertia move as far as the recordings tie them to the mass.
    Where the update would leave the inertia unphysical, the nearest physical one is kept.
    """
    x = flat_inertial(body)
    cov = np.asarray(covariance, dtype=float)
    gain = cov[:, MASS] / (cov[MASS, MASS] + std_kg**2)
    x = x + gain * (mass_kg - x[MASS])
    cov = cov - np.outer(gain, cov[MASS, :])
    mass = float(x[MASS])
    return Inertial(mass, tuple(x[COM]), nearest_physical_inertia(mass, symmetric_from_flat(x))), cov


def windows_from_recordings(recordings, config: IdentifyConfig) -> ShootingWindows:
    """Back-to-back shooting windows of every recording, batched, smoothed as `config` says."""
    return concat_windows(
        [
            make_windows(r.pose.t_s, r.pose.position, r.pose.quat_xyzw, r.wrench.t_s, r.wrench.force,
                         r.wrench.torque, window_s=config.window_s, substeps=config.substeps,
                         smoothing_hz=config.smoothing_hz)
            for r in recordings
        ]
    )


def newton_starts(least_squares: Inertial, prior: Inertial, bounds: InertialBounds,
                  config: IdentifyConfig) -> list[Inertial]:
    """The Newton fit's starts: least squares first, then `config.starts - 1` from the prior's spread."""
    return [_clip_into_bounds(least_squares, prior, bounds)] + prior_starts(prior, bounds, config.starts - 1,
                                                                            config.seed)


def _clip_into_bounds(inertial: Inertial, prior: Inertial, bounds: InertialBounds) -> Inertial:
    """The least-squares estimate moved inside C and made physical, or the prior if it cannot be."""
    m = float(np.clip(inertial.mass, bounds.lower[MASS], bounds.upper[MASS]))
    c = np.clip(inertial.com, bounds.lower[COM], bounds.upper[COM])
    candidate = Inertial(m, c, np.asarray(inertial.inertia) * (m / inertial.mass))
    d, _ = candidate.principal()
    if candidate.physical_violation() is not None or d[0] < 1e-3 * d[2]:
        return prior
    return candidate


def _replay(recording, X_tracked_body: Pose, candidates: dict, config: IdentifyConfig,
            thetas: dict | None = None):
    """Windowed replay from measured (unsmoothed) states for each candidate body, side by side.

    thetas: log-Cholesky parameters of candidates that have them (exact, where converting a body on the edge
    of the triangle inequality back could fail); a candidate with neither is converted, moved to the nearest
    physical inertia if it must be, and left out of the results if even that fails. Returns FitMetrics per
    candidate, its momentum-scaled mean squares per window [W, 2] (position, rotation), and position traces.
    """
    thetas = dict(thetas or {})
    for label, body in candidates.items():
        if label not in thetas:
            fixed = _physical_or_none(body)
            if fixed is not None:
                thetas[label] = theta_from_physical(fixed.mass, fixed.com, fixed.inertia_matrix())
    candidates = {k: v for k, v in candidates.items() if k in thetas}
    windows = windows_from_recordings([recording], replace(config, smoothing_hz=None))
    rollout = FreeBodyRollout(windows, X_tracked_body, sets=len(candidates), device=config.device)
    t = windows.t_start_s[None, :] + windows.dt_s * windows.substeps * np.arange(1, windows.sample_count + 1)[:, None]
    measured = windows.measured_position[1:]
    traces = {"t_s": t.T.reshape(-1).tolist(), "measured_position": measured.transpose(1, 0, 2).reshape(-1, 3).tolist(),
              "window_s": windows.window_s}
    fits, window_impulse = {}, {}
    thetas = np.stack([thetas[k] for k in candidates])
    all_scaled = rollout.residuals(thetas, momentum_scaled=True)
    all_plain = rollout.residuals(thetas, momentum_scaled=False)
    for k, label in enumerate(candidates):
        scaled = all_scaled[:, k]
        window_impulse[label] = np.stack([np.mean(np.sum(scaled[..., :3] ** 2, -1), axis=0),
                                          np.mean(np.sum(scaled[..., 3:] ** 2, -1), axis=0)], axis=1)
        r = all_plain[:, k]
        rp, rr = r[..., :3], r[..., 3:]
        fits[label] = FitMetrics(
            rmse_position_m=float(np.sqrt(np.mean(np.sum(rp**2, -1)))),
            rmse_rotation_rad=float(np.sqrt(np.mean(np.sum(rr**2, -1)))),
            loss=float(np.mean(np.sum(rp**2, -1) + np.sum(rr**2, -1))),
        )
        traces[f"{label}_position"] = (measured + rp).transpose(1, 0, 2).reshape(-1, 3).tolist()
    return fits, window_impulse, traces


def _predicts_better(window_impulse: dict, label: str, reference: str) -> bool:
    """Whether `label` predicts the held-out windows better than `reference` by more than twice the
    standard error of the paired difference (windows are nearly independent).

    Errors are momentum-scaled (see eval_tracked_pose_error), each channel relative to the
    reference's mean: the plain pose error favours too-large inertia when the wrench is noisy;
    scaled by each candidate's own mass and inertia it ranks them without that bias. Requiring a
    significant gain keeps the candidate known to be efficient (least squares, see `twin bench crlb`)
    unless the data say otherwise.
    """
    ref = window_impulse[reference]
    d = ((window_impulse[label] - ref) / np.maximum(ref.mean(axis=0), 1e-300)).sum(axis=1)
    return bool(d.mean() + 2 * d.std(ddof=1) / np.sqrt(len(d)) < 0)
