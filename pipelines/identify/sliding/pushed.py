"""Pushed-object identification as the build runs it: the support model chosen by prediction, the fit, the
wrench balance, the turn check and the replay."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .balance import TurnCheck, WrenchBalance, measured_friction, turn_check, wrench_balance_friction
from .body import SUPPORTS, PlanarBody, SlidingConfig
from .fit import SlidingFit, identify_sliding
from .rollout import SlidingRollout, replay_errors
from .windows import PushWindows, concat_push_windows, estimate_force_bias, push_windows


@dataclass(frozen=True)
class SupportChoice:
    """Which support model (`SUPPORTS`) `identify_pushed` kept, and why.

    support: the model kept; evaluated_on: "held-out recording" or "trial halves" (each half of every
    trial's windows predicted by a fit on the other half); per candidate, the prediction's position RMSE
    [m], heading RMSE [rad] and loss (sum of squared x, y and arc residuals [m^2]) on those windows.
    """

    support: str
    evaluated_on: str
    rmse_position_m: dict
    rmse_heading_rad: dict
    loss_m2: dict

    @property
    def words(self) -> str:
        """The choice in a sentence (asset.json provenance, the build's log)."""
        other = [s for s in self.loss_m2 if s != self.support]
        told = ", ".join(f"{s}: {1e3 * self.rmse_position_m[s]:.2f} mm, {np.degrees(self.rmse_heading_rad[s]):.2f} deg"
                         for s in (self.support, *other))
        margin = min((self.loss_m2[s] / max(self.loss_m2[self.support], 1e-30) for s in other), default=1.0)
        return (f"support {self.support!r}: its fit predicts the {self.evaluated_on} better ({told}; the next "
                f"best's squared error is {margin:.2f}x)")

    def provenance(self) -> dict:
        return {"model": self.support, "chosen_by": self.evaluated_on, "why": self.words,
                "rmse_position_m": self.rmse_position_m, "rmse_heading_rad": self.rmse_heading_rad,
                "loss_m2": self.loss_m2}


def _take(windows: PushWindows, mask: np.ndarray) -> PushWindows:
    return PushWindows(windows.dt_s, windows.substeps, windows.t_start_s[mask], windows.start[mask],
                       windows.force[:, mask], windows.contact[:, mask], windows.measured[:, mask],
                       windows.force_margin)


def _prediction(fit_on: PushWindows, check: PushWindows, body: PlanarBody, config: SlidingConfig, mu_prior: float,
                device: str) -> tuple[SlidingFit, np.ndarray]:
    """The fit on `fit_on` and its residuals [S, W, 3] predicting `check` (windows started at their measured
    velocities), at the friction `measured_friction` reports."""
    fit = identify_sliding(fit_on, body, config, mu_prior=mu_prior, free=(True, config.fit_mass, True), device=device)
    measured = measured_friction(fit, wrench_balance_friction(fit_on, body, config))
    theta = np.r_[measured[0] if measured is not None else fit.theta[0], fit.theta[1:]]
    return fit, SlidingRollout(check, body, config, device).residuals(theta)


def choose_support(windows: PushWindows, check: PushWindows | None, body: PlanarBody, mu_prior: float,
                   config: SlidingConfig, supports: tuple[str, ...] = SUPPORTS,
                   device: str = "cpu") -> tuple[SupportChoice, dict] | None:
    """Fit each support model of `supports` and keep the one that predicts better: the held-out windows
    `check` from a fit on all of `windows`, or without them each half of `windows` (in time) from a fit on
    the other. Returns the choice and, with `check`, the fits on all windows per support (so the kept one
    is not fitted twice); None when there is nothing to predict (one window, no held-out recording)."""
    if check is None:
        W = windows.window_count
        if W < 2:
            return None
        first = np.arange(W) < W / 2
        folds = [(_take(windows, first), _take(windows, ~first)), (_take(windows, ~first), _take(windows, first))]
    else:
        folds = [(windows, check)]
    fits, residuals = {}, {}
    for support in supports:
        c = replace(config, support=support)
        runs = [_prediction(a, b, body, c, mu_prior, device) for a, b in folds]
        if check is not None:
            fits[support] = runs[0][0]
        residuals[support] = np.concatenate([r for _, r in runs], axis=1)
    length = config.yaw_length_m or float(np.hypot(*body.half_extents_m[:2]))
    loss = {s: float(np.sum(r**2)) for s, r in residuals.items()}
    chosen = min(loss, key=loss.get)
    choice = SupportChoice(
        chosen, "held-out recording" if check is not None else "trial halves",
        {s: float(np.sqrt(np.mean(np.sum(r[..., :2] ** 2, axis=-1)))) for s, r in residuals.items()},
        {s: float(np.sqrt(np.mean(r[..., 2] ** 2)) / length) for s, r in residuals.items()}, loss)
    return choice, fits


@dataclass(frozen=True)
class PushedIdentification:
    """What `identify_pushed` gives the build.

    fit: the sliding fit on the trials; biases: the force offset per trial;
    baseline and final: (position RMSE [m], heading RMSE [rad], loss [m^2]) of the
    windowed replay at the prior's and the fitted theta (mu as `measured_friction` gives it), on the
    held-out recording when there is one, else on the trials; traces: the replay for the report
    (positions and headings);
    balance: the quasi-static wrench balance on the trials (None without a steady window), the
    measurement of mu where the fit's simulation sticks throughout (a slow push); turns: `turn_check` of
    the trials' windows. Where some window turns against its pushing moment, the turning has a cause the
    model lacks, and the I_zz a fit needs to follow it is a stand-in for that cause, not the body's
    inertia (`turns_explained`).
    config: the settings the fit ran with, `support` the model kept; support: how it was chosen
    (`choose_support`; None when there was one candidate, or nothing to predict).
    """

    fit: SlidingFit
    prior_theta: np.ndarray
    biases: list
    baseline: tuple[float, float, float]
    final: tuple[float, float, float]
    traces: dict
    config: SlidingConfig
    balance: WrenchBalance | None = None
    turns: TurnCheck | None = None
    support: SupportChoice | None = None

    @property
    def turns_explained(self) -> bool:
        """Whether every window's turn is one its pushing moment can give: only then can a fit measure I_zz."""
        return self.turns is None or not bool(self.turns.drives_turn.any())

    def provenance(self) -> dict:
        from dataclasses import asdict

        turns = None if self.turns is None else {
            "windows_against": int(self.turns.drives_turn.sum()), "windows": len(self.turns.drives_turn),
            "izz_balance_kgm2": [float(v) for v in self.turns.izz_balance_kgm2[self.turns.drives_turn]],
            "izz_fitted_kgm2": float(self.fit.theta[2]), "turns_explained": self.turns_explained}
        return {"kind": "sliding", **self.fit.provenance(), "prior_theta": list(map(float, self.prior_theta)),
                "force_bias_world": [b.provenance() for b in self.biases],
                "wrench_balance": self.balance.provenance() if self.balance else None,
                "turn_check": turns, "config": asdict(self.config),
                "support": self.support.provenance() if self.support else {
                    "model": self.config.support, "chosen_by": "setting",
                    "why": f"support {self.config.support!r}: the setting (SlidingConfig.support), not chosen from the data"}}


def identify_pushed(trials, holdout, body: PlanarBody, mu_prior: float, config: SlidingConfig,
                    device: str = "cpu", supports: tuple[str, ...] = ()) -> PushedIdentification:
    """Fit mu (with m and I_zz where the pushes determine them) on all trials; replay the holdout.

    supports: support models (`SUPPORTS`) to choose among: each is fitted and the one that predicts the
    held-out pushes better is kept (`choose_support`; without a holdout, the trials' halves each other),
    `config.support` is replaced by it in the result. Empty or one: `config.support` without a choice.
    """
    biases = [estimate_force_bias(r, config) for r in trials]
    windows = concat_push_windows([push_windows(r, body, config, b) for r, b in zip(trials, biases)])
    check = windows
    if holdout is not None:
        check = push_windows(holdout, body, config, estimate_force_bias(holdout, config))
    chosen, fit = None, None
    if len(set(supports)) > 1:
        found = choose_support(windows, check if holdout is not None else None, body, mu_prior, config,
                               tuple(dict.fromkeys(supports)), device)
        if found is not None:
            chosen, fits = found
            config = replace(config, support=chosen.support)
            fit = fits.get(chosen.support)
    if fit is None:
        fit = identify_sliding(windows, body, config, mu_prior=mu_prior, free=(True, config.fit_mass, True),
                               device=device)
    balance = wrench_balance_friction(windows, body, config)
    prior_theta = np.array([mu_prior, body.mass_kg, body.izz_kgm2])
    # replayed at the friction reported: where the fit only bounds mu, the wrench balance's
    measured = measured_friction(fit, balance)
    final_theta = np.r_[measured[0] if measured is not None else fit.theta[0], fit.theta[1:]]
    rollout = SlidingRollout(check, body, config, device)
    metrics, paths = {}, {}
    for name, theta in (("baseline", prior_theta), ("final", final_theta)):
        r = rollout.residuals(theta)
        p, h = replay_errors(rollout, theta)
        metrics[name] = (p, h, float(np.sum(r**2)))
        paths[name] = rollout.trajectories(theta)
    S = check.sample_count
    t = (check.t_start_s[None, :] + config.sample_period_s * np.arange(S + 1)[:, None]).ravel()

    def xyz(a):
        return np.c_[a[..., :2].reshape(-1, 2), np.zeros(len(t))]

    traces = {"t_s": t, "window_s": S * config.sample_period_s,
              "replayed": "held-out recording" if holdout is not None else "fitted trials",
              **{f"{k}_position": xyz(a) for k, a in (("measured", check.measured), *paths.items())},
              **{f"{k}_heading_rad": a[..., 2].ravel() for k, a in (("measured", check.measured), *paths.items())}}
    return PushedIdentification(fit, prior_theta, biases, metrics["baseline"], metrics["final"], traces, config,
                                balance, turn_check(windows, body, config), chosen)
