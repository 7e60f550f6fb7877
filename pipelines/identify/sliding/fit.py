"""The sliding fit: theta = (mu, m, I_zz) and the rollout's effects by L-BFGS-B on the tape's gradient."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .body import PlanarBody, SlidingConfig
from .rollout import EFFECT_SIZE, EFFECT_SLOTS, SlidingRollout, replay_errors, sliding_windows
from .windows import PushWindows


@dataclass(frozen=True)
class SlidingFit:
    """Result of `identify_sliding`.

    theta: (mu, mass [kg], I_zz [kg m^2]); std: their standard deviations from the
    curvature at the optimum, start velocities profiled out (residuals treated as
    independent, so optimistic); determined: per parameter, whether the data at
    least halve the prior's variance (else the value is essentially the prior's
    and is marked "prior"); mu is not determined when the simulation sticks in every window in which
    the object moved.
    effect [EFFECT_SIZE], effect_std: the fitted effect vector (zeros where no effect was
    fitted; see apply_sliding_effects) and the standard deviations of its fitted slots.
    rmse_position_m, rmse_heading_rad: windowed replay at theta over the fitted
    windows, each started at its fitted velocity.
    loss_history: objective per evaluation.
    """

    theta: np.ndarray
    std: np.ndarray
    determined: tuple[bool, bool, bool]
    rmse_position_m: float
    rmse_heading_rad: float
    window_count: int
    evaluations: int
    loss_history: list = field(default_factory=list)
    correction: np.ndarray | None = None
    """Fitted start-velocity corrections per window [W, 3]: vx, vy [m/s], yaw rate [rad/s]."""
    effect: np.ndarray = field(default_factory=lambda: np.zeros(EFFECT_SIZE))
    effect_std: np.ndarray = field(default_factory=lambda: np.zeros(EFFECT_SIZE))
    sliding_windows: int = 0
    """Windows in which the simulation at theta slides where the measured object moves (`sliding_windows`);
    with none while the object moved, mu is a lower bound and not determined."""

    def provenance(self) -> dict:
        names = ("friction", "mass", "izz")
        return {
            "theta": dict(zip(names, map(float, self.theta))),
            "std": dict(zip(names, map(float, self.std))),
            "determined_by_data": dict(zip(names, self.determined)),
            "windows": self.window_count,
            "sliding_windows": self.sliding_windows,
            "evaluations": self.evaluations,
            "rmse_position_m": self.rmse_position_m,
            "rmse_heading_rad": self.rmse_heading_rad,
        }


_EFFECT_SCALE = np.array([0.05, 0.05, 0.5, 1e-3, 0.005, 0.002, 0.002])
"""Typical sizes of the effect slots (force offset [N], drag [N s/m], turning drag [N m s], delay [s],
contact offset [m]): the optimiser's units."""


def _effect_bounds(config: SlidingConfig) -> tuple:
    """Drag is passive (it only takes energy out); a delay stays within the force kept beyond the windows; a
    contact offset within 2 cm (a calibration, not a different contact)."""
    return ((-5.0, 5.0), (-5.0, 5.0), (0.0, 50.0), (0.0, 0.5), (-config.max_delay_s, config.max_delay_s),
            (-0.02, 0.02), (-0.02, 0.02))


def friction_start(rollout: SlidingRollout, theta, mu_bounds: tuple[float, float], coarse: int = 17,
                   fine: int = 9) -> float:
    """The mu a gradient fit starts from: the best of a log scan over `mu_bounds`, refined between the best
    point's neighbours, at theta's mass and I_zz.

    Across stick and slip the loss in mu has plateaus and kinks: started from a prior above the truth, most
    windows stick, the gradient is zero or a line search fails, and L-BFGS-B returns the start (a MuJoCo
    push fitted at its prior, mu +10 %). A scan costs a forward rollout per point."""
    def loss(mu):
        return float(np.sum(rollout.residuals(np.r_[mu, theta[1:]]) ** 2))

    grid = np.geomspace(*mu_bounds, coarse)
    best = int(np.argmin([loss(mu) for mu in grid]))
    grid = np.geomspace(grid[max(best - 1, 0)], grid[min(best + 1, coarse - 1)], fine)
    return float(grid[int(np.argmin([loss(mu) for mu in grid]))])


def identify_sliding(
    windows: PushWindows,
    body: PlanarBody,
    config: SlidingConfig,
    mu_prior: float = 0.3,
    free: tuple[bool, bool, bool] = (True, True, True),
    device: str = "cpu",
    effects: tuple[str, ...] = (),
) -> SlidingFit:
    """Fit theta = (mu, m, I_zz), and the parameters of `effects` (names of EFFECT_SLOTS), to the
    windows by L-BFGS-B on the tape's gradient.

    The objective is the pose loss over sigma^2 (sigma: the fit's own residual
    RMS, refitted once) plus the log-normal prior of m and I_zz; mu and the
    effects have only their bounds. `free` freezes parameters at their prior
    (e.g. free=(True, False, False)).
    """
    from scipy.optimize import minimize

    rollout = SlidingRollout(windows, body, config, device)
    W = windows.window_count
    prior = np.log([mu_prior, body.mass_kg, body.izz_kgm2])
    prior_std = np.array([np.inf, body.mass_rel_std, body.izz_rel_std])
    prior_curv = np.where(np.isfinite(prior_std), 1.0 / prior_std**2, 0.0)
    lo = np.log([config.mu_bounds[0], body.mass_kg / 4, body.izz_kgm2 / 4])
    hi = np.log([config.mu_bounds[1], body.mass_kg * 4, body.izz_kgm2 * 4])
    free_idx = np.flatnonzero(free)
    slots = [k for name in effects for k in EFFECT_SLOTS[name]]
    k = len(free_idx)
    g = k + len(slots)  # global parameters: free theta (log) and effect slots (in _EFFECT_SCALE units)
    # corrections are optimised in units of a typical start-rate error: 1 cm/s and 0.1 rad/s
    c_scale = np.tile([0.01, 0.01, 0.1], W)
    history: list[float] = []
    n_res = windows.sample_count * W * 3

    def split(x):
        u = prior.copy()
        u[free_idx] = x[:k]
        e = np.zeros(EFFECT_SIZE)
        e[slots] = x[k:g] * _EFFECT_SCALE[slots]
        return u, e, (x[g:] * c_scale).reshape(W, 3)

    def data_gradient(x, sigma2):
        u, e, c = split(x)
        theta = np.exp(u)
        loss, g_theta, g_c, g_e = rollout.loss_and_grad(theta, c, e)
        return 0.5 * loss / sigma2, np.concatenate([(0.5 * g_theta * theta / sigma2)[free_idx],
                                                    0.5 * g_e[slots] * _EFFECT_SCALE[slots] / sigma2,
                                                    0.5 * g_c.ravel() * c_scale / sigma2])

    def objective(x, sigma2):
        value, grad = data_gradient(x, sigma2)
        u, _, _ = split(x)
        value += 0.5 * np.sum(prior_curv * (u - prior) ** 2)
        grad[:k] += (prior_curv * (u - prior))[free_idx]
        history.append(float(value))
        return value, grad

    # the data's weight against the prior is 1 / sigma^2: fitted at a typical tracker error first,
    # then again at the residual level that fit leaves
    x = np.concatenate([prior[free_idx], np.zeros(len(slots)), np.zeros(3 * W)])
    bounds = (list(zip(lo[free_idx], hi[free_idx]))
              + [(a / sc, b / sc) for a, b, sc in ((*_effect_bounds(config)[j], _EFFECT_SCALE[j]) for j in slots)]
              + [(-20.0, 20.0)] * (3 * W))
    def fit(x):
        sigma2 = (1e-3) ** 2
        for _ in range(2):
            x = minimize(objective, x, args=(sigma2,), jac=True, method="L-BFGS-B", bounds=bounds,
                         options={"maxiter": config.max_iterations, "ftol": 1e-10, "gtol": 1e-8}).x
            u, e, c = split(x)
            sigma2 = max(float(np.sum(rollout.residuals(np.exp(u), c, e) ** 2)) / n_res, 1e-12)
        return x, sigma2

    if free[0]:
        x[0] = np.log(friction_start(rollout, np.exp(prior), config.mu_bounds))
    x, sigma2 = fit(x)
    u, effect, correction = split(x)
    theta = np.exp(u)
    moving, slides = sliding_windows(rollout, theta, correction, effect)
    if free[0] and moving.any() and not slides.any():
        # stuck: on that plateau the gradient in mu is zero (newton.md), so a sliding fit below it is found by
        # a scan, and the fit restarted from the scan's best if that beats sticking
        scan = np.geomspace(config.mu_bounds[0], theta[0], 13)[:-1]
        losses = [float(np.sum(rollout.residuals(np.r_[mu, theta[1:]], correction, effect) ** 2)) for mu in scan]
        if min(losses) < sigma2 * n_res:
            x[0] = np.log(scan[int(np.argmin(losses))])
            x, sigma2 = fit(x)
            u, effect, correction = split(x)
            theta = np.exp(u)
            moving, slides = sliding_windows(rollout, theta, correction, effect)

    # curvature of the data term, Gauss-Newton: J^T J / sigma^2 from central differences of the residuals.
    # Across stick and slip the loss has kinks, where differences of the gradient gave an indefinite
    # Hessian (a MuJoCo push: mu reported undetermined while six windows slid); J^T J is never indefinite.
    # Each window's corrections touch only its own residuals, so three perturbations (one per component, all
    # windows at once) give their Jacobian blocks; the globals take one each.
    h = 1e-2
    n = g + 3 * W

    def jacobian_column(step):
        u_p, e_p, c_p = split(x + step)
        u_m, e_m, c_m = split(x - step)
        return (rollout.residuals(np.exp(u_p), c_p, e_p) - rollout.residuals(np.exp(u_m), c_m, e_m)) / (2 * h)

    J_t = np.stack([jacobian_column(np.eye(n)[j] * h) for j in range(g)], axis=-1)  # [S, W, 3, g]
    J_c = np.zeros((*J_t.shape[:3], 3))  # [S, W, 3, 3]: each window's residuals by its own corrections
    for comp in range(3):
        step = np.zeros(n)
        step[g + comp::3] = h
        J_c[..., comp] = jacobian_column(step)
    J_t = J_t.transpose(1, 0, 2, 3).reshape(W, -1, g) / np.sqrt(sigma2)
    J_c = J_c.transpose(1, 0, 2, 3).reshape(W, -1, 3) / np.sqrt(sigma2)
    # the globals' information with every window's start velocity profiled out (Schur complement)
    H = sum(J_t[w].T @ J_t[w] - (J_t[w].T @ J_c[w]) @ np.linalg.pinv(J_c[w].T @ J_c[w]) @ (J_c[w].T @ J_t[w])
            for w in range(W))
    H = 0.5 * (H + H.T)
    H_post = H + np.diag(np.r_[prior_curv[free_idx], np.zeros(len(slots))])
    cov = np.linalg.pinv(H_post)
    var = np.maximum(np.diag(cov), 0.0)
    std_log = np.array(prior_std, dtype=float)
    # a parameter the loss is flat in (e.g. mu while every window sticks) has no curvature: unknown, not exact
    std_log[free_idx] = np.where(np.diag(H_post)[:k] > 1e-12, np.sqrt(var[:k]), np.inf)
    # a simulated object that sticks in every window, where the real one moved, only bounds mu from below: the
    # curvature there is the cost of sliding at a smaller mu, not a measurement of mu
    sliding = int(np.sum(slides))
    if moving.any() and sliding == 0:
        std_log[0] = np.inf
    # determined: the data at least halve the prior's variance (mu has no prior: determined when it has curvature)
    determined = tuple(bool(free[i] and np.isfinite(std_log[i])
                            and (not np.isfinite(prior_std[i]) or std_log[i] ** 2 < 0.5 * prior_std[i] ** 2))
                       for i in range(3))
    std = theta * np.where(np.isfinite(std_log), std_log, 0.0)
    effect_std = np.zeros(EFFECT_SIZE)
    effect_std[slots] = np.sqrt(var[k:g]) * _EFFECT_SCALE[slots]
    rmse_p, rmse_h = replay_errors(rollout, theta, correction, effect)
    return SlidingFit(theta, std, determined, rmse_p, rmse_h, W, len(history), history, correction=correction,
                      effect=effect, effect_std=effect_std, sliding_windows=sliding)
